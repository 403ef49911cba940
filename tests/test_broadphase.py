"""Broadphase: every method returns exactly brute force's pairs; brute force is checked by hand.

Parametrised over :data:`physics.broadphase.METHODS`, so a method is tested the moment it
is registered. Exactness is bit-for-bit: boundary cases (touching at r_i + r_j, zero radii,
coincident centres, underflowing squares) must fall the same way in every method.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from steplab.physics import find_pairs as physics_find_pairs
from steplab.physics.broadphase import METHODS, BoundingVolumeHierarchy, CoherentSortAndSweep, cells, find_pairs
from steplab.physics.broadphase.common import MAX_COORDINATE

FAST = [m for m in METHODS if m != "brute"]


def python_pairs(c, r) -> list[list[int]]:
    """The definition, one pair at a time, in plain Python floats (IEEE doubles, same operations)."""
    out = []
    for i, j in itertools.combinations(range(len(c)), 2):
        dx, dy, dz = (float(c[i][k]) - float(c[j][k]) for k in range(3))
        s = float(r[i]) + float(r[j])
        if dx * dx + dy * dy + dz * dz <= s * s:
            out.append([i, j])
    return out


def check_contract(pairs: np.ndarray, n: int) -> None:
    assert pairs.dtype == np.int64 and pairs.ndim == 2 and pairs.shape[1] == 2
    if len(pairs):
        assert np.all(pairs[:, 0] < pairs[:, 1]) and pairs.min() >= 0 and pairs.max() < n
        key = pairs[:, 0] * n + pairs[:, 1]
        assert np.all(np.diff(key) > 0), "rows must be sorted and unique"


# --- scenes that probe the boundaries -------------------------------------------------------

COORDINATE = st.floats(-10, 10, allow_nan=False, allow_infinity=False) | st.sampled_from([0.0, 1.0, -1.0, 0.5])
RADIUS = st.floats(0, 5, allow_nan=False, allow_infinity=False) | st.sampled_from([0.0, 1e-9, 0.5, 1.0, 1e3])


@st.composite
def scenes(draw, max_bodies=40):
    """Centres and radii with coincident centres, zero, tiny and huge radii, exact touching,
    negative coordinates and coordinates near 1e6, at scales from 1e-6 to 1e3."""
    n = draw(st.integers(0, max_bodies))
    scale = draw(st.sampled_from([1e-6, 1e-3, 1.0, 1e3]))
    offset = draw(st.sampled_from([0.0, -1e6, 1e6, -123.5]))
    c = offset + draw(arrays(np.float64, (n, 3), elements=COORDINATE)) * scale
    r = draw(arrays(np.float64, n, elements=RADIUS)) * scale
    if n >= 2:
        for _ in range(draw(st.integers(0, 4))):  # coincident centres
            i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
            c[i] = c[j]
        for _ in range(draw(st.integers(0, 4))):  # touching: j at distance r_i + r_j from i
            i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
            direction = draw(st.sampled_from([(1, 0, 0), (0, -1, 0), (0, 0, 1), (0.6, 0.8, 0), (0, -0.6, 0.8)]))
            if i != j:
                c[j] = c[i] + (r[i] + r[j]) * np.array(direction)
    return c, r


@pytest.mark.parametrize("method", list(METHODS))
@settings(max_examples=150)
@given(scene=scenes())
def test_every_method_equals_brute_force(method, scene):
    c, r = scene
    expected = find_pairs(c, r, "brute")
    got = find_pairs(c, r, method)
    check_contract(got, len(c))
    np.testing.assert_array_equal(got, expected)


@settings(max_examples=100)
@given(scene=scenes(max_bodies=25))
def test_brute_force_is_the_definition(scene):
    c, r = scene
    pairs = find_pairs(c, r, "brute")
    check_contract(pairs, len(c))
    assert pairs.tolist() == python_pairs(c, r)


@pytest.mark.parametrize("method", list(METHODS))
def test_boundary_cases(method):
    # touching exactly counts; one ulp further does not
    assert find_pairs([[0, 0, 0], [2, 0, 0]], [1, 1], method).tolist() == [[0, 1]]
    assert find_pairs([[0, 0, 0], [np.nextafter(2.0, 3.0), 0, 0]], [1, 1], method).tolist() == []
    # a 3-4-5 triangle: distance exactly 5
    assert find_pairs([[0, 0, 0], [3, 4, 0]], [2, 3], method).tolist() == [[0, 1]]
    assert find_pairs([[0, 0, 0], [3, 4, 0]], [2, np.nextafter(5.0, 0.0) - 2], method).tolist() == []
    # coincident points of radius zero touch; separate ones do not
    assert find_pairs([[1, 1, 1], [1, 1, 1], [1, 1, 2]], 0.0, method).tolist() == [[0, 1]]
    # nobody, one body
    assert find_pairs(np.empty((0, 3)), np.empty(0), method).shape == (0, 2)
    assert find_pairs([[5, 5, 5]], [1e3], method).shape == (0, 2)
    # huge and tiny together, negative coordinates, far from the origin
    c = np.array([[-1e6, -1e6, -1e6], [-1e6 + 1e-6, -1e6, -1e6], [-1e6 + 500, -1e6, -1e6], [1e6, 1e6, 1e6]])
    r = np.array([6e-7, 6e-7, 600.0, 1e-9])
    assert find_pairs(c, r, method).tolist() == python_pairs(c, r) == [[0, 1], [0, 2], [1, 2]]
    # at the size limit, squares still do not overflow
    c = np.array([[-MAX_COORDINATE] * 3, [MAX_COORDINATE] * 3, [0.0] * 3])
    assert find_pairs(c, [MAX_COORDINATE] * 3, method).tolist() == python_pairs(c, [MAX_COORDINATE] * 3)
    # squares that underflow to zero: 1e-170 apart counts as touching at radius 0
    assert find_pairs([[0, 0, 0], [1e-170, 0, 0]], 0.0, method).tolist() == [[0, 1]]


def scene_of(distribution: str, n: int, seed: int):
    from steplab.studies.broadphase import parameters, scene

    return scene(distribution, n, parameters(True), np.random.default_rng(seed))


@pytest.mark.parametrize("distribution", ["uniform", "clustered", "one-cell", "layer", "mixed"])
def test_study_distributions_agree(distribution):
    """The study's scenes, large enough to exercise cells, levels and deep trees."""
    c, r = scene_of(distribution, 300 if distribution == "one-cell" else 3000, seed=7)
    expected = find_pairs(c, r, "brute")
    assert len(expected) > 0
    for method in FAST:
        np.testing.assert_array_equal(find_pairs(c, r, method), expected, err_msg=method)


