"""Implicit Euler on the bench's cloth: its largest useful dt, and its step against semi-implicit Euler's.

*Largest useful dt* of a method on the cloth: the largest dt = USEFUL_SPAN / n, n from
USEFUL_STEPS (a grid of factors sqrt(2), each dt ending exactly at the span's end), at
which the run's cloth at t = USEFUL_SPAN (0.2 s, while it falls about 0.2 m) lies within
USEFUL_ERROR (1 cm, 1 % of the cloth's side) of a fine reference, everywhere: semi-implicit
Euler at dt = REFERENCE_DT (its own error there is below 0.1 mm). Semi-implicit Euler's is
set by its stability limit, 2 / omega_max (3.2 ms, omega_max = 632 rad/s, ``steplab
check``): one grid point beyond it the cloth blows up. Implicit Euler's is set by its
accuracy only: it is stable at every dt, and first order with a large error constant
(numerical damping), so 1 cm is reached at a few times the explicit limit.

The ratio is one implicit Euler step (NumPy and scipy: Newton with conjugate gradients,
:class:`~steplab.integrators.ImplicitEuler`) at its largest useful dt over one step of
semi-implicit Euler in steplab's compiled loop, the marginal cost of more steps (as the
large-system comparisons time it), in the same rounds. The record adds the NumPy
semi-implicit step (the same backend as implicit Euler's) and the cost per simulated
second of each method at its largest useful dt. Both implicit variants are timed: Newton
iterated to its tolerance (what ``--integrator implicit-euler`` runs) and Baraff and
Witkin's single Newton iteration (``ImplicitEuler(newton_iterations=1)``).
"""

from __future__ import annotations

import numpy as np

from steplab.core.timing import Times, ready
from steplab.integrators.simulate import final_state_function

from .config import Config
from .record import Record
from .systems import cloth_model
from .timing import marginal_times, settled_samples

#: the span the accuracy is judged over, s, and its step counts (dt = span / n)
USEFUL_SPAN = 0.2
USEFUL_STEPS = (10, 14, 20, 28, 40, 57, 80, 113, 160)
#: largest acceptable distance of any particle from the reference at the span's end, m
USEFUL_ERROR = 0.01
#: the reference's dt, s (a quarter of it changes the reference by 8e-5 m)
REFERENCE_DT = 1e-4


def implicit_euler_cloth(config: Config, record: Record, progress) -> None:
    """Implicit Euler's step on the cloth at its largest useful dt against a semi-implicit Euler step."""
    import jax.numpy as jnp

    from steplab.integrators import ImplicitEuler, SemiImplicitEuler
    from steplab.integrators import conjugate_gradients as cg
    from steplab.integrators.implicit_euler import newton_report
    from steplab.physics.sparse_jacobian import newton_system

    model, y0, springs = cloth_model(config.cloth_side)
    converged = ImplicitEuler(linear_solver="cg")
    linearised = ImplicitEuler(linear_solver="cg", newton_iterations=1)
    compiled = final_state_function(model.cast(jnp), "semi-implicit-euler")
    # the configuration's dts (what the full bench last found), unless this run searches
    implicit_dt, explicit_dt = USEFUL_SPAN / config.implicit_steps, USEFUL_SPAN / config.semi_implicit_steps
    accuracy = None
    if config.implicit_search:
        accuracy = useful_dts(model, y0, compiled, converged)
        reference = accuracy.pop("reference")
        implicit_dt = accuracy["implicit-euler"]["dt"] or implicit_dt
        explicit_dt = accuracy["semi-implicit-euler"]["dt"] or explicit_dt
        accuracy["implicit-euler, one Newton iteration"] = {
            "dt": implicit_dt, "error": _implicit_error(model, y0, linearised, implicit_dt, reference)}
        progress("implicit Euler cloth: largest useful dt found")

    # a representative state: a few implicit steps into the fall
    y = y0
    for k in range(3):
        y = converged.step(model, k * implicit_dt, y, implicit_dt, None)[0]
    k = config.loop_steps  # calls of tens of ms: a marginal cost above the timer's noise
    yj = jnp.asarray(y)
    semi = SemiImplicitEuler()
    # the first Newton iteration's system, at v1 = v: A delta = -M G, G = -dt a(q + dt v, v)
    q1 = y[0] + implicit_dt * y[1]
    a, matrix, pattern = newton_system(model, implicit_dt, q1, y[1], implicit_dt)
    b = (implicit_dt * np.asarray(model.masses)[:, None] * a)[pattern.kept].ravel()
    x = np.ones(matrix.shape[0])
    samples = settled_samples({
        "implicit": lambda: converged.step(model, 0.0, y, implicit_dt, None),
        "linearised": lambda: linearised.step(model, 0.0, y, implicit_dt, None),
        ("compiled", 1): lambda: ready(compiled(yj, 0.0, explicit_dt, k)[0]),
        ("compiled", 2): lambda: ready(compiled(yj, 0.0, explicit_dt, 2 * k)[0]),
        "numpy": lambda: semi.step(model, 0.0, y, explicit_dt, None),
        # the pieces of an implicit step: per Newton iteration one compiled pass for the
        # forces and the Newton matrix, and a CG solve; per CG iteration (Gauss-Seidel
        # preconditioned) two triangular sweeps, about one and a half products with A
        "system": lambda: newton_system(model, implicit_dt, q1, y[1], implicit_dt),
        "solve": lambda: cg.solve(matrix, b),
        "product": lambda: matrix @ x,
    }, config.repeats, config.max_rounds, config.round_budget_seconds)
    first = cg.solve(matrix, b)
    profile = {"newton_to_rtol": newton_report(converged, model, 0.0, y, implicit_dt),
               "one_newton_iteration": newton_report(linearised, model, 0.0, y, implicit_dt),
               "seconds": {"newton_system": float(np.median(samples["system"])),
                           "cg_solve": float(np.median(samples["solve"])),
                           "cg_matrix_product": float(np.median(samples["product"]))},
               "cg_solve_iterations": first.iterations, "cg_preconditioner": cg.PRECONDITIONER,
               "newton_matrix_bytes": int(matrix.nbytes)}
    # the compiled loop's marginal cost of k more steps, as the large-system comparisons take it
    explicit, _ = marginal_times(samples[("compiled", 1)], samples[("compiled", 2)], k)
    numpy_step = Times.of(samples["numpy"])
    what = (f"cloth of {model.n_bodies:,} particles, {springs:,} springs and dampers, gravity: one implicit Euler "
            f"step (Newton to rtol, conjugate gradients) at its largest useful dt = {implicit_dt:.3g} s")
    peer = f"semi-implicit Euler step, compiled loop, at dt = {explicit_dt:.3g} s"
    for name, key, label in (("implicit_euler_cloth_step", "implicit", "Newton to rtol"),
                             ("implicit_euler_one_newton_cloth_step", "linearised", "one Newton iteration")):
        step = Times.of(samples[key])
        record.compare(name, "implicit Euler", what.replace("Newton to rtol", label), peer, step, explicit, None,
                       implicit_dt=implicit_dt, semi_implicit_dt=explicit_dt,
                       numpy_semi_implicit_step_seconds=numpy_step.median,
                       ratio_to_numpy_semi_implicit_step=step.median / numpy_step.median,
                       # seconds of computing per simulated second, each at its largest useful dt
                       cost_per_simulated_second={"implicit": step.median / implicit_dt,
                                                  "semi_implicit_compiled": explicit.median / explicit_dt},
                       accuracy=accuracy, useful_error=USEFUL_ERROR, useful_span=USEFUL_SPAN, profile=profile)
    progress("implicit Euler cloth: done")


