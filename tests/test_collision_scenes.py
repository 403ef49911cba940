"""The [collisions] scene table, the collision scenes, and `steplab run --detector`."""

import json
import math

import numpy as np
import pytest
from steplab.integrators import simulate
from steplab.physics.collision import Box, OrientedBox, Plane
from steplab.physics.scene import load_scene, parse_scene

from steplab.cli import main

BALL = """
[simulation]
dt = 0.001
t_end = 1.0

[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 1.0]
material = "rubber"

[forces.gravity]
"""

COLLISIONS = """
[collisions]
detector = "overlap"
restitution = 0.8
bisection_iterations = 7
max_impacts_per_step = 5
broadphase = "sap"

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 2.0]
offset = 0.0
material = "concrete"

[[collisions.boxes]]
name = "wall"
center = [1.0, 0.0, 0.5]
size = [0.1, 2.0, 1.0]

[[collisions.boxes]]
name = "ramp"
center = [-1.0, 0.0, 0.0]
size = [1.0, 1.0, 0.1]
axis = [0.0, 1.0, 0.0]
angle = 30.0
trigger = true

[[collisions.materials]]
pair = ["rubber", "concrete"]
restitution = 0.6
friction = 0.4
"""


def test_collisions_table_builds_the_world():
    world = parse_scene(BALL + COLLISIONS).collisions
    assert world.detector == "overlap" and world.bisection_iterations == 7 and world.max_impacts_per_step == 5
    assert world.broadphase == "sap"
    floor, wall, ramp = world.shapes
    assert isinstance(floor, Plane) and np.array_equal(floor.normal, [0, 0, 1])  # normalised
    assert isinstance(wall, Box) and np.array_equal(wall.lo, [0.95, -1, 0]) and np.array_equal(wall.hi, [1.05, 1, 1])
    assert isinstance(ramp, OrientedBox) and ramp.trigger
    np.testing.assert_allclose(ramp.rotation @ [1, 0, 0], [math.cos(math.pi / 6), 0, -math.sin(math.pi / 6)])
    assert world.properties(0, floor) == (0.6, 0.4)
    assert world.properties(0, wall) == (0.8, 0.0)  # rubber on "default": the defaults
    assert parse_scene(BALL).collisions is None


BAD = [
    ('restitution = 0.8', 'restitution = 1.5', "collisions.restitution: must be between 0 and 1"),
    ('restitution = 0.6', 'restitution = -0.1', "collisions.materials[0].restitution: must be between 0 and 1"),
    ('detector = "overlap"', 'detector = "sweep"', "collisions.detector: must be one of none, overlap, swept"),
    ('size = [0.1, 2.0, 1.0]', 'size = [0.0, 2.0, 1.0]', "collisions.boxes[0].size: must be > 0 in every component"),
    ('normal = [0.0, 0.0, 2.0]', 'normal = [0.0, 0.0, 0.0]', "collisions.planes[0].normal: must be a non-zero vector"),
    ('axis = [0.0, 1.0, 0.0]', 'axis = [0.0, 0.0, 0.0]', "collisions.boxes[1].axis: must be a non-zero vector"),
    ('pair = ["rubber", "concrete"]', 'pair = ["rubber", "concrte"]',
     "collisions.materials[0].pair: names material 'concrte', which no body or shape has"),
    ('name = "ramp"', 'name = "wall"', "collisions.boxes[1].name: duplicate shape name 'wall'"),
    ('bisection_iterations = 7', 'bisection_iterations = 2.5', "collisions.bisection_iterations: must be an integer"),
    ('max_impacts_per_step = 5', 'max_impacts_per_step = 0', "collisions.max_impacts_per_step: must be between 1"),
    ('broadphase = "sap"', 'broadphase = "octree"', "collisions.broadphase: must be one of"),
    ('restitution = 0.8', 'restitution = 0.8\nbounce = 1', "collisions: unknown key 'bounce'"),
    ('radius = 0.1', 'radius = -0.1', "bodies[0].radius: must be > 0"),
]


@pytest.mark.parametrize("old,new,message", BAD)
def test_bad_collision_input_is_one_line_with_status_2(tmp_path, capsys, old, new, message):
    text = BALL + COLLISIONS
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    status = main(["run", str(path)])
    err = capsys.readouterr().err
    assert status == 2 and message in err
    assert err.startswith(f"steplab run: error: {path}: ") and err.count("\n") == 1


def run_json(capsys, *argv):
    status = main(["run", *argv, "--json"])
    out, err = capsys.readouterr()
    assert status == 0, err
    return json.loads(out)


