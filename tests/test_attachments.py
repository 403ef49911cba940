"""Springs and dampers at body-frame points: torques, the physical pendulum, energy, dissipation.

References are independent of the code: the torque (R r) x F with R from scipy's rotation
matrix and F from Hooke's law written out; the physical pendulum's period from the small
oscillations of the linearised model (scipy.linalg.eigh), which tends to the closed form
2 pi sqrt(I_pivot / (m g d)) as the spring stiffens; the energy of a conservative system.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation
from steplab.integrators import simulate
from steplab.integrators.attached import AttachedStep, attached_stepper
from steplab.integrators.rotation_registry import get_rotation
from steplab.physics import attachments
from steplab.physics.scene import SceneError, load_scene, parse_scene

G = 9.81
#: the cube of the pendulum: mass, edge, and its corner's distance from the centre
MASS, EDGE = 1.0, 0.1
D = EDGE * np.sqrt(3) / 2
I_CM = MASS * EDGE**2 / 6  # a cube's moment about any axis through its centre
#: the body diagonal (1, 1, 1) / sqrt(3) turned onto +z: the corner straight above the centre
CORNER_UP = Rotation.from_rotvec(np.arccos(1 / np.sqrt(3)) * np.array([1.0, -1.0, 0.0]) / np.sqrt(2))


def closed_form_period():
    """T = 2 pi sqrt(I_pivot / (m g d)), I_pivot = I_cm + m d^2: the rigid pivot."""
    return 2 * np.pi * np.sqrt((I_CM + MASS * D**2) / (MASS * G * D))


def slow_mode(stiffness):
    """The pendulum's slow mode on a zero-length spring of ``stiffness``: (period, y' / theta').

    Swinging about x, the centre's y and the angle theta; the corner moves by y - d theta. About
    the equilibrium (the spring stretched by m g / k) the potential is 1/2 k (y - d theta)^2 +
    1/2 m g d theta^2, the kinetic energy 1/2 m y'^2 + 1/2 I theta'^2.
    """
    k = stiffness
    stiffness_matrix = np.array([[k, -k * D], [-k * D, k * D * D + MASS * G * D]])
    omega2, modes = scipy.linalg.eigh(stiffness_matrix, np.diag([MASS, I_CM]))
    return 2 * np.pi / np.sqrt(omega2[0]), modes[0, 0] / modes[1, 0]


def pendulum_scene(stiffness, amplitude=0.01, damping=0.0, integrator="velocity-verlet", rotation="dlm"):
    """The cube hung at a corner from a pinned anchor at the origin, swinging in its slow mode."""
    period, ratio = slow_mode(stiffness)
    omega = amplitude * 2 * np.pi / period
    w, x, y, z = (float(c) for c in np.roll(CORNER_UP.as_quat(), 1))
    omega, velocity, height = float(omega), float(ratio * omega), float(-D - MASS * G / stiffness)
    damper = f"""
[[forces.dampers]]
bodies = ["anchor", "cube"]
damping = {float(damping)!r}
offsets = [[0.0, 0.0, 0.0], [0.05, 0.05, 0.05]]
""" if damping else ""
    return parse_scene(f"""
[simulation]
integrator = "{integrator}"
rotation = "{rotation}"
dt = 0.001
t_end = 1.0

[[bodies]]
name = "anchor"
mass = 1.0
radius = 0.01
position = [0.0, 0.0, 0.0]
pinned = true

[[bodies]]
name = "cube"
mass = {MASS!r}
radius = 0.09
position = [0.0, 0.0, {height!r}]
shape = "box"
size = [{EDGE}, {EDGE}, {EDGE}]
orientation = [{w!r}, {x!r}, {y!r}, {z!r}]
angular_velocity = [{omega!r}, 0.0, 0.0]
velocity = [0.0, {velocity!r}, 0.0]

[forces.gravity]

[[forces.springs]]
bodies = ["anchor", "cube"]
stiffness = {float(stiffness)!r}
rest_length = 0.0
offsets = [[0.0, 0.0, 0.0], [0.05, 0.05, 0.05]]
{damper}""", "pendulum")


def run(scene, dt, t_end, integrator=None, rotation=None, save_every=1):
    """The coupled run: the translation trajectory and the AttachedStep that stepped it."""
    kept = []
    stepper = attached_stepper(scene.rigid_bodies, get_rotation(rotation or scene.rotation), kept)
    trajectory = simulate(scene.model, integrator or scene.integrator, scene.y0, 0.0, dt=dt, t_end=t_end,
                          stepper=stepper, save_every=save_every)
    return trajectory, kept[0]


def measured_period(trajectory):
    """The time of the centre's second crossing of y = 0 upwards (the first is t = 0), linearly interpolated."""
    t, y = trajectory.t, trajectory.positions[:, 1, 1]
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    return t[up] - y[up] * (t[up + 1] - t[up]) / (y[up + 1] - y[up])


