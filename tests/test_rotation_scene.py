"""Rotating bodies in scene files: the TOML keys, the run beside the translation, the reported fields."""

from __future__ import annotations

import numpy as np
import pytest
from steplab.integrators import UnknownIntegratorError, simulate
from steplab.integrators.scene_rotation import rotate_scene, rotation_arrays, rotation_summary
from steplab.integrators.torque_free import TorqueFreeMotion
from steplab.physics import quaternion as quat
from steplab.physics.scene import SceneError, load_scene, parse_scene

SIMULATION = '[simulation]\ndt = 0.01\nt_end = 1.0\n'


def scene(bodies: str, simulation: str = SIMULATION, forces: str = "[forces]\ngravity = {g = [0, 0, -9.81]}\n"):
    return parse_scene(f"{simulation}\n{forces}\n{bodies}", "s.toml")


BOX = '''
[[bodies]]
name = "box"
mass = 2.0
radius = 0.5
position = [0, 0, 1]
velocity = [1, 0, 3]
shape = "box"
size = [0.2, 0.4, 0.6]
orientation = [2, 0, 0, 0]
angular_velocity = [0.1, 3.0, 0.1]
'''
BALL = '''
[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [1, 0, 0]
'''


def test_body_keys_give_inertia_orientation_and_world_angular_velocity():
    s = scene(BOX + BALL)
    bodies = s.rigid_bodies
    assert bodies.index.tolist() == [0] and bodies.shapes == ("box",)  # the ball stays a point mass
    np.testing.assert_allclose(bodies.inertia[0], 2.0 / 12 * np.array([0.16 + 0.36, 0.04 + 0.36, 0.04 + 0.16]))
    assert bodies.orientations.tolist() == [[1.0, 0.0, 0.0, 0.0]]  # normalised on load
    assert bodies.angular_velocities.tolist() == [[0.1, 3.0, 0.1]]
    assert s.rotation is None


@pytest.mark.parametrize("extra, shape, inertia", [
    ('angular_velocity = [0, 0, 1]', "sphere", [0.004] * 3),
    ('inertia = [1, 2, 2.5]', "sphere", [1, 2, 2.5]),
    ('shape = "cylinder"\nlength = 0.6', "cylinder", [1 / 12 * (0.03 + 0.36)] * 2 + [0.005]),
])
def test_which_bodies_rotate(extra, shape, inertia):
    bodies = scene(BALL + extra + "\n").rigid_bodies
    assert bodies.shapes == (shape,)
    np.testing.assert_allclose(bodies.inertia[0], inertia, rtol=1e-14)


def test_a_scene_without_rotating_bodies_is_unchanged():
    s = load_scene("projectile")
    assert s.rigid_bodies is None
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt)
    assert rotate_scene(s, traj) is None
    summary = rotation_summary(s, traj, None)
    assert summary["rotating_bodies"] == [] and summary["final_orientations"] == [[1.0, 0.0, 0.0, 0.0]]


@pytest.mark.parametrize("rotation", ["explicit", "dlm", "rk4"])
def test_rotation_never_changes_the_translation(rotation):
    """The same scene with and without the spin: the same translational bytes."""
    spinning, still = scene(BOX + BALL), scene(BOX.replace('shape = "box"\nsize = [0.2, 0.4, 0.6]\n', "")
                                               .replace("orientation = [2, 0, 0, 0]\n", "")
                                               .replace("angular_velocity = [0.1, 3.0, 0.1]\n", "") + BALL)
    assert still.rigid_bodies is None
    runs = [simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt) for s in (spinning, still)]
    assert runs[0].y.tobytes() == runs[1].y.tobytes()
    rot = rotate_scene(spinning, runs[0], rotation)
    assert rot.orientations.shape == (len(runs[0].t), 1, 4) and rot.method == rotation
    assert not np.allclose(rot.orientations[-1], rot.orientations[0])


