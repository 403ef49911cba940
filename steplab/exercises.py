"""Checks for the notebooks' exercises: each compares a student's answer with theory.

Every check prints one line, ``correct: ...`` or ``not yet: ...`` (with a hint), and returns
whether the answer is right, so a notebook can be run top to bottom with the exercises still
open, and its solutions variant can ``assert`` each check. The answers are never the code's
own earlier output: they come from closed forms (a bounce loses eps^2 of its height, a ball
tunnels when v dt exceeds the wall plus its diameter), from order conditions, and, for the
stability limit, from the exercise's own experiment (the check runs it at the answer and a step
3 % longer), set beside the stiffest-mode prediction that ``steplab check`` prints.
"""

from __future__ import annotations

import numpy as np

#: how close a measured order must be to the true one (the truncation study's fit is ~0.01 off)
ORDER_TOLERANCE = 0.1
#: relative tolerance of a predicted number (a height, a speed): generous, it is a prediction
RELATIVE_TOLERANCE = 0.02
#: an experimental stability limit is found to within this fraction: a run at the answer holds, one
#: at a step this much longer diverges
LIMIT_TOLERANCE = 0.03
#: the stability exercise's run: a dt is stable when this many steps end without DivergenceError
STABILITY_STEPS = 2000
#: Ralston's method, the 2-stage 2nd order method with the smallest error constant: its
#: entries a_21, b_1, b_2, c_2
RALSTON_ENTRIES = (2 / 3, 1 / 4, 3 / 4, 2 / 3)


def _verdict(ok: bool, correct: str, hint: str) -> bool:
    print(f"correct: {correct}" if ok else f"not yet: {hint}")
    return ok


def _number(x) -> float | None:
    """``x`` as a finite float (a number, or an array of one element, as an answer read from a scene's
    arrays is), or None."""
    try:
        value = float(np.asarray(x, dtype=float).reshape(()))
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None


def _close(x, target: float, rtol: float) -> bool:
    value = _number(x)
    return value is not None and abs(value - target) <= rtol * abs(target)


def check_bounce_height(height, bounce: int = 3, *, restitution: float = 0.858, drop_height: float = 0.92) -> bool:
    """The height the ``bounce``-th bounce reaches: each bounce keeps eps^2 of the height before."""
    expected = restitution ** (2 * bounce) * drop_height
    return _verdict(_close(height, expected, RELATIVE_TOLERANCE),
                    f"bounce {bounce} reaches eps^{2 * bounce} H = {expected:.4f} m",
                    f"{height!r} m is not it: the speed after a bounce is eps times the speed before, and "
                    f"the height goes as the speed squared; now bounce {bounce} times")


def check_ralston(tableau, measured_order) -> bool:
    """Ralston's tableau (a_21 = c_2 = 2/3, b = (1/4, 3/4)) and its measured order (2)."""
    from steplab.integrators import ButcherTableau

    if not isinstance(tableau, ButcherTableau):
        return _verdict(False, "", f"a ButcherTableau, please (got {type(tableau).__name__}): "
                        "ButcherTableau(a_lower=((a21,),), b=(b1, b2), c=(c2,))")
    shape_ok = len(tableau.b) == 2 and len(tableau.c) == 1 and len(tableau.a_lower) == 1
    entries = np.concatenate([np.ravel(row) for row in tableau.a_lower] + [np.ravel(tableau.b), np.ravel(tableau.c)])
    entries_ok = shape_ok and np.allclose(entries, RALSTON_ENTRIES, rtol=0, atol=1e-12)
    if not entries_ok:
        b = np.asarray(tableau.b, float)
        c = np.asarray(tableau.c, float) if shape_ok else np.zeros(1)
        # the order conditions of a 2-stage method: sum b = 1 (order 1), b . c = 1/2 (order 2)
        second_order = shape_ok and np.isclose(b.sum(), 1) and np.isclose(b[1] * c[0], 0.5)
        hint = ("second order, but not Ralston's: Ralston takes c_2 = 2/3" if second_order else
                "two stages, sum(b) = 1 and b_2 c_2 = 1/2 for second order; Ralston takes c_2 = 2/3")
        return _verdict(False, "", hint)
    order_ok = _close(measured_order, 2.0, ORDER_TOLERANCE / 2)
    return _verdict(order_ok,
                    f"Ralston's tableau, and a measured order of {_number(measured_order):.2f}: second order"
                    if order_ok else "",
                    f"the tableau is right; the measured order {measured_order!r} is not about 2: fit log(error) "
                    "against log(dt) (fit_order(error_curve(...)))")


