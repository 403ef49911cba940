"""Stacks of boxes: where the boxes of a column or a pyramid stand, touching.

The ``[[stacks]]`` table of a scene (:mod:`.scene`) builds its boxes from this layout. A
stack stands on the point ``base`` (the centre of the bottom face of its bottom row) with
its rows along z, bottom up:

- ``"column"``: one box per row, each centred over the one below;
- ``"pyramid"``: ``rows - k`` boxes in row k (k = 0 at the bottom) side by side along x,
  each row shifted by half a box against the one below, so that every box above the
  bottom row rests half on each of two boxes (Box2D's ``large_pyramid``). A pyramid of
  n rows has n (n + 1) / 2 boxes.

``gap`` is the clearance between neighbouring faces: above the floor, between rows and
between neighbours in a row; 0 puts every face on its neighbour's.
"""

from __future__ import annotations

import numpy as np

KINDS = ("column", "pyramid")


def stack_layout(kind: str, rows: int, size, gap: float, base) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3), m, and row numbers (n,) of the boxes of a stack, bottom row first,
    each row along +x.

    Parameters
    ----------
    kind : {"column", "pyramid"}
    rows : int
        >= 1.
    size : array, shape (3,)
        The box's edges (a, b, c), m: a along x, c along z (the height of a row).
    gap : float
        Clearance between faces, m (>= 0).
    base : array, shape (3,)
        Centre of the bottom face of the bottom row, m.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown stack kind {kind!r}; valid: {', '.join(KINDS)}")
    a, _, c = np.asarray(size, dtype=float)
    base = np.asarray(base, dtype=float)
    row = np.repeat(np.arange(rows), 1 if kind == "column" else np.arange(rows, 0, -1))
    # place j of each row, 0 .. (boxes in the row - 1): the running count minus the row's start
    start = np.concatenate([[0], np.cumsum(np.bincount(row))[:-1]])
    place = np.arange(len(row)) - start[row]
    across = 0.0 if kind == "column" else (place - 0.5 * (rows - 1 - row)) * (a + gap)
    centres = np.zeros((len(row), 3))
    centres[:, 0] = across
    centres[:, 2] = gap + 0.5 * c + row * (c + gap)
    return base + centres, row
