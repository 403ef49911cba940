"""The pbd and xpbd step on the JAX backend: :mod:`.constraint_projection`'s Gauss-Seidel sweep, traced.

A Gauss-Seidel sweep is sequential: each projection reads the positions the previous ones
moved. In the sweep's order, though, it is sequential only from colour to colour. The
constraints are visited colour after colour of a proper edge colouring
(:func:`.constraint_projection.ordered`), and no two constraints of one colour share a body,
so projecting a whole colour at once from the same positions gives what projecting its
constraints one after another gives. This path is therefore the same Gauss-Seidel sweep in
the same order as the Numba kernel, not a Jacobi variant: a ``lax.fori_loop`` over the
colours, each colour one vectorised gather, solve and scatter-add over its constraints.
The colours are padded to one length with constraints of denominator 0, which move
nothing (as a pair of pinned bodies in the Numba kernel). Each projection runs the
kernel's operations in the kernel's order; XLA may still fuse a multiply and an add,
so the two paths agree to round-off, not to the byte (tests/test_position_based.py).

The colouring and the padded tables are built once, in NumPy, when the loop is traced
(:func:`colour_table`); the coefficients that depend on the step (alpha_tilde, gamma,
the denominator) are computed in the step from the traced dt, so one compilation serves
every dt.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ColourTable(NamedTuple):
    """The constraints by colour, padded: row c holds colour c's constraints (the Numba kernel's order),
    each column (C, M), M the largest colour; a padding slot has ``live`` False.

    ``i``, ``j`` (int32) the bodies; ``rest_length``, m; ``compliance``, m/N; ``damping``, N s/m;
    plus ``inverse_mass`` (N,), 1/kg and ``external`` (N, 3), m/s^2.
    """

    i: object
    j: object
    rest_length: object
    compliance: object
    damping: object
    live: object
    inverse_mass: object
    external: object


def colour_table(constraints, colours, inverse_mass, external, dtype) -> ColourTable:
    """The :class:`ColourTable` of ``constraints`` in sweep order with colour starts ``colours``, as JAX arrays."""
    import jax.numpy as jnp

    sizes = np.diff(colours)
    width = max(int(sizes.max(initial=0)), 1)
    slot = np.zeros((max(len(sizes), 1), width), np.int64)
    live = np.zeros(slot.shape, bool)
    for c, (lo, hi) in enumerate(zip(colours[:-1], colours[1:])):
        slot[c, :hi - lo] = np.arange(lo, hi)
        live[c, :hi - lo] = True

    def padded(column, dtype):
        return jnp.asarray(np.where(live, np.asarray(column)[slot] if len(column) else 0, 0), dtype)

    return ColourTable(padded(constraints.i, jnp.int32), padded(constraints.j, jnp.int32),
                       padded(constraints.rest_length, dtype), padded(constraints.compliance, dtype),
                       padded(constraints.damping, dtype), jnp.asarray(live),
                       jnp.asarray(inverse_mass, dtype), jnp.asarray(external, dtype))


def advance(table: ColourTable, q, v, steps):
    """One step on the JAX backend: ``steps`` a :class:`.constraint_projection.Substeps` (h may be traced),
    q, v (N, 3); returns (q1, v1). The Numba kernel's :func:`.constraint_projection.advance`, traced."""
    import jax.numpy as jnp
    from jax import lax

    from .projection_law import factors, projection

    h = steps.h
    w = table.inverse_mass[table.i] + table.inverse_mass[table.j]
    alpha_tilde, gamma, denominator = factors(table.compliance, table.damping, w, h)
    denominator = jnp.where(table.live & (w != 0.0), denominator, 0.0)

    def colour(c, state):
        dx, lam, x_prev = state
        a, b = table.i[c], table.j[c]
        u = dx[b] - dx[a]
        d = x_prev[b] - x_prev[a] + u
        squared = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        du = d[:, 0] * u[:, 0] + d[:, 1] * u[:, 1] + d[:, 2] * u[:, 2]
        length = jnp.sqrt(squared)
        below = denominator[c] * squared
        held = alpha_tilde[c] * lam[c] if steps.carried else 0.0
        s = projection(table.rest_length[c], length, du, gamma[c], below, held)
        s = jnp.where(below != 0.0, s, 0.0)
        if steps.carried:
            lam = lam.at[c].add(s * length)
        # x_i -= w_i s d, x_j += w_j s d; padding slots add 0 (s = 0)
        dx = dx.at[a].add(-(table.inverse_mass[a] * s)[:, None] * d)
        dx = dx.at[b].add((table.inverse_mass[b] * s)[:, None] * d)
        return dx, lam, x_prev

    def iteration(_, state):
        return lax.fori_loop(0, table.i.shape[0], colour, state)

    def substep(_, qv):
        q, v = qv
        dx = h * (v + h * table.external)
        lam = jnp.zeros_like(table.rest_length)
        dx, _, _ = lax.fori_loop(0, steps.iterations, iteration, (dx, lam, q))
        return q + dx, dx / h

    return lax.fori_loop(0, steps.substeps, substep, (q, v))
