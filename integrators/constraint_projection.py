"""The Gauss-Seidel sweep over distance constraints shared by ``pbd`` and ``xpbd`` (a Numba kernel).

One projection of constraint p (bodies i, j; C = |x_j - x_i| - l_rest, gradient n = (x_j - x_i) / |.|
on j and -n on i) is Macklin, Mueller and Chentanez (MIG 2016) eq. 18 with the damping of
their eq. 26:

    dlambda = (-C - alpha_tilde lambda - gamma grad C . (x - x_prev)) / ((1 + gamma) w + alpha_tilde),
    x_i -= w_i dlambda n,   x_j += w_j dlambda n,   lambda += dlambda,

on x = x_prev + dx. The sweep moves the displacement dx over the substep, not x itself:
x - x_prev is then dx exactly, and the velocity dx / h carries the round-off of dx, not
that of x divided by h (which at h = 1 ms would be a thousand times larger).

with w = w_i + w_j the inverse masses, alpha_tilde = alpha / h^2 (alpha = 1 / k the
compliance, h the substep) and, for a damper of coefficient beta beside the spring,
beta_tilde = h^2 beta and gamma = alpha_tilde beta_tilde / h = alpha beta / h = beta / (k h).
(Their eq. 26 follows from adding the Rayleigh dissipation beta (grad C . v)^2 / 2 to the
implicit-Euler step and writing v = (x - x_prev) / h.) ``accumulate`` False holds
lambda at 0 in every iteration: each projection then removes the fraction
w / (w + alpha_tilde) of C, Mueller et al.'s (2007) stiffness per iteration, with nothing
carried between iterations. The sweep is Gauss-Seidel (each projection sees the positions
the previous ones moved), a Numba loop; the NumPy path calls it, and the JAX path
(:mod:`.constraint_projection_jax`) is the same sweep. Both evaluate the projection through the
one definition, :func:`.projection_law.factors` and :func:`.projection_law.projection` (plain arithmetic, which Numba
compiles into the kernel and JAX evaluates on a colour's columns).

The constraints are swept in the order of a greedy edge colouring (:func:`ordered`), colour
after colour. Within a colour no two constraints share a body, so its projections are
independent: the sweep projects eight consecutive constraints of a colour at once, each in a
lane of LLVM vector code (:func:`.projection_block.project_block`: the bodies' coordinates
loaded into lanes, the square roots and divisions eight at a time, the moves stored back), and a
segment's last few one by one (:func:`.projection_block.project_one`). That is the sequential
Gauss-Seidel sweep exactly, the same operations in the same order per constraint (so the same
bytes). What depends only on the constraint and the substep h (alpha_tilde, gamma and the
denominator (1 + gamma) w + alpha_tilde) is computed once per run (:func:`sweep_columns`).
Positions and velocities are coordinate rows, (3, M) each, a row per coordinate
(:func:`coordinates`), the bodies in the rows :mod:`.arrangement` lays them out in, so that
four constraints whose ends advance by 1 (a run) read each coordinate as one vector load; the
step moves them in place (the velocity's rows carry the displacement during the substep,
:func:`advance`). The colours are swept in bands of bodies (:func:`wavefront`), each body still
receiving its projections in colour order (the same bytes), so that a band's bodies stay in the
core's caches, each segment's runs first (:func:`runs_first`); the sweep prefetches the columns
:data:`PREFETCH_AHEAD` constraints ahead (their reads from memory then overlap the sweep when the
caches are cold). On the 25,600-particle cloth, one step, warm (AMD Zen 3): 0.49-0.52 ms on
padded rows (x, y, z, 0) in the grid's numbering, 0.38-0.40 ms now (docs/performance.md has the
steps before and the cold-cache times).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .prefetch import prefetch
from .projection_block import EQUAL_MASSES, HALF, LANES, RUN, project_block, project_one
from .projection_law import factors


class Sweep(NamedTuple):
    """The constraints as the sweep reads them, in its order, for one substep h (:func:`sweep_columns`).

    ``i``, ``j`` (P,) uint32 the bodies; ``rest_length``, m; ``alpha_tilde`` = alpha / h^2;
    ``gamma`` = alpha beta / h; ``denominator`` = (1 + gamma) w + alpha_tilde, 0 for a pair of
    pinned bodies (skipped); ``segments`` (S + 1,) int64: segment s is ``[segments[s], segments[s + 1])``,
    constraints of one colour (:func:`wavefront`), so no two of a segment share a body; ``kinds``
    (B,) uint8, for each block of LANES the sweep projects at once, in the sweep's order (a segment's
    constraints from its start, LANES at a time), how its code may read it (:func:`block_kinds`).
    """

    i: np.ndarray
    j: np.ndarray
    rest_length: np.ndarray
    alpha_tilde: np.ndarray
    gamma: np.ndarray
    denominator: np.ndarray
    segments: np.ndarray
    kinds: np.ndarray


class Substeps(NamedTuple):
    """How a step runs: ``substeps`` of ``h`` s, each ``iterations`` sweeps, the multipliers
    ``carried`` between the iterations (xpbd with more than one iteration) or held at 0."""

    h: float
    substeps: int
    iterations: int
    carried: bool


class Workspace(NamedTuple):
    """Scratch a step writes, allocated once per run: the ``state`` q, v (2, 3, M) as coordinate rows
    (:func:`coordinates`), which the step moves in place (during a substep v's rows carry the displacement
    dx, q's the positions at the start of the substep), and the multipliers ``lam`` (P,)."""

    state: np.ndarray
    lam: np.ndarray


def ordered(constraints, n_bodies: int):
    """``constraints`` (a physics.constraints.DistanceConstraints) sorted by the colour of a greedy edge
    colouring, then by their bodies (for locality): the order the sweep visits them in; and where
    each colour starts, (C + 1,) int64."""
    from .colouring import greedy_edge_colouring

    colour = greedy_edge_colouring(n_bodies, constraints.i, constraints.j)
    order = np.lexsort((constraints.j, constraints.i, colour))
    starts = np.searchsorted(colour[order], np.arange(colour.max(initial=-1) + 2)).astype(np.int64)
    return type(constraints)(*(np.ascontiguousarray(a[order]) for a in constraints)), starts


#: bodies per band of :func:`wavefront`: a band's window, (BAND + colours x reach) bodies of 64 bytes
#: (position and displacement rows), is 213 kB on the bench's 160 x 160 cloth, well inside the 1 MB L2
BAND = 2048


def wavefront(constraints, colours, band: int = BAND):
    """The constraints in colour order (:func:`ordered`: ``colours`` (C + 1,) the colour starts) reordered
    into bands that sweep the bodies once, with the same bytes: (constraints, segment starts (S + 1,) int64).

    The colour-by-colour sweep passes over every body once per colour, eight times a step on a
    cloth, and on a large cloth each pass reads the bodies from the L3 cache. Only the order in
    which each body receives its projections fixes the result, though: a projection reads its
    two bodies as the projections of the lower colours left them (one per colour, since no two
    of a colour share a body). So the sweep may run band by band, each band colour by colour,
    as long as every body still sees its colours in order. With ``reach`` = max |i - j| + 1
    (bodies apart in index along a constraint: the cloth's side + 1 in its grid order), the
    constraint of colour c whose larger body is m goes to band t = (m + c reach) // band. A
    constraint of a lower colour c' < c sharing one of its bodies has larger body at most
    m + reach - 1 < m + (c - c') reach, so it lies in the same band or an earlier one (and in the
    same band it comes first, colours in order); one of a higher colour lies in the same band
    or a later one by the same bound. Within a band the segments are the colours in order, each
    with its runs first (:func:`runs_first`). The bytes are those of the colour-by-colour sweep (tested); the bodies
    a band touches stay in the core's caches while it is swept. With bodies in no spatial order
    (reach ~ N) the bands just repeat the colours: the same sweep, without the locality.
    """
    counts = np.diff(colours)
    colour = np.repeat(np.arange(len(counts)), counts)
    i, j = constraints.i.astype(np.int64), constraints.j.astype(np.int64)
    reach = int(np.abs(j - i).max(initial=0)) + 1
    key = (np.maximum(i, j) + colour * reach) // band * len(counts) + colour
    order = np.argsort(key, kind="stable")  # within a segment, runs_first orders the constraints
    key = key[order]
    segments = np.append(np.flatnonzero(np.diff(key, prepend=-1)), len(key)).astype(np.int64)
    order = order[runs_first(i[order], j[order], segments)]
    return type(constraints)(*(np.ascontiguousarray(a[order]) for a in constraints)), segments


def runs_first(i, j, segments) -> np.ndarray:
    """The order within each segment (constraints of one colour, in any order the same bytes) that puts its
    runs in whole blocks: (P,) indices into i, j.

    A run is a family of constraints whose two ends both advance by 1 (i + l, j + l for l = 0, 1, ...):
    a block whose two halves of HALF constraints are each a run (:func:`layouts`) reads each coordinate
    of its sixteen bodies as four vector loads (:mod:`.projection_block`), where a block by index loads
    sixteen scattered values. Each segment's maximal runs (by offset j - i, then i) are cut into whole
    halves from their start and placed first, so that the blocks, LANES at a time from the segment's
    start, fall on them (a run's halves, or the last half of one run and the first of the next); each
    run's last (length mod HALF) constraints follow, in blocks by index and one by one.
    """
    i, j = i.astype(np.int64), j.astype(np.int64)
    segment = np.repeat(np.arange(len(segments) - 1), np.diff(segments))
    by = np.lexsort((i, j - i, segment))
    i, offset, segment = i[by], (j - i)[by], segment[by]
    starts = np.ones(len(i), bool)
    starts[1:] = (segment[1:] != segment[:-1]) | (offset[1:] != offset[:-1]) | (i[1:] != i[:-1] + 1)
    run = np.cumsum(starts) - 1
    first = np.flatnonzero(starts)
    position = np.arange(len(i)) - first[run]
    leftover = position >= np.diff(np.append(first, len(i)))[run] // HALF * HALF
    return by[np.lexsort((position, run, leftover, segment))]


def sweep_columns(constraints, segments, inverse_mass, h: float) -> Sweep:
    """The :class:`Sweep` of ``constraints`` (in sweep order, segment starts ``segments``) for substeps of ``h``:
    the per-constraint factors evaluated as the projection would, the same operations in the same order."""
    w = inverse_mass[constraints.i] + inverse_mass[constraints.j]
    alpha_tilde, gamma, denominator = factors(constraints.compliance, constraints.damping, w, h)
    denominator = np.where(w == 0.0, 0.0, denominator)
    i, j = constraints.i.astype(np.uint32), constraints.j.astype(np.uint32)
    return Sweep(i, j, constraints.rest_length, alpha_tilde, gamma, denominator, segments,
                 block_kinds(i, j, inverse_mass, segments))


def block_starts(segments) -> np.ndarray:
    """The first constraint of each block of LANES the sweep projects at once: a segment's from its start."""
    counts = np.diff(segments) // LANES
    before = np.cumsum(counts) - counts  # blocks before each segment's
    return np.repeat(segments[:-1], counts) + LANES * (np.arange(counts.sum()) - np.repeat(before, counts))


def layouts(i, j, segments) -> np.ndarray:
    """For each block (:func:`block_starts`), how its bodies lie, (B,) uint8, in the sweep's order: RUN (1)
    where in each half of its lanes both ends advance by 1 from lane to lane (i[k + l] = i[k] + l and
    j[k + l] = j[k] + l for l < HALF, and so from k + HALF), 0 elsewhere (:mod:`.projection_block` reads
    each way with its own code)."""
    starts = block_starts(segments)
    i_, j_ = (e[starts[:, None] + np.arange(LANES)].astype(np.int64) for e in (i, j))
    half, lane = np.divmod(np.arange(LANES), HALF)
    first = half * HALF  # each lane's half's first lane
    run = ((i_ - i_[:, first]) == lane).all(axis=1) & ((j_ - j_[:, first]) == lane).all(axis=1)
    return np.where(run, RUN, 0).astype(np.uint8)


def block_kinds(i, j, inverse_mass, segments) -> np.ndarray:
    """How the sweep's code may read each block (:func:`block_starts`), (B,) uint8: its :func:`layouts`, plus
    EQUAL_MASSES where w_i = w_j in every lane.

    On the bench's 160 x 160 cloth, its bodies laid out by :mod:`.arrangement`, 97.5 % of the blocks are runs,
    and all but those at a pinned body join equal masses. In a run the code reads four indices and loads
    each coordinate of each half's four bodies as one vector, instead of loading sixteen indices and
    gathering; with
    equal masses, d_i + (-(w_i s)) e = d_i - (w s) e exactly, so one product a lane moves both ends.
    The arithmetic, and so the bytes, are the same (:mod:`.projection_block`).
    """
    lanes = block_starts(segments)[:, None] + np.arange(LANES)
    equal = (inverse_mass[i[lanes]] == inverse_mass[j[lanes]]).all(axis=1)
    return layouts(i, j, segments) | np.where(equal, EQUAL_MASSES, 0).astype(np.uint8)


def workspace(n_bodies: int, n_constraints: int) -> Workspace:
    return Workspace(aligned_zeros((2, 3, row_length(n_bodies))), np.empty(n_constraints))


def row_length(n_bodies: int) -> int:
    """M, the length of a coordinate row for N bodies: N rounded up to a cache line of float64, plus one line.

    Each row then starts on a cache line, a block's vector loads from a body near the end stay inside
    the row, and rows lie apart by no multiple of 4 kB (at N = 25,600 they would, 50 pages:
    a store to x then looks to the core like it may feed the next load of y, which then waits)."""
    return -(-n_bodies // LANES) * LANES + LANES


#: bytes of a cache line
CACHE_LINE = 64


def aligned_zeros(shape: tuple) -> np.ndarray:
    """Zeros (float64) starting on a cache line (NumPy's large arrays start 16 bytes past a page, which
    would split every vector load at a row's start over two lines)."""
    size = int(np.prod(shape))
    buffer = np.zeros(size + CACHE_LINE // 8)
    start = (-buffer.ctypes.data % CACHE_LINE) // 8
    return buffer[start:start + size].reshape(shape)


def coordinates(a: np.ndarray) -> np.ndarray:
    """(N, 3) -> (3, M): a coordinate a row (:func:`row_length`, zeros past N), as the sweep moves them.

    One row per coordinate, the bodies along it: four bodies in a run are then one vector load per
    coordinate, not four rows to transpose into lanes (:mod:`.projection_block`)."""
    out = aligned_zeros((3, row_length(len(a))))
    out[:, :len(a)] = a.T
    return out


def bodies(rows: np.ndarray, n_bodies: int) -> np.ndarray:
    """The view (..., N, 3) of coordinate rows (..., 3, M): the inverse of :func:`coordinates`, no copy."""
    return np.swapaxes(rows[..., :n_bodies], -1, -2)


#: constraints ahead of the gather whose columns the sweep prefetches (:func:`_segment`): far enough to
#: cover a read from memory (~100 ns, ~3 ns a constraint), near enough to stay in L1 (128 x 32 bytes);
#: 96 to 192 measured alike, from cold caches on the bench's cloth (docs/performance.md)
PREFETCH_AHEAD = 128


@njit(inline="always", error_model="numpy")
def _segment(span, rows, inverse_mass, sweep, carried, work):
    """One segment's projections (``span`` = (lo, hi, block): constraints lo to hi, no two sharing a body, its
    first block of LANES the sweep's ``block``-th) on the coordinate rows ``rows`` = (dx, x_prev), (3, M) each:
    LANES at a time (:func:`.projection_block.project_block`, each way its bodies lie with its own code), the
    rest one by one."""
    lo, hi, block = span
    k = lo
    while k + LANES <= hi:
        # ask for the columns PREFETCH_AHEAD constraints on (this segment's next blocks, the next
        # segment's): the columns are read once a step, from memory when the caches are cold, and the
        # hardware prefetcher alone leaves those reads mostly unoverlapped with the sweep's work
        ahead = k + PREFETCH_AHEAD  # past the last constraint at the end: harmless for a prefetch
        prefetch(sweep.i, ahead)
        prefetch(sweep.j, ahead)
        prefetch(sweep.rest_length, ahead)
        prefetch(sweep.gamma, ahead)
        prefetch(sweep.denominator, ahead)
        # each kind its own code (a constant argument): RUN (1) or by index (0), EQUAL_MASSES (4) added
        kind = sweep.kinds[block]
        if kind == 5:
            project_block(rows, inverse_mass, sweep, work.lam, carried, k, 5)
        elif kind == 1:
            project_block(rows, inverse_mass, sweep, work.lam, carried, k, 1)
        elif kind == 4:
            project_block(rows, inverse_mass, sweep, work.lam, carried, k, 4)
        else:
            project_block(rows, inverse_mass, sweep, work.lam, carried, k, 0)
        k += LANES
        block += 1
    for p in range(k, hi):
        project_one(p, rows[0], rows[1], inverse_mass, sweep, work.lam, carried)


@njit(cache=True, error_model="numpy")
def project(dx, x_prev, inverse_mass, sweep, iterations, carried, work):
    """``iterations`` Gauss-Seidel sweeps over ``sweep`` (a :class:`Sweep`), moving ``dx`` (3, M) in place.

    ``x_prev`` (3, M) are the positions at the start of the substep, ``dx`` the predicted
    displacement h v* on entry and the projected one on return, both coordinate rows (:func:`coordinates`);
    the multipliers ``work.lam`` (P,) start at 0 in each substep and are only read and written
    when ``carried`` (otherwise held at 0 and untouched, which saves the sweep 16 bytes of
    traffic per constraint). Coincident bodies (no direction) and pairs of pinned bodies
    (denominator 0) move nothing.
    """
    if carried:
        work.lam[:] = 0.0
    for _ in range(iterations):
        block = 0
        for c in range(sweep.segments.shape[0] - 1):
            lo, hi = sweep.segments[c], sweep.segments[c + 1]
            _segment((lo, hi, block), (dx, x_prev), inverse_mass, sweep, carried, work)
            block += (hi - lo) // LANES


@njit(cache=True, error_model="numpy")
def advance(q, v, external, inverse_mass, sweep, steps, work):
    """``steps.substeps`` substeps of ``steps.h`` of a position-based step (a :class:`Substeps`), on q, v
    (3, M), coordinate rows (:func:`coordinates`), in place, allocating nothing:

        v <- dx = h (v + h a_ext),  project dx (:func:`project`, from x_prev = q),  q += dx,  v = dx / h.

    ``external`` (3, M), m/s^2, coordinate rows too; ``sweep`` a :class:`Sweep` for h; ``work`` a
    :class:`Workspace`. The displacement lives in v's rows and the start positions are q's own: no copy
    of the state is written, so a step from cold caches reads q and v once and writes them in place (a
    separate dx and x_prev, written first, cost their reads for ownership from memory, 1.2 MB on the
    bench's cloth).
    """
    h = steps.h
    q_, v_, a_ = q.reshape(-1), v.reshape(-1), external.reshape(-1)
    for _ in range(steps.substeps):
        # predict, x* = q + h v*, v* = v + h a_ext, in one contiguous loop too (the rows' ends stay 0)
        for k in range(v_.shape[0]):
            v_[k] = h * (v_[k] + h * a_[k])
        project(v, q, inverse_mass, sweep, steps.iterations, steps.carried, work)
        # update, in one contiguous loop over the rows that the compiler vectorises (scalar divisions
        # cost a quarter of the step); the rows' ends past N stay 0 (0 + 0, 0 / h)
        for k in range(q_.shape[0]):
            q_[k] += v_[k]
            v_[k] = v_[k] / h
