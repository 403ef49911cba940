"""The bodies' motion inside a step: each on a straight chord, from where it last changed to the end.

At the start of a step every body's chord runs from its state y to its integrated end
state y_end. A collision at time t_c gives its bodies a new chord, from their state
just after the collision to their new end state; every other body stays on its chord.
A body's state at time t is the point of its chord at fraction
(t - t_from) / (t_end - t_from), positions and velocities alike (:mod:`.step`).

Only the states of the bodies a collision involves are ever computed (O(1) per
collision, not O(N)); they are written into one state array, :attr:`Chords.now`, whose
other rows are stale. The swept bounds of every body's rest of the step are kept beside
the chords: the step's bounds (:func:`.pairs.candidates`) contain every later part of
an unchanged chord, and a changed body's bounds are replaced by its new chord's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class ChordArrays(NamedTuple):
    """The chords, as the kernels take them: (2, N, 3) states from ``y_from`` at ``t_from`` (N,)
    to ``y_end`` at ``t_end`` (changed in place as chords restart).

    Passed as a plain tuple (``tuple(ChordArrays(...))``) and unpacked in this order: Numba
    types a plain tuple argument in C, a NamedTuple in Python (about 1 us a call, and the
    event loop makes several calls per impact). Like every structure of the per-impact
    kernels it holds only what they read: each array passed costs its unboxing, per call.
    """

    y_from: np.ndarray
    y_end: np.ndarray
    t_from: np.ndarray
    t_end: float


class Chords:
    """Every body's chord in one step, and the swept bounds of what is left of it.

    Parameters
    ----------
    y, y_end : ndarray, shape (2, N, 3)
        States at the start and at the end of the step (``y_end`` is shared and updated in place).
    t, t_end : float
        The step.
    radii : ndarray, shape (N,)
    margin : float
        Added to every reach (the contact slop).
    """

    def __init__(self, y, y_end, t, t_end, radii, margin):
        self.y_from = y.copy()
        self.now = y.copy()
        self.y_end = y_end
        self.t_from = np.full(len(radii), float(t))
        self.t_end = t_end
        self.radii = radii
        self.centers, self.reach = swept_bounds(y[0], y_end[0], radii, margin)
        self.arrays = tuple(ChordArrays(self.y_from, y_end, self.t_from, float(t_end)))

    def at(self, bodies, t, t_sub=None, s=None) -> np.ndarray:
        """Write the states of ``bodies`` at time ``t`` into :attr:`now` and return it.

        A body whose chord starts at ``t_sub`` is placed at the given fraction ``s`` (the
        detector's own number, so the point of impact is where the test found it).
        """
        bodies = np.asarray(bodies, dtype=np.int64)
        if t_sub is None:
            _at(self.arrays, self.now, bodies, float(t), False, 0.0, 0.0)
        else:
            _at(self.arrays, self.now, bodies, float(t), True, float(t_sub), float(s))
        return self.now

    def restart(self, bodies, t, y_rest, margin) -> None:
        """``bodies`` continue from their states in :attr:`now` at ``t`` to their new end states ``y_rest``."""
        _restart(self.arrays, self.now, (self.centers, self.reach, self.radii), np.asarray(bodies, dtype=np.int64),
                 float(t), np.asarray(y_rest, dtype=float), float(margin))


def swept_bounds(q0, q1, radii, margin):
    """Spheres holding the bodies along their chords ``q0 -> q1``: centre (the chord's middle),
    reach (radius + half the chord + margin) (:func:`.pairs.candidates`)."""
    return _swept_bounds(np.ascontiguousarray(q0, dtype=float), np.ascontiguousarray(q1, dtype=float),
                         np.asarray(radii, dtype=float), float(margin))


@njit(cache=True)
def _swept_bounds(q0, q1, radii, margin):
    """:func:`swept_bounds` compiled: NumPy's expressions element by element (the same numbers)."""
    n = len(radii)
    centers, reach = np.empty((n, 3)), np.empty(n)
    for b in range(n):
        _bound(centers, reach, b, (q0[b, 0], q0[b, 1], q0[b, 2]), (q1[b, 0], q1[b, 1], q1[b, 2]), radii[b], margin)
    return centers, reach


@njit(cache=True, inline="always")
def _bound(centers, reach, b, start, end, radius, margin):
    """Body b's swept sphere of the chord start -> end: centre the middle, reach r + |chord| / 2 + margin."""
    total = 0.0
    for k in range(3):
        centers[b, k] = 0.5 * (start[k] + end[k])
        dk = end[k] - start[k]
        total += dk * dk
    reach[b] = radius + 0.5 * np.sqrt(total) + margin


@njit(cache=True, inline="always")
def state_at(chords, b, t, f_sub):
    """Body ``b``'s state at ``t`` on its chord, ``(q, v)`` as 3-tuples: linear in time from
    ``y_from`` to ``y_end``; ``f_sub`` >= 0 is the fraction to take instead (the detector's own number)."""
    y_from, y_end, t_from, t_end = chords
    length = t_end - t_from[b]
    f = (t - t_from[b]) / length if length > 0 else 0.0
    if f_sub >= 0:
        f = f_sub
    return _along(y_from, y_end, 0, b, f), _along(y_from, y_end, 1, b, f)


@njit(cache=True, inline="always")
def _along(y_from, y_end, d, b, f):
    """y0 + f (y1 - y0) for row (d, b) of the chords' states, a 3-tuple."""
    return (y_from[d, b, 0] + f * (y_end[d, b, 0] - y_from[d, b, 0]),
            y_from[d, b, 1] + f * (y_end[d, b, 1] - y_from[d, b, 1]),
            y_from[d, b, 2] + f * (y_end[d, b, 2] - y_from[d, b, 2]))


@njit(cache=True)
def _at(chords, now, bodies, t, has_sub, t_sub, s):
    """:meth:`Chords.at`, compiled: the NumPy expressions element by element (the same numbers)."""
    t_from = chords[2]
    for b in bodies:
        q, v = state_at(chords, b, t, s if has_sub and t_from[b] == t_sub else -1.0)
        now[0, b, 0], now[0, b, 1], now[0, b, 2] = q
        now[1, b, 0], now[1, b, 1], now[1, b, 2] = v


@njit(cache=True)
def _restart(chords, now, bounds, bodies, t, y_rest, margin):
    """:meth:`Chords.restart`, compiled: the same assignments and :func:`swept_bounds` row by row;
    ``bounds`` = (centers, reach, radii) of the swept spheres."""
    y_from, y_end, t_from, _ = chords
    centers, reach, radii = bounds
    for p in range(bodies.shape[0]):
        b = bodies[p]
        for d in range(2):
            for k in range(3):
                y_from[d, b, k] = now[d, b, k]
                y_end[d, b, k] = y_rest[d, p, k]
        t_from[b] = t
        _bound(centers, reach, b, (y_from[0, b, 0], y_from[0, b, 1], y_from[0, b, 2]),
               (y_rest[0, p, 0], y_rest[0, p, 1], y_rest[0, p, 2]), radii[b], margin)


@njit(cache=True)
def turning_bounds(q0, q1, omega, bounding, step):
    """The rigid solver's bounds for a step: each body's reach (its bounding radius grown by the
    most its rotation can move a point, ``bounding (1 + min(|omega| dt, cap))``) and its speculative
    margin (that growth, plus the constant ``margin``, plus how far it moves on its chord ``q0 ->
    q1``); ``step`` = (dt, cap, margin). NumPy's expressions element by element, in their order (the
    same numbers; its norms and temporaries took 0.3 ms a step of 10^4 bodies)."""
    dt, cap, margin = step
    n = len(bounding)
    reach, speculative = np.empty(n), np.empty(n)
    for b in range(n):
        speed = np.sqrt(omega[b, 0] * omega[b, 0] + omega[b, 1] * omega[b, 1] + omega[b, 2] * omega[b, 2])
        reach[b] = bounding[b] * (1.0 + np.minimum(speed * dt, cap))
        d0, d1, d2 = q1[b, 0] - q0[b, 0], q1[b, 1] - q0[b, 1], q1[b, 2] - q0[b, 2]
        speculative[b] = reach[b] - bounding[b] + margin + np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return reach, speculative
