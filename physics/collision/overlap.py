"""Overlap testing: has a collision already happened? Then when, by bisection.

After a step, every candidate pair is tested for overlap at the end of the step. A pair
that did not touch at the start and overlaps at the end collided somewhere in between;
the collision time is found by *bisection* along the step (the lecture: move the objects
back or forward half a step, then half of that, ...). Each iteration halves the bracket
[lo, hi] known to hold the first touch, so after k iterations it is 2^-k of the step
wide; the lecture's "in practice, usually 5 iterations is pretty close" is 1/32 of a
step. The collision is resolved at ``hi``, the first time found to overlap, where the
overlap is small and the normal still points the right way.

Its weakness: a pair that does not overlap at the end of any step is never seen. A
sphere of radius r crossing a wall of thickness w overlaps it while its centre is within
a band w + 2r wide, so it is missed when v dt > w + 2r and the band falls between two
steps. Seen is not stopped, either: resolved past the wall's middle, the nearest face is
the far one and the push-out sends the sphere on, which the bisection bracket, v dt / 2^k,
allows from v dt > 2^(k-1) (w + 2r) (``studies/tunnelling.py`` derives both miss rates and
measures them). In a busy scene it misses somewhat less:
resolving one collision splits the step for every body (:mod:`.step`), and the state at the
split is one more place where overlaps are seen.
"""

from __future__ import annotations

import numpy as np

NO_IMPACT = np.inf


def bisect(pairs, radii, q0, q1, iterations: int):
    """The bracket [lo, hi] (fractions of the step) of first overlap, for pairs apart at 0 and overlapping at 1.

    Bodies move along the chords ``q0 -> q1``; each iteration tests the middle of the bracket.
    """
    lo, hi = np.zeros(len(pairs)), np.ones(len(pairs))
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        overlapping = pairs.contact(radii, q0, q1, mid).penetration_depth > 0
        hi = np.where(overlapping, mid, hi)
        lo = np.where(overlapping, lo, mid)
    return lo, hi


def collision_times(pairs, radii, q0, q1, iterations: int):
    """For pairs apart at the start: (time to resolve at, bracket start), inf when no overlap at the end."""
    overlapping = np.flatnonzero(pairs.contact(radii, q1).penetration_depth > 0)
    s, lo = np.full(len(pairs), NO_IMPACT), np.zeros(len(pairs))
    if overlapping.size:
        lo[overlapping], s[overlapping] = bisect(pairs.subset(overlapping), radii, q0, q1, iterations)
    return s, lo
