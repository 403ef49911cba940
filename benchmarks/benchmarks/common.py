"""Scenes the benchmarks share, built in code with a fixed seed (no files, no randomness)."""

from __future__ import annotations

import numpy as np
import steplab.physics  # noqa: F401  (float64 JAX before any array exists)
from steplab.integrators import INTEGRATORS, Stepper
from steplab.physics import Drag, Friction, Gravity, Model, Springs
from steplab.physics.soft_body import connect, grid

SEED = 20240611
#: every fixed-step integrator, from the registry: a new one is benchmarked when registered
STEPPERS = [name for name, method in INTEGRATORS.items() if isinstance(method, Stepper)]


def particle_chain(n: int, xp=np):
    """n spheres under gravity and drag, consecutive ones joined by springs; and a state (2, n, 3)."""
    rng = np.random.default_rng(SEED)
    radii = rng.uniform(0.01, 0.1, n)
    forces = [Gravity(), Drag.from_coefficients(radii)]
    if n > 1:
        i = np.arange(n - 1)
        forces.append(Springs(i, i + 1, np.full(n - 1, 50.0), np.full(n - 1, 0.5)))
    model = Model(rng.uniform(0.5, 2.0, n), radii, forces, xp=xp)
    y = np.stack([np.cumsum(rng.uniform(0.4, 0.6, (n, 3)), axis=0), rng.normal(0.0, 1.0, (n, 3))])
    return model, y


def cloth(side: int, forces: str, xp=np):
    """A side x side cloth resting just above the ground, with the forces named by ``forces``.

    ``gravity``: gravity only; ``springs``: structural and shear springs only; ``full``:
    gravity, springs, dampers, drag and ground friction.
    """
    mesh = grid(side, side, 1.0 / side, origin=(0.0, 0.0, 0.0))
    n = side * side
    radii = np.full(n, 0.2 / side)
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=50.0, damping=0.005)
    chosen = {"gravity": [Gravity()], "springs": [springs],
              "full": [Gravity(), springs, dampers, Drag.from_coefficients(radii),
                       Friction(0.5, 0.3, np.array([0.0, 0.0, 1.0]), 0.0, radii)]}[forces]
    model = Model(np.full(n, 1e-3), radii, chosen, xp=xp)
    rng = np.random.default_rng(SEED)
    q = mesh.vertices + np.array([0.0, 0.0, 1.0]) * radii[:, None] + rng.normal(0.0, 1e-3, (n, 3))
    return model, np.stack([q, rng.normal(0.0, 0.1, (n, 3))])


def ready(x):
    """Wait for a JAX result (asynchronous dispatch would otherwise time only the launch)."""
    import jax

    return jax.block_until_ready(x)