def check_stability_limit(dt_found, scene: str = "soft-cube", integrator: str = "semi-implicit-euler",
                          steps: int = STABILITY_STEPS) -> bool:
    """An experimental largest stable dt, by the exercise's definition, set beside ``steplab check``'s prediction.

    The answer is right when a run of ``steps`` steps at ``dt_found`` ends without
    ``DivergenceError`` and one at a step LIMIT_TOLERANCE longer does not: the limit the
    experiment defines, found to within LIMIT_TOLERANCE. The verdict then sets it beside the
    prediction from the stiffest mode that ``steplab check`` prints: ``dt_max`` if that mode were
    undamped, ``damped dt_max`` at its damping ratio (on the soft cube the measured limit lies
    between the two; the other modes are damped differently). Copying a predicted limit is not
    an answer: the undamped one is past the limit the experiment finds.
    """
    from steplab.integrators import DivergenceError, get_integrator, simulate
    from steplab.integrators.stable_dt import stable_steps
    from steplab.physics.scene import load_scene

    loaded = load_scene(scene)
    rows = stable_steps(loaded.model, loaded.y0[0], [get_integrator(integrator)])[1]
    if not rows or rows[0].dt_max is None:  # a solver, an unconditionally stable method, or no spring to limit it
        raise ValueError(f"check_stability_limit: {integrator} has no stability limit on {scene} to find (steplab "
                         "check predicts none); the exercise is for an explicit fixed-step method on a scene "
                         "with springs, such as semi-implicit-euler on soft-cube")
    lo, hi = sorted([rows[0].dt_max_damped, rows[0].dt_max])
    value = _number(dt_found)
    if value is None or value <= 0:
        # a hint guides the experiment; it never prints the limit, which is the answer
        return _verdict(False, "", "no dt yet: start from a dt that runs (the scene's) and one that diverges, "
                        "and bisect between them, calling a run stable when it finishes without DivergenceError")

    def diverges(dt: float) -> int | None:
        """The step at which a run of ``steps`` steps of ``dt`` diverges, or None when it holds."""
        try:
            simulate(loaded.model, integrator, loaded.y0, 0.0, dt=dt, n_steps=steps)
        except DivergenceError as err:
            return err.step
        return None

    failed = diverges(value)
    if failed is not None:
        return _verdict(False, "", f"{value:.4g} s is past the limit: a run of {steps} steps there diverges at "
                        f"step {failed}; keep bisecting downwards")
    longer = value * (1 + LIMIT_TOLERANCE)
    if diverges(longer) is None:
        return _verdict(False, "", f"{value:.4g} s runs, but so does a step {LIMIT_TOLERANCE:.0%} longer: the limit "
                        "is higher; keep bisecting upwards")
    where = "between" if lo <= value <= hi else "outside"
    return _verdict(True, f"{value:.4g} s: {steps} steps there hold, {longer:.4g} s diverges; {where} steplab "
                    f"check's damped ({lo:.4g} s) and undamped ({hi:.4g} s) limits", "")


def check_tunnelling_speed(speed, scene: str = "tunnelling") -> bool:
    """The speed above which overlap testing can miss the scene's wall: (w + 2 r) / dt."""
    from steplab.physics.collision import Box
    from steplab.physics.scene import load_scene

    shot = load_scene(scene)
    walls = [] if shot.collisions is None else [s for s in shot.collisions.shapes if isinstance(s, Box)]
    if len(walls) != 1:
        raise ValueError(f"check_tunnelling_speed: the scene {scene!r} has {len(walls)} box walls; the exercise's "
                         "scene has one (tunnelling)")
    (wall,) = walls
    thickness, radius = float(wall.hi[0] - wall.lo[0]), float(shot.model.radii[0])
    expected = (thickness + 2 * radius) / shot.dt
    return _verdict(_close(speed, expected, RELATIVE_TOLERANCE),
                    f"above (w + 2 r) / dt = {expected:.4g} m/s a step can jump from one side of the wall to "
                    "the other without ever overlapping it",
                    f"{speed!r} m/s is not it: overlap testing sees the ball only at the ends of steps, v dt "
                    "apart; how long is the stretch of x where the ball overlaps the wall?")


def check_position_verlet(stepper, measured_order) -> bool:
    """A drift-kick-drift leapfrog: the same steps as steplab's position Verlet, and order 2."""
    from steplab.integrators import Stepper, simulate
    from steplab.physics.scene import load_scene

    if not isinstance(stepper, Stepper):
        return _verdict(False, "", f"a Stepper instance, please (got {type(stepper).__name__})")
    osc = load_scene("oscillator")
    mine = simulate(osc.model, stepper, osc.y0, 0.0, 1.0, 0.01).y[-1]
    theirs = simulate(osc.model, "position-verlet", osc.y0, 0.0, 1.0, 0.01).y[-1]
    if not np.allclose(mine, theirs, rtol=0, atol=1e-12):
        return _verdict(False, "", "its steps differ from drift-kick-drift: drift the positions half a step, "
                        "kick the velocity a whole step with the force there, drift half a step again")
    order_ok = _close(measured_order, 2.0, ORDER_TOLERANCE / 2)
    return _verdict(order_ok, f"drift-kick-drift, order {_number(measured_order):.2f}" if order_ok else "",
                    f"the steps are right; the measured order {measured_order!r} is not about 2")
