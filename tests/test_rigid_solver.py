"""The contact solver on rigid bodies (issue 26): laws of contact with an angular part.

Each test checks a law an independent argument gives: conservation of momentum, the rolling
sphere's 5/7 v0 and its time, the incline's tan(theta) <= mu, a box's rest on its 4 corners.
"""

from __future__ import annotations

import dataclasses
import importlib
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import get_integrator, get_rotation, simulate
from steplab.integrators.rotation import simulate_rotation
from steplab.physics import Gravity, Model
from steplab.physics import quaternion as quat
from steplab.physics.collision import CollisionWorld, PairProperties, Plane
from steplab.physics.collision import rigid_solver as rs
from steplab.physics.collision.rigid_solver_step import ROTATION_STAGES, RigidScene, RigidSolverStep
from steplab.physics.rigid_body import RigidBodies, RotationModel, principal_inertia
from steplab.physics.scene import parse_scene

#: the rigid narrow phase's module (the package's name ``manifolds`` is its function)
manifolds = importlib.import_module("steplab.physics.collision.manifolds")
G = 9.81
SPHERE, BOX = manifolds.SPHERE, manifolds.BOX
EULER = get_integrator("semi-implicit-euler")


def rigid_world(kind, radius, half, masses, orientations=None, omega=None, shapes=(), friction=0.0,
                restitution=0.0, **solver):
    """A world of bodies that all rotate, with their principal inertia from their shape."""
    n = len(kind)
    names = {SPHERE: "sphere", BOX: "box"}
    inertia = np.array([principal_inertia(names[k], m, r, 2 * np.asarray(h)) for k, m, r, h in
                        zip(kind, masses, radius, half)])
    bodies = RigidBodies(np.arange(n), inertia,
                         np.tile(quat.IDENTITY, (n, 1)) if orientations is None else np.asarray(orientations, float),
                         np.zeros((n, 3)) if omega is None else np.asarray(omega, float),
                         tuple(names[k] for k in kind))
    world = CollisionWorld(shapes=tuple(shapes), method="solver",
                           pair_properties=PairProperties(restitution, friction),
                           rigid=RigidScene(np.asarray(kind, np.int8), np.asarray(radius, float),
                                            np.asarray(half, float), bodies))
    if solver:
        world = dataclasses.replace(world, solver=dataclasses.replace(world.solver, **solver))
    return world


def run(world, model, y0, dt, steps, narrow_phase=manifolds):
    kept = []

    def stepper(model, integrator):
        kept.append(RigidSolverStep(world, model, integrator, narrow_phase))
        return kept[-1]

    traj = simulate(model, EULER, y0, 0.0, dt=dt, n_steps=steps, stepper=stepper)
    return traj, kept[0]


FLOOR = Plane(np.array([0.0, 0.0, 1.0]))


def test_the_kernels_rotation_is_the_quaternion_modules():
    rng = np.random.default_rng(1)
    q = quat.normalize(np, rng.normal(size=(5, 4)))
    x = rng.normal(size=(5, 3))
    got = np.array([rs.rotate(q, k, tuple(x[k])) for k in range(5)])
    np.testing.assert_allclose(got, quat.rotate(np, q, x), rtol=0, atol=1e-15)


@pytest.mark.parametrize("rotation", sorted(ROTATION_STAGES))
def test_a_free_body_turns_as_its_rotation_method_does_at_the_substep(rotation):
    """A tumbling box in free fall: the solver's substeps turn it as the rotation method itself does
    with steps of h = dt / substeps (its gyroscopic term, then its orientation update)."""
    half, dt, steps = np.array([0.3, 0.2, 0.05]), 1 / 60, 30
    omega0 = np.array([0.3, 5.0, 0.4])  # near the unstable middle axis: the gyroscopic term matters
    tilt = quat.from_axis_angle(np, np.array([1.0, 0.0, 0.0]), 0.4)
    world = rigid_world([BOX], [0.05], [half], [1.0], orientations=[tilt], omega=[omega0], shapes=[FLOOR])
    world = dataclasses.replace(world, rigid=dataclasses.replace(world.rigid, rotation=rotation))
    _, step = run(world, Model([1.0], [0.05], [Gravity()]), np.array([[[0.0, 0.0, 100.0]], [np.zeros(3)]]), dt,
                  steps)
    body = world.rigid.bodies
    h = dt / world.solver.substeps
    _, q, w = simulate_rotation(get_rotation(rotation), RotationModel(body.inertia), body.orientations,
                                body.body_angular_velocities(), h, steps * world.solver.substeps)
    assert quat.angle_between(np, step.orientation[0], q[-1, 0]) < 1e-12
    np.testing.assert_allclose(step.omega[0], quat.rotate(np, q[-1, 0], w[-1, 0]), rtol=0, atol=1e-12)
    assert quat.angle_between(np, step.orientation[0], body.orientations[0]) > 1.0  # it did tumble


