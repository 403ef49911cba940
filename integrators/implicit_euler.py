"""Implicit (backward) Euler with Newton iteration: a dense solve, or conjugate gradients at scale."""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import NamedTuple

import numpy as np
from steplab.physics.model import dense_problem

from .base import Stepper, check_count, check_real, solve_or_nan

#: Newton iterations before a step is declared failed (its state becomes NaN, so the
#: driver's divergence check reports the step); also the most ``newton_iterations`` may ask for
MAX_NEWTON_ITERATIONS = 50
#: ``linear_solver="auto"`` solves Newton's system densely up to this many bodies and by
#: conjugate gradients above. The dense solve costs N^3 (a step of the bench's cloth at
#: dt = 5 ms: 27 ms at 100 bodies, 0.16 s at 400, where CG takes 0.15 and 0.5 ms; the
#: (3N)^2 Jacobian of its 25,600 particles would take 47 GB), but every built-in scene and study is
#: below this size, so their numbers stay the dense solve's (CG's agree to its tolerance)
DENSE_MAX_BODIES = 200
LINEAR_SOLVERS = ("auto", "dense", "cg")


class NewtonSettings(NamedTuple):
    """How a conjugate-gradient step iterates: Newton stops at ``rtol`` (or after exactly ``iterations``,
    when given), each CG solve at relative residual ``cg_rtol``."""

    rtol: float
    cg_rtol: float
    iterations: int | None = None


