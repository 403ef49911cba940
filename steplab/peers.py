"""What ``steplab bench`` measures steplab against: the same method, written by others.

Every peer takes the same model, initial state, dt and number of steps as steplab and
returns the same final state (to round-off; ``tests/test_bench.py`` checks it):

- :func:`numba_semi_implicit_euler` — a Numba loop over bodies and springs, the
  compiled-code limit for the method;
- :func:`numpy_semi_implicit_euler` — a plain Python loop over steps with NumPy inside,
  what one writes without a compiler;
- :func:`diffrax_fixed_step` — diffrax's ``SemiImplicitEuler``, ``Euler`` and an RK4
  (:class:`DiffraxRK4`, a Butcher tableau on diffrax's ``AbstractERK``) with a constant step;
- :func:`memory_stream` — NumPy passes over the same bytes, the memory-traffic bound of a
  large step.

diffrax is set up as its FAQ ("Diffrax seems to be slower than <some other library>?")
asks for a fair comparison: one ``jax.jit`` around the whole solve, compiled before
timing, ``block_until_ready`` on the output, the same solver, step and precision
(float64), and ``EQX_ON_ERROR=nan`` (set by :mod:`steplab.bench` before Equinox is
imported) so diffrax skips the run-time checks other JAX code does not make.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar  # at module level: dataclasses resolve the string annotation here

import numpy as np

from steplab.physics import Dampers, Drag, Gravity, Springs


@dataclasses.dataclass(frozen=True)
class PointMasses:
    """A model's bodies and forces as the plain float64 arrays a hand-written step reads.

    Supports gravity, springs, dampers and drag (the forces of the benchmarked scenes).

    Attributes
    ----------
    inverse_masses : ndarray, shape (N,)
        1/m, zero for pinned bodies.
    field : ndarray, shape (N, 3)
        Gravitational acceleration, zero for pinned bodies.
    spring_i, spring_j, stiffness, rest_length : ndarrays, shape (P,)
    damper_i, damper_j, damping : ndarrays, shape (D,)
    beta : ndarray, shape (N,)
        Drag factor 1/2 rho C_D S_ref per body, kg/m.
    """

    inverse_masses: np.ndarray
    field: np.ndarray
    spring_i: np.ndarray
    spring_j: np.ndarray
    stiffness: np.ndarray
    rest_length: np.ndarray
    damper_i: np.ndarray
    damper_j: np.ndarray
    damping: np.ndarray
    beta: np.ndarray

    @classmethod
    def from_model(cls, model) -> PointMasses:
        n = model.n_bodies
        pinned = np.asarray(model.pinned, bool)
        g = np.zeros(3)
        springs, dampers, beta = [], [], np.zeros(n)
        for force in model.forces:
            if isinstance(force, Gravity):
                g = g + np.asarray(force.g, float)
            elif isinstance(force, Springs):
                springs.append(force)
            elif isinstance(force, Dampers):
                dampers.append(force)
            elif isinstance(force, Drag):
                beta = beta + np.asarray(force.beta, float)
            else:
                raise ValueError(f"the hand-written peers do not model the force {force.name!r}")

        def cat(items, field, dtype=float):
            return np.concatenate([np.asarray(getattr(f, field), dtype) for f in items] or [np.zeros(0, dtype)])

        return cls(
            inverse_masses=np.asarray(model.inverse_masses, float),
            field=np.where(pinned[:, None], 0.0, np.broadcast_to(g, (n, 3))),
            spring_i=cat(springs, "i", np.int64), spring_j=cat(springs, "j", np.int64),
            stiffness=cat(springs, "stiffness"), rest_length=cat(springs, "rest_length"),
            damper_i=cat(dampers, "i", np.int64), damper_j=cat(dampers, "j", np.int64),
            damping=cat(dampers, "damping"), beta=beta,
        )

    @property
    def arrays(self) -> tuple[np.ndarray, ...]:
        return tuple(getattr(self, f.name) for f in dataclasses.fields(self))

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.arrays)


# --- Numba: the compiled-code limit --------------------------------------------------------


def numba_semi_implicit_euler(system: PointMasses, y0, dt: float, n: int) -> np.ndarray:
    """``n`` semi-implicit Euler steps of ``system`` from ``y0`` (2, N, 3), as a Numba loop.

    The state is updated in place in a copy of ``y0``, which is returned.
    """
    y = np.array(y0, dtype=float, copy=True)
    numba_kernel()(y[0], y[1], *system.arrays, float(dt), int(n))
    return y


_KERNEL = None


def numba_kernel():
    """The jitted loop ``kernel(q, v, *PointMasses.arrays, dt, n)``, stepping q and v in place.

    Compiled on first use (and cached on disk), so importing steplab never needs Numba.
    """
    global _KERNEL
    if _KERNEL is None:
        import numba

        _KERNEL = numba.njit(cache=True, fastmath=False)(_semi_implicit_euler_loop)
    return _KERNEL


def _semi_implicit_euler_loop(q, v, inverse_masses, field, si, sj, stiffness, rest_length,
                              di, dj, damping, beta, dt, n):
    # The same arithmetic as steplab's forces and SemiImplicitEuler.step, scalar by scalar:
    # F = sum of spring, damper and drag forces; a = F / m + g; v1 = v + dt a; q1 = q + dt v1.
    bodies = q.shape[0]
    f = np.zeros((bodies, 3))
    for _ in range(n):
        f[:, :] = 0.0
        for p in range(si.shape[0]):
            a, b = si[p], sj[p]
            dx, dy, dz = q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            if length > 0:
                s = stiffness[p] * (length - rest_length[p])
                fx, fy, fz = s * (dx / length), s * (dy / length), s * (dz / length)
                f[a, 0] += fx
                f[a, 1] += fy
                f[a, 2] += fz
                f[b, 0] -= fx
                f[b, 1] -= fy
                f[b, 2] -= fz
        for p in range(di.shape[0]):
            a, b = di[p], dj[p]
            dx, dy, dz = q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            if length > 0:
                ux, uy, uz = dx / length, dy / length, dz / length
                s = damping[p] * ((v[b, 0] - v[a, 0]) * ux + (v[b, 1] - v[a, 1]) * uy + (v[b, 2] - v[a, 2]) * uz)
                f[a, 0] += s * ux
                f[a, 1] += s * uy
                f[a, 2] += s * uz
                f[b, 0] -= s * ux
                f[b, 1] -= s * uy
                f[b, 2] -= s * uz
        for i in range(bodies):
            drag = beta[i] * np.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
            for c in range(3):
                v[i, c] += dt * ((f[i, c] - drag * v[i, c]) * inverse_masses[i] + field[i, c])
                q[i, c] += dt * v[i, c]


# --- a plain Python loop with NumPy inside ------------------------------------------------


def numpy_semi_implicit_euler(system: PointMasses, y0, dt: float, n: int) -> np.ndarray:
    """``n`` semi-implicit Euler steps as a Python loop over steps, vectorised NumPy per step."""
    s = system
    q, v = (np.array(x, dtype=float) for x in y0)
    for _ in range(n):
        f = np.zeros_like(q)
        if s.spring_i.size:
            delta = q[s.spring_j] - q[s.spring_i]
            length = np.sqrt(np.einsum("ij,ij->i", delta, delta))
            unit = delta / np.where(length > 0, length, 1.0)[:, None]
            fs = (s.stiffness * (length - s.rest_length))[:, None] * unit
            np.add.at(f, s.spring_i, fs)
            np.subtract.at(f, s.spring_j, fs)
        if s.damper_i.size:
            delta = q[s.damper_j] - q[s.damper_i]
            length = np.sqrt(np.einsum("ij,ij->i", delta, delta))
            unit = delta / np.where(length > 0, length, 1.0)[:, None]
            u = v[s.damper_j] - v[s.damper_i]
            fd = (s.damping * np.einsum("ij,ij->i", u, unit))[:, None] * unit
            np.add.at(f, s.damper_i, fd)
            np.subtract.at(f, s.damper_j, fd)
        f -= (s.beta * np.sqrt(np.einsum("ij,ij->i", v, v)))[:, None] * v
        v = v + dt * (f * s.inverse_masses[:, None] + s.field)
        q = q + dt * v
    return np.stack([q, v])


# --- diffrax --------------------------------------------------------------------------------


def diffrax_rk4():
    """Classical 4th order Runge-Kutta as a diffrax solver (diffrax ships none)."""
    return _diffrax_rk4_class()()


_RK4_CLASS = None


def _diffrax_rk4_class():
    global _RK4_CLASS
    if _RK4_CLASS is None:
        import diffrax

        class DiffraxRK4(diffrax.AbstractERK):
            """4th order classical Runge-Kutta method. Uses 4 stages (no error estimate)."""

            tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
                a_lower=(np.array([1 / 2]), np.array([0.0, 1 / 2]), np.array([0.0, 0.0, 1.0])),
                b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
                b_error=np.zeros(4),  # constant steps only: no embedded method
                c=np.array([1 / 2, 1 / 2, 1.0]),
            )
            interpolation_cls: ClassVar = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k

            def order(self, terms):
                return 4

        _RK4_CLASS = DiffraxRK4
    return _RK4_CLASS


#: diffrax's step budget of one adaptive solve in a tolerance search
ADAPTIVE_MAX_STEPS = 2**20
#: steplab method name -> what diffrax calls the same method
DIFFRAX_METHODS = ("semi-implicit-euler", "euler", "rk4")


def diffrax_fixed_step(model, method: str, t_start: float, dt: float, n: int):
    """A jitted ``f(y0) -> (y_n, steps taken)``: ``n`` constant steps of ``method`` in diffrax.

    ``model`` is on the JAX backend. For ``semi-implicit-euler`` the force must not depend
    on velocity (diffrax's ``SemiImplicitEuler`` updates v from q alone, then q from v),
    which holds for springs and gravity.
    """
    import diffrax
    import jax
    import jax.numpy as jnp

    if method == "semi-implicit-euler":
        # diffrax updates the first half of the pair from the second, then the second
        # from the new first: y = (v, q) gives v1 = v + dt a(q), q1 = q + dt v1.
        terms = (diffrax.ODETerm(lambda t, q, args: model.acceleration(t, q, jnp.zeros_like(q))),
                 diffrax.ODETerm(lambda t, v, args: v))
        solver = diffrax.SemiImplicitEuler()
        pack, unpack = (lambda y: (y[1], y[0])), (lambda s: jnp.stack([s[1], s[0]]))
    elif method in ("euler", "rk4"):
        terms = diffrax.ODETerm(lambda t, y, args: model.vector_field(t, y))
        solver = diffrax.Euler() if method == "euler" else diffrax_rk4()
        pack, unpack = (lambda y: y), (lambda s: s)
    else:
        raise ValueError(f"no diffrax counterpart for {method!r}; valid: {', '.join(DIFFRAX_METHODS)}")

    @jax.jit
    def run(y0):
        sol = diffrax.diffeqsolve(terms, solver, t_start, t_start + n * dt, dt, pack(y0),
                                  saveat=diffrax.SaveAt(t1=True),
                                  stepsize_controller=diffrax.ConstantStepSize(),
                                  max_steps=n + 1, throw=False)
        final = jax.tree_util.tree_map(lambda x: x[-1], sol.ys)
        return unpack(final), sol.stats["num_steps"]

    return run


def diffrax_adaptive(model, method: str, t_start: float, t_end: float):
    """A jitted ``f(y0, rtol) -> (y(t_end), steps)``: an adaptive diffrax solve, atol = rtol.

    ``method`` is a reference name (``"diffrax-tsit5"``); the solve is
    :func:`steplab.integrators.references.solve_adaptive`'s. The tolerance is traced, so
    one compilation serves a whole tolerance search. A solve that fails (its step budget,
    ``ADAPTIVE_MAX_STEPS``) returns inf, not the state where it stopped short of t_end.
    """
    import jax
    import jax.numpy as jnp

    from steplab.integrators.references import solve_adaptive

    @jax.jit
    def run(y0, rtol):
        sol = solve_adaptive(model.vector_field, (t_start, t_end), y0, method, rtol, rtol, at_saved_times=False,
                             max_steps=ADAPTIVE_MAX_STEPS)
        return jnp.where(sol.success, sol.ys[-1], jnp.inf), sol.steps

    return run


# --- the memory-traffic bound ----------------------------------------------------------------


def memory_stream(read_write_bytes: int, read_only_bytes: int):
    """A call that streams bytes through memory as an in-place step must, and nothing more.

    Each call reads and writes ``read_write_bytes`` once in place (the state, with a NumPy
    multiply into itself: no second buffer, no write-allocate traffic) and reads
    ``read_only_bytes`` once (the force data, with a NumPy sum). The buffers are allocated
    and paged in here, so the timed calls touch no fresh memory.
    """
    state = np.ones(max(read_write_bytes // 8, 1))
    data = np.ones(max(read_only_bytes // 8, 1))

    def stream():
        np.multiply(state, 1.0, out=state)
        data.sum()

    stream()
    return stream
