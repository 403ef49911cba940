"""Rotation (issue 25): one compiled step of many free tumbling bodies, and its ratio to the memory bound.

``time_step`` times one call of the compiled loop of one step (what ``simulate_rotation(backend="jax")``
runs between saved states) on the exponential map (the engines' method, issue 25's target) and dlm;
``TumblingKernel`` the exponential map's Numba kernel (``backend="numba"``), the step the ratio times.
``track_ratio_to_memory_bound`` is ``steplab bench``'s comparison: the marginal step in the loop over
the time NumPy takes to stream the bytes the step moves, in the same rounds (target 2).
"""

from __future__ import annotations

import numpy as np

from steplab.bench.timing import pin_threads

from .common import ready

# one thread per side, as ``steplab bench`` runs its ratios: before JAX or Numba is imported
pin_threads()


class TumblingStep:
    """One compiled step of N free bodies with random moments (I1 <= I2 <= I3 in [1, 2] kg m^2), h |omega| ~ 0.03."""

    params = (["exponential-map", "dlm"], [1_000, 100_000])
    param_names = ["rotation", "bodies"]

    def setup(self, rotation, n):
        import jax.numpy as jnp
        from steplab.integrators import get_rotation
        from steplab.integrators.rotation import compiled_steps
        from steplab.physics.rigid_body import RotationModel

        rng = np.random.default_rng(0)
        inertia = np.sort(rng.uniform(1.0, 2.0, (n, 3)), axis=1)
        q = rng.normal(size=(n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        step = compiled_steps(get_rotation(rotation), RotationModel(inertia), 1 / 60, 1)
        q, omega = ready((jnp.asarray(q), jnp.asarray(rng.normal(size=(n, 3)))))
        self.call = lambda: ready(step(q, omega))
        self.call()  # compile

    def time_step(self, rotation, n):
        self.call()


class TumblingKernel:
    """One exponential-map step of N free bodies by the Numba kernel (structure of arrays), as TumblingStep."""

    params = [1_000, 100_000]
    param_names = ["bodies"]

    def setup(self, n):
        from steplab.integrators.rotation_compiled import exponential_map_steps, free_bodies

        rng = np.random.default_rng(0)
        inertia = np.sort(rng.uniform(1.0, 2.0, (n, 3)), axis=1)
        q = rng.normal(size=(n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        bodies = free_bodies(q, rng.normal(size=(n, 3)), inertia)
        self.call = lambda: exponential_map_steps(bodies, 1 / 60, 1)
        self.call()  # compile

    def time_step(self, n):
        self.call()


class TumblingRatio:
    """``steplab bench``'s vs_memory_bound_rotation_1e5, measured once in ``setup_cache``."""

    unit = "ratio"
    timeout = 300

    def setup_cache(self):
        from steplab.bench import QUICK, Record
        from steplab.bench.rotation import tumbling_bodies

        record = Record(QUICK, quick=True)
        tumbling_bodies(QUICK, record, lambda message: None)
        return record.data["ratios"]["vs_memory_bound_rotation_1e5"]

    def track_ratio_to_memory_bound(self, ratio):
        return ratio
