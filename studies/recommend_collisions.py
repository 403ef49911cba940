"""``steplab recommend`` on a scene with collisions: measured with the collisions, not without.

Between impacts a ball under gravity flies a parabola that every second-order method
integrates exactly, so the closed form of the collision-free scene would pass a step of
half a second that never sees the floor. Here every measurement is a run of the lecture's
event loop (earliest impact first, split the step, integrate the rest):

1. **The reference** is the same loop with the most accurate explicit fixed-step method
   (the highest order, rk4) at a fine dt, run again at half that dt to see how well it
   has converged (the two runs' largest position difference); halved again, twice at
   most, while the difference is above a tenth of the tolerance.
2. **Trajectories**, where the reference converged to the tolerance: a candidate's error
   is its largest position error at its own step times (every one of them is a step
   time of the reference too, whose step count is a multiple of the candidate's).
3. **Statistics**, where it did not (many balls: chaos, an impact a few microseconds
   earlier sends a ball elsewhere): the quantities that do converge are compared instead,
   the mechanical energy over time, the impact count and the largest penetration.

As for collision-free scenes, a method is accepted at a dt only if it also passes at
half that dt (no lucky cancellation), and the cheapest accepted run (median wall time
of the NumPy event loop) is the answer. The answer states its impacts beside the
reference's. When nothing passes, :class:`NoCollisionStepError` carries the evidence.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper, get_integrator, simulate
from steplab.integrators.scene_rotation import keeping, solved_rotation
from steplab.integrators.simulate import DivergenceError
from steplab.physics.broadphase import find_pairs
from steplab.physics.collision import ImpactCapError, Sphere, collide

from steplab.core.timing import interleaved_medians

from .recommend import NoFixedStepError, check_dt_max

#: the reference's first dt is at most the finer of the scene's dt and --dt-max divided by
#: this (then halved, and checked): a fixed-step method's error falls at least as dt, so
#: half the step a scene was built for, and a quarter, measure its error at that step
REFERENCE_REFINEMENT = 2
#: runs of the reference at halving dt at most (the first, its check at dt/2, and two more
#: halvings while they differ by more than tol / REFERENCE_MARGIN: a chaotic scene never
#: gets there, but its energy and impacts, the statistics compared instead, settle)
REFERENCE_RUNS = 4
#: the reference has converged once its two finest runs differ by less than tol / this
#: (its own error is then a tenth of what a candidate is allowed)
REFERENCE_MARGIN = 10
#: statistics: the largest difference in mechanical energy over time, as a fraction of the
#: largest |energy| of the reference run: 2 % of the energy is 1 % of the speeds (E ~ v^2)
ENERGY_RTOL = 0.02
#: statistics: the impact count may differ by this fraction (at least one impact): in a
#: chaotic scene the reference itself, at dt and dt/2, differs by a few per cent
IMPACT_RTOL = 0.1
#: wall-time repeats of the recommended run (median)
TIMING_REPEATS = 3
#: the most steps of a reference run (the NumPy event loop: a minute or so for a few bodies); a finer
#: reference, from a small --dt-max or a long run, is refused in one line before any run
REFERENCE_MAX_STEPS = 2**20
#: the finest candidate dt, in reference dts: a candidate at the reference's dt is the
#: reference, and its check at dt/2 needs one more
FINEST_CANDIDATE = 2


class NoCollisionStepError(NoFixedStepError):
    """No candidate meets the tolerance on a collision scene; ``evidence`` is the record."""

    def __init__(self, message: str, evidence: dict):
        super().__init__(message)
        self.evidence = evidence


class CollisionProblem(NamedTuple):
    """The run a step is recommended for: ``model`` from ``y0`` (2, N, 3) over [``t_start``,
    ``t_end``] (s), with the collisions of ``world`` (a physics.collision.CollisionWorld, with
    the detector to use); ``rigid_bodies`` (physics.rigid_body.RigidBodies), the scene's rotating
    bodies, whose spin 1/2 omega . I omega counts in the energy where the collisions turn them."""

    model: object
    y0: np.ndarray
    t_start: float
    t_end: float
    world: object
    rigid_bodies: object = None


def recommend_with_collisions(problem: CollisionProblem, tol: float, *, scene_dt: float, dt_max: float | None = None,
                              integrators=None, progress: bool = False) -> dict:
    """The cheapest fixed-step integrator and dt meeting ``tol`` on a scene with collisions.

    Parameters
    ----------
    problem : CollisionProblem
        The scene's model, initial state, interval and collisions.
    tol : float
        Largest position error over the run (trajectories), m; in the statistics regime the
        largest penetration, m (energy and impacts have their own tolerances, above).
    scene_dt : float
        The step the scene was built for, s: it sets the reference's dt.
    dt_max : float, optional
        Largest dt considered, s (a frame, 1/60). Default: a quarter of the run.
    integrators : sequence of str, optional
        Candidates (fixed-step). Default: every fixed-step method.
    progress : bool
        Show a progress bar (tqdm) over the reference and the candidate methods.

    Returns
    -------
    dict
        ``integrator, dt, steps, error, seconds`` as for a collision-free scene, and
        ``impacts``, ``regime`` ("trajectories" or "statistics"), ``reference`` (its
        integrator, dt, steps, impacts, ``convergence`` in m, ``converged``), the run's
        ``energy_error`` and ``penetration``, and ``note`` in the statistics regime.

    Raises
    ------
    NoCollisionStepError
        Nothing passes; the message names the best candidate and its errors.
    """
    model, world = problem.model, problem.world
    span = problem.t_end - problem.t_start
    dt_max = span / 4 if dt_max is None else dt_max
    check_dt_max(span, dt_max)  # also a count too large for a float (dt_max = 1e-320)
    coarsest = max(1, math.ceil(span / dt_max * (1 - 1e-12)))  # steps of the largest candidate dt
    only = solver_integrator(world)
    if only is None:
        names = list(integrators) if integrators is not None else [
            n for n, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    else:  # the contact solver steps with one integrator: the candidates and the reference are it
        other = next((n for n in integrators or () if get_integrator(n).name != only), None)
        if other is not None:
            raise ValueError(f"--integrators: this scene's collisions are the contact solver ([collisions] method "
                             f"= \"solver\"), which steps with {only} only (velocities, contacts, then positions, "
                             f"per substep), not {other}; give --integrators {only}, or leave it out")
        names = [only]
    first = first_reference_steps(span, coarsest, min(scene_dt, dt_max), REFERENCE_MAX_STEPS, "collisions")
    from tqdm import tqdm

    # one tick for the reference, one per candidate method; shown after a second
    bar = tqdm(total=len(names) + 1, desc="recommend: reference", unit="method", disable=not progress,
               leave=False, delay=1.0)
    reference = _reference(problem, tol, first, only or _reference_method())
    bar.update()
    ref_run, ref_energy, ref_steps = reference.pop("run"), reference.pop("energies"), reference["steps"]
    regime = "trajectories" if reference["converged"] else "statistics"
    ref_scale = max(float(np.max(np.abs(ref_energy))), np.finfo(float).tiny)
    radii = np.asarray(model.radii, dtype=float)

    def measure(method, n):
        """One candidate run: its errors against the reference, or why it has none."""
        point = {"integrator": method, "dt": span / n, "steps": n}
        try:
            run, energies = _measured_run(problem, method, n)
        except (DivergenceError, ImpactCapError) as err:  # a coarse dt may crowd a step past the cap
            return point | {"failed": str(err)}
        stride = ref_steps // n
        ref_y = ref_run.y[::stride]
        point["error"] = float(np.max(np.linalg.norm(run.y[:, 0] - ref_y[:, 0], axis=-1)))
        point["impacts"] = run.collisions.count("impact")
        point["passes"] = regime == "trajectories" and point["error"] <= tol
        if regime == "statistics" or point["passes"]:  # what the statistics need, or the answer shows
            point["energy_error"] = float(np.max(np.abs(energies - ref_energy[::stride]))) / ref_scale
            point["penetration"] = largest_penetration(world, radii, run.y[:, 0])
        if regime == "statistics":
            point["passes"] = all(v <= 1.0 for v in _statistics_ratios(point, reference, tol))
        return point

    accepted, tried = [], []
    finest = ref_steps // FINEST_CANDIDATE
    for method in names:
        bar.set_description(f"recommend: {method}")
        accepted.extend(climb(functools.partial(measure, method), coarsest, finest, tried))
        bar.update()
    bar.close()
    evidence = {"regime": regime, "reference": reference, "tol": tol, "dt_max": dt_max}
    if not accepted:
        measured = [p for p in tried if "error" in p]
        best = min(measured, key=lambda p: _badness(p, reference, tol, regime), default=None)
        raise NoCollisionStepError(_refusal(reference, regime, tol, best, span / finest), evidence | {"best": best})
    # every answer timed in the same interleaved rounds: a burst of load falls on them alike
    seconds = interleaved_medians({k: functools.partial(_run, problem, p["integrator"], p["steps"])
                                   for k, p in enumerate(accepted)}, TIMING_REPEATS)
    for k, point in enumerate(accepted):
        point["seconds"] = seconds[k]
    best = min(accepted, key=lambda p: p["seconds"])
    result = {k: best[k] for k in ("integrator", "dt", "error", "seconds", "steps", "impacts", "energy_error",
                                   "penetration")} | evidence
    result["detector"] = world.detector
    if regime == "statistics":
        result["note"] = (f"trajectories do not converge to {tol:g} m (the reference at dt and dt/2 differ by "
                          f"{reference['convergence']:.3g} m): compared energy over time, impact count and "
                          "penetration instead")
    return result


def first_reference_steps(span: float, coarsest: int, dt: float, limit: int, what: str) -> int:
    """The reference's first step count over ``span``: the coarsest candidate's count times a power of
    two, so that every candidate's step times are among its own, at least 4 times the coarsest (the
    coarsest candidate and its check at dt/2 are both coarser), and its dt at most ``dt`` (the smaller
    of --dt-max and the scene's) / REFERENCE_REFINEMENT. Refused in one line when it and its check at
    dt/2 take more than ``limit`` steps (recommend's limit with ``what``: collisions, attached forces)."""
    target = dt / REFERENCE_REFINEMENT
    halvings = max(2, math.ceil(math.log2(span / (coarsest * target))))
    first = coarsest * 2**halvings
    if 2 * first > limit:
        raise ValueError(f"the reference run at dt = {span / (2 * first):.3g} s (the smaller of --dt-max and the "
                         f"scene's dt, halved twice) takes {2 * first} steps, more than recommend's limit of {limit} "
                         f"with {what}: pass a larger --dt-max or an earlier --t-end")
    return first


def climb(measure, coarsest: int, finest: int, tried: list) -> list[dict]:
    """A method's accepted point, as a list of none or one: ``measure(n)`` at coarsest, 2 coarsest, ...
    steps up to ``finest`` (each point appended to ``tried``) until one passes and so does the next
    at dt/2 (no lucky cancellation); the coarser of the two is accepted."""
    previous, n = None, coarsest
    while n <= finest:
        point = measure(n)
        tried.append(point)
        if point.get("passes") and previous is not None:
            return [previous]
        previous = point if point.get("passes") else None
        n *= 2
    return []


def _run(problem: CollisionProblem, method, n, kept: list | None = None):
    """The problem's run with ``method`` in ``n`` steps, with its collisions (their step appended to ``kept``)."""
    span = problem.t_end - problem.t_start
    stepper = problem.world.stepper if kept is None else keeping(problem.world.stepper, kept)
    return simulate(problem.model, method, problem.y0, problem.t_start, dt=span / n, n_steps=n, stepper=stepper)


def _measured_run(problem: CollisionProblem, method, n) -> tuple:
    """:func:`_run` and its mechanical energy at every step (K,), J: the rotating bodies' spin included
    where the collision step turned them (the contact solver, the event loop's spinning spheres), as
    ``steplab run`` reports it."""
    kept = []
    run = _run(problem, method, n, kept)
    rotation = None
    if problem.rigid_bodies is not None and hasattr(kept[0], "rotation_at"):
        rotation = solved_rotation(problem.rigid_bodies, run, kept[0])
    return run, np.array([float(problem.model.energy(y, rotation.at(k) if rotation is not None else None))
                          for k, y in enumerate(run.y)])


def _reference(problem: CollisionProblem, tol, n, method: str) -> dict:
    """Reference runs of ``method`` at n, 2n, ... steps until two agree to tol / REFERENCE_MARGIN (REFERENCE_RUNS
    at most, none beyond REFERENCE_MAX_STEPS)."""
    span = problem.t_end - problem.t_start
    runs = [_measured_run(problem, method, n), _measured_run(problem, method, 2 * n)]
    differences = [_difference(runs[-2][0], runs[-1][0])]
    while len(runs) < REFERENCE_RUNS and differences[-1] > tol / REFERENCE_MARGIN and 4 * n <= REFERENCE_MAX_STEPS:
        n *= 2
        runs.append(_measured_run(problem, method, 2 * n))
        differences.append(_difference(runs[-2][0], runs[-1][0]))
    (fine, energy_fine), (coarse, energy_coarse) = runs[-1], runs[-2]
    scale = max(float(np.max(np.abs(energy_fine))), np.finfo(float).tiny)
    return {"integrator": method, "dt": span / fine.steps, "steps": fine.steps,
            "impacts": fine.collisions.count("impact"), "impacts_at_2dt": coarse.collisions.count("impact"),
            "convergence": differences[-1], "converged": differences[-1] <= tol,
            "energy_convergence": float(np.max(np.abs(energy_fine[::2] - energy_coarse))) / scale,
            "run": fine, "energies": energy_fine}


def solver_integrator(world) -> str | None:
    """The one integrator ``world``'s collision method steps with (the contact solver's, semi-implicit Euler),
    or None where any fixed-step method runs with it (the event loop)."""
    if world.method != "solver":
        return None
    from steplab.physics.collision.solver_step import INTEGRATOR

    return INTEGRATOR


def _reference_method() -> str:
    """The explicit fixed-step method of the highest order (rk4): the one the methods say is best."""
    steppers = [m for m in INTEGRATORS.values() if isinstance(m, Stepper) and not m.implicit and m.order]
    return max(steppers, key=lambda m: m.order).name


def _difference(coarse, fine) -> float:
    """Largest position difference of two runs at the coarse run's step times, m."""
    return float(np.max(np.linalg.norm(coarse.y[:, 0] - fine.y[::2, 0], axis=-1)))


def _statistics_ratios(point, reference, tol) -> tuple[float, float, float]:
    """Energy, impact and penetration errors as fractions of their tolerances."""
    impacts = abs(point["impacts"] - reference["impacts"]) / max(1.0, IMPACT_RTOL * reference["impacts"])
    return point["energy_error"] / ENERGY_RTOL, impacts, point["penetration"] / tol


def _badness(point, reference, tol, regime) -> float:
    """How far a candidate is from passing (for the evidence of a refusal): its worst ratio."""
    if regime == "trajectories":
        return point["error"] / tol
    return max(_statistics_ratios(point, reference, tol))


def _refusal(reference, regime, tol, best, finest_dt) -> str:
    ref = (f"reference {reference['integrator']} at dt = {reference['dt']:.3g} s: {reference['impacts']} impacts, "
           f"converged to {reference['convergence']:.3g} m")
    if best is None:
        return f"no fixed-step method runs this scene with dt >= {finest_dt:.3g} s ({ref})"
    errors = (f"error {best['error']:.3g} m" if regime == "trajectories" else
              f"energy error {100 * best['energy_error']:.3g} % (allowed {100 * ENERGY_RTOL:g} %), "
              f"penetration {best['penetration']:.3g} m")
    what = (f"{tol:g} m" if regime == "trajectories" else
            "the energy, impact and penetration tolerances (trajectories do not converge)")
    return (f"no fixed-step method reaches {what} with dt >= {finest_dt:.3g} s; best: {best['integrator']} at "
            f"dt = {best['dt']:.3g} s, {errors}, {best['impacts']} impacts ({ref})")


def largest_penetration(world, radii, q) -> float:
    """The deepest overlap of any two bodies, or of a body and a solid static shape, m.

    Parameters
    ----------
    world : CollisionWorld
    radii : ndarray, shape (N,)
    q : ndarray, shape (K, N, 3)
        Positions at K times.
    """
    deepest = 0.0
    k, n = q.shape[:2]
    flat = Sphere.unchecked(q.reshape(-1, 3), np.tile(radii, k))
    for shape in world.shapes:  # trigger volumes are meant to be entered
        if not shape.trigger:
            deepest = max(deepest, float(np.max(collide(flat, shape).penetration_depth, initial=0.0)))
    if n > 1 and k:
        # one broadphase call for all K states: state k is moved k * spacing along x, where
        # spacing exceeds the scene's extent, so only bodies of the same state can pair
        # (the shift costs only the rounding of |x| <= K * spacing, far below a penetration)
        spacing = 2 * (float(np.ptp(q[..., 0])) + 2 * float(np.max(radii))) + 1.0
        shifted = q.copy()
        shifted[..., 0] += spacing * np.arange(k)[:, None]
        centers = shifted.reshape(-1, 3)
        pairs = find_pairs(centers, np.tile(radii, k))
        if len(pairs):
            d = np.linalg.norm(q.reshape(-1, 3)[pairs[:, 0]] - q.reshape(-1, 3)[pairs[:, 1]], axis=-1)
            r = radii[pairs[:, 0] % n] + radii[pairs[:, 1] % n]
            deepest = max(deepest, float(np.max(r - d)))
    return deepest


def check_integrators(names) -> list[str]:
    """The candidates of ``--integrators``: registry names of fixed-step methods (ValueError otherwise)."""
    steppers = []
    for name in (n for n in names if n):
        method = get_integrator(name)
        if not isinstance(method, Stepper):
            raise ValueError(f"--integrators: {method.name} is not a fixed-step integrator ({method.kind}); "
                             f"valid: {', '.join(n for n, m in INTEGRATORS.items() if isinstance(m, Stepper))}")
        steppers.append(name)  # as given: a plugin's package.module:Name is found again by simulate
    return steppers