def useful_dts(model, y0, compiled, implicit) -> dict:
    """The largest useful dt of semi-implicit and implicit Euler on ``model`` (see the module)."""
    import jax.numpy as jnp

    def semi_implicit_final(dt):
        y, bad = compiled(jnp.asarray(y0), 0.0, dt, int(round(USEFUL_SPAN / dt)))
        return None if int(bad) >= 0 else np.asarray(y)

    reference = semi_implicit_final(REFERENCE_DT)
    out = {"reference": reference, "reference_dt": REFERENCE_DT}
    errors = {}
    for n in sorted(USEFUL_STEPS, reverse=True):  # from the smallest dt up, until it blows up or strays
        final = semi_implicit_final(USEFUL_SPAN / n)
        errors[USEFUL_SPAN / n] = None if final is None else _distance(final, reference)
        if errors[USEFUL_SPAN / n] is None or errors[USEFUL_SPAN / n] > USEFUL_ERROR:
            break
    out["semi-implicit-euler"] = _largest(errors)
    errors = {}
    for n in sorted(USEFUL_STEPS):  # implicit Euler never blows up: from the largest dt down
        errors[USEFUL_SPAN / n] = _implicit_error(model, y0, implicit, USEFUL_SPAN / n, reference)
        if errors[USEFUL_SPAN / n] <= USEFUL_ERROR:
            break
    out["implicit-euler"] = _largest(errors)
    return out


def _implicit_error(model, y0, stepper, dt, reference) -> float:
    y = y0
    for k in range(int(round(USEFUL_SPAN / dt))):
        y = stepper.step(model, k * dt, y, dt, None)[0]
    return _distance(y, reference)


def _distance(y, reference) -> float:
    """Largest distance of a particle from its place in the reference, m (inf for a non-finite state)."""
    distance = np.linalg.norm(np.asarray(y)[0] - reference[0], axis=1)
    return float(np.max(distance)) if np.all(np.isfinite(distance)) else float("inf")


def _largest(errors: dict) -> dict:
    """The largest dt whose error is at most USEFUL_ERROR, and every dt's error (None: blew up)."""
    good = [dt for dt, e in errors.items() if e is not None and e <= USEFUL_ERROR]
    return {"dt": max(good) if good else None, "errors": {f"{dt:.6g}": e for dt, e in errors.items()}}