def test_a_box_resting_on_the_floor_has_four_points_no_torque_and_stays():
    """A 1 kg box of 0.4 x 0.3 x 0.2 m set down on the floor: four corners carry it, the weight
    is shared so that the torques about its centre cancel, and it neither moves nor turns."""
    half = [0.2, 0.15, 0.1]
    world = rigid_world([BOX], [0.1], [half], [1.0], shapes=[FLOOR], friction=0.5)
    model = Model([1.0], [0.1], [Gravity()])
    y0 = np.array([[[0.0, 0.0, 0.1]], [[0.0, 0.0, 0.0]]])
    traj, step = run(world, model, y0, 1 / 60, 600)
    solved = step._previous
    assert len(solved.pn) == 4
    points = step.narrow_phase.manifolds(step.shapes, step.narrow_phase.Poses(traj.positions[-1], step.orientation),
                                         np.zeros((0, 2), int), world.shapes, np.full(1, 1e-3))
    lever = points.point - traj.positions[-1]
    force = -solved.total[:, None] * solved.normal  # on the box, from the floor
    torque = np.cross(lever, force).sum(axis=0)
    assert np.sum(solved.total) == pytest.approx(G / 60, rel=1e-6)  # the weight's impulse over the step
    assert np.max(np.abs(torque)) < 1e-9 * G * 0.2
    # settled after 10 s: the soft contacts' first deflection (Gauss-Seidel takes the corners one
    # after another) moved it sideways by 20 um and turned it by 1e-4 rad, and nothing since
    assert np.max(np.abs(traj.velocities[-1])) < 1e-12
    assert np.max(np.abs(step.omega)) < 1e-12
    assert np.max(np.abs(traj.positions[-1, 0, :2])) < 1e-4
    assert quat.angle_between(np, step.orientation[0], quat.IDENTITY) < 1e-3  # rad: 1.3e-4 measured


def sliding_sphere(v0, mu, dt, t_end, radius=0.1):
    """A ball thrown along the floor without spin: (trajectory, step, v(t), omega r)."""
    world = rigid_world([SPHERE], [radius], [[0.0, 0.0, 0.0]], [1.0], shapes=[FLOOR], friction=mu)
    model = Model([1.0], [radius], [Gravity()])
    y0 = np.array([[[0.0, 0.0, radius]], [[v0, 0.0, 0.0]]])
    traj, step = run(world, model, y0, dt, round(t_end / dt))
    return traj, step


def test_a_sliding_sphere_rolls_at_five_sevenths_from_two_v0_over_seven_mu_g():
    """Friction mu m g slows the ball (dv/dt = -mu g) and spins it up (I domega/dt = mu m g r, I = 2/5 m r^2)
    until v = omega r: then it rolls at 5/7 v0, from t = 2 v0 / (7 mu g), and friction stops acting."""
    v0, mu, dt = 2.0, 0.2, 1 / 60
    traj, step = sliding_sphere(v0, mu, dt, 1.0)
    v = traj.velocities[:, 0, 0]
    assert v[-1] == pytest.approx(5 / 7 * v0, rel=5e-3)  # the target at 60 Hz
    assert abs(step.omega[0, 1]) * 0.1 == pytest.approx(v[-1], rel=5e-3)  # rolling: omega r = v (about +y)
    t_roll = 2 * v0 / (7 * mu * G)
    sliding = traj.t[:-1][np.diff(v) < -0.5 * mu * G * dt]  # steps in which friction still slowed it
    assert abs(sliding[-1] + dt - t_roll) <= dt  # the slip ends within a step of the law's time
    slope = np.polyfit(traj.t[1:10], v[1:10], 1)[0]
    assert slope == pytest.approx(-mu * G, rel=1e-2)


