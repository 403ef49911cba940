"""``steplab animate`` on a scene whose springs act at body-frame points (spring-pendulum): stepped
with the rotation as ``steplab run`` steps it, its energy the one run reports, its springs drawn to
their attachment points and the view the plane of the swing."""

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import refused, run_main, spy_on_animate
from steplab.physics.scene import load_scene

T_END = "0.05"  # 50 steps of the scene's 1 ms
#: what the tests of the panels' runs and of the view need: 20 steps, 21 frames to draw rather than 51 (the two
#: methods' final energies already differ by 2e-4 of them, and the swing is already in x-z)
SHORT = "0.02"
#: the spring-pendulum's cube: 1 kg, 0.1 m on a side, hung at its corner (a/2, a/2, a/2) by k = 1e5 N/m, L = 0
MASS, SIDE, STIFFNESS, CORNER = 1.0, 0.1, 1e5, np.array([0.05, 0.05, 0.05])


def matrix(q):
    """The rotation matrix of the unit quaternion [w, x, y, z] (written out, not steplab's)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def run_json(capsys, *argv) -> dict:
    status, out, err = run_main(capsys, ["run", *argv, "--json"])
    assert status == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def animated(tmp_path_factory):
    """``steplab animate spring-pendulum --t-end T_END --fps 5``, run once for the tests of that one run (rendering
    its GIF takes seconds): the status, stdout, stderr, the GIF's path and what it drew (the ``drawn`` fixture's)."""
    from steplab.cli import main

    out = tmp_path_factory.mktemp("animate") / "a.gif"
    stdout, stderr = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        drawn = spy_on_animate(patch)
        try:
            status = main(["animate", "spring-pendulum", "--t-end", T_END, "--fps", "5", "--out", str(out)])
        except SystemExit as exit_:
            status = exit_.code
    return status, stdout.getvalue(), stderr.getvalue(), out, drawn


def test_animate_draws_the_spring_pendulum_with_the_energy_run_reports(capsys, animated):
    from PIL import Image

    status, text, err, out, drawn = animated
    assert status == 0, err
    assert "rotation: exponential-map (coupled)" in text  # the scene's rotation method, as run's without --rotation
    with Image.open(out) as gif:
        assert gif.n_frames == 51
    [energies] = drawn["energies"]
    summary = run_json(capsys, "spring-pendulum", "--t-end", T_END)
    # the spin and the springs at the turned lever arms: the translation and the springs at the initial
    # arms (model.energy) differ from this by some 4 % after 50 ms
    assert energies[0][0] == pytest.approx(summary["energy_start"], rel=1e-12)
    assert energies[0][-1] == pytest.approx(summary["energy_end"], rel=1e-12)
    assert drawn["views"] == [[1, 2]]  # it swings about x: y-z


def test_the_energy_drawn_is_the_whole_energy_at_each_frames_orientation(animated):
    status, _, err, _, drawn = animated
    assert status == 0, err
    [([(_, traj)], [rotation])] = drawn["calls"]
    [[energies]] = drawn["energies"]
    g = 9.81
    for k in (17, len(traj.t) - 1):
        x, v = traj.y[k]
        q, omega = rotation.orientations[k, 0], rotation.angular_velocities[k, 0]  # the cube, body 1
        point = x[1] + matrix(q) @ CORNER
        spring = 0.5 * STIFFNESS * np.linalg.norm(point - x[0]) ** 2
        spin = 0.5 * (MASS * SIDE**2 / 6) * omega @ omega  # a cube's inertia is the same about every axis
        expected = 0.5 * MASS * v[1] @ v[1] + MASS * g * (x[0, 2] + x[1, 2]) + spring + spin
        assert energies[k] == pytest.approx(expected, rel=1e-12)


def test_compare_runs_each_integrator_with_the_rotation(capsys, tmp_path, drawn):
    names = ["semi-implicit-euler", "velocity-verlet"]
    status, _, err = run_main(capsys, ["animate", "spring-pendulum", "--compare", ",".join(names), "--t-end", SHORT,
                                       "--fps", "5", "--out", str(tmp_path / "a.gif")])
    assert status == 0, err
    [energies] = drawn["energies"]
    [(runs, rotations)] = drawn["calls"]
    assert len(energies) == len(rotations) == 2
    for name, (_, traj), e in zip(names, runs, energies):
        assert traj.integrator == name
        assert e[-1] == pytest.approx(run_json(capsys, "spring-pendulum", "--integrator", name, "--t-end",
                                               SHORT)["energy_end"], rel=1e-12)


def test_springs_are_drawn_to_the_attachment_points():
    from steplab.animate import attached_segments

    scene = load_scene("spring-pendulum")
    model, bodies = scene.model, scene.rigid_bodies
    x = np.array([[0.0, 0.0, 1.0], [0.01, -0.02, 0.9]])
    half = 0.3  # the cube turned by 0.6 rad about x from its initial orientation
    turn = np.array([np.cos(half), np.sin(half), 0.0, 0.0])
    w1, v1 = turn[0], turn[1:]
    w2, v2 = bodies.orientations[0][0], bodies.orientations[0][1:]
    q = np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])
    orientations = np.array([[1.0, 0.0, 0.0, 0.0], q])
    springs, pointers = attached_segments(model, x, orientations, bodies.index, model.radii)
    point = x[1] + matrix(q) @ CORNER
    assert np.linalg.norm(point - x[1] - np.array([0, 0, np.linalg.norm(CORNER)])) > 0.01  # not straight above
    np.testing.assert_allclose(springs, [[x[0], point]], atol=1e-15)  # the anchor to the corner, not the centre
    np.testing.assert_allclose(pointers, [[x[1], point]], atol=1e-15)  # the cube's lever arm shows its turn


def test_a_rotating_body_without_an_attachment_point_shows_its_x_axis():
    from steplab.animate import attached_segments

    scene = load_scene("spring-pendulum")
    model = scene.model
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.9]])
    q = np.array([np.cos(0.25), 0.0, np.sin(0.25), 0.0])  # 0.5 rad about y
    # both bodies rotating, the anchor's end of the spring at its centre
    springs, pointers = attached_segments(model, x, np.array([q, q]), np.array([0, 1]), np.array([0.2, 0.1]))
    assert springs.shape == (1, 2, 3) and pointers.shape == (2, 2, 3)
    np.testing.assert_allclose(pointers[1], [x[0], x[0] + 0.2 * matrix(q)[:, 0]], atol=1e-15)


def _two_pendulums_swinging_in_xz(tmp_path):
    """spring-pendulum turned 90 degrees about z (it swings in x-z), and a second one beside it, 0.3 m along y."""
    text = (Path(__file__).parents[1] / "physics" / "scenes" / "spring-pendulum.toml").read_text()
    head, bodies = text.split("[[bodies]]", 1)
    bodies = ("[[bodies]]" + bodies).split("[forces.gravity]")[0]
    turned = {"orientation": "[0.6279630301995545, 0.45970084338098294, 0.0, 0.6279630301995544]",
              "angular_velocity": "[0.0, 0.9627069342295576, 0.0]", "velocity": "[-0.08337286614422316, 0.0, 0.0]"}
    lines = []
    for line in bodies.splitlines():
        key = line.split(" = ")[0]
        lines.append(f"{key} = {turned[key]}" if key in turned else line)
    bodies = "\n".join(lines) + "\n"
    beside = (bodies.replace('"anchor"', '"anchor2"').replace('"cube"', '"cube2"')
              .replace("[0.0, 0.0, 1.0]", "[0.0, 0.3, 1.0]").replace("[0.0, 0.0, 0.9132993596215562]",
                                                                       "[0.0, 0.3, 0.9132993596215562]"))
    spring = ('[[forces.springs]]\nbodies = ["{a}", "{c}"]\nstiffness = 1e5\nrest_length = 0.0\n'
              'offsets = [[0.0, 0.0, 0.0], [0.05, 0.05, 0.05]]\n')
    path = tmp_path / "two-pendulums.toml"
    path.write_text(head + bodies + beside + "[forces.gravity]\n\n" + spring.format(a="anchor", c="cube")
                    + spring.format(a="anchor2", c="cube2"))
    return path


def test_the_default_view_is_the_plane_of_the_swing(capsys, tmp_path, drawn):
    scene = _two_pendulums_swinging_in_xz(tmp_path)
    status, _, err = run_main(capsys, ["animate", str(scene), "--t-end", SHORT, "--fps", "5",
                                       "--out", str(tmp_path / "a.gif")])
    assert status == 0, err
    # the pendulums 0.3 m apart along y do not move along it: the extent of all the bodies picked y-z
    [(runs, _)] = drawn["calls"]
    positions = runs[0][1].positions
    assert np.ptp(positions[..., 1]) > np.ptp(positions[..., 0])
    assert drawn["views"] == [[0, 2]]


def test_with_collisions_it_is_one_line(capsys, tmp_path):
    err = refused(capsys, ["animate", "spring-pendulum", "--detector", "overlap", "--t-end", T_END,
                           "--out", str(tmp_path / "a.gif")])
    assert "not the event loop; use [collisions] method = \"solver\", or --detector none" in err
    assert not list(tmp_path.iterdir())
