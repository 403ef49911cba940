"""The step's table of times of impact: every candidate pair tested once, until its bodies change.

The incremental event loop (:mod:`.step`) tests the step's candidate pairs once, keeps
each pair's collision time, and after an impact re-tests only the pairs of the bodies
the impact moved. The times of the others stay valid: their chords are unchanged.

A tested group of pairs is one :class:`PairTable`: the pairs, their start state, their
times as fractions ``s`` of the sub-step ``[t_sub, t_sub + h]`` they were tested on,
and the *stamp* of each body when they were tested. Every body's stamp counts the
changes of its chord; a pair is valid while its bodies' stamps are the ones it was
tested with. The finite times sit in a heap, earliest first; invalid entries are
dropped when they come to the top (lazy deletion), so a change costs O(1) per body.

Ties are broken as the full re-test breaks them (its ``argmin`` over the groups in
order): body pairs before shapes, shapes in the world's order, pairs lexicographically;
simultaneous impacts (a row of touching balls, all at s = 0) are so resolved in the
same order by both loops.
"""

from __future__ import annotations

import dataclasses
import heapq
from math import isfinite

import numpy as np

from .detectors import Impact, StartState
from .pairs import BodyPairs, ShapePairs

#: groups up to this many pairs are scanned in Python (:meth:`ImpactQueue.add`)
SMALL = 32


@dataclasses.dataclass
class PairTable:
    """One group of pairs tested on the sub-step ``[t_sub, t_sub + h]``, with the stamps it was tested with."""

    pairs: object
    start: StartState
    s: np.ndarray
    lo: np.ndarray
    t_sub: float
    h: float
    stamp_i: np.ndarray
    stamp_j: np.ndarray | None
    valid: np.ndarray

    def current(self, stamps) -> np.ndarray:
        """Which pairs are still valid: not re-tested since, and their bodies unchanged."""
        ok = self.valid & (stamps[self.pairs.i] == self.stamp_i)
        if self.stamp_j is not None:
            ok &= stamps[self.pairs.j] == self.stamp_j
        return ok

    def impact(self, k: int, t: float, h: float) -> Impact:
        """Pair ``k``'s collision as an :class:`Impact` of the sub-step ``[t, t + h]``."""
        if t == self.t_sub:  # tested on this very sub-step: the detector's own fractions
            return Impact(float(self.s[k]), float(self.lo[k]), self.pairs, k)
        s = max(0.0, (self.t_sub + self.s[k] * self.h - t) / h)
        lo = min(s, max(0.0, (self.t_sub + self.lo[k] * self.h - t) / h))
        return Impact(float(s), float(lo), self.pairs, k)