@pytest.mark.parametrize("degrees, sticks", [(20.0, True), (35.0, False)])
def test_a_box_on_an_incline_sticks_for_tan_theta_below_mu_and_slides_at_g_sin_minus_mu_cos(degrees, sticks):
    """A box on a plane tilted by theta, mu = 0.5 (tan 26.6 deg): static friction holds it at 20 deg;
    at 35 deg it slides with a = g (sin theta - mu cos theta) = 1.61 m/s^2."""
    mu, theta, dt = 0.5, np.radians(degrees), 1 / 60
    normal = np.array([np.sin(theta), 0.0, np.cos(theta)])
    downhill = np.array([np.cos(theta), 0.0, -np.sin(theta)])
    half = np.array([0.1, 0.1, 0.05])
    tilt = quat.from_axis_angle(np, np.array([0.0, 1.0, 0.0]), theta)
    world = rigid_world([BOX], [0.05], [half], [1.0], orientations=[tilt], shapes=[Plane(normal)], friction=mu)
    model = Model([1.0], [0.05], [Gravity()])
    y0 = np.array([[half[2] * normal], [np.zeros(3)]])
    traj, step = run(world, model, y0, dt, 120)
    along = traj.velocities[:, 0] @ downhill
    if sticks:
        assert np.max(np.abs(along[30:])) < 1e-6
    else:
        a = G * (np.sin(theta) - mu * np.cos(theta))
        slope = np.polyfit(traj.t[30:], along[30:], 1)[0]
        assert slope == pytest.approx(a, rel=1e-3)
    assert np.max(np.abs(step.omega)) < 1e-4  # no tipping (half height = half the half length); 3e-6 rad/s measured


def test_body_contacts_keep_linear_and_angular_momentum_to_round_off():
    """Two spinning balls in an oblique hit with friction and restitution, no gravity: the impulses at the
    shared contact point are equal and opposite, so sum m v and sum (m x ^ v + I omega) are kept."""
    radius, masses = 0.1, np.array([1.0, 3.0])
    world = rigid_world([SPHERE, SPHERE], [radius] * 2, np.zeros((2, 3)), masses,
                        omega=[[0.0, 0.0, 20.0], [5.0, -3.0, 1.0]], friction=0.5, restitution=0.5)
    model = Model(masses, np.full(2, radius), [])
    y0 = np.array([[[0.0, 0.0, 0.0], [0.3, 0.08, 0.02]], [[2.0, 0.0, 0.0], [-1.0, 0.1, 0.0]]])
    inertia = 0.4 * masses * radius**2

    def momenta(q, v, omega):
        return (masses @ v, np.sum(masses[:, None] * np.cross(q, v), axis=0) + inertia @ omega)

    p0, l0 = momenta(y0[0], y0[1], world.rigid.bodies.angular_velocities)
    traj, step = run(world, model, y0, 1 / 60, 12)
    assert step.log.count() == 1  # one impact
    p1, l1 = momenta(traj.positions[-1], traj.velocities[-1], step.omega)
    assert not np.allclose(step.omega, world.rigid.bodies.angular_velocities)  # friction changed the spins
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-14 * np.abs(p0).max())
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-14 * np.abs(l0).max())


def _shuffled(narrow_phase, rename=False):
    """``narrow_phase`` whose manifolds come in a seeded random order (and, with ``rename``, whose
    feature ids change from call to call: the same points under other names)."""
    rng = np.random.default_rng(7)
    calls = []

    def shuffled(*args):
        points = narrow_phase.manifolds(*args)
        order = rng.permutation(len(points.a))
        feature = points.feature + len(calls) if rename else points.feature
        calls.append(1)
        return manifolds.ManifoldPoints(*(np.asarray(c)[order] for c in points._replace(feature=feature)))

    return types.SimpleNamespace(RigidShapes=narrow_phase.RigidShapes, Poses=narrow_phase.Poses,
                                 bounding_radius=narrow_phase.bounding_radius, manifolds=shuffled)


