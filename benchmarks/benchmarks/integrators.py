"""The cost of a step: every fixed-step integrator x number of bodies x backend."""

from __future__ import annotations

from steplab.integrators import get_integrator
from steplab.integrators.simulate import final_state_function

from .common import STEPPERS, particle_chain, ready

DT = 1e-3
#: a method that builds and factors a dense (3N x 3N) Jacobian (implicit Euler on JAX, the damping
#: Eulers): 0.4 to 3 s a step at 10^3 bodies, refused at 10^5, so only the single body is benchmarked;
#: implicit Euler on NumPy solves by conjugate gradients on the sparse Jacobian above 200 bodies, and
#: runs at every size (1 ms a step at 10^3 bodies, 0.09 s at 10^5)
IMPLICIT_MAX_BODIES = 1


class IntegratorStep:
    """One step of a chain of spheres under gravity, drag and springs.

    ``numpy`` is steplab's readable step-by-step path; ``jax`` the same step compiled in
    ``setup`` (at 1 body it mostly measures the dispatch of a compiled call, see
    :class:`CompiledLoop` for the in-loop cost).
    """

    params = (STEPPERS, [1, 1_000, 100_000], ["numpy", "jax"])
    param_names = ["integrator", "bodies", "backend"]
    timeout = 300

    def setup(self, integrator, bodies, backend):
        method = get_integrator(integrator)
        model, y = particle_chain(bodies)
        sparse = backend == "numpy" and getattr(method, "uses_cg", lambda model: False)(model)
        if method.implicit and bodies > IMPLICIT_MAX_BODIES and not sparse:
            raise NotImplementedError("dense Newton Jacobian: too large")
        if backend == "jax":
            import jax
            import jax.numpy as jnp

            model, y = model.cast(jnp), jnp.asarray(y)
            step = jax.jit(lambda y, carry: method.step(model, 0.0, y, DT, carry)[0])
            self.call = lambda y, carry: ready(step(y, carry))
        else:
            self.call = lambda y, carry: method.step(model, 0.0, y, DT, carry)[0]
        self.y, self.carry = y, method.init(model, 0.0, y)
        self.call(self.y, self.carry)  # compile (jax), warm caches (numpy)

    def time_step(self, integrator, bodies, backend):
        self.call(self.y, self.carry)


class CompiledLoop:
    """1000 steps of one body on a spring inside steplab's compiled loop: the per-step floor."""

    params = STEPPERS
    param_names = ["integrator"]

    def setup(self, integrator):
        import jax.numpy as jnp

        model, y = particle_chain(2)
        self.run = final_state_function(model.cast(jnp), integrator)
        # every argument a device array before the clock starts: the timed call converts nothing
        self.args = ready((jnp.asarray(y), jnp.asarray(0.0), jnp.asarray(DT), jnp.asarray(1000)))
        ready(self.run(*self.args))  # compile and warm up

    def time_1000_steps(self, integrator):
        ready(self.run(*self.args))
