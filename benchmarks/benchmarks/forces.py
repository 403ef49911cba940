"""Force evaluation per force model: a scene pays only for the forces it declares.

The same cloth with gravity only (the acceleration is the constant g: no arrays touched),
with springs only, and with the full set (gravity, springs, dampers, drag, ground friction).
"""

from __future__ import annotations

from .common import cloth, ready


class ForceEvaluation:
    """One evaluation of the acceleration a(t, q, v) of a cloth.

    ``jax`` times one compiled call and nothing else: positions and velocities are separate
    device arrays made in ``setup`` (slicing ``y[0]``, ``y[1]`` of a JAX array in the timed
    call would run two eager operations, hundreds of microseconds of dispatch that no
    compiled step pays), the call is compiled and run once in ``setup``, and the timed call
    waits for its result.
    """

    params = (["gravity", "springs", "full"], [10, 100], ["numpy", "jax"])
    param_names = ["forces", "cloth_side", "backend"]

    def setup(self, forces, side, backend):
        model, y = cloth(side, forces)
        if backend == "jax":
            import jax
            import jax.numpy as jnp

            model = model.cast(jnp)
            q, v = ready((jnp.asarray(y[0]), jnp.asarray(y[1])))
            acceleration = jax.jit(lambda q, v: model.acceleration(0.0, q, v))
            self.call = lambda: ready(acceleration(q, v))
        else:
            q, v = y[0], y[1]
            self.call = lambda: model.acceleration(0.0, q, v)
        self.call()  # compile (jax), warm caches (numpy)

    def time_acceleration(self, forces, side, backend):
        self.call()
