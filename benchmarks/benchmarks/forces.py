"""Force evaluation per force model: a scene pays only for the forces it declares.

The same cloth with gravity only (the acceleration is the constant g: no arrays touched),
with springs only, and with the full set (gravity, springs, dampers, drag, ground friction).
"""

from __future__ import annotations

from .common import cloth, ready


class ForceEvaluation:
    params = (["gravity", "springs", "full"], [10, 100], ["numpy", "jax"])
    param_names = ["forces", "cloth_side", "backend"]

    def setup(self, forces, side, backend):
        model, y = cloth(side, forces)
        if backend == "jax":
            import jax
            import jax.numpy as jnp

            model, y = model.cast(jnp), jnp.asarray(y)
            acceleration = jax.jit(model.acceleration)
            self.call = lambda: ready(acceleration(0.0, y[0], y[1]))
        else:
            self.call = lambda: model.acceleration(0.0, y[0], y[1])
        self.call()

    def time_acceleration(self, forces, side, backend):
        self.call()
