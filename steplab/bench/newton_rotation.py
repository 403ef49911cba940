"""NVIDIA Newton's rigid-body solvers on the rotation study's tumbling body (issues 25 and 28).

The body is the ``dzhanibekov`` scene's: a free 0.2 kg box of 0.3 x 0.2 x 0.1 m spun at 1 rev/s
about its intermediate axis with a 0.05 rad/s nudge about the others, at the scene's dt (a
frame, 1/60 s), in each of Newton's rigid solvers
(:data:`steplab.engines.newton_engine.RIGID_SOLVERS`). For each:

- the nearest steplab rotation method: the largest difference in q and in omega (body frame,
  relative to |omega|) over the first IDENTIFY_STEPS steps, before the flip, where the
  intermediate axis's instability grows every difference (float32 round-off too) by orders of
  magnitude; *equal* within ROUND_OFF (float32's, a second of steps);
- its drift of the energy and of |L| after DRIFT_SECONDS, beside steplab's methods';
- its cost per step beside steplab's NumPy step of the nearest method, in the same rounds (one
  body: both are per-call overhead, Warp's kernel launches against NumPy's small-array calls).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from .config import Config
from .record import Record
from .timing import marginal_times, settled_samples

#: a third of a second of frames: before the flip, the intermediate axis's instability (rate
#: omega sqrt((I2 - I1)(I3 - I2) / (I1 I3)) = 3.0 /s) grows a difference only e-fold
IDENTIFY_STEPS = 20
#: float32 round-off over IDENTIFY_STEPS steps, relative: 20 steps of 6e-8, grown e-fold, is 3e-6
ROUND_OFF = 1e-5
#: s, the drift's span: two flips (the explicit gyroscopic term gains a quarter of the energy;
#: by 100 s those methods have diverged)
DRIFT_SECONDS = 10.0
#: steps of the timed runs: the cost per step is (t(2K) - t(K)) / K, without the set-up
TIMED_STEPS = 60


def tumbling_box():
    """The dzhanibekov scene's box: (principal moments (3,), omega in the body frame (3,), dt)."""
    from steplab.physics.scene import load_scene

    scene = load_scene("dzhanibekov")
    bodies = scene.rigid_bodies
    return bodies.inertia[0], bodies.body_angular_velocities()[0], scene.dt


def _drift(inertia, omega) -> dict:
    from steplab.physics.rigid_body import rotational_energy

    energy = rotational_energy(np, inertia, omega)
    momentum = np.linalg.norm(inertia * omega, axis=-1)
    return {"energy": float(energy[-1] / energy[0] - 1), "momentum": float(momentum[-1] / momentum[0] - 1)}


def rotation_apart(q, omega, q_ref, omega_ref) -> float:
    """Largest difference of two runs: in q (sign-aligned: q and -q are one rotation) and in omega / |omega|."""
    sign = np.where(np.sum(q * q_ref, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return float(max(np.max(np.abs(sign * q - q_ref)),
                     np.max(np.abs(omega - omega_ref)) / np.max(np.linalg.norm(omega_ref, axis=-1))))


def newton_tumbling(config: Config, record: Record, progress) -> None:
    """Each Newton rigid solver on the tumbling box: its nearest steplab rotation method, drift and cost."""
    from steplab.engines import ENGINES
    from steplab.engines.newton_engine import RIGID_SOLVERS, free_body_rotation
    from steplab.integrators import ROTATIONS, get_rotation
    from steplab.integrators.rotation import simulate_rotation
    from steplab.physics import quaternion as quat
    from steplab.physics.rigid_body import RotationModel

    if not ENGINES["newton"].available():
        record.data["details"]["newton_tumbling"] = "newton is not installed (pip install steplab[newton]): not run"
        return
    inertia, omega0, dt = tumbling_box()
    n, drift_steps = IDENTIFY_STEPS, int(round(DRIFT_SECONDS / dt))
    model = RotationModel(inertia[None, :])

    def steplab(name: str, steps: int):
        _, q, omega = simulate_rotation(get_rotation(name), model, quat.IDENTITY[None, :], omega0[None, :], dt, steps,
                                        check=False)
        return q[:, 0], omega[:, 0]

    short = {name: steplab(name, n) for name in ROTATIONS}
    out = {"dt": dt, "inertia": inertia.tolist(), "omega0": omega0.tolist(), "identify_steps": n,
           "drift_seconds": drift_steps * dt,
           "steplab_drift": {name: _drift(inertia, steplab(name, drift_steps)[1]) for name in ROTATIONS}}
    k = TIMED_STEPS
    for solver in RIGID_SOLVERS:
        q, omega = free_body_rotation(inertia, omega0, dt, n, solver)
        apart = {name: rotation_apart(q, omega, *ref) for name, ref in short.items()}
        nearest = min(apart, key=apart.get)
        samples = settled_samples({
            ("newton", 1): partial(free_body_rotation, inertia, omega0, dt, k, solver),
            ("newton", 2): partial(free_body_rotation, inertia, omega0, dt, 2 * k, solver),
            ("steplab", 1): partial(steplab, nearest, k), ("steplab", 2): partial(steplab, nearest, 2 * k)},
            config.repeats, config.max_rounds, config.round_budget_seconds)
        cost = {side: marginal_times(samples[(side, 1)], samples[(side, 2)], k)[0].median
                for side in ("newton", "steplab")}
        out[solver] = {"nearest": nearest, "difference": apart[nearest],
                       "equals": nearest if apart[nearest] <= ROUND_OFF else "none", "differences": apart,
                       "drift": _drift(inertia, free_body_rotation(inertia, omega0, dt, drift_steps, solver)[1]),
                       "seconds_per_step": cost["newton"], "steplab_seconds_per_step": cost["steplab"]}
    record.data["details"]["newton_tumbling"] = out
    progress("newton tumbling body: done")