def energies(scene, trajectory, step: AttachedStep):
    """model.energy along the run: the potential at the attachment points plus both kinetic energies."""
    rotation = step.rotation_trajectory(trajectory)
    out = []
    for k in range(len(trajectory.t)):
        bodies = rotation.at(k)
        model = step.model_at(bodies.orientations, bodies.body_angular_velocities())
        out.append(float(model.energy(trajectory.y[k], bodies)))
    return np.array(out)


def test_the_torque_of_a_spring_at_an_offset_is_r_cross_f(rng):
    scene = pendulum_scene(1e3)
    model, (anchor, cube) = scene.model, (0, 1)
    for _ in range(5):
        q = rng.normal(size=(2, 3))
        rotation = Rotation.random(random_state=rng.integers(2**31))
        orientations = np.array([[1.0, 0.0, 0.0, 0.0], np.roll(rotation.as_quat(), 1)])
        at = attachments.model_at(model, orientations, np.zeros((2, 3)))
        torque = attachments.torques(at, q, np.zeros((2, 3)))
        # by hand: the corner at x + R r, Hooke's law of a zero-length spring on the cube, (R r) x F
        arm = rotation.as_matrix() @ np.array([0.05, 0.05, 0.05])
        force_on_cube = -1e3 * (q[cube] + arm - q[anchor])
        np.testing.assert_allclose(torque[cube], np.cross(arm, force_on_cube), rtol=1e-13, atol=1e-13)
        assert np.all(torque[anchor] == 0)  # a point mass: no torque
        net = at.net_force(0.0, q, np.zeros((2, 3)))  # the centre feels the force at the corner, and gravity
        np.testing.assert_allclose(net[cube], force_on_cube + np.array([0, 0, -G * MASS]), rtol=1e-13, atol=1e-12)


def test_lever_arms_turned_in_place_are_the_model_built_at_those_orientations(rng):
    # hung-box's spring and damper on one corner (two forces, one block of points), turned in place to
    # random orientations and spins: the acceleration, torque and potential of the model built afresh
    # there, bit for bit; the torque also as (R r) x F with r rotated again from the orientations (the
    # route before the arms were read back); a model built before the turns keeps its arms
    from steplab.physics.rigid_body import torque_of_forces

    scene = load_scene("hung-box")
    model = scene.model
    orientations, spins = scene.rigid_bodies.of_all(model.n_bodies)
    lever = attachments.LeverArms(model, orientations, spins)
    before = attachments.model_at(model, orientations, spins)
    q, v = rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
    held = before.acceleration(0.0, q, v).copy()
    for _ in range(5):
        turned, spin = orientations.copy(), spins.copy()
        turned[1] = np.roll(Rotation.random(random_state=rng.integers(2**31)).as_quat(), 1)
        spin[1] = rng.normal(size=3)
        at, fresh = lever.turn(turned, spin), attachments.model_at(model, turned, spin)
        np.testing.assert_array_equal(at.acceleration(0.0, q, v), fresh.acceleration(0.0, q, v))
        assert at.potential_energy(q) == fresh.potential_energy(q)
        torque = attachments.torques(at, q, v)
        by_hand = np.zeros_like(q)
        for f in attachments.attached_forces(fresh):
            force = f.pair_force(np, q, v)
            np.add.at(by_hand, f.i, torque_of_forces(np, turned[f.i], f.attachment.offsets[:, 0], force))
            np.add.at(by_hand, f.j, torque_of_forces(np, turned[f.j], f.attachment.offsets[:, 1], -force))
        np.testing.assert_array_equal(torque, by_hand)
        assert np.any(torque[1] != 0)
    np.testing.assert_array_equal(before.acceleration(0.0, q, v), held)


def test_the_physical_pendulum_swings_with_its_closed_form_period_at_second_order():
    # velocity Verlet with dlm: the error of the period falls as dt^2 towards the linearised model's
    # period, which tends to the closed form as the spring stiffens (the stretch m g / k lengthens
    # the pendulum: 4e-3 at k = 1e4, falling as 1 / k)
    lengthening = [slow_mode(k)[0] / closed_form_period() - 1 for k in (1e4, 1e6, 1e8)]
    assert 0 < lengthening[2] < 1e-6 and lengthening[0] / lengthening[1] == pytest.approx(100, rel=0.05)
    stiffness = 1e4
    exact, _ = slow_mode(stiffness)
    # a 1 mrad swing: the amplitude's own lengthening, theta^2 / 16, is 6e-8
    errors = [abs(measured_period(run(pendulum_scene(stiffness, amplitude=1e-3), dt, 0.8)[0]) - exact)
              for dt in (4e-3, 2e-3)]
    assert errors[1] < 3e-5 * exact
    assert 2**1.8 < errors[0] / errors[1] < 2**2.2, errors  # order 2


