"""The stacking section of steplab bench: its box pits, and a tiny run of the section."""

import dataclasses
import itertools
import os

import numpy as np
import pytest
from steplab.physics.collision.shapes import Plane

from steplab import bench
from steplab.bench import stacking


@pytest.mark.parametrize("n", [1, 50, 1_000])
def test_box_pit_starts_apart_inside_its_walls(n):
    scene = stacking.box_pit(n)
    assert scene.model.n_bodies == scene.rigid_bodies.n == n and set(scene.rigid_bodies.shapes) == {"box"}
    q, r = scene.y0[0], scene.model.radii
    planes = [s for s in scene.collisions.shapes if isinstance(s, Plane)]
    assert len(planes) == 5 and scene.collisions.method == "solver"
    for plane in planes:  # every bounding sphere inside the floor and the four walls
        assert np.all(q @ plane.normal - plane.offset > r)
    # no two bounding spheres touch (brute force over the pairs)
    for i, j in itertools.combinations(range(min(n, 300)), 2):
        assert np.linalg.norm(q[i] - q[j]) > r[i] + r[j]
    np.testing.assert_allclose(np.linalg.norm(scene.rigid_bodies.orientations, axis=1), 1.0, rtol=1e-12)
    assert stacking.box_pit_toml(n) == stacking.box_pit_toml(n)  # seeded: the same bytes
    assert stacking.box_pit_toml(n, seed=1) != stacking.box_pit_toml(n)


def test_box_pit_needs_a_box():
    with pytest.raises(ValueError, match="at least one box, got n = 0"):
        stacking.box_pit_toml(0)


def test_tiny_stacking_section_records_the_pyramid_and_the_pit(monkeypatch):
    """The section on a tiny configuration with pybullet as the one peer (MuJoCo as not installed)."""
    from steplab.engines import ENGINES

    monkeypatch.setattr(ENGINES["mujoco"], "available", classmethod(lambda cls: False))
    config = dataclasses.replace(bench.QUICK, stack_pyramid_rows=3, stack_steps=1, box_pit_runs=((20, 2),),
                                 repeats=1, max_rounds=2, round_budget_seconds=0.5, collision_repeats=1)
    record = bench.Record(config, quick=True)
    stacking.stacking(config, record, lambda message: None)
    pyramid = record.data["stacking"]["pyramid_3"]
    assert set(pyramid["not_compared"]) == {"mujoco_pgs", "mujoco_newton"}
    assert "not installed" in pyramid["not_compared"]["mujoco_pgs"]
    assert pyramid["top_start"] == 2.5 and pyramid["seconds_per_step"]["steplab"] > 0
    pit = record.data["stacking"]["box_pit_20"]
    assert pit["boxes"] == 20 and pit["real_time_factor"]["steplab"] > 0
    if ENGINES["bullet"].available():
        for name in ("vs_pybullet_pyramid_3", "vs_pybullet_box_pit_20"):
            s = record.data["seconds"][name]
            assert s["group"] == "stacking" and 0 < s["steplab_spread"]["min"] <= s["steplab_spread"]["max"]
    assert "vs_mujoco_pgs_pyramid_3" not in record.data["targets"]


def test_the_box_pit_on_two_cores_runs_in_a_child_with_two_threads():
    """The 2-core timing (issue 26's "on 2 cores") comes from a child process given 2 cores and 2 Numba
    threads, its scene's solver set to 2 threads, whatever the bench process runs on; it says so in
    its record."""
    child = stacking.on_cores(20, 2, 1, 2, processes=2)
    assert child["numba_threads"] == 2 and child["cores"] == min(2, len(os.sched_getaffinity(0)))
    # every process recorded, fastest first; the one judged is the median (of two: the faster)
    times = [run["median"] for run in child["processes"]]
    assert len(times) == 2 and times == sorted(times) and child["seconds_per_step"]["median"] == times[0]
    assert child["solver_threads"] == 2 and child["settings"].endswith(", 2 threads")  # the scene asks for them
    assert child["seconds_per_step"]["median"] > 0 and child["threading_layer"] in ("omp", "tbb", "workqueue")