@dataclasses.dataclass(frozen=True)
class ImplicitEuler(Stepper):
    """1st order implicit (backward) Euler. One force and Jacobian evaluation per Newton iteration.

    v1 = v + dt a(t + dt, q1, v1),  q1 = q + dt v1. Substituting q1 leaves 3N unknowns
    v1, found by Newton's method on G(v1) = v1 - v - dt a(t + dt, q + dt v1, v1) = 0 with
    dG/dv1 = I - dt^2 da/dq - dt da/dv, the model's analytic spring/damper/drag Jacobian.
    A-stable (L-stable): a stiff soft body stays stable at any dt, at the price of
    numerical damping.

    Newton's linear system is solved one of two ways:

    - ``"dense"``: the (3N)^2 Jacobian of :meth:`Model.jacobian` and a dense solve (NumPy
      or JAX): exact Newton, quadratic convergence, N^3 work;
    - ``"cg"``: conjugate gradients on the sparse Jacobian (NumPy only), as in Baraff and
      Witkin, "Large steps in cloth simulation" (SIGGRAPH 1998). Multiplied by the masses
      the system is (M - dt D - dt^2 K) delta = -M G, with K = dF/dq and D = dF/dv
      assembled from the forces' 3x3 blocks (:func:`steplab.physics.sparse_jacobian.newton_matrix`);
      its first iteration, from v1 = v, is their step (M - h D - h^2 K) dv = h (f + h K v)
      (linearised at q + h v), the later ones converge the nonlinear system. CG needs A
      symmetric positive definite: K and D are the symmetric part (J + J^T) / 2 of the
      forces' Jacobians (a damper's dependence on positions is not symmetric), and where
      that A is not positive definite (compressed springs' negative stiffness outweighs
      the masses) or an iteration does not contract, the step goes on with the forces'
      definite part (that negative stiffness left out too, as Choi and Ko, 2002, do). What
      the matrix leaves out stays in G, so the iteration converges to the same v1, only
      linearly, and stops on an estimate of its error: the update times theta / (1 - theta),
      theta the ratio of successive updates (Hairer and Wanner, Solving ODEs II, IV.8).
      Where the definite matrix's iteration does not contract either (heavy dampers, whose
      dependence on positions it leaves out, at a long step), the step is solved again by
      Newton's method on the exact sparse Jacobian with sparse LU (:func:`_newton_exact`).
      Pinned bodies (infinite mass, v1 = v) are left out of the system: Baraff and
      Witkin's constraint filter with all three directions held. Each iteration evaluates
      the forces and the matrix in one compiled pass over the springs and dampers
      (:func:`~steplab.physics.sparse_jacobian.newton_system`) and solves by CG
      preconditioned with symmetric block Gauss-Seidel; each solve is checked
      (:mod:`.conjugate_gradients`): one that stops short of ``cg_rtol`` warns with its
      residual (:class:`CGConvergenceWarning`); one that fails makes the step NaN, which
      the driver reports as a divergence. On the bench's cloth at its largest useful dt a
      step takes 3 or 4 Newton iterations and about 20 CG iterations, 40-50 ms (one Newton
      iteration: 10 ms).

    Parameters
    ----------
    rtol : float, optional
        In (0, 1). Newton stops when the update (dense) or its error estimate (cg) is below
        ``rtol (1 + |v1|)`` (max norm). Default: the square root of the machine epsilon of
        the state's precision; Newton's quadratic convergence leaves the dense iterate far
        more accurate than that.
    linear_solver : {"auto", "dense", "cg"}
        ``"auto"`` (default): dense up to DENSE_MAX_BODIES bodies (and always on JAX), CG above.
    cg_rtol : float, optional
        Relative residual |b - A x| / |b| each CG solve stops at, in (0, 1). Default:
        ``conjugate_gradients.CG_RTOL``, looked up when a CG step runs (so that listing
        the integrators imports neither the compiled solver nor Numba).
    newton_iterations : int, optional
        Take exactly this many Newton iterations (1 to :data:`MAX_NEWTON_ITERATIONS`) instead of
        iterating to ``rtol``: 1 is
        Baraff and Witkin's linearised step (linearised at the predicted position q + dt v),
        first order too, with a step error of the linearisation's, O(dt^2) per step.
    """

    rtol: float | None = None
    linear_solver: str = "auto"
    cg_rtol: float | None = None
    newton_iterations: int | None = None

    name = "implicit-euler"
    order = 1
    evaluations = 1
    implicit = True
    scheme = "implicit"
    style = ("tab:brown", "X")
    stability_note = "none: |1 / (1 - z)| <= 1 on the whole left half-plane (A-stable)"

    def __post_init__(self):
        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValueError(f"implicit-euler: linear_solver must be one of {', '.join(LINEAR_SOLVERS)}, "
                             f"got {self.linear_solver!r}")
        for key in ("rtol", "cg_rtol"):
            value = getattr(self, key)
            if value is not None:
                check_real(self.name, key, value, lambda x: 0 < x < 1, "a number in (0, 1), or None for the default")
        if self.newton_iterations is not None:
            check_count(self.name, "newton_iterations", self.newton_iterations, MAX_NEWTON_ITERATIONS,
                        "steplab.integrators.implicit_euler.MAX_NEWTON_ITERATIONS, the most a step iterates to rtol")

    def stability_function(self, z):
        """R(z) = 1 / (1 - z): v1 = v + dt a(v1) on y' = lambda y gives y1 = y / (1 - lambda dt)."""
        return 1 / (1 - z)

    def uses_cg(self, model) -> bool:
        """Whether a step on ``model`` solves Newton's system by conjugate gradients."""
        if self.linear_solver == "auto":
            return model.xp is np and model.n_bodies > DENSE_MAX_BODIES
        if self.linear_solver == "cg" and model.xp is not np:
            raise ValueError("implicit-euler: linear_solver='cg' runs on the NumPy backend (scipy.sparse); "
                             "use backend 'numpy', or linear_solver='dense' on JAX")
        return self.linear_solver == "cg"

    def newton_settings(self, rtol: float) -> NewtonSettings:
        """The CG step's :class:`NewtonSettings` at Newton tolerance ``rtol``."""
        from . import conjugate_gradients

        cg_rtol = conjugate_gradients.CG_RTOL if self.cg_rtol is None else self.cg_rtol
        return NewtonSettings(rtol, cg_rtol, self.newton_iterations)

    def step(self, model, t, y, dt, carry):
        rtol = self.rtol if self.rtol is not None else float(np.sqrt(np.finfo(y.dtype).eps))
        if self.uses_cg(model):
            q, v = y[0], y[1]
            v1 = _newton_cg(model, t + dt, q, v, dt, self.newton_settings(rtol))
            return np.stack([q + dt * v1, v1]), carry
        xp = model.xp
        q, v = y[0], y[1]
        t1 = t + dt
        n3 = 3 * model.n_bodies
        if problem := dense_problem(model.n_bodies):  # before the identity, as large as the Jacobians
            raise ValueError(f"implicit-euler: {problem}")
        eye = xp.eye(n3, dtype=y.dtype)

        def update(v1):
            q1 = q + dt * v1
            residual = v1 - v - dt * model.acceleration(t1, q1, v1)
            dadq, dadv = model.jacobian(t1, q1, v1)
            delta = solve_or_nan(xp, eye - (dt * dt) * dadq - dt * dadv, -residual.reshape(n3))
            return v1 + delta.reshape(v.shape), xp.max(xp.abs(delta)) <= rtol * (1 + xp.max(xp.abs(v1)))

        v1 = _newton(xp, update, v, self.newton_iterations)
        return xp.stack([q + dt * v1, v1]), carry