@pytest.mark.parametrize("distribution", ["uniform", "clustered", "layer", "dense"])
@pytest.mark.parametrize("threads", [2, 3])
def test_the_grid_on_threads_finds_the_same_pairs_in_the_same_order(distribution, threads, rng):
    """From PARALLEL_BODIES spheres the one-level grid searches in parts on Numba's threads, each part
    into its own rows; "dense" overfills those rows (15 pairs a sphere against room for 8), so
    the parts are searched again with room for all."""
    if distribution == "dense":
        c, r = rng.uniform(0, 3.0, (2500, 3)), rng.uniform(0.2, 0.25, 2500)
    else:
        c, r = scene_of(distribution, 3000, seed=7)
    assert len(c) >= cells.PARALLEL_BODIES
    expected = find_pairs(c, r, "brute")
    np.testing.assert_array_equal(find_pairs(c, r, "grid", threads=threads), expected)
    np.testing.assert_array_equal(find_pairs(c, r, "grid"), expected)


@pytest.mark.parametrize("method", FAST)
def test_far_outlier_and_equal_radii_spread(method, rng):
    # one body far away (a dense grid must coarsen; the hash must not care) and a shell of
    # equal spheres whose boxes sit exactly on cell boundaries
    c = np.concatenate([rng.uniform(0, 20, (400, 3)), [[1e7, -1e7, 3e6]], np.round(rng.uniform(0, 20, (200, 3)))])
    r = np.concatenate([rng.uniform(0.2, 0.6, 400), [1.0], np.full(200, 0.5)])
    np.testing.assert_array_equal(find_pairs(c, r, method), find_pairs(c, r, "brute"))


def test_default_method_and_physics_export():
    c = [[0, 0, 0], [1.5, 0, 0], [9, 9, 9]]
    assert physics_find_pairs(c, [1.0, 0.5, 1.0]).tolist() == [[0, 1]]
    assert physics_find_pairs is find_pairs