def test_rotation_follows_the_exact_solution_and_the_saved_times():
    inertia_scene = BALL + 'inertia = [1, 2, 3]\nangular_velocity = [0.3, 1.0, -0.2]\n'
    s = scene(inertia_scene, SIMULATION + 'rotation = "rk4"\n', forces="")
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt, save_every=7)
    rot = rotate_scene(s, traj)
    assert rot.method == "rk4" and np.array_equal(rot.t, traj.t)
    motion = TorqueFreeMotion([1, 2, 3], quat.IDENTITY, [0.3, 1.0, -0.2])
    assert np.max(quat.angle_between(np, rot.orientations[:, 0], motion.orientation(traj.t))) < 1e-9
    body_omega = quat.rotate_inverse(np, rot.orientations[:, 0], rot.angular_velocities[:, 0])
    np.testing.assert_allclose(body_omega, motion.angular_velocity(traj.t), atol=1e-9)
    # a reference solve is matched by the rotation reference
    ref = simulate(s.model, "scipy-dop853", s.y0, s.t_start, s.t_end, 0.25)
    rot = rotate_scene(s, ref)
    assert np.max(quat.angle_between(np, rot.orientations[:, 0], motion.orientation(ref.t))) < 1e-10


def test_run_fields_and_npz_arrays():
    s = scene(BOX + BALL, forces="")
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt, save_every=10)
    rot = rotate_scene(s, traj, "dlm")
    summary = rotation_summary(s, traj, rot)
    assert summary["rotating_bodies"] == ["box"] and summary["rotation"] == "dlm"
    assert summary["final_orientations"][1] == [1.0, 0.0, 0.0, 0.0]
    # no forces: the total angular momentum about the origin is conserved (dlm keeps the spin's
    # vector: each of its sub-flows is an exact rotation)
    np.testing.assert_allclose(summary["angular_momentum_end"], summary["angular_momentum_start"], atol=1e-13)
    spin = s.rigid_bodies.angular_momenta()[0]
    orbital = 2.0 * np.cross([0, 0, 1], [1, 0, 3])
    np.testing.assert_allclose(summary["angular_momentum_start"], spin + orbital, atol=1e-15)
    arrays = rotation_arrays(rot, 2)
    assert arrays["orientations"].shape == (len(traj.t), 2, 4)
    assert arrays["angular_velocities"].shape == (len(traj.t), 2, 3)
    # the rotational energy is in model.energy
    e_rot = 0.5 * np.sum(s.rigid_bodies.inertia * s.rigid_bodies.body_angular_velocities() ** 2)
    assert s.model.energy(s.y0, s.rigid_bodies) == pytest.approx(s.model.energy(s.y0) + e_rot, rel=1e-15)
    midpoint = rotate_scene(s, traj, "implicit-midpoint")  # keeps the energy to round-off
    assert s.model.energy(traj.y[-1], midpoint.at(-1)) == pytest.approx(s.model.energy(s.y0, s.rigid_bodies),
                                                                        rel=1e-13)


def test_unknown_rotation_method_is_one_line():
    s = scene(BALL, SIMULATION + 'rotation = "euler"\n')
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt)
    with pytest.raises(UnknownIntegratorError, match="unknown rotation method 'euler'; valid: explicit"):
        rotate_scene(s, traj)


@pytest.mark.parametrize("extra, message", [
    ('shape = "cone"', "bodies[0].shape: must be one of sphere, box, capsule, cylinder, got 'cone'"),
    ('inertia = [0, 1, 1]', "bodies[0].inertia: inertia must be > 0 kg m^2 in every moment"),
    ('inertia = [1, 1, 2.5]', "bodies[0].inertia: inertia [1.0, 1.0, 2.5] breaks the triangle inequality"),
    ('inertia = [1, 1, inf]', "bodies[0].inertia: must be finite"),
    ('orientation = [0, 0, 0, 0]', "bodies[0].orientation: orientation must be a non-zero quaternion"),
    ('orientation = [1, 0, nan, 0]', "bodies[0].orientation: orientation must be a finite quaternion"),
    ('orientation = [1, 0, 0]', "bodies[0].orientation: must be a quaternion [w, x, y, z] of 4 numbers"),
    ('shape = "box"', "bodies[0].size: missing required key"),
    ('size = [1, 1, 1]', 'bodies[0].size: is the edges of a box; this body\'s shape is "sphere"'),
    ('shape = "box"\nsize = [1, 0, 1]', "bodies[0].size: must be > 0 in every component"),
    ('shape = "capsule"\nlength = -1', "bodies[0].length: must be >= 0"),
    ('shape = "cylinder"', "bodies[0].length: missing required key"),
    ('angular_velocity = [1, 2]', "bodies[0].angular_velocity: must be a list of 3 numbers"),
])
def test_bad_body_keys_are_one_line(extra, message):
    with pytest.raises(SceneError) as err:
        scene(BALL + extra + "\n")
    assert message in str(err.value) and "\n" not in str(err.value) and str(err.value).startswith("s.toml: ")


