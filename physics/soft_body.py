"""Spring-mass-damper soft bodies: a particle per vertex, springs and dampers between them.

The lecture's soft body connects *all unique pairs* of vertices with a spring and a
damper whose rest length is the initial distance. A mesh can instead be connected
along its edges only (a cloth's structural and shear springs), which scales as O(V)
rather than O(V^2).

The lecture's ``CalcForce(i)`` has two bugs that steplab does not copy: it overwrites
the net force (``net_force = SForce + DForce``) instead of accumulating it, so
gravity and every spring but the last are lost, and it does not skip ``j == i``, where
the spring direction is the normalised zero vector (0/0). Here the pair lists hold each
unique pair once, and :class:`physics.Springs` / :class:`physics.Dampers` add every
pair's force to both ends (``tests/test_soft_body.py`` pins the difference).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from .dampers import Dampers
from .springs import Springs


@dataclasses.dataclass(frozen=True)
class Mesh:
    """Vertices (V, 3) m and edges (E, 2) indices into them."""

    vertices: np.ndarray
    edges: np.ndarray


def all_pairs(n: int) -> np.ndarray:
    """Every unique pair (i < j) of n vertices, shape (n (n - 1) / 2, 2)."""
    i, j = np.triu_indices(n, k=1)  # row-major: (0, 1), (0, 2), ..., (1, 2), ...
    return np.stack([i, j], axis=1).astype(np.int64)


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0)) -> Mesh:
    """The 8 corners of an axis-aligned box with its 12 edges."""
    size, center = np.asarray(size, float), np.asarray(center, float)
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))
    vertices = center + corners * size
    edges = [(a, b) for a, b in all_pairs(8) if np.count_nonzero(corners[a] != corners[b]) == 1]
    return Mesh(vertices, np.array(edges, dtype=np.int64))


def grid(rows: int, cols: int, spacing: float, origin=(0.0, 0.0, 0.0), shear: bool = True) -> Mesh:
    """A rows x cols grid of vertices in the x-y plane (a cloth), row-major.

    Edges: structural (to the right and below neighbours) and, with ``shear``, both
    diagonals of each cell, which keep the cloth from shearing flat.
    """
    index = np.arange(rows * cols).reshape(rows, cols)
    ys, xs = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    vertices = np.asarray(origin, float) + spacing * np.stack(
        [xs.ravel(), -ys.ravel(), np.zeros(rows * cols)], axis=1)
    pairs = [np.stack([index[:, :-1].ravel(), index[:, 1:].ravel()], 1),
             np.stack([index[:-1, :].ravel(), index[1:, :].ravel()], 1)]
    if shear:
        pairs += [np.stack([index[:-1, :-1].ravel(), index[1:, 1:].ravel()], 1),
                  np.stack([index[:-1, 1:].ravel(), index[1:, :-1].ravel()], 1)]
    return Mesh(vertices, np.concatenate(pairs).astype(np.int64))


def connect(vertices, pairs, stiffness: float, damping: float, offset: int = 0):
    """Springs and dampers on the given vertex pairs, rest lengths from the initial distances.

    Parameters
    ----------
    vertices : array, shape (V, 3)
    pairs : int array, shape (P, 2)
    offset : int
        Index of vertex 0 among all bodies of the scene.

    Returns
    -------
    springs : Springs
    dampers : Dampers or None (when ``damping`` is 0)
    """
    vertices = np.asarray(vertices, float)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    rest = np.linalg.norm(vertices[pairs[:, 1]] - vertices[pairs[:, 0]], axis=1)
    i, j = pairs[:, 0] + offset, pairs[:, 1] + offset
    springs = Springs(i, j, np.full(len(pairs), float(stiffness)), rest)
    dampers = Dampers(i, j, np.full(len(pairs), float(damping))) if damping else None
    return springs, dampers