# --- frame coherence ------------------------------------------------------------------------


@settings(max_examples=40)
@given(scene=scenes(max_bodies=30), seed=st.integers(0, 2**32 - 1),
       motion=st.sampled_from([0.0, 1e-3, 0.1, 1.0, 30.0]))
def test_coherent_sweep_across_frames(scene, seed, motion):
    c, r = scene
    rng = np.random.default_rng(seed)
    sweep = CoherentSortAndSweep()
    span = 1.0 + float(np.abs(c).max(initial=0.0)) * 1e-9 + float(r.max(initial=0.0))
    v = rng.normal(0, motion * span, c.shape)
    for frame in range(6):
        got = sweep.update(c, r)
        check_contract(got, len(c))
        np.testing.assert_array_equal(got, find_pairs(c, r, "brute"), err_msg=f"frame {frame}")
        c = c + v
        if frame == 3:
            r = r * rng.uniform(0.5, 2.0, len(r))  # radii may change between frames too
    assert sweep.frames == 6 and sweep.full_sorts >= 1


def test_coherent_sweep_counts_swaps_and_falls_back():
    # four unit spheres in a row at x = 0, 10, 20, 30; body 0 jumps to x = 21, past body 1
    # and into body 2: sorted bounds go from lo0 hi0 lo1 hi1 lo2 hi2 ... to lo1 hi1 lo2 lo0
    # hi2 hi0 ..., 3 + 4 = 7 inversions (swaps) on x, none on y or z
    c = np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0]])
    sweep = CoherentSortAndSweep()
    assert sweep.update(c, 1.0).shape == (0, 2) and sweep.full_sorts == 1
    assert sweep.update(c, 1.0).shape == (0, 2) and sweep.swaps == 0
    c[0, 0] = 21.0
    assert sweep.update(c, 1.0).tolist() == [[0, 2]]
    assert sweep.swaps == 7 and sweep.full_sorts == 1 and sweep.total_swaps == 7 and sweep.box_pairs == 1
    # more bodies: a full sort, then repairs again
    c2 = np.vstack([c, [[26.0, 0, 0]]])
    assert sweep.update(c2, 1.0).tolist() == find_pairs(c2, 1.0).tolist()
    assert sweep.full_sorts == 2
    sweep.reset()
    sweep.update(c2, 1.0)
    assert sweep.full_sorts == 3 and sweep.frames == 5


def test_coherent_sweep_abandons_a_hopeless_repair(rng):
    c = rng.uniform(0, 100, (2000, 3))
    sweep = CoherentSortAndSweep()
    sweep.update(c, 1.0)
    shuffled = c[rng.permutation(len(c))]  # every body jumps: ~n^2 / 4 inversions per axis
    np.testing.assert_array_equal(sweep.update(shuffled, 1.0), find_pairs(shuffled, 1.0, "brute"))
    assert sweep.full_sorts == 2 and sweep.swaps == 0


# --- bounding-volume hierarchy -------------------------------------------------------------


@settings(max_examples=40)
@given(scene=scenes(max_bodies=60), seed=st.integers(0, 2**32 - 1), leaf_size=st.sampled_from([1, 2, 4, 7]))
def test_bvh_refit_stays_exact(scene, seed, leaf_size):
    c, r = scene
    rng = np.random.default_rng(seed)
    tree = BoundingVolumeHierarchy(c, r, leaf_size=leaf_size)
    np.testing.assert_array_equal(tree.pairs(), find_pairs(c, r, "brute"))
    for _ in range(3):
        c = c + rng.normal(0, 1.0 + float(r.max(initial=0.0)), c.shape)
        r = r * rng.uniform(0.5, 1.5, len(r))
        tree.refit(c, r)
        np.testing.assert_array_equal(tree.pairs(), find_pairs(c, r, "brute"))


