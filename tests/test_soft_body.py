"""Soft bodies: pair counts, rest lengths, meshes, and the lecture's CalcForce bugs pinned."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from helpers import tetrahedron
from numpy.testing import assert_allclose, assert_array_equal
from steplab.integrators import simulate
from steplab.physics import Gravity, Model
from steplab.physics.soft_body import all_pairs, box, connect, grid
from steplab.physics.state import lecture_state

# --- connections ---------------------------------------------------------------------------


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 8, 13])
def test_all_pairs_counts_each_unique_pair_once(n):
    pairs = all_pairs(n)
    assert pairs.shape == (n * (n - 1) // 2, 2)
    assert np.all(pairs[:, 0] < pairs[:, 1])  # no self pairs, one orientation
    assert {tuple(p) for p in pairs.tolist()} == set(itertools.combinations(range(n), 2))


def test_connect_rest_lengths_are_initial_distances(rng):
    vertices = rng.normal(size=(6, 3))
    pairs = all_pairs(6)
    springs, dampers = connect(vertices, pairs, stiffness=300.0, damping=2.0, offset=5)
    assert_array_equal(springs.i, pairs[:, 0] + 5)
    assert_array_equal(springs.j, pairs[:, 1] + 5)
    for (a, b), rest in zip(pairs, springs.rest_length):
        assert rest == pytest.approx(np.sqrt(np.sum((vertices[b] - vertices[a]) ** 2)), rel=1e-15)
    assert_array_equal(springs.stiffness, 300.0)
    assert_array_equal(dampers.i, springs.i)
    assert_array_equal(dampers.j, springs.j)
    assert_array_equal(dampers.damping, 2.0)
    assert connect(vertices, pairs, 300.0, 0.0)[1] is None  # no damping, no dampers


@pytest.mark.parametrize("name", ["semi-implicit-euler", "rk4", "implicit-euler"])
def test_soft_body_at_rest_without_gravity_stays_at_rest(name, rng):
    vertices = rng.normal(size=(5, 3))
    springs, dampers = connect(vertices, all_pairs(5), stiffness=1000.0, damping=3.0)
    model = Model(np.full(5, 0.2), np.full(5, 0.05), [springs, dampers])
    y0 = np.stack([vertices, np.zeros_like(vertices)])
    assert_allclose(model.net_force(0.0, vertices, y0[1]), 0.0, atol=1e-10)
    run = simulate(model, name, y0, 0.0, 0.5, 0.01)
    assert_allclose(run.y[-1, 0], vertices, rtol=0, atol=1e-12)
    assert_allclose(run.y[-1, 1], 0.0, atol=1e-10)


# --- meshes --------------------------------------------------------------------------------


def test_box_has_8_corners_and_12_axis_aligned_edges():
    size, center = np.array([1.0, 2.0, 3.0]), np.array([0.5, -1.0, 2.0])
    mesh = box(size, center)
    assert mesh.vertices.shape == (8, 3) and mesh.edges.shape == (12, 2)
    assert_allclose(mesh.vertices.mean(axis=0), center, atol=1e-15)
    assert_allclose(mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0), size)
    delta = np.abs(mesh.vertices[mesh.edges[:, 1]] - mesh.vertices[mesh.edges[:, 0]])
    assert np.all(np.count_nonzero(delta > 0, axis=1) == 1)  # along one axis each
    for axis in range(3):  # four edges along each axis, as long as the box
        along = delta[:, axis] > 0
        assert along.sum() == 4
        assert_allclose(delta[along, axis], size[axis])
    degree = np.bincount(mesh.edges.ravel(), minlength=8)
    assert_array_equal(degree, 3)


@pytest.mark.parametrize("rows, cols", [(1, 1), (1, 5), (2, 2), (3, 4), (12, 12)])
@pytest.mark.parametrize("shear", [True, False])
def test_grid_edge_counts(rows, cols, shear):
    mesh = grid(rows, cols, spacing=0.1, origin=(1.0, 2.0, 3.0), shear=shear)
    structural = rows * (cols - 1) + (rows - 1) * cols
    diagonals = 2 * (rows - 1) * (cols - 1) if shear else 0
    assert mesh.vertices.shape == (rows * cols, 3)
    assert mesh.edges.shape == (structural + diagonals, 2)
    assert len({tuple(sorted(e)) for e in mesh.edges.tolist()}) == len(mesh.edges)  # no duplicates
    lengths = np.linalg.norm(mesh.vertices[mesh.edges[:, 1]] - mesh.vertices[mesh.edges[:, 0]], axis=1)
    assert np.sum(np.isclose(lengths, 0.1)) == structural
    assert np.sum(np.isclose(lengths, 0.1 * np.sqrt(2))) == diagonals
    assert_allclose(mesh.vertices[0], [1.0, 2.0, 3.0])
    assert_allclose(mesh.vertices[:, 2], 3.0)  # a flat cloth in the x-y plane


# --- the lecture's CalcForce ---------------------------------------------------------------

G = np.array([0.0, 0.0, -9.81])


def lecture_calc_force(i, cur_S, mass, k, lrest, c, g=G):
    """The lecture's ``vector CalcForce(i)``, transcribed literally (bugs included).

    cur_S is the lecture's state S = (m1 V1, p1, m2 V2, p2, ...); k, lrest and c are the
    N x N pair matrices. In NumPy, normalising the zero vector (j == i) is 0/0 = NaN.
    """
    N = len(mass)
    net_force = mass[i] * g  # Initialize net force for gravity
    for j in range(N):
        d = cur_S[2 * j + 1] - cur_S[2 * i + 1]
        length = np.sqrt(d @ d)
        d = d / length  # d.normalize()
        SForce = k[i][j] * (length - lrest[i][j]) * d
        relativeVel = (cur_S[2 * j] / mass[j]) - (cur_S[2 * i] / mass[i])
        DForce = c[i][j] * relativeVel.dot(d) * d
        net_force = SForce + DForce  # "increment net force" -- but it overwrites
    return net_force


def corrected_calc_force(i, cur_S, mass, k, lrest, c, g=G):
    """The same loop with the two bugs fixed: skip j == i, and accumulate with +=."""
    N = len(mass)
    net_force = mass[i] * g
    for j in range(N):
        if j == i:
            continue
        d = cur_S[2 * j + 1] - cur_S[2 * i + 1]
        length = np.sqrt(d @ d)
        d = d / length
        SForce = k[i][j] * (length - lrest[i][j]) * d
        relativeVel = (cur_S[2 * j] / mass[j]) - (cur_S[2 * i] / mass[i])
        DForce = c[i][j] * relativeVel.dot(d) * d
        net_force = net_force + SForce + DForce
    return net_force


@pytest.fixture
def deformed_soft_body(rng):
    """A 4-vertex all-pairs soft body (per-pair stiffness and damping), deformed and moving.

    Returns steplab's model, the state y, and the lecture's S and pair matrices.
    """
    rest_shape = tetrahedron()
    n = len(rest_shape)
    pairs = all_pairs(n)
    stiffness = rng.uniform(50, 150, len(pairs))
    damping = rng.uniform(0.5, 2.0, len(pairs))
    springs, dampers = connect(rest_shape, pairs, 1.0, 1.0)
    springs = type(springs)(springs.i, springs.j, stiffness, springs.rest_length)
    dampers = type(dampers)(dampers.i, dampers.j, damping)
    mass = rng.uniform(0.2, 0.6, n)
    model = Model(mass, np.full(n, 0.05), [Gravity(G), springs, dampers])
    y = np.stack([rest_shape + rng.uniform(-0.15, 0.15, (n, 3)), rng.normal(size=(n, 3))])

    k, lrest, c = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for (a, b), kk, ll, cc in zip(pairs, stiffness, springs.rest_length, damping):
        k[a, b] = k[b, a] = kk
        lrest[a, b] = lrest[b, a] = ll
        c[a, b] = c[b, a] = cc
    return model, y, lecture_state(y, mass), mass, k, lrest, c


def test_lecture_calc_force_differs_from_steplab(deformed_soft_body):
    model, y, S, mass, k, lrest, c = deformed_soft_body
    steplab = model.net_force(0.0, y[0], y[1])
    with np.errstate(invalid="ignore", divide="ignore"):
        lecture = np.array([lecture_calc_force(i, S, mass, k, lrest, c) for i in range(len(mass))])
    # j == i is not skipped: for the last vertex the loop ends on 0/0, a NaN force
    assert np.all(np.isnan(lecture[-1]))
    # the others keep only their spring and damper to the last vertex: no gravity, no
    # other springs -- finite but wrong
    assert np.all(np.isfinite(lecture[:-1]))
    for i in range(len(mass) - 1):
        assert not np.allclose(lecture[i], steplab[i], rtol=1e-3)
    # what the literal transcription computes for vertex 0 is exactly the pair (0, N-1)
    only_last = corrected_calc_force(0, S, mass, k * _only(0, 3), lrest, c * _only(0, 3), g=0 * G)
    assert_allclose(lecture[0], only_last, rtol=1e-14)


def _only(i, j, n=4):
    """A pair-matrix mask keeping only the pair (i, j)."""
    mask = np.zeros((n, n))
    mask[i, j] = mask[j, i] = 1.0
    return mask


def test_corrected_calc_force_equals_steplab_net_force(deformed_soft_body):
    model, y, S, mass, k, lrest, c = deformed_soft_body
    corrected = np.array([corrected_calc_force(i, S, mass, k, lrest, c) for i in range(len(mass))])
    steplab = model.net_force(0.0, y[0], y[1])
    assert np.abs(steplab).max() > 10  # far from equilibrium
    assert_allclose(steplab, corrected, rtol=1e-13, atol=1e-12)
    # and on the JAX backend
    import jax.numpy as jnp

    jmodel = model.cast(jnp)
    assert_allclose(np.asarray(jmodel.net_force(0.0, jnp.asarray(y[0]), jnp.asarray(y[1]))), corrected,
                    rtol=1e-13, atol=1e-12)
