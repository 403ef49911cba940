"""``steplab recommend`` on a scene with springs or dampers at body-frame points: translation and rotation together.

A force at a point of a rotating body (an ``offsets`` entry, :mod:`steplab.physics.attachments`)
couples the two motions: the force on the centre depends on the orientation through the lever
arm R(q) r, and the torque on the body depends on the positions. Every measurement here is a run of
the coupled step that ``steplab run`` takes (:func:`steplab.integrators.attached.attached_stepper`),
the candidate's translation integrator beside the run's rotation method, and it is measured in both:

1. **The error** of a run is the larger of two lengths, each the largest over the run's step
  times: the centres' position error and the **lever-arm error**, the largest difference of the
  world-frame lever arms R(q) r of the attachment points (the points relative to their centres,
  every offset of every rotating body). The second is the orientation error as a length where it
  acts: a body turned wrongly by an angle theta about an axis perpendicular to r misplaces its
  attachment point by about theta |r|. The attachment point in the world, x + R(q) r, is then
  within twice the error.
2. **The reference** is velocity Verlet with ``dlm`` (:data:`REFERENCE_INTEGRATOR`,
   :data:`REFERENCE_ROTATION`), whose coupled step is a second-order Strang splitting
   (:mod:`steplab.integrators.attached`); a pair that does not compose holds one motion fixed while
   the other steps, which is first order (:mod:`steplab.integrators.coupled_stability`).
   Its first dt is the finer of the scene's dt and ``dt_max``, halved
   (:data:`.recommend_collisions.REFERENCE_REFINEMENT`) and rounded down to the coarsest candidate's
   dt over a power of two, so that every candidate's step times are among its own; it is run again at
   half that dt, and halved again, until two runs agree to tol / :data:`.recommend_collisions.REFERENCE_MARGIN`
   in both lengths. A reference of more than :data:`REFERENCE_MAX_STEPS` steps is refused in one line.
3. **The candidates**, each fixed-step integrator with the run's rotation method, run at the
   coarsest step count (a quarter of the run, or ``dt_max``) and at twice as many, down to twice
   the reference's dt (:data:`.recommend_collisions.FINEST_CANDIDATE`). A divergence is a failed
   point. As for every scene, a method is accepted at a dt only if it also passes at half that dt
   (no lucky cancellation), and the cheapest accepted run, by median wall time of the NumPy loop
   (the accepted runs timed in the same interleaved rounds), is the answer.

When nothing passes, :class:`NoAttachedStepError` carries the evidence and names the best attempt.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper
from steplab.integrators.attached import attached_stepper
from steplab.integrators.rotation_registry import get_rotation
from steplab.integrators.simulate import DivergenceError, simulate
from steplab.physics import quaternion as quat
from steplab.physics.attachments import attached_forces

from steplab.core.timing import interleaved_medians

from .recommend import NoFixedStepError, check_dt_max
from .recommend_collisions import (
    FINEST_CANDIDATE,
    REFERENCE_MARGIN,
    TIMING_REPEATS,
    check_integrators,
    climb,
    first_reference_steps,
)

#: the reference pair: velocity Verlet with dlm, the coupled step's Strang splitting (second order)
REFERENCE_INTEGRATOR = "velocity-verlet"
REFERENCE_ROTATION = "dlm"
#: the most steps of one reference run: the coupled NumPy step rebuilds the model at the new lever
#: arms in every stage, about 0.5 ms a step on spring-pendulum, so about a minute; the runs before it
#: (each half as long) add as much again. A finer reference, from a tight --tol, a small --dt-max or a
#: long run, is refused in one line (before any run where the first one is already too fine)
REFERENCE_MAX_STEPS = 2**17


class NoAttachedStepError(NoFixedStepError):
    """No candidate meets the tolerance on a scene with attached forces; ``evidence`` is the record."""

    def __init__(self, message: str, evidence: dict):
        super().__init__(message)
        self.evidence = evidence


def recommend_attached(scene, t_end: float, tol: float, *, rotation, dt_max: float | None = None, integrators=None,
                       progress: bool = False) -> dict:
    """The cheapest fixed-step integrator and dt meeting ``tol`` on a scene with springs or dampers at
    body-frame points, its translation and rotation stepped together (see the module).

    Parameters
    ----------
    scene : physics.scene.Scene
        A scene whose model has attached forces (``offsets``), with its ``rigid_bodies``; run from
        ``scene.t_start`` with ``scene.y0``.
    t_end : float
        The end of the run, s.
    tol : float
        Largest error over the run, m: the centres' positions and the lever arms R(q) r of the
        attachment points (the orientation error as a length), each at every step time.
    rotation : str or integrators.rotation.RotationMethod
        The run's rotation method (``--rotation``, else the scene's): every candidate steps with it.
    dt_max : float, optional
        Largest dt considered, s (a frame, 1/60). Default: a quarter of the run.
    integrators : sequence of str, optional
        Candidates (fixed-step, ValueError otherwise). Default: every fixed-step method.
    progress : bool
        Show a progress bar (tqdm) over the reference and the candidate methods.

    Returns
    -------
    dict
        ``integrator, rotation, dt, steps, error, position_error, arm_error, seconds`` of the answer
        (``seconds``: median wall time of its NumPy run), ``reference`` (``integrator, rotation, dt,
        steps, convergence`` in m, the larger of ``position_convergence`` and ``arm_convergence``,
        the differences of its two finest runs), ``tol``, ``dt_max`` and ``skipped`` (method: why it
        was not measured; empty unless a plugin's step refuses the coupling).

    Raises
    ------
    ValueError
        One line: no attached forces; a ``dt_max`` below what recommend measures; a candidate that is
        not a fixed-step method; a reference over :data:`REFERENCE_MAX_STEPS` steps.
    NoAttachedStepError
        Nothing passes; the message names the best candidate and its errors.
    """
    model, bodies = scene.model, scene.rigid_bodies
    if not attached_forces(model):
        raise ValueError(f"scene {scene.name}: no springs or dampers at body-frame points (offsets); "
                         "recommend_attached measures the coupled step of such scenes only")
    rotation = get_rotation(rotation)
    span = t_end - scene.t_start
    if not span > 0:
        raise ValueError(f"t_end = {t_end:g} s is not after the scene's start, {scene.t_start:g} s")
    dt_max = span / 4 if dt_max is None else dt_max
    check_dt_max(span, dt_max)  # also a count too large for a float (dt_max = 1e-320)
    coarsest = max(1, math.ceil(span / dt_max * (1 - 1e-12)))  # steps of the largest candidate dt
    named = integrators is not None
    names = check_integrators(integrators) if named else [n for n, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    if not names:
        raise ValueError("--integrators: give at least one fixed-step integrator")
    points = _attachment_points(model, bodies)
    first = first_reference_steps(span, coarsest, min(scene.dt, dt_max), REFERENCE_MAX_STEPS, "attached forces")
    from tqdm import tqdm

    # one tick for the reference, one per candidate method; shown after a second
    bar = tqdm(total=len(names) + 1, desc="recommend: reference", unit="method", disable=not progress,
               leave=False, delay=1.0)
    run = functools.partial(_run, scene, span)
    reference, ref_y, ref_q = _reference(run, span, points, tol, first)
    bar.update()
    ref_steps = reference["steps"]

    def measure(method, n):
        """One candidate run: its errors against the reference, or why it has none."""
        point = {"integrator": method, "dt": span / n, "steps": n}
        try:
            traj, qs = run(method, rotation, n)
        except DivergenceError as err:
            return point | {"failed": str(err)}
        stride = ref_steps // n
        position, arm = _errors((traj.y, qs), (ref_y[::stride], ref_q[::stride]), points)
        return point | {"error": max(position, arm), "position_error": position, "arm_error": arm,
                        "passes": max(position, arm) <= tol}

    accepted, tried, skipped = [], [], {}
    finest = ref_steps // FINEST_CANDIDATE
    for method in names:
        bar.set_description(f"recommend: {method}")
        try:
            accepted.extend(climb(functools.partial(measure, method), coarsest, finest, tried))
        except ValueError as err:  # the coupled step refuses this integrator (a plugin's step, say)
            if named:
                raise ValueError(f"--integrators: {method} cannot step springs or dampers at body-frame points: "
                                 f"{err}") from None
            skipped[method] = str(err)
        bar.update()
    bar.close()
    evidence = {"rotation": rotation.name, "reference": reference, "tol": tol, "dt_max": dt_max, "skipped": skipped}
    if not accepted:
        # the coarsest pass whose check at dt/2 is finer than the reference allows, else the smallest error
        unconfirmed = [p for p in tried if p.get("passes")]
        best = (min(unconfirmed, key=lambda p: p["steps"]) if unconfirmed else
                min((p for p in tried if "error" in p), key=lambda p: p["error"], default=None))
        message = _refusal(reference, rotation.name, tol, best, span / finest)
        raise NoAttachedStepError(message, evidence | {"best": best})
    # every answer timed in the same interleaved rounds: a burst of load falls on them alike
    seconds = interleaved_medians({k: functools.partial(run, p["integrator"], rotation, p["steps"])
                                   for k, p in enumerate(accepted)}, TIMING_REPEATS)
    for k, point in enumerate(accepted):
        point["seconds"] = seconds[k]
    best = min(accepted, key=lambda p: p["seconds"])
    keys = ("integrator", "dt", "steps", "error", "position_error", "arm_error", "seconds")
    return {k: best[k] for k in keys} | evidence


def _run(scene, span: float, method, rotation, n: int):
    """The scene's coupled run with ``method`` and ``rotation`` in ``n`` steps over ``span``: the translation's
    :class:`.simulate.Trajectory` and the rotating bodies' orientations at its step times, (n + 1, R, 4)."""
    kept = []
    with np.errstate(all="ignore"):  # a diverging run overflows before the loop sees it: a DivergenceError
        traj = simulate(scene.model, method, scene.y0, scene.t_start, dt=span / n, n_steps=n,
                        stepper=attached_stepper(scene.rigid_bodies, rotation, kept))
    return traj, kept[0].rotation_trajectory(traj).orientations


def _attachment_points(model, bodies) -> tuple[np.ndarray, np.ndarray]:
    """Every body-frame attachment point on a rotating body: its row among ``bodies`` (P,) and offset (P, 3)."""
    row = {int(body): k for k, body in enumerate(bodies.index)}
    rows, offsets = [], []
    for f in attached_forces(model):
        for end, index in enumerate((f.i, f.j)):
            for body, offset in zip(np.asarray(index), np.asarray(f.attachment.offsets)[:, end]):
                if int(body) in row and np.any(offset != 0):
                    rows.append(row[int(body)])
                    offsets.append(offset)
    return np.asarray(rows, dtype=int), np.asarray(offsets, dtype=float).reshape(-1, 3)


def _errors(run, reference, points) -> tuple[float, float]:
    """The largest position difference of the centres and of the lever arms R(q) r of the attachment points, m,
    of two runs ``(ys, qs)`` at the same times."""
    (ys, qs), (ref_ys, ref_qs) = run, reference
    position = float(np.max(np.linalg.norm(ys[:, 0] - ref_ys[:, 0], axis=-1)))
    rows, offsets = points
    if not len(rows):
        return position, 0.0
    arms = quat.rotate(np, qs[:, rows], offsets) - quat.rotate(np, ref_qs[:, rows], offsets)
    return position, float(np.max(np.linalg.norm(arms, axis=-1)))


def _reference(run, span: float, points, tol, n) -> tuple[dict, np.ndarray, np.ndarray]:
    """Runs of the reference pair at n, 2n, ... steps until two agree to tol / REFERENCE_MARGIN in positions and
    lever arms: its record, and the finest run's states (K, 2, N, 3) and orientations (K, R, 4)."""
    rotation = get_rotation(REFERENCE_ROTATION)
    coarse = _reference_run(run, rotation, n)
    while True:
        fine = _reference_run(run, rotation, 2 * n)
        differences = (None if coarse is None or fine is None else
                       _errors(coarse, (fine[0][::2], fine[1][::2]), points))
        if differences is not None and max(differences) <= tol / REFERENCE_MARGIN:
            break
        if 4 * n > REFERENCE_MAX_STEPS:
            seen = ("diverged" if differences is None else
                    f"its runs at dt and dt/2 differ by {max(differences):.3g} m")
            raise ValueError(f"the reference ({REFERENCE_INTEGRATOR} with {REFERENCE_ROTATION}) has not converged to "
                             f"tol / {REFERENCE_MARGIN} = {tol / REFERENCE_MARGIN:.3g} m at {2 * n} steps ({seen}); "
                             f"the next, dt = {span / (4 * n):.3g} s, takes {4 * n} steps, more than recommend's "
                             f"limit of {REFERENCE_MAX_STEPS} with attached forces: pass a larger --tol or an earlier "
                             "--t-end")
        coarse, n = fine, 2 * n
    position, arm = differences
    record = {"integrator": REFERENCE_INTEGRATOR, "rotation": REFERENCE_ROTATION, "dt": span / (2 * n),
              "steps": 2 * n, "convergence": max(position, arm), "position_convergence": position,
              "arm_convergence": arm}
    return record, fine[0], fine[1]


def _reference_run(run, rotation, n):
    """``(ys, qs)`` of the reference pair in ``n`` steps, None where it diverges (its dt is then halved)."""
    try:
        traj, qs = run(REFERENCE_INTEGRATOR, rotation, n)
    except DivergenceError:
        return None
    return traj.y, qs


def _refusal(reference, rotation: str, tol, best, finest_dt) -> str:
    ref = (f"reference {reference['integrator']} with {reference['rotation']} at dt = {reference['dt']:.3g} s, "
           f"converged to {reference['convergence']:.3g} m")
    if best is None:
        return (f"no fixed-step method with rotation {rotation} runs this scene without diverging with dt >= "
                f"{finest_dt:.3g} s ({ref})")
    attempt = (f"{best['integrator']} at dt = {best['dt']:.3g} s, error {best['error']:.3g} m (positions "
               f"{best['position_error']:.3g} m, lever arms {best['arm_error']:.3g} m)")
    if best.get("passes"):  # within tol at the finest dt measured: its check at dt/2 needs a finer reference
        return (f"no fixed-step method with rotation {rotation} reaches {tol:g} m (positions and lever arms) at a dt "
                f"and at dt/2 with dt >= {finest_dt:.3g} s; {attempt} is within it, unconfirmed at dt/2: pass "
                f"--dt-max {best['dt']:.6g} to measure finer ({ref})")
    return (f"no fixed-step method with rotation {rotation} reaches {tol:g} m (positions and lever arms) with dt >= "
            f"{finest_dt:.3g} s; best: {attempt} ({ref})")
