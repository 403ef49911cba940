"""The large systems the bench builds: 10^6 particles, a cloth of 10^5 springs, and the bytes a step moves."""

from __future__ import annotations

import numpy as np

from .config import SEED


def particles_model(n: int, seed: int = SEED):
    """``n`` spheres under gravity and quadratic drag, and a random initial state (2, n, 3)."""
    from steplab.physics import Drag, Gravity, Model

    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.01, 0.1, n)
    model = Model(rng.uniform(0.5, 2.0, n), radii, [Gravity(), Drag.from_coefficients(radii)])
    y0 = np.stack([rng.uniform(-100.0, 100.0, (n, 3)), rng.normal(0.0, 5.0, (n, 3))])
    return model, y0


def cloth_model(side: int):
    """A side x side cloth: structural and shear springs with dampers, gravity, two corners pinned.

    1 g per particle and 50 N/m springs: stable with semi-implicit Euler at dt = 5e-4 s
    (omega dt < 0.5 for a particle held by eight springs).
    """
    from steplab.physics import Gravity, Model
    from steplab.physics.soft_body import connect, grid

    mesh = grid(side, side, 1.0 / side, origin=(0.0, 0.0, 2.0))
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=50.0, damping=0.005)
    n = side * side
    pinned = np.zeros(n, bool)
    pinned[[0, side - 1]] = True
    model = Model(np.full(n, 1e-3), np.full(n, 0.2 / side), [Gravity(), springs, dampers], pinned=pinned)
    velocity = np.random.default_rng(SEED).normal(0.0, 0.01, (n, 3)) * ~pinned[:, None]
    return model, np.stack([mesh.vertices, velocity]), springs.i.size


def step_bytes(model, system) -> tuple[int, int]:
    """Bytes one semi-implicit Euler step must move: (read and written, read only).

    The state q, v is read and written; the force data (1/m, drag factors, per-body gravity
    where bodies are pinned, spring and damper indices and coefficients) is only read.
    """
    state = 2 * model.n_bodies * 3 * 8
    data = system.inverse_masses.nbytes + system.spring_i.nbytes * 4 + system.damper_i.nbytes * 3
    if np.any(system.beta):
        data += system.beta.nbytes
    if np.asarray(model.pinned).any():
        data += system.field.nbytes  # gravity masked per body
    return state, data