def test_scene_rotation_on_jax_agrees_with_numpy():
    s = scene(BOX + BALL, forces="")
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, s.t_end, s.dt, save_every=7)  # 100 steps: 14 x 7 + 2
    numpy_run, jax_run = (rotate_scene(s, traj, "exponential-map", backend=b) for b in ("numpy", "jax"))
    assert jax_run.orientations.shape == (len(traj.t), 1, 4)
    np.testing.assert_allclose(jax_run.orientations, numpy_run.orientations, rtol=0, atol=1e-13)
    np.testing.assert_allclose(jax_run.angular_velocities, numpy_run.angular_velocities, rtol=0, atol=1e-12)


@pytest.mark.parametrize("extra, message", [
    ("inertia = [0, 1, 1]", "inertia must be > 0 kg m^2 in every moment"),
    ("inertia = [-1, 1, 1]", "inertia must be > 0 kg m^2 in every moment"),
    ("inertia = [1, 1, inf]", "bodies[0].inertia: must be finite"),
    ("inertia = [1, 1, 2.5]", "breaks the triangle inequality"),
    ("orientation = [0, 0, 0, 0]", "orientation must be a non-zero quaternion"),
    ("orientation = [1, nan, 0, 0]", "orientation must be a finite quaternion"),
    ('shape = "cone"', "bodies[0].shape: must be one of sphere, box, capsule, cylinder, got 'cone'"),
    ('[[bodies]]\nname = "point"\nmass = 1.0\nradius = 0.1\nposition = [1, 0, 0]\n[[forces.springs]]\n'
     'bodies = ["ball", "point"]\nstiffness = 1.0\noffsets = [[0, 0, 0], [0.1, 0, 0]]',
     "puts an end off the centre of 'point', which does not rotate"),
])
def test_bad_rotation_input_at_the_command_line_is_one_line_with_status_2(tmp_path, capsys, extra, message):
    from steplab.cli import main

    path = tmp_path / "s.toml"
    path.write_text(f"{SIMULATION}\n{BALL}{extra}\n")
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_a_float32_run_turns_its_free_bodies_in_float32(backend):
    """--precision float32: the free bodies' state is rounded to float32 after every step, as the
    translation's (it was stepped and stored in float64), and the NPZ arrays stay float32."""
    from steplab.integrators import get_rotation
    from steplab.integrators.rotation import simulate_rotation
    from steplab.physics.rigid_body import RotationModel

    s = load_scene("dzhanibekov")
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, n_steps=12, dt=s.dt, dtype=np.float32, save_every=5)
    rot = rotate_scene(s, traj, "dlm", backend=backend)
    assert rot.orientations.dtype == rot.angular_velocities.dtype == np.float32
    arrays = rotation_arrays(rot, s.model.n_bodies)
    assert arrays["orientations"].dtype == arrays["angular_velocities"].dtype == np.float32
    # step by step, rounding the state to float32 after each step
    bodies, method = s.rigid_bodies, get_rotation("dlm")
    q, omega = bodies.orientations, bodies.body_angular_velocities()
    for k in range(12):
        q, omega = (np.float32(a).astype(float) for a in simulate_rotation(
            method, RotationModel(bodies.inertia), q, omega, s.dt, 1, t0=k * s.dt)[1:3])
        q, omega = q[-1], omega[-1]
    np.testing.assert_allclose(rot.orientations[-1], q.astype(np.float32), rtol=0, atol=2e-7)
    assert not np.array_equal(rot.orientations[-1].astype(float), _float64_run(s)[-1])


def _float64_run(s):
    traj = simulate(s.model, s.integrator, s.y0, s.t_start, n_steps=12, dt=s.dt, save_every=5)
    return rotate_scene(s, traj, "dlm").orientations