def newton_report(stepper: ImplicitEuler, model, t, y, dt) -> list[dict]:
    """What one conjugate-gradient step of ``stepper`` does, Newton iteration by iteration.

    One dict per iteration: ``update`` (max |delta|), ``cg_iterations``, ``cg_residual``
    (|b - A x| / |b|), ``definite`` (whether A was the definite part). The step itself is
    the same as ``stepper.step``'s (NumPy).
    """
    rtol = stepper.rtol if stepper.rtol is not None else float(np.sqrt(np.finfo(np.asarray(y).dtype).eps))
    report = []
    _newton_cg(model, t + dt, y[0], y[1], dt, stepper.newton_settings(rtol), report)
    return report


def _newton_cg(model, t1, q, v, dt, settings: NewtonSettings, report=None):
    """v1 of implicit Euler by Newton's method with CG solves (NumPy); NaN if neither it nor the fallback converges.

    Each iteration: G = v1 - v - dt a(t1, q + dt v1, v1); A delta = -M G over the free
    bodies (:func:`_solve_newton_system`); v1 += delta. Stops when the error estimate
    theta / (1 - theta) |delta| (theta = |delta_k| / |delta_k-1|; the plain |delta| at
    the first iteration) is below rtol (1 + |v1|) (``settings``, a :class:`NewtonSettings`).
    An iteration that does not contract (theta >= 1: far from the solution, where compressed
    springs make the symmetric Newton step overshoot) switches to the definite matrix for
    the rest of the step, whose steps are shorter and safer (projected Newton); where that
    one does not contract either, or the iterations run out, :func:`_newton_exact` solves the
    step. With ``settings.iterations``, exactly that many (unless the state stops being finite).
    ``report``: a list each iteration appends its numbers to (:func:`newton_report`).
    """
    from steplab.physics.sparse_jacobian import newton_matrix, newton_system

    from . import conjugate_gradients

    rtol, cg_rtol, iterations = settings
    masses = np.asarray(model.masses, dtype=float)
    pinned = np.asarray(model.pinned)
    v1, previous, definite = v, None, False
    for k in range(MAX_NEWTON_ITERATIONS if iterations is None else iterations):
        q1 = q + dt * v1
        residual, matrix, pattern = newton_system(model, t1, q1, v1, dt, definite)
        residual *= -dt  # G = v1 - v - dt a, in place
        residual += v1 - v
        if not np.all(np.isfinite(residual)):
            break
        free = pattern.kept
        b = residual[free] if free.size < v.shape[0] else residual.copy()
        b *= -masses[free, None]
        solved, definite = _solve_newton_system(matrix, b, cg_rtol, definite,
                                                functools.partial(newton_matrix, model, t1, q1, v1, dt, True))
        del matrix  # its 10 MB go back before the next one is made, which can then reuse them
        if not np.all(np.isfinite(solved.x)):
            break
        if not solved.converged:
            warnings.warn(conjugate_gradients.CGConvergenceWarning(
                f"implicit-euler: conjugate gradients stopped at relative residual {solved.residual:.3g} "
                f"(> cg_rtol = {cg_rtol:g}) after {solved.iterations} iterations, dt = {dt:g} s, "
                f"{free.size} free bodies"), stacklevel=4)
        delta = np.zeros_like(v)
        delta[free] = solved.x.reshape(-1, 3)
        delta[pinned] = -residual[pinned]  # G's rows of a pinned body are v1 - v: zero after any update
        size = float(np.max(np.abs(delta)))
        if report is not None:
            report.append({"update": size, "cg_iterations": solved.iterations, "cg_residual": solved.residual,
                           "definite": definite})
        tolerance = rtol * (1 + float(np.max(np.abs(v1))))
        v1 = v1 + delta
        theta = None if previous is None or previous == 0 else size / previous
        if theta is None:
            estimate = size
        elif theta < 1:
            estimate = theta / (1 - theta) * size
        elif definite and iterations is None:  # the definite matrix does not contract either
            break
        else:
            estimate, definite = np.inf, True
        if estimate <= tolerance or k + 1 == iterations:
            return v1
        previous = size
    if iterations is not None:  # the state stopped being finite
        return np.full_like(v, np.nan)
    return _newton_exact(model, t1, q, v, dt, rtol, report)


