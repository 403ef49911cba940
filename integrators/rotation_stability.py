"""The largest stable omega dt of a rotation method, measured on a free body: what ``steplab check`` predicts.

A rotation method's stability is nonlinear (it depends on the spin's direction in the body,
not on one eigenvalue), so it is measured, as :mod:`.linear_stability` derives the translation
limits from ``step`` itself: bodies spun in the given directions at every omega dt of a grid,
run together for a number of steps; a body is stable while its energy stays below
(1 + ``growth``) times the start. The limit is the largest grid point below the first unstable
one. The energy is the criterion because it is what an explicit gyroscopic term gains; a
method that damps (implicit-gyroscopic) stays "stable" while inaccurate.
"""

from __future__ import annotations

import numpy as np
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import RotationModel, rotational_energy

from .rotation import simulate_rotation

#: the omega dt grid of the measurement (rad per step) and its run
OMEGA_DT_GRID = tuple(np.geomspace(0.05, 50, 31))
STEPS = 1000
#: stable while the energy stays below (1 + this) times its start
ENERGY_GROWTH = 0.1


def stable_omega_dt(method, inertia, directions, grid=OMEGA_DT_GRID, steps: int = STEPS,
                    growth: float = ENERGY_GROWTH) -> list[float | None]:
    """Largest stable |omega| dt for a spin along each body-frame direction.

    Parameters
    ----------
    method : RotationMethod
    inertia : array, shape (3,)
    directions : array, shape (D, 3)
        Body-frame spin directions (normalised here).
    grid : sequence of float, increasing

    Returns
    -------
    list of D floats or None
        None: stable at every grid point; 0.0: unstable already at the smallest.
    """
    directions = np.asarray(directions, float)
    directions = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    grid = np.asarray(grid, float)
    omega0 = (directions[:, None, :] * grid[None, :, None]).reshape(-1, 3)  # dt = 1: omega is omega dt
    model = RotationModel(np.broadcast_to(np.asarray(inertia, float), omega0.shape).copy())
    _, _, omega = simulate_rotation(method, model, np.broadcast_to(quat.IDENTITY, (len(omega0), 4)), omega0, 1.0,
                                    steps, check=False)
    with np.errstate(over="ignore", invalid="ignore"):  # the diverged bodies: inf or NaN, so unstable
        energy = rotational_energy(np, model.inertia, omega)
        stable = np.all(energy <= (1 + growth) * energy[0], axis=0).reshape(len(directions), len(grid))
    limits = []
    for row in stable:
        unstable = np.nonzero(~row)[0]
        limits.append(None if not len(unstable) else (float(grid[unstable[0] - 1]) if unstable[0] else 0.0))
    return limits


def stable_rotation_dt(method, bodies) -> float | None:
    """The largest dt (s) at which ``method`` keeps every rotating body of a scene stable.

    Each body's limit is measured along its own spin direction: dt_max = (omega dt)_max / |omega|.
    None: no limit found on the grid (or nothing spins).
    """
    omega = bodies.body_angular_velocities()
    speed = np.linalg.norm(omega, axis=-1)
    spinning = speed > 0
    limits = []
    for inertia, direction, s in zip(bodies.inertia[spinning], omega[spinning], speed[spinning]):
        limit = stable_omega_dt(method, inertia, direction[None])[0]
        if limit is not None:
            limits.append(limit / s)
    return min(limits) if limits else None