def test_warm_starting_by_feature_survives_a_reordering_of_the_contacts():
    """A box tumbling onto the floor: the contacts in another order each step give the same bytes; the
    same points under changing feature ids (no warm start found) do not."""
    tilt = quat.from_axis_angle(np, np.array([1.0, 1.0, 0.0]) / np.sqrt(2), 0.3)
    world = rigid_world([BOX], [0.1], [[0.2, 0.15, 0.1]], [1.0], orientations=[tilt], omega=[[1.0, -2.0, 0.5]],
                        shapes=[FLOOR], friction=0.5)
    model = Model([1.0], [0.1], [Gravity()])
    y0 = np.array([[[0.0, 0.0, 0.3]], [[0.5, 0.0, -1.0]]])
    ordered, a = run(world, model, y0, 1 / 60, 60)
    shuffled, b = run(world, model, y0, 1 / 60, 60, _shuffled(manifolds))
    renamed, c = run(world, model, y0, 1 / 60, 60, _shuffled(manifolds, rename=True))
    assert len(a._previous.pn) >= 2  # it came to lie on the floor
    assert ordered.y.tobytes() == shuffled.y.tobytes()
    assert a.orientation.tobytes() == b.orientation.tobytes()
    assert not np.array_equal(ordered.y, renamed.y)


BOX_SCENE = """
[simulation]
dt = 0.0166666666666666667
t_end = 0.5
[[bodies]]
name = "crate"
mass = 2.0
radius = 0.1
shape = "box"
size = [0.4, 0.3, 0.2]
position = [0.0, 0.0, 0.3]
orientation = [0.98, 0.1, 0.15, 0.0]
angular_velocity = [1.0, -2.0, 0.5]
[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [1.0, 0.0, 0.1]
velocity = [-1.0, 0.0, 0.0]
[forces.gravity]
[collisions]
method = "{method}"
friction = 0.4
restitution = 0.3
[[collisions.planes]]
normal = [0.0, 0.0, 1.0]
"""


def test_the_event_loop_refuses_boxes_in_one_line_naming_the_solver(tmp_path, capsys):
    from steplab.cli import main

    path = tmp_path / "crate.toml"
    path.write_text(BOX_SCENE.replace("{method}", "event"))
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert 'boxes and capsules need [collisions] method = "solver"' in err


def test_a_scene_file_builds_the_rigid_world():
    """The issue-25 keys give the solver its shapes: the box's half edges, the ball a point mass."""
    scene = parse_scene(BOX_SCENE.replace("{method}", "solver"))
    rigid = scene.collisions.rigid
    assert rigid.kind.tolist() == [BOX, SPHERE] and rigid.has_corners
    np.testing.assert_array_equal(rigid.half, [[0.2, 0.15, 0.1], [0.0, 0.0, 0.0]])
    assert rigid.bodies.index.tolist() == [0] and rigid.rotation == "exponential-map"


def test_rolling_resistance_slows_a_rolling_ball_at_five_sevenths_c_g():
    """A torque c_r r m g against the rolling of a ball that rolls (v = omega r): (m + I / r^2) dv/dt =
    -c_r m g, so dv/dt = -5/7 c_r g; without the setting it rolls on at constant speed."""
    radius, v0, c = 0.1, 1.0, 0.05

    def rolling(c_r):
        world = rigid_world([SPHERE], [radius], [[0.0, 0.0, 0.0]], [1.0], omega=[[0.0, v0 / radius, 0.0]],
                            shapes=[FLOOR], friction=0.5, rolling_resistance=c_r)
        y0 = np.array([[[0.0, 0.0, radius]], [[v0, 0.0, 0.0]]])
        traj, _ = run(world, Model([1.0], [radius], [Gravity()]), y0, 1 / 60, 60)
        return traj.t[10:], traj.velocities[10:, 0, 0]

    t, v = rolling(c)
    assert np.polyfit(t, v, 1)[0] == pytest.approx(-5 / 7 * c * G, rel=1e-2)
    t, v = rolling(0.0)
    assert np.max(np.abs(v - v[0])) < 1e-3 * v0  # the contact's deflection shortens the lever: 6e-4 measured


def test_a_fast_ball_meets_the_other_speculatively_and_never_passes_it():
    """60 m/s at 60 Hz is a metre per step, five times the gap: the contact is found while still
    0.4 m apart (the bound is swept over the step), closes exactly and passes the momentum on."""
    world = rigid_world([SPHERE, SPHERE], [0.1, 0.1], np.zeros((2, 3)), [1.0, 1.0], restitution=1.0)
    y0 = np.array([[[0.0, 0.0, 0.0], [0.6, 0.0, 0.0]], [[60.0, 0.0, 0.0], [0.0, 0.0, 0.0]]])
    traj, step = run(world, Model(np.ones(2), np.full(2, 0.1), []), y0, 1 / 60, 3)
    gap = traj.positions[:, 1, 0] - traj.positions[:, 0, 0]
    assert np.all(gap >= 0.2 - 1e-12)  # never inside each other
    np.testing.assert_allclose(traj.velocities[-1, :, 0], [0.0, 60.0], atol=1e-9)  # eps = 1: equal masses swap
    assert step.log.count() == 1


