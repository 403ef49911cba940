"""The rigid solver step's bookkeeping kernels against their definitions written plainly (issue 26).

The warm start's match of each point with the last step's and the impacts the log records are
compiled and cut into parts on the solver's threads; each is checked here
against a few lines of Python that say what it must give, on random sorted points, on 1 to 3 threads.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.physics.collision import rigid_solver as rs
from steplab.physics.collision.rigid_columns import first_impacts


def sorted_points(rng, bodies, points, statics=3, features=4):
    """Random points (a, b, feature), int64, sorted and distinct, a != b, b < 0 a static shape."""
    a = rng.integers(0, bodies, points)
    b = rng.integers(-statics, bodies, points)
    f = rng.integers(0, features, points)
    keys = sorted({(int(i), int(j), int(k)) for i, j, k in zip(a, b, f) if i != j})
    columns = np.array(keys, np.int64).reshape(-1, 3).T
    return tuple(np.ascontiguousarray(c) for c in columns)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 80), st.integers(0, 80), st.integers(1, 3))
def test_previous_rows_match_each_point_by_its_key(seed, old_count, new_count, threads):
    """Each new point's row is the last step's contact (``place`` of its sorted index) with the same
    (a, b, feature), or -1: a dictionary lookup."""
    rng = np.random.default_rng(seed)
    old, new = sorted_points(rng, 6, old_count), sorted_points(rng, 6, new_count)
    place = rng.permutation(len(old[0])).astype(np.int64)
    where = {key: int(place[p]) for p, key in enumerate(zip(*(c.tolist() for c in old)))}
    expected = [where.get(key, -1) for key in zip(*(c.tolist() for c in new))]
    assert rs.previous_rows(old, new, place, threads).tolist() == expected


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 120), st.integers(1, 3))
def test_first_impacts_are_each_pairs_first_newly_pressed_point(seed, count, threads):
    """Of each pair (a, b), in the pairs' sorted order, the first point (lowest feature) pressed now and
    not in the last step (no match, or a match whose impulse was 0), given as its row of the sweep."""
    rng = np.random.default_rng(seed)
    key = sorted_points(rng, 5, count)
    n = len(key[0])
    place = rng.permutation(n).astype(np.int64)
    total = np.where(rng.random(n) < 0.5, rng.random(n), 0.0)
    previous_total = np.where(rng.random(7) < 0.5, 1.0, 0.0)
    rows = rng.integers(-1, 7, n).astype(np.int64)
    expected, seen = [], set()
    for i in range(n):
        pair = (key[0][i], key[1][i])
        if pair not in seen and total[place[i]] > 0 and (rows[i] < 0 or previous_total[rows[i]] == 0):
            seen.add(pair)
            expected.append(int(place[i]))
    assert first_impacts(key, place, rows, previous_total, total, threads).tolist() == expected