def test_bvh_structure(rng):
    n = 1000
    tree = BoundingVolumeHierarchy(rng.uniform(0, 10, (n, 3)), 0.1)
    assert sorted(tree.order.tolist()) == list(range(n))
    leaves = tree.left < 0
    assert tree.count[leaves].sum() == n and tree.count[leaves].max() <= 4
    assert np.all(tree.left[~leaves] > np.flatnonzero(~leaves)), "children after parents"
    # a parent's box holds its children's
    for node in np.flatnonzero(~leaves):
        for child in (tree.left[node], tree.right[node]):
            assert np.all(tree.box_lo[node] <= tree.box_lo[child]) and np.all(tree.box_hi[child] <= tree.box_hi[node])
    # balanced by median splits
    depth = np.zeros(len(tree.left), dtype=int)
    for node in np.flatnonzero(~leaves):
        depth[tree.left[node]] = depth[tree.right[node]] = depth[node] + 1
    assert depth.max() <= math.ceil(math.log2(n / 4)) + 1
    with pytest.raises(ValueError, match="same 1000 bodies"):
        tree.refit(np.zeros((5, 3)), 1.0)


# --- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize("centers, radii, method, message", [
    ([[0, 0, np.nan]], [1.0], "grid", "centers must be finite, but center 0"),
    ([[0, 0, 0], [np.inf, 0, 0]], [1.0, 1.0], "sap", "centers must be finite, but center 1"),
    ([[0, 0, 0]], [-1.0], "bvh", "radii must be finite, >= 0"),
    ([[0, 0, 0]], [np.nan], "hash", "radii must be finite, >= 0"),
    ([[0, 0]], [1.0], "brute", r"centers must have shape \(n, 3\)"),
    (np.zeros((3, 3)), [1.0, 2.0], "grid", r"radii must have shape \(3,\)"),
    ([[0, 0, 0]], [[1.0]], "grid", r"radii must have shape \(1,\)"),
    ([["a", "b", "c"]], [1.0], "grid", "arrays of real numbers"),
    ([[2e150, 0, 0]], [1.0], "grid", r"\|x\| <= 1e\+150"),
    ([[0, 0, 0]], [1.0], "octree", "unknown broadphase method 'octree'; valid: brute, grid, hash, sap, "
                                   "sap-coherent, bvh"),
    ([[0, 0, 0]], [1.0], None, "unknown broadphase method None"),
])
def test_bad_input_raises_one_line_value_error(centers, radii, method, message):
    with pytest.raises(ValueError, match=message) as err:
        find_pairs(centers, radii, method)
    assert "\n" not in str(err.value)


def test_coherent_and_bvh_check_input_too():
    with pytest.raises(ValueError, match="centers must be finite"):
        CoherentSortAndSweep().update([[np.nan, 0, 0]], 1.0)
    with pytest.raises(ValueError, match="radii must be finite"):
        BoundingVolumeHierarchy([[0, 0, 0]], -1.0)
    with pytest.raises(ValueError, match="leaf_size must be an integer >= 1"):
        BoundingVolumeHierarchy([[0, 0, 0]], 1.0, leaf_size=0)


# --- the study's record ----------------------------------------------------------------------


def test_study_record_and_figures(tmp_path):
    from steplab.studies.broadphase import STUDY

    params = STUDY.parameters(True)
    params.update(sizes=[100, 300], repeats=1, coherence={**params["coherence"], "n": 300, "frames": 4,
                                                          "motion_sweep": [0.01, 1.0], "sweep_frames": 2})
    record = STUDY.compute(params)
    assert not record["mismatches"]
    row = record["series"][0]
    assert {"method", "distribution", "n", "seconds", "pairs", "peak_bytes"} <= set(row)
    assert {(s["method"], s["distribution"]) for s in record["series"]} >= {
        (m, d) for m in ("brute", "grid", "hash", "sap", "bvh", "ckdtree") for d in params["distributions"]}
    assert all(s["peak_bytes"] > 0 for s in record["series"] if s["method"] != "ckdtree-query")
    assert set(record["slopes"]) >= {"grid", "ckdtree"} and set(record["slopes"]["grid"]) == set(
        params["distributions"])
    assert record["coherence"]["agree"] and len(record["coherence"]["frames"]["fresh"]) == 4
    assert "coherent_over_fresh_per_frame" in record["targets"]
    figures = STUDY.plot(record, tmp_path)
    assert {"broadphase_scaling.png", "broadphase_memory.png", "broadphase_coherence.png"} <= set(figures)
    assert all((tmp_path / f).stat().st_size > 0 for f in figures)
    assert STUDY.summary(record)