class ImpactQueue:
    """The tested pairs of one step, and their collision times earliest first.

    Parameters
    ----------
    n_bodies : int
    """

    def __init__(self, n_bodies: int):
        self.stamps = np.zeros(n_bodies, np.int64)
        self.tables: list[PairTable] = []
        self._heap: list = []
        self._watched: list[tuple[int, np.ndarray]] = []

    def add(self, pairs, start: StartState, s, lo, t_sub: float, h: float, watch=None) -> None:
        """Enter a tested group: ``s``, ``lo`` its times as fractions of ``[t_sub, t_sub + h]``.

        ``watch`` (bool per pair, optional): resting contacts to test again at every later
        collision of the step (see :meth:`take_watched`).
        """
        body = isinstance(pairs, BodyPairs)
        table = PairTable(pairs, start, s, lo, t_sub, h, self.stamps[pairs.i],
                          self.stamps[pairs.j] if body else None, np.ones(len(pairs), bool))
        number = len(self.tables)
        self.tables.append(table)
        rank = 0 if body else 1 + pairs.index
        if len(s) <= SMALL:  # a few pairs (a re-test): Python's scalars are cheaper than NumPy's calls
            times = np.asarray(s).tolist()
            finite = [k for k, x in enumerate(times) if isfinite(x)]
            if finite:
                times, i = [times[k] for k in finite], pairs.i.tolist()
                i = [i[k] for k in finite]
                if body:
                    j = pairs.j.tolist()
                    j = [j[k] for k in finite]
        else:
            where = np.flatnonzero(np.isfinite(s))
            finite = where.tolist()
            times, i = np.asarray(s)[where].tolist(), pairs.i[where].tolist()
            j = pairs.j[where].tolist() if body else None
        if finite:
            heap, push = self._heap, heapq.heappush
            for n, k in enumerate(finite):
                push(heap, (t_sub + times[n] * h, rank, i[n], j[n] if body else 0, number, k))
        if watch is not None:
            watched = np.flatnonzero(watch)
            if watched.size:
                self._watched.append((number, watched))

    def changed(self, bodies) -> None:
        """The chords of ``bodies`` changed: every pair tested with them is out of date."""
        self.stamps[bodies] += 1

    def _valid(self, table: PairTable, k: int) -> bool:
        if not table.valid[k] or self.stamps[table.pairs.i[k]] != table.stamp_i[k]:
            return False
        return table.stamp_j is None or self.stamps[table.pairs.j[k]] == table.stamp_j[k]

    def pop(self, ignored) -> tuple[PairTable, int] | None:
        """The valid pair with the earliest collision, not in ``ignored`` (removed from the queue), or None."""
        while self._heap:
            *_, number, k = heapq.heappop(self._heap)
            table = self.tables[number]
            if self._valid(table, k) and not (ignored and table.pairs.key(k) in ignored):
                return table, k
        return None

    def take_all(self) -> list:
        """Empty the queue: every valid pair, merged into groups (:meth:`current_groups`), to test again."""
        groups, _ = self.current_groups()
        for table in self.tables:
            table.valid[:] = False
        self._heap, self._watched = [], []
        return groups

    def take_watched(self) -> list:
        """The watched resting contacts still valid, as pairs groups to test again; marked re-tested.

        A pair touching at its test, approaching slower than its rest speed, is a resting
        contact: no time of impact. But its approach speed grows along the chord when it
        ends the step faster than the rest speed (a body pushed into the floor by a
        collision); the full re-test, which looks at every touching pair again at every
        collision, then finds it an impact at the first collision after the crossing. These
        few pairs are watched and tested again at each collision, so both loops agree.
        """
        watched, self._watched = self._watched, []
        groups = []
        for number, ks in watched:
            table = self.tables[number]
            ks = ks[table.current(self.stamps)[ks]]
            if ks.size:
                table.valid[ks] = False
                groups.append(table.pairs.subset(ks))
        return groups

    def current_groups(self) -> tuple[list, list[StartState]]:
        """The valid pairs of every table merged into the full re-test's groups, with their start states.

        One :class:`BodyPairs` in lexicographic order, then one :class:`ShapePairs` per shape
        in the world's order, bodies ascending: the groups and order the full re-test's
        broadphase produces, which resting contact (Gauss-Seidel) passes over in order.
        """
        body, shapes = [], {}
        for table in self.tables:
            ok = np.flatnonzero(table.current(self.stamps))
            if ok.size:
                (body if isinstance(table.pairs, BodyPairs) else shapes.setdefault(table.pairs.index, [])).append(
                    (table, ok))
        groups, starts = [], []
        if body:
            i = np.concatenate([t.pairs.i[ok] for t, ok in body])
            j = np.concatenate([t.pairs.j[ok] for t, ok in body])
            order = np.lexsort((j, i))
            groups.append(BodyPairs(i[order], j[order]))
            starts.append(_merged_starts(body, order))
        for index in sorted(shapes):
            parts = shapes[index]
            i = np.concatenate([t.pairs.i[ok] for t, ok in parts])
            order = np.argsort(i, kind="stable")
            groups.append(ShapePairs(index, parts[0][0].pairs.shape, i[order]))
            starts.append(_merged_starts(parts, order))
        return groups, starts


def _merged_starts(parts, order) -> StartState:
    """The start states of the pairs ``ok`` of each table, concatenated and put in ``order``."""
    def cat(field):
        return np.concatenate([np.broadcast_to(getattr(t.start, field), t.s.shape)[ok] if field == "rest_speed"
                               else getattr(t.start, field)[ok] for t, ok in parts])[order]
    return StartState(cat("in_contact"), cat("speed"), cat("normal"), cat("rest_speed"))