@pytest.mark.slow
@pytest.mark.parametrize("integrator, rotation", [("velocity-verlet", "dlm"),
                                                  ("semi-implicit-euler", "exponential-map")])
def test_the_pendulum_period_converges_at_second_order(integrator, rotation):
    # the period's error is second order for both: symplectic Euler's phase error is O(dt^2) on an
    # oscillator, though its positions are first order (measured: -6.140e-5, -1.527e-5, -3.763e-6
    # relative at dt = 4, 2, 1 ms, for both compositions alike to 1e-12)
    stiffness = 1e4
    exact, _ = slow_mode(stiffness)
    dts = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    errors = np.array([abs(measured_period(run(pendulum_scene(stiffness, amplitude=1e-3), dt, 0.8, integrator,
                                               rotation)[0]) - exact) for dt in dts])
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert abs(slope - 2) < 0.2, (slope, errors)


def test_energy_of_a_spring_hung_box_is_kept_by_verlet_with_dlm():
    # a larger swing (0.3 rad) on a softer spring: the energy error stays O(dt^2) and bounded
    scene = pendulum_scene(2e3, amplitude=0.3)
    drift = []
    for dt in (2e-3, 1e-3):  # over most of a swing, the energy every 10 ms
        trajectory, step = run(scene, dt, 0.5, save_every=round(0.01 / dt))
        energy = energies(scene, trajectory, step)
        drift.append(np.max(np.abs(energy - energy[0])))
    swing = MASS * G * D * (1 - np.cos(0.3))  # the energy that goes back and forth, J
    assert drift[1] < 1e-4 * swing
    assert 2**1.5 < drift[0] / drift[1] < 2**2.5, drift  # second order, no drift


def test_a_damper_at_an_offset_dissipates_energy_monotonically():
    # no gravity, no spring: a spinning, drifting cube tied at a corner to a pinned anchor by a
    # dashpot alone; its energy is kinetic (translation and rotation) and only the damper changes it
    scene = parse_scene("""
[simulation]
dt = 0.001
t_end = 1.0
[[bodies]]
name = "anchor"
mass = 1.0
radius = 0.01
position = [0.0, 0.0, 0.0]
pinned = true
[[bodies]]
name = "cube"
mass = 1.0
radius = 0.09
position = [0.0, 0.0, -0.5]
velocity = [0.3, 0.2, -0.1]
angular_velocity = [1.0, 2.0, 3.0]
shape = "box"
size = [0.1, 0.1, 0.1]
[[forces.dampers]]
bodies = ["anchor", "cube"]
damping = 10.0
offsets = [[0.0, 0.0, 0.0], [0.05, 0.05, 0.05]]
""", "dashpot")
    trajectory, step = run(scene, 1e-3, 0.5, "semi-implicit-euler", "exponential-map")
    energy = energies(scene, trajectory, step)
    assert np.all(np.diff(energy) < 0)
    # what it loses is the dashpot's power c (d . u)^2 at the corner, written out here (anchor at rest)
    rotation = step.rotation_trajectory(trajectory)
    arms = Rotation.from_quat(np.roll(rotation.orientations[:, 0], -1, axis=-1)).apply([0.05, 0.05, 0.05])
    corner = trajectory.positions[:, 1] + arms
    speed = trajectory.velocities[:, 1] + np.cross(rotation.angular_velocities[:, 0], arms)
    power = 10.0 * np.sum(corner * speed, axis=1) ** 2 / np.sum(corner * corner, axis=1)
    lost = np.sum(0.5 * (power[1:] + power[:-1]) * np.diff(trajectory.t))
    assert energy[0] - energy[-1] == pytest.approx(lost, rel=2e-2)
    assert lost > 0.05 * energy[0]


def test_the_built_in_scene_swings_with_the_period_its_description_states():
    scene = load_scene("spring-pendulum")
    assert "0.6527 s" in scene.description and f"{closed_form_period():.4f}" == "0.6527"
    trajectory, step = run(scene, scene.dt, 0.7)
    # a 0.1 rad swing: the period is longer by theta^2 / 16 = 6e-4, the stretch of the spring by 6e-4
    assert measured_period(trajectory) == pytest.approx(closed_form_period(), rel=3e-3)
    assert step.rotation_trajectory(trajectory).orientations.shape == (len(trajectory.t), 1, 4)


def test_scenes_without_offsets_keep_their_forces():
    scene = load_scene("cloth")
    assert all(getattr(f, "attachment", None) is None for f in scene.model.forces)
    assert attachments.attached_forces(scene.model) == ()