def energy(world, masses, y, step):
    """Kinetic (translation and spin) plus gravity's potential energy, J."""
    spin = quat.rotate_inverse(np, step.orientation, step.omega)
    return (0.5 * masses @ np.sum(y[1] ** 2, axis=1) + 0.5 * np.sum(world.rigid.bodies.inertia * spin**2)
            + G * masses @ y[0][:, 2])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_no_energy_gain_on_random_piles_of_boxes(seed, restitution):
    """Eight boxes of random size, mass, orientation, velocity and spin (seeded) tumble onto the floor
    and onto each other: with eps <= 1 the energy never rises above its start."""
    n, rng = 8, np.random.default_rng(seed)
    k = np.arange(n)
    position = np.stack([k % 2 * 0.6 - 0.3, k // 2 % 2 * 0.6 - 0.3, 0.4 + k // 4 * 0.6], axis=1)
    position += rng.uniform(-0.05, 0.05, (n, 3))  # apart: the largest box's half diagonal is 0.26 m
    half, masses = rng.uniform(0.05, 0.15, (n, 3)), rng.uniform(0.5, 2.0, n)
    world = rigid_world([BOX] * n, [0.0] * n, half, masses, orientations=quat.normalize(np, rng.normal(size=(n, 4))),
                        omega=3 * rng.normal(size=(n, 3)), shapes=[FLOOR], friction=0.5, restitution=restitution)
    step = RigidSolverStep(world, Model(masses, np.full(n, 0.1), [Gravity()]), EULER)
    y = np.stack([position, rng.normal(size=(n, 3))])
    start = energy(world, masses, y, step)
    highest = start
    for k in range(180):
        y, _ = step(k / 60, y, 1 / 60, None)
        highest = max(highest, energy(world, masses, y, step))
    assert step.log.count() >= n  # every box hit something
    assert highest <= start
    assert energy(world, masses, y, step) < 0.5 * start  # and most of it went


def sphere_row(velocities, restitution, iterations, substeps):
    """Rotating spheres (1 kg, r = 0.1 m, frictionless) touching in a row along x in free space, the
    moving ones 1 cm off the row: (final velocities, step, the kinetic energy after each step)."""
    n = len(velocities)
    v0 = np.zeros((n, 3))
    v0[:, 0] = velocities
    x = 0.2 * np.arange(n) - np.sign(velocities) * 0.01
    world = rigid_world([SPHERE] * n, [0.1] * n, np.zeros((n, 3)), np.ones(n), restitution=restitution,
                        iterations=iterations, substeps=substeps)
    step = RigidSolverStep(world, Model(np.ones(n), np.full(n, 0.1), []), EULER)
    y = np.stack([np.column_stack([x, np.zeros(n), np.zeros(n)]), v0])
    kinetic = []
    for k in range(30):
        y, _ = step(k / 60, y, 1 / 60, None)
        kinetic.append(0.5 * np.sum(y[1] ** 2) + 0.5 * 0.4 * 0.01 * np.sum(step.omega**2))
    return y[1], step, np.array(kinetic)


@pytest.mark.parametrize("balls", [3, 5])
@pytest.mark.parametrize("restitution", [1.0, 0.9])
@pytest.mark.parametrize("iterations, substeps", [(4, 4), (30, 16)])
def test_newtons_cradle_in_the_solver_never_gains_energy_and_keeps_momentum(balls, restitution, iterations,
                                                                           substeps):
    """One ball at 1 m/s into a row: the impulses that an earlier contact's impulse raised must not
    bounce back too (that gave 1.31 times the energy). Kinetic energy never rises above 1/2 J, and
    sum m v stays 1 kg m/s."""
    v, step, kinetic = sphere_row([1.0] + [0.0] * (balls - 1), restitution, iterations, substeps)
    assert step.log.count() >= balls - 1  # every contact was hit
    assert np.max(kinetic) <= 0.5 * (1 + 1e-12)
    np.testing.assert_allclose(v.sum(axis=0), [1.0, 0.0, 0.0], rtol=0, atol=1e-14)
    assert np.all(np.diff(v[:, 0]) >= -1e-12)  # the balls break away: none approaches the next


def test_the_symmetric_three_ball_impact_reverses_the_outer_balls_and_keeps_energy():
    """Smith et al. (2012): +-1 m/s into a ball at rest between, eps = 1. By symmetry the middle ball
    gets equal and opposite impulses and stays; energy and momentum then make the outer ones
    reverse: v = (-1, 0, 1)."""
    v, _, kinetic = sphere_row([1.0, 0.0, -1.0], 1.0, 30, 16)
    np.testing.assert_allclose(v[:, 0], [-1.0, 0.0, 1.0], rtol=0, atol=1e-12)
    assert np.max(kinetic) <= 1.0 * (1 + 1e-12)
    assert kinetic[-1] == pytest.approx(1.0, rel=1e-12)


@settings(max_examples=20, deadline=None, derandomize=True)
@given(balls=st.integers(2, 5), seed=st.integers(0, 2**32 - 1), restitution=st.floats(0.0, 1.0))
def test_spinning_balls_in_a_row_never_gain_energy(balls, seed, restitution):
    """Balls of random mass, speed along the row and spin, with friction 0.3, 1 cm apart in free
    space: whatever the order the contacts close in, with eps <= 1 the kinetic energy never rises
    and the momentum is kept."""
    rng = np.random.default_rng(seed)
    masses, radius = rng.uniform(0.5, 3.0, balls), 0.1
    omega = rng.normal(scale=10.0, size=(balls, 3))
    world = rigid_world([SPHERE] * balls, [radius] * balls, np.zeros((balls, 3)), masses, omega=omega,
                        friction=0.3, restitution=restitution)
    step = RigidSolverStep(world, Model(masses, np.full(balls, radius), []), EULER)
    q = np.column_stack([0.21 * np.arange(balls), rng.uniform(-0.02, 0.02, (balls, 2))])
    y = np.stack([q, np.column_stack([rng.uniform(-2.0, 2.0, balls), np.zeros((balls, 2))])])
    inertia = 0.4 * masses * radius**2

    def kinetic(v, w):
        return 0.5 * masses @ np.sum(v**2, axis=1) + 0.5 * inertia @ np.sum(w**2, axis=1)

    start, p0 = kinetic(y[1], omega), masses @ y[1]
    for k in range(30):
        y, _ = step(k / 60, y, 1 / 60, None)
        assert kinetic(y[1], step.omega) <= start * (1 + 1e-12)
    np.testing.assert_allclose(masses @ y[1], p0, rtol=0, atol=1e-13 * max(np.abs(p0).max(), 1.0))


def test_a_column_of_boxes_deflects_n_squared_g_over_omega_squared():
    """Five 1 m boxes at rest: the soft contact is a spring k = m_n omega^2 at each of a face's four
    corners (m_n = m/4 on the floor, m/8 between boxes, with the turning in it), so the floor's
    contact sinks N g / omega^2 and each box-box contact carrying j boxes 2 j g / omega^2: the top
    sinks N^2 g / omega^2 in all (6.90 mm at 30 Hz)."""
    n, h = 5, 0.5
    world = rigid_world([BOX] * n, [0.0] * n, [[h, h, h]] * n, [1.0] * n, shapes=[FLOOR], friction=0.6)
    position = np.array([[0.0, 0.0, h + 2 * h * k] for k in range(n)])
    traj, step = run(world, Model(np.ones(n), np.full(n, h), [Gravity()]), np.stack([position, 0 * position]),
                     1 / 60, 180)
    omega = 2 * np.pi * world.solver.contact_hertz
    assert position[-1, 2] - traj.positions[-1, -1, 2] == pytest.approx(n**2 * G / omega**2, rel=1e-3)
    assert np.max(np.abs(traj.velocities[-1])) < 1e-6  # at rest: 3e-8 m/s left by Gauss-Seidel


def test_two_spinning_cubes_keep_linear_and_angular_momentum_to_round_off():
    """Cubes (I a multiple of the identity, so I omega is L whatever the orientation) in an oblique,
    spinning hit with friction and restitution, no gravity: sum m v and sum (m x ^ v + I omega) kept."""
    masses, h = np.array([1.0, 2.5]), 0.1
    world = rigid_world([BOX, BOX], [0.0, 0.0], [[h, h, h]] * 2, masses,
                        orientations=quat.normalize(np, np.array([[1.0, 0.2, 0.1, 0.0], [0.9, 0.0, 0.3, 0.2]])),
                        omega=[[0.0, 4.0, 9.0], [3.0, -2.0, 1.0]], friction=0.5, restitution=0.5)
    inertia = masses * (2 * h) ** 2 / 6
    y0 = np.array([[[0.0, 0.0, 0.0], [0.4, 0.1, 0.05]], [[2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]])

    def momenta(q, v, omega):
        return masses @ v, np.sum(masses[:, None] * np.cross(q, v), axis=0) + inertia @ omega

    p0, l0 = momenta(y0[0], y0[1], world.rigid.bodies.angular_velocities)
    traj, step = run(world, Model(masses, np.full(2, h), []), y0, 1 / 60, 12)
    assert step.log.count() == 1
    p1, l1 = momenta(traj.positions[-1], traj.velocities[-1], step.omega)
    assert np.linalg.norm(step.omega - world.rigid.bodies.angular_velocities) > 0.1  # the hit changed the spins
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-14 * np.abs(p0).max())
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-14 * np.abs(l0).max())


def test_steplab_run_steps_a_box_scene_with_the_solver_and_reports_its_rotation(tmp_path, capsys):
    """``steplab run --json``: the crate's final orientation and spin are the solver's (it landed and
    stopped tumbling), the ball rolls without a row of rotation; a rotation method that cannot go
    between the solver's stages is one line, status 2."""
    import json

    from steplab.cli import main

    path = tmp_path / "crate.toml"
    path.write_text(BOX_SCENE.replace("{method}", "solver").replace("t_end = 0.5", "t_end = 2.0"))
    assert main(["run", str(path), "--json", "--save-every", "7", "--out", str(tmp_path / "crate.npz")]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rotation"] == "exponential-map" and summary["rotating_bodies"] == ["crate"]
    crate = np.array(summary["final_angular_velocities"][0])
    assert np.linalg.norm(crate) < 0.05  # at rest on the floor after 2 s (2.3 rad/s at the start)
    assert np.isfinite(summary["collisions"]["largest_residual"]) and summary["collisions"]["impacts"] >= 2
    saved = np.load(tmp_path / "crate.npz")
    assert saved["orientations"].shape == (len(saved["t"]), 2, 4)
    np.testing.assert_allclose(saved["orientations"][-1, 0], summary["final_orientations"][0], rtol=0, atol=0)
    assert main(["run", str(path), "--rotation", "dlm"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not compose with it" in err


def test_the_restitution_budget_counts_the_kicks_of_forces_that_change_within_the_step(monkeypatch):
    """A 1 kg cube under gravity and quadratic drag, spinning, thrown sideways far above the floor: no
    contact and no gyroscopic term (equal moments). The restitution pass returns at most D = E0 + W - E1,
    the kinetic energy the step took; with no contact D must be 0, E0 + W being the kinetic energy at the
    step's end, 1/2 m v^2 + 1/2 I |omega|^2, written out here. Drag changes from substep to substep, so
    its work is each kick's, h F . (v before + v after) / 2, not the last substep's m a times the whole
    step's move (exact for a constant field only: 8.6 J too much in the first step here)."""
    from steplab.physics import Drag

    mass, half = 1.0, 0.1
    world = rigid_world([BOX], [half * np.sqrt(3)], [[half] * 3], [mass], omega=[[1.0, 2.0, 3.0]],
                        shapes=(Plane(np.array([0.0, 0.0, 1.0]), -100.0),))
    model = Model([mass], [half * np.sqrt(3)], [Gravity(), Drag(beta=np.array([0.5]))])
    y0 = np.array([[[0.0, 0.0, 0.0]], [[20.0, 0.0, 5.0]]])
    budgets, finish = [], rs.finish

    def kept_finish(bodies, contacts, sub, layout):  # E0 + W as the pass's limit counts it
        budgets.append(bodies.energy[0] + mass * bodies.accel[0] @ bodies.dq[0])
        return finish(bodies, contacts, sub, layout)

    monkeypatch.setattr(rs, "finish", kept_finish)
    traj, _ = run(world, model, y0, 1 / 60, 20)
    spin = 0.5 * mass * (2 * half) ** 2 / 6 * 14.0  # 1/2 I |omega|^2, omega = (1, 2, 3) rad/s kept
    assert len(budgets) == 20
    for budget, v in zip(budgets, traj.velocities[1:, 0]):
        assert budget == pytest.approx(0.5 * mass * v @ v + spin, rel=1e-12)