@pytest.mark.parametrize("detector", ["swept", "overlap"])
def test_n_balls_runs_with_either_detector(capsys, detector):
    s = run_json(capsys, "n-balls", "--detector", detector, "--t-end", "1.0")
    assert s["detector"] == detector and s["collisions"]["impacts"] > 10
    q = np.array(s["final_positions"])
    assert np.all(np.abs(q[:, :2]) <= 1.1 - 0.1 + 1e-12) and np.all(q[:, 2] >= 0.1 - 1e-12)  # inside the box
    assert s["energy_end"] < s["energy_start"]
    none = run_json(capsys, "n-balls", "--detector", "none", "--t-end", "1.0")
    assert none["detector"] == "none" and none["collisions"] is None


def test_tunnelling_scene_tunnels_with_overlap_and_not_with_swept(capsys):
    through = run_json(capsys, "tunnelling")
    assert through["final_positions"][0][0] == pytest.approx(4.0) and through["collisions"]["impacts"] == 0
    back = run_json(capsys, "tunnelling", "--detector", "swept")
    assert back["final_velocities"][0][0] == -75.0 and back["collisions"]["impacts"] == 1  # eps = 0.5


def test_drop_bounces_with_the_lectures_golf_ball(capsys):
    scene = load_scene("drop")
    traj = simulate(scene.model, scene.integrator, scene.y0, 0.0, 1.2, scene.dt, collisions=scene.collisions)
    first = traj.collisions.events[0]
    assert first.other_name == "floor" and first.restitution == 0.858
    assert first.t == pytest.approx(math.sqrt(2 * 0.92 / 9.81), rel=2e-3)
    h = traj.positions[traj.t > first.t, 0, 2].max()  # floor at z = -r: the bottom's height is the centre's z
    assert math.sqrt(h / 0.92) == pytest.approx(0.858, rel=5e-3)


def test_billiards_break_keeps_every_ball_on_the_table():
    scene = load_scene("billiards")
    traj = simulate(scene.model, scene.integrator, scene.y0, 0.0, 1.0, scene.dt, collisions=scene.collisions,
                    save_every=100)
    r = float(scene.model.radii[0])
    q = traj.positions[-1]
    assert np.all(q[:, 2] == pytest.approx(r, abs=1e-12))
    assert np.all((q[:, 0] >= r - 1e-12) & (q[:, 0] <= 2.54 - r + 1e-12))
    assert np.all((q[:, 1] >= r - 1e-12) & (q[:, 1] <= 1.27 - r + 1e-12))
    moving = np.linalg.norm(traj.velocities[-1], axis=1) > 0.05
    assert moving.sum() >= 8 and traj.collisions.count() >= 15  # the rack broke up
    energy = [float(scene.model.energy(y)) for y in traj.y]
    assert np.all(np.diff(energy) <= 0)


def test_newtons_cradle_swings_the_last_ball_out():
    scene = load_scene("newtons-cradle")
    traj = simulate(scene.model, scene.integrator, scene.y0, 0.0, 0.6, scene.dt, collisions=scene.collisions)
    balls = [k for k, n in enumerate(scene.model.names) if n.startswith("ball")]
    first = [(e.body_name, e.other_name) for e in traj.collisions.events[:4]]
    assert first == [("ball1", "ball2"), ("ball2", "ball3"), ("ball3", "ball4"), ("ball4", "ball5")]
    x = traj.positions[:, balls, 0]
    assert x[:, 4].max() - 0.16 == pytest.approx(0.15, rel=2e-3)  # out as far as ball 1 was pulled back
    assert np.abs(x[-1, :4] - [0.0, 0.04, 0.08, 0.12]).max() < 2e-3  # the others stay


def test_collision_log_written_beside_the_trajectory(capsys, tmp_path):
    out = tmp_path / "run.npz"
    s = run_json(capsys, "drop", "--out", str(out))
    log = (tmp_path / "run.collisions.csv").read_text().splitlines()
    assert s["collisions_out"] == str(tmp_path / "run.collisions.csv")
    assert log[0] == "t,kind,body,other,nx,ny,nz,impact_speed,impulse,restitution,t_lo,t_hi"
    assert len(log) == 1 + s["collisions"]["impacts"] and log[1].split(",")[1:4] == ["impact", "ball", "floor"]
    assert json.loads(str(np.load(out)["metadata"]))["detector"] == "swept"


def test_collisions_on_jax_are_refused_with_one_line(capsys):
    status = main(["run", "drop", "--backend", "jax"])
    err = capsys.readouterr().err
    assert status == 2 and "NumPy backend only" in err and "--detector none" in err and err.count("\n") == 1
    assert main(["run", "drop", "--backend", "jax", "--detector", "none", "--t-end", "0.1"]) == 0


def test_run_summary_mentions_the_collisions(capsys):
    assert main(["run", "tunnelling", "--detector", "swept"]) == 0
    out = capsys.readouterr().out
    assert "collisions (swept): 1 impact," in out  # one impact, in the singular (issue 17)