@pytest.mark.parametrize("offsets, message", [
    ("[[0.1, 0.0, 0.0], [0.0, 0.0, 0.0]]", "forces.springs[0].offsets: puts an end off the centre of 'anchor', which "
                                           "does not rotate: a point attachment needs a rotating body: give it a "
                                           "shape, inertia, orientation or angular_velocity"),
    ("[[0.0, 0.0, 0.0]]", "forces.springs[0].offsets: must be two body-frame points"),
    ("[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]", "forces.springs[0].offsets: has 3 entries"),
])
def test_bad_offsets_are_one_line(offsets, message):
    text = f"""
[simulation]
dt = 0.01
t_end = 1.0
[[bodies]]
name = "anchor"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 0.0]
pinned = true
[[bodies]]
name = "box"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, -1.0]
shape = "box"
size = [0.1, 0.1, 0.1]
[[forces.springs]]
bodies = ["anchor", "box"]
stiffness = 10.0
offsets = {offsets}
"""
    with pytest.raises(SceneError) as err:
        parse_scene(text, "bad.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_steplab_run_couples_the_rotation_and_refuses_what_it_cannot_couple(capsys):
    from steplab.cli import main

    assert main(["run", "spring-pendulum", "--t-end", "0.1", "--integrator", "velocity-verlet", "--rotation", "dlm",
                 "--json"]) == 0
    import json

    record = json.loads(capsys.readouterr().out)
    assert record["rotation"].startswith("dlm") and record["rotating_bodies"] == ["cube"]
    assert abs(record["energy_relative_change"]) < 1e-6  # the potential at the corner, both kinetic energies
    for argv, message in ((["--detector", "swept"], "not the event loop; use [collisions] method = \"solver\", or "
                                                    "--detector none"),
                          (["--integrator", "xpbd"], "need a fixed-step integrator that evaluates their forces"),
                          (["--integrator", "scipy-dop853"], "not 'scipy-dop853' (use semi-implicit-euler")):
        assert main(["run", "spring-pendulum", "--t-end", "0.01", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert main(["recommend", "spring-pendulum", "--tol", "1e-3", "--detector", "swept"]) == 2  # not measured so
    err = capsys.readouterr().err
    assert "measures springs and dampers at body-frame points (offsets) without collisions only; use --detector " \
           "none" in err and err.count("\n") == 1


def test_the_free_rotation_beside_the_translation_refuses_an_attached_scene():
    from steplab.integrators.scene_rotation import rotate_scene

    scene = load_scene("spring-pendulum")
    stepper = attached_stepper(scene.rigid_bodies, get_rotation(scene.rotation))
    trajectory = simulate(scene.model, "semi-implicit-euler", scene.y0, 0.0, dt=scene.dt, n_steps=2, stepper=stepper)
    with pytest.raises(ValueError, match="step its translation and rotation together"):
        rotate_scene(scene, trajectory)


def test_simulate_without_the_attached_step_refuses_an_attached_scene():
    # the plain step would keep the lever arms at their start: a wrong answer (y after 1 s 6.9e-5 m, not 1.66e-3)
    scene = load_scene("spring-pendulum")
    for method in ("semi-implicit-euler", "rk4", "xpbd"):
        with pytest.raises(ValueError, match="springs or dampers at body-frame points.*attached_stepper"):
            simulate(scene.model, method, scene.y0, 0.0, dt=scene.dt, n_steps=2)


def random_attached_scene(seed: int):
    """A pinned anchor and a chain of three tumbling boxes of random sizes, orientations and spins, joined
    corner to corner (random body-frame points) by springs and dampers, under gravity."""
    rng = np.random.default_rng(seed)
    bodies = ["[[bodies]]\nname = \"anchor\"\nmass = 1.0\nradius = 0.01\nposition = [0.0, 0.0, 0.0]\npinned = true"]
    forces = []
    for k in range(3):
        size, w = rng.uniform(0.05, 0.2, 3), Rotation.random(random_state=rng.integers(2**31)).as_quat()
        bodies.append(f"""[[bodies]]
name = "box{k}"
mass = {rng.uniform(0.5, 2.0)!r}
radius = 0.2
position = {(np.array([0.0, 0.0, -0.3 * (k + 1)]) + rng.normal(0, 0.03, 3)).tolist()}
velocity = {rng.normal(0, 0.2, 3).tolist()}
shape = "box"
size = {size.tolist()}
orientation = {np.roll(w, 1).tolist()}
angular_velocity = {rng.normal(0, 2.0, 3).tolist()}""")
        a, b = ("anchor" if k == 0 else f"box{k - 1}"), f"box{k}"
        first = [0.0, 0.0, 0.0] if k == 0 else rng.uniform(-0.05, 0.05, 3).tolist()
        offsets = [first, rng.uniform(-0.05, 0.05, 3).tolist()]
        forces.append(f"""[[forces.springs]]
bodies = ["{a}", "{b}"]
stiffness = {rng.uniform(200.0, 2000.0)!r}
rest_length = 0.25
offsets = {offsets}
[[forces.dampers]]
bodies = ["{a}", "{b}"]
damping = {rng.uniform(0.1, 1.0)!r}
offsets = {offsets}""")
    return parse_scene("[simulation]\ndt = 0.001\nt_end = 0.3\n" + "\n".join(bodies) + "\n[forces.gravity]\n"
                       + "\n".join(forces), f"random-{seed}")


def run_on(scene, backend, integrator, rotation, n_steps, save_every=1):
    """The coupled run on ``backend``: the translation trajectory and the rotation at its saved times."""
    kept = []
    stepper = attached_stepper(scene.rigid_bodies, get_rotation(rotation), kept)
    trajectory = simulate(scene.model, integrator, scene.y0, 0.0, dt=scene.dt, n_steps=n_steps, stepper=stepper,
                          backend=backend, save_every=save_every)
    return trajectory, kept[0].rotation_trajectory(trajectory)


@functools.cache
def random_chain_run(backend, integrator, rotation, dtype=None):
    """``run_on(random_attached_scene(25), backend, integrator, rotation, 200, 20)``, in ``dtype`` when given (the
    simulate default, float64, when not): run once per test process and shared by the tests that compare it (a
    seeded scene, a deterministic run), its arrays read-only so that no test can change what another gets."""
    scene = random_attached_scene(25)
    kept = []
    options = {} if dtype is None else {"dtype": np.dtype(dtype)}
    trajectory = simulate(scene.model, integrator, scene.y0, 0.0, dt=scene.dt, n_steps=200, backend=backend,
                          save_every=20, stepper=attached_stepper(scene.rigid_bodies, get_rotation(rotation), kept),
                          **options)
    rotation_run = kept[0].rotation_trajectory(trajectory)
    for array in (trajectory.t, trajectory.y, rotation_run.t, rotation_run.orientations,
                  rotation_run.angular_velocities):
        array.flags.writeable = False
    return trajectory, rotation_run


def assert_round_off(a, b, relative):
    """Equal to ``relative`` times the largest component (XLA fuses and reorders the sums)."""
    scale = max(np.max(np.abs(a)), np.max(np.abs(b)))
    np.testing.assert_allclose(a, b, rtol=0, atol=relative * scale)


#: how far the two backends may differ after 200 steps, relative to each array's largest component.
#: Measured: at most 1e-14 on the random chain. The spring-pendulum's spring (1e5 N/m, sqrt(k/m) =
#: 316 /s) turns the round-off of its 1 m positions, 1e-16 m, into velocities of 3e-14 m/s against
#: the 0.08 m/s of the swing: 3e-12 measured. A state one step off would differ by 1e-2.
AGREEMENT = {"spring-pendulum": 1e-10, "random": 1e-12}


@pytest.mark.parametrize("integrator, rotation", [("semi-implicit-euler", "exponential-map"),
                                                  ("velocity-verlet", "dlm"),  # the Strang splitting
                                                  ("rk4", "rk4")])  # a rotation method's inner stages
@pytest.mark.parametrize("scene", ["spring-pendulum", "random"])
def test_numpy_and_the_compiled_jax_loop_agree_on_attached_scenes(scene, integrator, rotation):
    relative = AGREEMENT[scene]
    steps, save_every = 200, 20
    if scene == "spring-pendulum":
        scene = load_scene("spring-pendulum")
        numpy, numpy_rotation = run_on(scene, "numpy", integrator, rotation, steps, save_every)
        jax, jax_rotation = run_on(scene, "jax", integrator, rotation, steps, save_every)
    else:  # the random chain's runs, shared with the float32 tests below (the same runs)
        scene = random_attached_scene(25)
        numpy, numpy_rotation = random_chain_run("numpy", integrator, rotation)
        jax, jax_rotation = random_chain_run("jax", integrator, rotation)
    assert jax.backend == "jax" and jax.steps == steps and np.array_equal(jax.t, numpy.t)
    assert jax.y.shape == numpy.y.shape == (steps // save_every + 1, 2, scene.model.n_bodies, 3)
    assert jax_rotation.orientations.shape == numpy_rotation.orientations.shape
    assert not np.array_equal(numpy.y[-1], numpy.y[0])  # it moved
    for a, b in ((numpy.positions, jax.positions), (numpy.velocities, jax.velocities),
                 (numpy_rotation.orientations, jax_rotation.orientations),
                 (numpy_rotation.angular_velocities, jax_rotation.angular_velocities)):
        assert_round_off(a, b, relative)


def test_a_compiled_attached_run_that_diverges_is_reported_like_any_divergence():
    from steplab.integrators import DivergenceError

    scene = random_attached_scene(3)
    message = "'euler with explicit' diverged with dt = 0.05 s: the state is non-finite"
    with pytest.raises(DivergenceError, match=message):
        kept = []
        simulate(scene.model, "euler", scene.y0, 0.0, dt=0.05, n_steps=2000, backend="jax",
                 stepper=attached_stepper(scene.rigid_bodies, get_rotation("explicit"), kept))


def test_the_scene_stepper_of_a_scene_that_names_no_rotation_method_uses_the_default(tmp_path):
    """A scene with springs at body-frame points and no [simulation] rotation: the default method
    (was: 'unknown rotation method None')."""
    from pathlib import Path

    from steplab.integrators.attached import scene_stepper
    from steplab.integrators.rotation import DEFAULT_ROTATION
    from steplab.physics.scene import load_scene

    text = (Path(__file__).resolve().parent.parent / "physics" / "scenes" / "spring-pendulum.toml").read_text()
    assert 'rotation = "exponential-map"\n' in text
    path = tmp_path / "no-rotation.toml"
    path.write_text(text.replace('rotation = "exponential-map"\n', ""))
    scene = load_scene(path)
    assert scene.rotation is None
    kept = []
    from steplab.integrators import get_integrator

    step = scene_stepper(scene, kept)(scene.model, get_integrator(scene.integrator))
    assert kept == [step] and step.coupling.rotation.name == DEFAULT_ROTATION


#: pairs of each stage order: the Strang splitting, the joint tableau, the held step (composing and not,
#: a rotation method's inner stages among them), float64 and float32
TURNED_PAIRS = [("velocity-verlet", "dlm", "float64"), ("velocity-verlet", "implicit-midpoint", "float64"),
                ("rk4", "rk4", "float64"), ("semi-implicit-euler", "exponential-map", "float64"),
                ("euler", "explicit", "float64"), ("semi-implicit-euler", "rk4", "float64"),
                ("heun", "dlm", "float64"), ("velocity-verlet", "dlm", "float32"),
                ("semi-implicit-euler", "rk4", "float32")]


@pytest.mark.parametrize("integrator, rotation, precision", TURNED_PAIRS)
def test_the_numpy_coupled_step_turning_one_model_is_bit_for_bit_the_step_building_models(integrator, rotation,
                                                                                            precision):
    """On NumPy the coupled step turns one model's lever arms in place at every stage
    (:class:`.attachments.LeverArms`); a step that builds a new model at each stage
    (:func:`.attachments.model_at`, nothing held turns) takes the same states, bit for bit."""
    from steplab.integrators import get_integrator
    from steplab.integrators.attached import coupled_step, first_kept

    scene = random_attached_scene(7)
    dtype = np.dtype(precision)
    step = AttachedStep(scene.model.cast(np, dtype), scene.rigid_bodies, get_integrator(integrator),
                        get_rotation(rotation))
    turning = step.coupling
    assert isinstance(turning.lever_arms, attachments.LeverArms)
    fresh = turning.fresh()
    assert fresh.lever_arms is None
    y, q, omega = scene.y0.astype(dtype), step.q.astype(dtype), step.omega.astype(dtype)
    turned = (y, q, omega, first_kept(turning, 0.0, y, q, omega))
    fresh_states = (y, q, omega, first_kept(fresh, 0.0, y, q, omega))
    for k in range(30):
        turned = coupled_step(turning, k * scene.dt, *turned, scene.dt)
        fresh_states = coupled_step(fresh, k * scene.dt, *fresh_states, scene.dt)
        for a, b in zip(turned[:3], fresh_states[:3]):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), k
    assert not np.array_equal(turned[2], omega)  # it turned
    # and a model the step gives out is a new one, which its next steps do not turn
    end = step.final_model()
    assert end is not turning.lever_arms.model
    arms = [f.attachment.arms.copy() for f in attachments.attached_forces(end)]
    coupled_step(turning, 0.0, *turned, scene.dt)
    for f, before in zip(attachments.attached_forces(end), arms):
        assert f.attachment.arms.tobytes() == before.tobytes()


class _AsksTheStartAgain:
    """A rotation 'method' that asks the held torque at the start, at a stage inside the step, and at the
    start again (no method here does, but one may): it records them and leaves (q, omega) as they are."""

    name, composes_with = "asks-the-start-again", ()

    def __init__(self, stage_q, stage_omega):
        self.stage, self.asked = (stage_q, stage_omega), []

    def step(self, model, t, q, omega, dt):
        self.asked = [model.torque(np, t, q, omega), model.torque(np, t, *self.stage), model.torque(np, t, q, omega)]
        return q, omega


def test_the_held_start_model_is_not_read_after_a_stage_turns_its_lever_arms(rng):
    """The held step keeps the start's model over the rotation's stages; with the lever arms turned in place,
    a stage turns it too. The torques asked at the start, before and after a stage, and at that stage, are
    those of models built afresh there (:func:`.attachments.model_at`, independently of the turned one),
    and the translation stepped with the start's model."""
    from steplab.integrators import get_integrator
    from steplab.integrators.attached import Coupling, held_step
    from steplab.physics import quaternion as quat

    scene = random_attached_scene(11)
    bodies, model = scene.rigid_bodies, scene.model
    q0, omega0 = bodies.orientations.copy(), bodies.body_angular_velocities()
    stage_q = quat.normalize(np, q0 + rng.normal(0, 0.3, q0.shape))
    stage_omega = omega0 + rng.normal(0, 1.0, omega0.shape)
    method = _AsksTheStartAgain(stage_q, stage_omega)
    integrator = get_integrator("velocity-verlet")
    c = Coupling(model, bodies, integrator, method).turning(q0, omega0)
    y1, q1, omega1 = held_step(c, 0.0, scene.y0, q0, omega0, scene.dt)
    assert q1 is q0 and omega1 is omega0

    def independent(q, omega):  # the model built at q (body-frame omega), all bodies' frames by hand
        n = model.n_bodies
        orientations, spins = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.zeros((n, 3))
        orientations[bodies.index], spins[bodies.index] = q, quat.rotate(np, q, omega)
        return attachments.model_at(model, orientations, spins)

    def torque(q, omega):
        world = attachments.torques(independent(q, omega), scene.y0[0], scene.y0[1])[bodies.index]
        return quat.rotate_inverse(np, q, world)

    start, stage, start_again = method.asked
    assert start.tobytes() == torque(q0, omega0).tobytes()
    assert stage.tobytes() == torque(stage_q, stage_omega).tobytes()
    assert not np.allclose(stage, start)  # the stage's arms are not the start's
    assert start_again.tobytes() == start.tobytes()
    fresh = independent(q0, omega0)
    expected, _ = integrator.step(fresh, 0.0, scene.y0, scene.dt, integrator.init(fresh, 0.0, scene.y0))
    assert y1.tobytes() == expected.tobytes()


@pytest.mark.parametrize("integrator, rotation", [("semi-implicit-euler", "exponential-map"),
                                                  ("velocity-verlet", "dlm"),  # the Strang splitting's carry
                                                  ("rk4", "rk4")])
def test_the_compiled_loop_runs_attached_scenes_in_float32(integrator, rotation):
    """In float32 the compiled loop carries the state, and the Strang splitting's kept acceleration and
    torque, in float32 (the loop's dt is float64: the carry came out float64 and JAX refused the loop).
    The run keeps to float64's within float32's round-off grown over 200 steps of the random chain:
    1e-4 of each array's largest component against at most 7e-6 measured, where the state one step
    later differs by 9e-4 (positions) to 0.1 (velocities)."""
    # random_attached_scene(25), 200 steps saved every 20th, on the compiled loop in float64 and in float32
    wide, wide_rotation = random_chain_run("jax", integrator, rotation)
    narrow, narrow_rotation = random_chain_run("jax", integrator, rotation, "float32")
    assert narrow.y.dtype == np.float32 and narrow_rotation.orientations.dtype == np.float32
    assert not np.array_equal(narrow.y[-1], wide.y[-1].astype(np.float32))  # float32's own round-off
    for a, b in ((wide.positions, narrow.positions), (wide.velocities, narrow.velocities),
                 (wide_rotation.orientations, narrow_rotation.orientations),
                 (wide_rotation.angular_velocities, narrow_rotation.angular_velocities)):
        assert_round_off(a, b, 1e-4)


@pytest.mark.parametrize("integrator, rotation", [("semi-implicit-euler", "exponential-map"),  # the held step
                                                  ("semi-implicit-euler", "dlm"),  # a held step not composing
                                                  ("velocity-verlet", "dlm"),  # the Strang splitting
                                                  ("rk4", "rk4")])  # the joint tableau
def test_a_numpy_float32_coupled_run_computes_in_float32(integrator, rotation):
    """The rotation methods compute with float64 moments; their orientations carried float64 into the lever
    arms, the forces and the translation, so after its first step a NumPy float32 run computed in float64
    and only its saved states were float32. Every array a step returns is float32 now, and the run keeps
    to the compiled float32 loop's within float32's round-off (1e-4 of each array's largest component)."""
    from steplab.integrators import get_integrator

    scene = random_attached_scene(25)
    model = scene.model.cast(np, np.float32)
    step = AttachedStep(model, scene.rigid_bodies, get_integrator(integrator), get_rotation(rotation))
    y, dt = scene.y0.astype(np.float32), np.float32(scene.dt)
    for k in range(3):
        y, _ = step(k * dt, y, dt, None)
        assert y.dtype == step.q.dtype == step.omega.dtype == np.float32, k
        assert all(a.dtype == np.float32 for a in step._kept or ()), k
    runs = {}
    for backend in ("numpy", "jax"):  # 200 steps saved every 20th, in float32 (the jax run shared with the test above)
        trajectory, rotation_run = random_chain_run(backend, integrator, rotation, "float32")
        runs[backend] = (trajectory.positions, trajectory.velocities, rotation_run.orientations,
                         rotation_run.angular_velocities)
    for a, b in zip(runs["numpy"], runs["jax"]):
        assert a.dtype == b.dtype == np.float32
        assert_round_off(a, b, 1e-4)


def test_implicit_midpoint_held_beside_semi_implicit_euler_steps_and_grows_as_the_pair_does():
    """Held beside semi-implicit Euler, implicit-midpoint's Newton iteration carries spring-pendulum's spring
    torque. It stopped at step 3 of 1 ms (before): the torque's derivative was left out of Newton's matrix
    (a fixed point contracting by 0.11 an iteration at 1 ms, 16 iterations, past 1 near 3 ms), and its
    corrections stalled at the torque's round-off, 8e-17, above the tolerance of 4 ulps of |pi0|, 8e-19.
    Now each step takes 3-4 iterations, and what is left is the pair's own held coupling: its errors against
    DOP853 (centres and lever arms over 0.1 s) are semi-implicit Euler with dlm's to 3 % (5.54e-3 against
    5.39e-3 at 100 steps, 4.05e-3 both at 200), and its step grows as dlm's does (1.02059 against 1.02102
    a step at 1 ms): the warning `steplab run` gives is the pair's instability, not Newton's."""
    from spring_pendulum_reference import independent_errors
    from steplab.integrators import get_integrator
    from steplab.integrators.coupled_stability import coupled_growth

    scene = load_scene("spring-pendulum")
    errors = {rotation: [max(independent_errors(scene, "semi-implicit-euler", rotation, n, 0.1)) for n in (100, 200)]
              for rotation in ("implicit-midpoint", "dlm")}
    assert np.all(np.isfinite(errors["implicit-midpoint"])) and errors["implicit-midpoint"][1] < errors[
        "implicit-midpoint"][0]
    np.testing.assert_allclose(errors["implicit-midpoint"], errors["dlm"], rtol=0.05)
    growth = {rotation: coupled_growth(scene.model, scene.rigid_bodies, get_integrator("semi-implicit-euler"),
                                       get_rotation(rotation), scene.y0, 1e-3) for rotation in ("implicit-midpoint",
                                                                                                "dlm")}
    assert 1.02 < growth["implicit-midpoint"] == pytest.approx(growth["dlm"], rel=1e-3)


@functools.cache
def _held_spring_pendulum_run(backend: str, dtype: str) -> tuple:
    """The spring pendulum held by implicit-midpoint, 200 steps of its dt saved every 20th, on ``backend`` in
    ``dtype``: (positions, velocities, orientations, angular velocities), read-only. Run once per test run and
    process: both precisions' tests compare against the float64 runs (each deterministic)."""
    scene = load_scene("spring-pendulum")
    kept = []
    trajectory = simulate(scene.model, "semi-implicit-euler", scene.y0, 0.0, dt=scene.dt, n_steps=200,
                          backend=backend, dtype=np.dtype(dtype), save_every=20,
                          stepper=attached_stepper(scene.rigid_bodies, get_rotation("implicit-midpoint"), kept))
    rotation = kept[0].rotation_trajectory(trajectory)
    arrays = (trajectory.positions, trajectory.velocities, rotation.orientations, rotation.angular_velocities)
    for array in arrays:
        array.flags.writeable = False
    return arrays


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_implicit_midpoint_held_on_the_spring_pendulum_agrees_on_numpy_and_jax(precision):
    """The held pair's Newton iteration with the torque's finite-difference derivative, on NumPy and as the
    compiled loop (a fixed MIDPOINT_COMPILED_ITERATIONS): 200 steps of 1 ms agree to AGREEMENT (1.2e-12
    measured in float64). In float32 the lever arms and the forces are float32, and so is the torque's
    round-off: the difference step and the tolerance take float32's eps (with float64's the first step did
    not converge); both backends keep to the float64 run within float32's round-off, which the stiff spring
    turns into 6e-4 of the swing's velocities (measured), under 2e-3."""
    runs = {(backend, np.dtype(dtype)): _held_spring_pendulum_run(backend, dtype)
            for backend in ("numpy", "jax") for dtype in {"float64", precision}}
    wide, narrow = np.dtype(np.float64), np.dtype(precision)
    for a, b in zip(runs["numpy", narrow], runs["jax", narrow]):
        assert a.dtype == b.dtype == narrow
        assert_round_off(a, b, AGREEMENT["spring-pendulum"] if narrow == wide else 2e-3)
    for backend in ("numpy", "jax"):
        for a, b in zip(runs[backend, narrow], runs[backend, wide]):
            assert_round_off(a.astype(np.float64), b, 2e-3)