def _newton_exact(model, t1, q, v, dt, rtol, report=None):
    """v1 of implicit Euler by Newton's method on the exact sparse Jacobian, each system solved by sparse LU
    (SuperLU, :func:`scipy.sparse.linalg.spsolve`), from v1 = v; NaN if it never converges.

    The conjugate-gradient step's fallback, where its symmetric or definite matrix leaves out so much that its
    iteration does not contract: a heavily damped cloth, whose dampers' dependence on positions (not symmetric,
    c |u| / l per pair) outweighs the masses at a frame's step (c = 3 N s/m on the 12 x 12 cloth at 1/60 s). The
    exact Newton iteration converges there, quadratically, as the dense solve does; a pinned body's rows are the
    identity (its acceleration, and so its rows of da/dq and da/dv, are zero), so its v1 stays v.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve
    from steplab.physics.sparse_jacobian import sparse_jacobian

    eye = sp.identity(v.size, format="csc")
    v1 = v
    for _ in range(MAX_NEWTON_ITERATIONS):
        q1 = q + dt * v1
        residual = v1 - v - dt * model.acceleration(t1, q1, v1)
        dadq, dadv = sparse_jacobian(model, t1, q1, v1)
        delta = spsolve((eye - (dt * dt) * dadq - dt * dadv).tocsc(), -residual.ravel()).reshape(v.shape)
        if not np.all(np.isfinite(delta)):
            break
        size = float(np.max(np.abs(delta)))
        if report is not None:
            report.append({"update": size, "cg_iterations": 0, "cg_residual": 0.0, "definite": False, "exact": True})
        v1 = v1 + delta
        if size <= rtol * (1 + float(np.max(np.abs(v1)))):
            return v1
    return np.full_like(v, np.nan)


def _solve_newton_system(matrix, b, cg_rtol, definite, definite_matrix):
    """CG on A delta = b (b = -M G over the free bodies): (CGResult, definite).

    ``matrix`` is A from the symmetric part of the forces' Jacobian (or, with
    ``definite``, their definite part), which is positive definite unless compressed
    springs' negative stiffness or the dampers' dependence on positions outweighs the
    masses; where it is not (CG meets p^T A p <= 0, or a diagonal block is not positive
    definite), the system is solved again with the definite part, which always is
    (unless it overflows: then a NaN solution, a failed step), built by ``definite_matrix()`` (which
    returns :func:`~steplab.physics.sparse_jacobian.newton_matrix`'s pair);
    the flag returned says which was solved.
    """
    from . import conjugate_gradients

    b = b.ravel()
    while True:
        try:
            return conjugate_gradients.solve(matrix, b, cg_rtol), definite
        except conjugate_gradients.NotPositiveDefiniteError:
            if definite:
                return conjugate_gradients.CGResult(np.full_like(b, np.nan), 0, float("nan"), False), True
            definite = True
            matrix, _ = definite_matrix()


def _newton(xp, update, x0, iterations=None):
    """Iterate ``x, converged = update(x)`` until converged; NaN if it never does.

    With ``iterations``, exactly that many updates, whatever their convergence.
    """
    if iterations is not None:
        if xp is np:
            for _ in range(iterations):
                x0 = update(x0)[0]
            return x0
        from jax import lax

        return lax.fori_loop(0, iterations, lambda k, x: update(x)[0], x0)
    if xp is np:
        x = x0
        for _ in range(MAX_NEWTON_ITERATIONS):
            x, converged = update(x)
            if converged:
                return x
        return np.full_like(x, np.nan)

    from jax import lax

    def cond(state):
        _, converged, k = state
        return ~converged & (k < MAX_NEWTON_ITERATIONS)

    def body(state):
        x, _, k = state
        x, converged = update(x)
        return x, converged, k + 1

    x, converged, _ = lax.while_loop(cond, body, (x0, xp.asarray(False), 0))
    return xp.where(converged, x, xp.nan)
