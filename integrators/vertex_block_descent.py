"""Vertex block descent, ``vbd`` (A. H. Chen, Z. Liu, Y. Yang and C. Yuksel, SIGGRAPH 2024).

The springs' implicit-Euler step found by Gauss-Seidel over the vertices, each a 3x3 Newton
step (:mod:`.block_descent`), the vertices visited colour by colour (:mod:`.colouring`).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .colouring import adjacency, greedy_colouring
from .position_based import PositionBased


class DescentCarry(NamedTuple):
    """What a vbd run keeps between steps: the sweep's :class:`~.block_descent.VertexSprings`, the
    external acceleration (N, 3), m/s^2, and the velocity one substep back (N, 3), m/s (None at the
    start), from which the adaptive initial guess takes the last substep's acceleration."""

    graph: tuple
    external: np.ndarray
    v_before: np.ndarray | None


@dataclasses.dataclass(frozen=True)
class VBD(PositionBased):
    """1st order vertex block descent on the springs' implicit-Euler step (Chen et al., SIGGRAPH 2024).

    Each substep h minimises implicit Euler's incremental potential G(x) (inertia plus the
    springs' energy plus the dampers' dissipation; :mod:`.block_descent`) by ``iterations``
    Gauss-Seidel sweeps over the vertices, one 3x3 Newton step per vertex with its neighbours
    held, vertex colour by colour of a greedy colouring of the spring graph (independent
    vertices, so a colour could be stepped in parallel). Converged, the substep is
    implicit Euler's (A-stable, the springs keep their stiffness k); stopped early, each local
    step still lowers G (stable in every run measured: the tests, and the soft-bodies study up
    to k = 1e8 N/m at dt = 1/60 s), and under-converged it is softer, not stiffer.

    Initial guess: Chen et al.'s adaptive one, x = q + h v + h^2 a~ with a~ the part of the
    last substep's acceleration (v - v_before) / h along the external field a_ext, clamped to
    [0, |a_ext|] (a body resting on something, not accelerating, does not start a full g h^2
    below where it is); on the first substep a~ = a_ext, the inertial target. Springs of
    stiffness ``inf`` are refused (their Hessian is infinite; pbd and xpbd take them).
    A. H. Chen, Z. Liu, Y. Yang and C. Yuksel, "Vertex block descent", ACM Trans. Graph. 43(4), 2024.
    """

    name = "vbd"
    accumulate = False  # no multipliers: the unknowns are the positions
    style = ("#637939", "H")  # moss: no other method has it

    def init(self, model, t, y):
        from .block_descent import VertexSprings

        if model.xp is not np:
            raise ValueError(f"{self.name} runs on the NumPy backend only (its sweep over the vertices is a Numba loop "
                             "with a 3x3 solve per vertex, not ported to JAX); use --backend numpy")
        c, external, inverse_mass = self.constraints(model)
        if np.any(c.compliance == 0.0):
            p = int(np.flatnonzero(c.compliance == 0.0)[0])
            raise ValueError(f"{self.name}: the spring between bodies {c.i[p]} and {c.j[p]} has stiffness = inf, "
                             "an inextensible constraint, whose Hessian vertex block descent cannot invert; "
                             "pbd and xpbd take it")
        graph = adjacency(model.n_bodies, c.i, c.j)
        colour = greedy_colouring(graph)
        free = np.flatnonzero(inverse_mass > 0)
        s = graph.spring
        mass = np.divide(1.0, inverse_mass, out=np.full(model.n_bodies, np.inf), where=inverse_mass > 0)
        springs = VertexSprings(graph.offsets, graph.other, 1.0 / c.compliance[s], c.rest_length[s], c.damping[s],
                                free[np.argsort(colour[free], kind="stable")], mass)
        return DescentCarry(springs, external, None)

    def check_dt(self, model, dt: float) -> None:
        """Refuses (one line, naming the body) a vertex whose 3x3 Hessian block the cofactor solve cannot take
        at substeps of ``dt``: its determinant, a sum of six products of three entries, stays below 6 H^3, with
        H = m / h^2 + the sum of 2 k + c / h over the vertex's springs the largest an entry can be; past the
        float range the step moves by NaN. The springs' part of the block is positive semidefinite, so the
        determinant is at least (m / h^2)^3: below the smallest normal float it may be 0, and the solve
        divides by it. Springs of stiffness inf are :meth:`init`'s to refuse."""
        c, _, inverse_mass = self.constraints(model)
        h = self.substep(dt)
        limit = float(np.cbrt(np.finfo(float).max / 6))
        smallest = float(np.cbrt(np.finfo(float).tiny))
        with np.errstate(over="ignore", under="ignore", divide="ignore"):
            inertia = np.divide(1.0, inverse_mass, out=np.zeros_like(inverse_mass), where=inverse_mass > 0) / (h * h)
        light = np.flatnonzero((inverse_mass > 0) & ~(inertia >= smallest))
        if light.size:
            b = int(light[0])
            raise ValueError(f"{self.name}: body {b}: its inertia term m / h^2 = {inertia[b]:g} at the substep h = "
                             f"{h:g} s is below {smallest:.3g}, where its 3x3 solve's determinant, at least "
                             "(m / h^2)^3, may underflow to 0 (a larger mass, or a shorter substep)")
        with np.errstate(over="ignore", divide="ignore"):
            per_spring = np.where(c.compliance > 0, 2.0 / np.where(c.compliance > 0, c.compliance, 1.0), 0.0)
            per_spring = per_spring + c.damping / h
            block = np.divide(1.0, inverse_mass, out=np.zeros_like(inverse_mass), where=inverse_mass > 0) / (h * h)
            np.add.at(block, c.i, per_spring)
            np.add.at(block, c.j, per_spring)
        bad = np.flatnonzero((inverse_mass > 0) & ~(block <= limit))
        if bad.size:
            b = int(bad[0])
            raise ValueError(f"{self.name}: body {b}: its Hessian block (m / h^2 plus 2 k + c / h of each of its "
                             f"springs) reaches {block[b]:g} at the substep h = {h:g} s, past the {limit:.3g} its 3x3 "
                             "solve can take (a smaller stiffness, damping or mass, or a longer substep)")

    def step(self, model, t, y, dt, carry):
        from .block_descent import descend  # Numba: only when a vbd run steps

        if carry is None:
            carry = self.init(model, t, y)
        graph, external, v_before = carry
        if v_before is None:  # a run's first step
            self.check_dt(model, dt)
        q, v = np.array(y[0], float), np.array(y[1], float)
        h = dt / self.substeps
        for _ in range(self.substeps):
            dy = h * (v + h * external)  # y - q, the inertial target
            dx = dy if v_before is None else h * (v + h * adaptive_acceleration(external, (v - v_before) / h))
            dx = np.array(dx)
            descend(dx, q, dy, graph, h, self.iterations)
            v_before = v
            q, v = q + dx, dx / h
        return np.stack([q, v]).astype(y.dtype, copy=False), DescentCarry(graph, external, v_before)


def adaptive_acceleration(external: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    """a~ = clamp(a . e, 0, |a_ext|) e, e = a_ext / |a_ext| per body (0 where a_ext = 0): the last
    substep's acceleration ``acceleration`` (N, 3) along the external field ``external`` (N, 3)."""
    size = np.linalg.norm(external, axis=1)
    e = np.divide(external, size[:, None], out=np.zeros_like(external), where=size[:, None] > 0)
    along = np.clip(np.einsum("nd,nd->n", acceleration, e), 0.0, size)
    return along[:, None] * e
