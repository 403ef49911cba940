"""The contact solver's sweep order: the pile cut into domains, each domain's contacts swept by one thread.

A Gauss–Seidel sweep solves one contact after another, each seeing the velocities its
predecessors left. Two contacts that share no dynamic body do not read or write each other's
velocities, so two runs of contacts with no dynamic body in common can be swept at once, on two
threads, with the bytes of one after the other. The sweep therefore cuts the pile into D
*domains* (:func:`cut_into_domains`): a plane halves the moving bodies, a plane halves each half,
and so on, D = 2^L pieces after L levels. Then, in every pass over the contacts:

- phase 0: each domain's manifolds (both bodies in it, or one body and a static shape, b < 0,
  whose velocity nobody writes) are swept by one thread, the D domains at once;
- phase p = 1 .. L: the manifolds that cross a cut of level L - p (joining two domains whose
  numbers first differ in bit p - 1), grouped by the piece that cut halved (domain >> p): the
  groups of a phase share no body, so they too are swept at once, each by one thread; the last
  phase is the first cut's, one group.

This is nested dissection (George, "Nested dissection of a regular finite element mesh", SIAM J.
Numer. Anal. 1973) applied to the sweep's order. Within a group the manifolds keep the sorted
order (a, b), their points together, which sweeps a stack numbered from the bottom up from the
bottom up; a small scene (one domain) is swept in exactly that order.

D depends on the number of bodies alone (:func:`domain_count`: 2 from 2,048 bodies, more from 32,768),
never on the threads, so the order and the bytes are the same on any number of them; threads beyond D
wait in the sweep, not in the other stages.

Why domains and not colours (Box2D v3's constraint graph, which this module used before,
docs/performance.md): a colour is one parallel region per colour and pass, whose threads
wait for the slowest at each of its 6 to 21 colours, and the colouring itself ran on one thread
(0.5 ms of the 10^4 box pit's step); colours also interleave a stack's rows, which moved the
20-row pyramid's top box 15.6 mm against 7.2 in the sorted order. On the 10^4 box pit, 2 threads:
12.5 to 13.3 ms a step coloured, 11.4 to 12.5 in two domains; in the machine's slower state 14.1 to
14.9 against 12.5 to 13.1.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

#: a scene of this many bodies or more is cut in two (fewer: one domain, swept in the sorted order on
#: one thread): a 2,500-box pit on 2 threads took 3.3 ms a step in two domains, 4.4 in one (3.5 coloured)
CUT_BODIES = 2048
#: and halved again while each domain keeps this many bodies, at most MOST_DOMAINS: the 10^4 box pit stays
#: in 2 (0.6 % of its manifolds cross the cut), which on 2 threads was a step 5 to 10 % faster than 4 or 8
#: domains (medians of four processes alternating: 12.8 against 14.1 and 13.8 ms); more domains are for
#: more threads, which this 2-core machine cannot time
DOMAIN_BODIES = 8192
MOST_DOMAINS = 64
#: an extent of a piece this fraction of its widest is wide enough to be cut across (:func:`halves`):
#: the cut's section, where the two halves' bodies touch, is then at most 1 / WIDE the narrowest
WIDE = 0.75


class SweepLayout(NamedTuple):
    """Where the sweep's groups of contacts and the domains' bodies lie (:func:`lay_out`).

    Group g is the contact rows ``group_rows[g] .. group_rows[g + 1] - 1``; phase p the groups
    ``phase_start[p] .. phase_start[p + 1] - 1`` (phase 0: the D domains, group d domain d's). Domain
    d's bodies are ``bodies[body_start[d] .. body_start[d + 1] - 1]``, each domain's ascending."""

    group_rows: np.ndarray   # (G + 1,) int64, G = 2 D - 1
    phase_start: np.ndarray  # (L + 2,) int64
    bodies: np.ndarray       # (N,) int64
    body_start: np.ndarray   # (D + 1,) int64


def domain_count(n: int) -> int:
    """The number of domains of a scene of ``n`` bodies: a power of two (:data:`CUT_BODIES`,
    :data:`DOMAIN_BODIES`)."""
    if n < CUT_BODIES:
        return 1
    count = 2
    while 2 * count * DOMAIN_BODIES <= n and 2 * count <= MOST_DOMAINS:
        count *= 2
    return count


@njit(cache=True)
def cut_into_domains(q, movable, count):
    """Each body's domain, 0 .. ``count`` - 1 (int64, ``count`` a power of two): the bodies halved by
    :func:`halves` level by level, domain d's halves becoming 2 d and 2 d + 1."""
    domain = np.zeros(len(q), np.int64)
    pieces = 1
    while pieces < count:
        cut = 2 * domain
        for d in range(pieces):
            members = np.flatnonzero(domain == d)
            cut[members] += halves(q, movable, members)
        domain = cut
        pieces *= 2
    return domain


@njit(cache=True)
def halves(q, movable, members):
    """Each of the bodies ``members``' half, 0 or 1 (int64), of a plane that halves the movable ones'
    centres ``q`` (N, 3) across one of their wide extents: the two halves of a pile touch along the
    plane alone (the 10^4 box pit's step 30: 0.6 % of its manifolds join them), so few manifolds wait
    for the cut's phase. Pinned bodies are on the side of their centre.

    Of the extents at least :data:`WIDE` of the widest, the plane is across the one whose halves cut
    the bodies' numbering into the fewest runs. A body's rows of v, omega and the other body columns
    share cache lines with its neighbours in the numbering (a line holds 2.7 rows of v), and where
    two neighbours are in two halves, two threads write one line: each write takes the line from
    the other core's cache. The 10^4 box pit is numbered along x, then y, then layer by layer;
    across x (as wide as y) its halves changed 364 times along the numbering, 317 of v's 3,750 lines
    written by both threads; across y 62 to 80 times (docs/performance.md). (Compiled: in NumPy this
    took 0.27 ms of the pit's step.)"""
    half = np.zeros(len(members), np.int64)
    moving = members[movable[members]]
    if len(moving) == 0:
        return half
    extent = np.empty(3)
    for axis in range(3):
        extent[axis] = np.ptp(q[moving, axis])
    chosen, fewest, plane = -1, 0, 0.0
    for axis in range(3):
        if extent[axis] < WIDE * extent.max():
            continue
        median = np.median(q[moving, axis])
        runs = 0
        for m in range(1, len(members)):
            runs += (q[members[m], axis] >= median) != (q[members[m - 1], axis] >= median)
        if chosen < 0 or runs < fewest:
            chosen, fewest, plane = axis, runs, median
    for m in range(len(members)):
        half[m] = q[members[m], chosen] >= plane
    return half


@njit(cache=True)
def lay_out(a, b, domain, count):
    """(order, :class:`SweepLayout`) of contacts sorted by (a, b, ...) between bodies in ``domain`` (N,)
    of ``count`` (a power of two; b < 0: a static shape): ``order`` (C,) lists the rows group by group,
    each group's in their sorted order (a stable counting sort: a manifold's points stay together)."""
    levels = 0
    while (1 << levels) < count:
        levels += 1
    phase_start = np.empty(levels + 2, np.int64)  # phase p's first group: D + D/2 + ... over the phases before
    phase_start[0] = 0
    for p in range(levels + 1):
        phase_start[p + 1] = phase_start[p] + (count >> p)
    groups = phase_start[-1]
    group = np.empty(len(a), np.int64)
    sizes = np.zeros(groups, np.int64)
    for k in range(len(a)):
        d = domain[a[k]]
        crossing = 0 if b[k] < 0 else d ^ domain[b[k]]
        p = 0  # the phase: the highest bit in which the two domains differ, plus one
        while crossing:
            crossing >>= 1
            p += 1
        group[k] = phase_start[p] + (d >> p)
        sizes[group[k]] += 1
    group_rows = np.zeros(groups + 1, np.int64)
    for g in range(groups):
        group_rows[g + 1] = group_rows[g] + sizes[g]
    place = group_rows[:-1].copy()
    order = np.empty(len(a), np.int64)
    for k in range(len(a)):
        order[place[group[k]]] = k
        place[group[k]] += 1
    body_start = np.zeros(count + 1, np.int64)
    for body in range(len(domain)):
        body_start[domain[body] + 1] += 1
    for d in range(count):
        body_start[d + 1] += body_start[d]
    place = body_start[:-1].copy()  # a counting sort again: each domain's bodies ascending (Numba's
    bodies = np.empty(len(domain), np.int64)  # stable argsort took 0.5 ms on the 10^4 box pit's)
    for body in range(len(domain)):
        bodies[place[domain[body]]] = body
        place[domain[body]] += 1
    return order, SweepLayout(group_rows, phase_start, bodies, body_start)


@njit(cache=True, inline="always")
def phases(layout):
    """How many phases a pass over ``layout``'s contacts has (the domains', then each level's cuts')."""
    return len(layout.phase_start) - 1


@njit(cache=True, inline="always")
def groups_in(layout, phase):
    """How many groups phase ``phase`` of ``layout`` has: each swept by one thread, all at once."""
    return layout.phase_start[phase + 1] - layout.phase_start[phase]


@njit(cache=True, inline="always")
def rows_of(layout, phase, g):
    """(first, end) contact rows of group ``g`` of phase ``phase`` of ``layout``: a pass over the contacts is

        for phase in range(phases(layout)):
            for g in prange(groups_in(layout, phase)):
                ... rows_of(layout, phase, g) ...
    """
    group = layout.phase_start[phase] + g
    return layout.group_rows[group], layout.group_rows[group + 1]


@njit(cache=True, inline="always")
def bodies_of(layout, domain):
    """(first, end) in ``layout.bodies`` of domain ``domain``'s bodies."""
    return layout.body_start[domain], layout.body_start[domain + 1]


@njit(cache=True, inline="always")
def span(start, end, part, parts):
    """Part ``part`` of ``parts`` nearly equal parts of start .. end - 1: (its first, its end)."""
    return start + (end - start) * part // parts, start + (end - start) * (part + 1) // parts
