"""Spheres with spin in the event loop: the impulse's angular part, Coulomb friction in an impact,
and a ball that slides until it rolls, against closed forms written out here (not the kernels').

The closed forms, for a ball of mass m, radius R and moment of inertia I landing on a floor of
upward normal z with velocity v (v_n = -v . z > 0 into the floor) and spin omega, restitution
eps and friction mu. The contact point is r = -R z from the centre, so its slip is
u_t = v_t + (omega x r)_t = v_t - R (omega x z)_t. The normal impulse is equation 4,
J_n = m (1 + eps) v_n, whatever the spin. A tangential impulse P changes the slip by
(1/m + R^2 / I) P, so stopping it takes P = -u_t / k, k = 1/m + R^2 / I (k = 7 / (2 m) for a
solid ball, I = 2/5 m R^2):

- it sticks when |u_t| / k <= mu J_n: v_t+ = v_t - u_t / (m k), omega+ = omega + (R / (I k)) z x u_t,
  for a solid ball v_t+ = (5 v_t + 2 R (omega x z)_t) / 7 and the slip after is 0;
- otherwise it slides, P = -mu J_n u_t / |u_t|: v_t+ = v_t - mu (1 + eps) v_n u_t / |u_t|,
  omega+ = omega + (R mu J_n / I) z x u_t / |u_t|.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import simulate
from steplab.physics.collision.compiled_response import Spin, no_spin, resolve_pair
from steplab.physics.scene import parse_scene
from steplab.studies import stacking_theory as theory

UP = np.array([0.0, 0.0, 1.0])


def spin_of(omega, inertia, radii):
    """A Spin of bodies with these omegas (K, 3), moments of inertia and radii (K,)."""
    omega = np.array(omega, dtype=float).reshape(-1, 3)
    n = len(omega)
    return Spin(omega, 1.0 / np.asarray(inertia, float), np.asarray(radii, float),
                np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.zeros(n))


def floor_impact(v, omega, m, radius, inertia, eps, mu):
    """The kernel's response of a ball on the floor z = 0 (touching it): (v+, omega+, Lambda)."""
    y = np.array([[[0.0, 0.0, radius]], [v]], dtype=float)
    spin = spin_of([omega], [inertia], [radius])
    lam = resolve_pair(y, (0, -1), np.array([1.0 / m]), -UP, 0.0, (eps, mu), spin)
    return y[1, 0], spin.omega[0], lam


def closed_form(v, omega, m, radius, inertia, eps, mu):
    """The closed form of the module's docstring: (v+, omega+, sticks)."""
    v, omega = np.asarray(v, float), np.asarray(omega, float)
    v_n = -v @ UP
    j_n = m * (1 + eps) * v_n
    v_t = v - (v @ UP) * UP
    u_t = v_t - radius * (np.cross(omega, UP) - (np.cross(omega, UP) @ UP) * UP)
    k = 1 / m + radius**2 / inertia
    sticks = np.linalg.norm(u_t) / k <= mu * j_n
    p = -u_t / k if sticks else -mu * j_n * u_t / np.linalg.norm(u_t)
    v_after = v_t + p / m + eps * v_n * UP
    omega_after = omega + (radius / inertia) * np.cross(-UP, p)  # I domega = r x P, r = -R z
    return v_after, omega_after, sticks


def slip(v, omega, radius):
    return v - radius * np.cross(omega, UP) - ((v - radius * np.cross(omega, UP)) @ UP) * UP


@pytest.mark.parametrize("mu, sticks", [(0.05, False), (0.9, True)])
def test_an_oblique_impact_of_a_spinning_ball_slides_or_sticks_as_the_closed_form(mu, sticks):
    m, radius, eps = 0.7, 0.11, 0.6
    inertia = 0.4 * m * radius**2
    v, omega = np.array([1.3, -0.4, -2.0]), np.array([3.0, 5.0, -7.0])
    v1, w1, lam = floor_impact(v, omega, m, radius, inertia, eps, mu)
    v_exact, w_exact, stuck = closed_form(v, omega, m, radius, inertia, eps, mu)
    assert stuck == sticks
    np.testing.assert_allclose(v1, v_exact, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(w1, w_exact, rtol=1e-13, atol=1e-13)
    assert v1[2] == pytest.approx(eps * 2.0, rel=1e-14)  # the spin never changes the bounce
    assert w1[2] == omega[2]  # nor the spin about the normal (no torsional friction at a point)
    u_before, u_after = slip(v, omega, radius), slip(v1, w1, radius)
    if sticks:
        assert np.linalg.norm(u_after) < 1e-13
        # the solid ball's rule: v_t+ = (5 v_t + 2 R (omega x z)_t) / 7
        rolled = (5 * v[:2] + 2 * radius * np.cross(omega, UP)[:2]) / 7
        np.testing.assert_allclose(v1[:2], rolled, rtol=1e-13)
    else:  # dv_t = -mu (1 + eps) |v_n| along the slip, and the slip keeps its direction
        dv = v1[:2] - v[:2]
        np.testing.assert_allclose(dv, -mu * (1 + eps) * 2.0 * u_before[:2] / np.linalg.norm(u_before), rtol=1e-13)
        np.testing.assert_allclose(np.cross(u_before, u_after), 0.0, atol=1e-12)
        assert u_before[:2] @ u_after[:2] > 0
    # angular momentum about the contact point, m r_c x v + I omega with r_c = R z from it, is kept
    about_contact = (m * np.cross(radius * UP, v) + inertia * omega, m * np.cross(radius * UP, v1) + inertia * w1)
    np.testing.assert_allclose(about_contact[1][:2], about_contact[0][:2], rtol=1e-13, atol=1e-15)


def test_the_transition_between_sliding_and_sticking_is_at_the_threshold_and_continuous():
    m, radius, eps, v_n = 1.0, 0.1, 0.5, 1.2
    inertia = 0.4 * m * radius**2
    v, omega = np.array([2.0, 0.0, -v_n]), np.array([0.0, -4.0, 0.0])
    u = 2.0 - radius * -4.0  # the slip along x: v_x - R omega_y
    threshold = u / ((1 / m + radius**2 / inertia) * m * (1 + eps) * v_n)  # |u_t| / (k J_n)
    after = {}
    for factor in (1 - 1e-9, 1.0, 1 + 1e-9):
        v1, w1, _ = floor_impact(v, omega, m, radius, inertia, eps, threshold * factor)
        after[factor] = (v1, w1)
        left = np.linalg.norm(slip(v1, w1, radius))
        expected = max(0.0, u - (1 / m + radius**2 / inertia) * threshold * factor * m * (1 + eps) * v_n)
        assert left == pytest.approx(expected, abs=1e-12)
    # continuous across it, and the solid ball's sticking rule at it: (5 v + 2 R omega_y) / 7 along x
    np.testing.assert_allclose(after[1 - 1e-9][0], after[1 + 1e-9][0], atol=1e-8)
    assert after[1.0][0][0] == pytest.approx((5 * 2.0 + 2 * radius * -4.0) / 7, rel=1e-13)


def random_pair(seed):
    """Two touching spheres with random masses, radii, moments of inertia, velocities and spins."""
    rng = np.random.default_rng(seed)
    m, radius = rng.uniform(0.2, 3.0, 2), rng.uniform(0.05, 0.5, 2)
    inertia = rng.uniform(0.2, 0.7, 2) * m * radius**2  # from a hollow-ish to a solid-ish ball
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    x = np.stack([rng.normal(size=3), np.zeros(3)])
    x[1] = x[0] + (radius[0] + radius[1]) * n  # touching, n from 0 to 1
    y = np.stack([x, rng.normal(size=(2, 3)) * 2])
    return y, m, radius, inertia, n, rng.normal(size=(2, 3)) * 10


def totals(y, m, inertia, omega):
    momentum = (m[:, None] * y[1]).sum(axis=0)
    angular = (np.cross(y[0], m[:, None] * y[1]) + inertia[:, None] * omega).sum(axis=0)  # about the origin
    energy = 0.5 * (m * (y[1] ** 2).sum(axis=1)).sum() + 0.5 * (inertia * (omega**2).sum(axis=1)).sum()
    return momentum, angular, energy


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), eps=st.floats(0, 1), mu=st.sampled_from([0.0, 0.1, 0.5, 3.0]))
def test_sphere_sphere_with_spin_keeps_momentum_and_angular_momentum_and_never_gains_energy(seed, eps, mu):
    y, m, radius, inertia, n, omega = random_pair(seed)
    spin = spin_of(omega.copy(), inertia, radius)
    before = totals(y, m, inertia, omega)
    resolve_pair(y, (0, 1), 1.0 / m, n, 0.0, (eps, mu), spin)
    after = totals(y, m, inertia, spin.omega)
    scale = np.abs(m[:, None] * y[1]).sum() + np.abs(np.cross(y[0], m[:, None] * y[1])).sum() + 1.0
    np.testing.assert_allclose(after[0], before[0], atol=1e-13 * scale)
    np.testing.assert_allclose(after[1], before[1], atol=1e-13 * scale + 1e-13 * np.abs(inertia[:, None] * omega).sum())
    assert after[2] <= before[2] * (1 + 1e-13)
    # each body's spin changes by (R / I) n x Lambda: about the normal it never changes
    np.testing.assert_allclose(spin.omega @ n, omega @ n, atol=1e-12 * np.abs(omega).max())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), eps=st.floats(0, 1), mu=st.floats(0, 5))
def test_a_spinning_ball_on_the_floor_never_gains_energy_and_matches_the_closed_form(seed, eps, mu):
    rng = np.random.default_rng(seed)
    m, radius = rng.uniform(0.1, 5.0), rng.uniform(0.01, 1.0)
    inertia = rng.uniform(0.2, 0.7) * m * radius**2
    v = rng.normal(size=3) * 3
    v[2] = -abs(v[2]) - 0.01
    omega = rng.normal(size=3) * 20
    v1, w1, _ = floor_impact(v, omega, m, radius, inertia, eps, mu)
    energy = [0.5 * m * v @ v + 0.5 * inertia * omega @ omega, 0.5 * m * v1 @ v1 + 0.5 * inertia * w1 @ w1]
    assert energy[1] <= energy[0] * (1 + 1e-13)
    v_exact, w_exact, _ = closed_form(v, omega, m, radius, inertia, eps, mu)
    np.testing.assert_allclose(v1, v_exact, rtol=1e-12, atol=1e-12 * (1 + np.abs(v).max()))
    np.testing.assert_allclose(w1, w_exact, rtol=1e-12, atol=1e-12 * (1 + np.abs(omega).max()))


def test_without_spin_the_response_is_the_point_masses_bit_for_bit():
    y, m, radius, inertia, n, omega = random_pair(7)
    ys = y.copy(), y.copy()
    lam_point = resolve_pair(ys[0], (0, 1), 1.0 / m, n, 0.01, (0.7, 0.4), no_spin())
    still = spin_of(np.zeros((2, 3)), [np.inf, np.inf], radius)  # 1/I = 0: bodies that do not turn
    lam_spin = resolve_pair(ys[1], (0, 1), 1.0 / m, n, 0.01, (0.7, 0.4), still)
    assert lam_point.tobytes() == lam_spin.tobytes() and ys[0].tobytes() == ys[1].tobytes()


# --- the event loop's runs ---------------------------------------------------------------------

ROLLING = """
[simulation]
integrator = "semi-implicit-euler"
dt = {dt!r}
t_end = 1.0

[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 0.1]
velocity = [2.0, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 0.0]

[forces.gravity]

[collisions]
restitution = 0.0
friction = 0.2

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 1.0]
"""


def run_kept(scene, compiled=True, event_loop="auto"):
    """``scene`` run with its collisions; (trajectory, the step) (the step holds the spin)."""
    world = dataclasses.replace(scene.collisions, compiled_loop=compiled, event_loop=event_loop)
    kept = []

    def stepper(model, integrator):
        kept.append(world.stepper(model, integrator))
        return kept[-1]

    traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, scene.t_end, scene.dt, stepper=stepper)
    return traj, kept[0]


@pytest.mark.parametrize("dt, compiled", [(1 / 30, True), (1 / 60, True), (1 / 240, True), (1 / 60, False)])
def test_a_ball_launched_sliding_rolls_at_five_sevenths_exactly_at_every_step_end(dt, compiled):
    """The slide's closed form over each step (:mod:`.resting`): v, omega r, x and the orientation at
    every step's end are the exact motion's, v0 - mu g t and 5/2 mu g t until t = 2 v0 / (7 mu g),
    then 5/7 v0, at any dt, compiled or not."""
    scene = parse_scene(ROLLING.format(dt=dt), "rolling.toml")
    traj, step = run_kept(scene, compiled)
    assert type(step).__name__ == "SpinningCollisionStep" and step.compiled_loop == compiled
    orientations, omega = step.rotation_at(np.arange(len(traj.t)))
    v0, mu, radius, g = 2.0, 0.2, 0.1, theory.G
    answer = theory.sliding_to_rolling(v0, mu, radius)
    v_exact, spin_exact = theory.rolling_speed(v0, mu, radius, traj.t)
    t = traj.t
    x_exact = np.where(t < answer["t_roll"], v0 * t - 0.5 * mu * g * t**2,
                       answer["x_roll"] + answer["v_roll"] * (t - answer["t_roll"]))
    np.testing.assert_allclose(traj.velocities[:, 0, 0], v_exact, atol=1e-13)
    np.testing.assert_allclose(omega[:, 0, 1] * radius, spin_exact, atol=1e-13)
    np.testing.assert_allclose(traj.positions[:, 0, 0], x_exact, atol=1e-13)
    assert traj.velocities[-1, 0, 0] == pytest.approx(5 / 7 * v0, rel=1e-14)
    np.testing.assert_array_equal(traj.positions[:, 0, 2], 0.1)  # on the floor throughout
    # the orientation: turned about y by the spin's integral, exactly
    slide = np.minimum(t, answer["t_roll"])
    angle = 1.25 * mu * g * slide**2 / radius + answer["omega_roll"] * (t - slide)
    np.testing.assert_allclose(orientations[:, 0], np.column_stack([np.cos(angle / 2), 0 * t, np.sin(angle / 2),
                                                                    0 * t]), atol=1e-12)


def room(seed, friction=0.3, balls=12):
    """Balls of random size, spin and speed in a closed box with friction: many impacts, some resting."""
    rng = np.random.default_rng(seed)
    bodies = []
    for k in range(balls):
        bodies.append(f"""
[[bodies]]
name = "b{k}"
mass = {rng.uniform(0.5, 2.0)!r}
radius = {rng.uniform(0.08, 0.15)!r}
position = {[float(x) for x in rng.uniform([-0.7, -0.7, 0.2], [0.7, 0.7, 1.6])]!r}
velocity = {[float(x) for x in rng.normal(size=3) * 2]!r}
angular_velocity = {[float(x) for x in rng.normal(size=3) * 15]!r}
""")
    walls = "".join(f'\n[[collisions.planes]]\nnormal = {n}\noffset = -1.0\n' for n in (
        "[1.0, 0.0, 0.0]", "[-1.0, 0.0, 0.0]", "[0.0, 1.0, 0.0]", "[0.0, -1.0, 0.0]", "[0.0, 0.0, -1.0]"))
    return parse_scene(f"""
[simulation]
integrator = "semi-implicit-euler"
dt = 0.01
t_end = 1.5
{''.join(bodies)}
[forces.gravity]

[collisions]
restitution = 0.7
friction = {friction!r}

[[collisions.planes]]
normal = [0.0, 0.0, 1.0]
{walls}""", "room.toml")


def test_the_compiled_and_the_python_event_loops_agree_bit_for_bit_with_spin():
    scene = room(3)
    (fast, fast_step), (slow, slow_step) = run_kept(scene, True), run_kept(scene, False)
    assert fast_step.compiled_loop and not slow_step.compiled_loop
    assert fast.collisions.count() > 50  # impacts with friction, balls that end up rolling on the floor
    assert fast.y.tobytes() == slow.y.tobytes()
    assert fast_step.spin.omega.tobytes() == slow_step.spin.omega.tobytes()
    assert fast_step.spin.orientation.tobytes() == slow_step.spin.orientation.tobytes()
    assert not np.allclose(fast_step.spin.omega, scene.rigid_bodies.angular_velocities)  # friction turned them
    # the full loop (every pair tested again after every impact) reaches the same state
    full, full_step = run_kept(scene, False, "full")
    np.testing.assert_allclose(full.y[-1], fast.y[-1], atol=1e-9)
    np.testing.assert_allclose(full_step.spin.omega, fast_step.spin.omega, atol=1e-8)


def test_energy_never_grows_in_a_room_of_spinning_balls():
    scene = room(11, friction=0.5)
    traj, step = run_kept(scene)
    orientations, omega = step.rotation_at(np.arange(len(traj.t)))
    bodies = scene.rigid_bodies
    inertia = np.asarray(bodies.inertia)[:, 0]
    m = 1.0 / np.asarray(scene.model.inverse_masses)
    energy = (0.5 * (m * (traj.velocities**2).sum(axis=2)).sum(axis=1)
              + 0.5 * (inertia * (omega[:, bodies.index] ** 2).sum(axis=2)).sum(axis=1)
              + (m * theory.G * traj.positions[..., 2]).sum(axis=1))
    # each step's end: no more than the step before (the integrator's own O(g dt^2) per resting ball aside)
    assert np.max(np.diff(energy)) <= 1e-9 * energy[0] + 0.5 * m.sum() * (theory.G * scene.dt) ** 2
    assert energy[-1] < 0.5 * energy[0]


def test_frictionless_spheres_keep_the_plain_step_and_their_spin():
    scene = room(5, friction=0.0)
    traj, step = run_kept(scene)
    assert type(step).__name__ == "CollisionStep" and len(step.spin.omega) == 0


def refusal(tmp_path, capsys, old, new):
    """``steplab run`` of the rolling scene with ``old`` replaced by ``new``: status 2 and one line, returned."""
    from steplab.cli import main

    path = tmp_path / "edited.toml"
    path.write_text(ROLLING.format(dt=0.01).replace(old, new))
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_a_sphere_of_three_moments_is_refused_in_one_line_naming_the_solver(tmp_path, capsys):
    err = refusal(tmp_path, capsys, "angular_velocity = [0.0, 0.0, 0.0]", "inertia = [1.0, 2.0, 2.5]")
    assert 'method = "solver"' in err and "one moment of inertia" in err


@pytest.mark.parametrize("old, new", [
    ("friction = 0.2", "friction = -0.2"),
    ('name = "ball"\nmass = 1.0\nradius = 0.1\n', 'name = "ball"\nmass = 1.0\n'),
])
def test_bad_spin_input_is_one_line_with_status_2(old, new, tmp_path, capsys):
    refusal(tmp_path, capsys, old, new)


def test_angular_velocity_on_particles_is_one_line_with_status_2(tmp_path, capsys):
    """Particles are points: they take no spin (the key is refused by name)."""
    from steplab.cli import main

    path = tmp_path / "points.toml"
    path.write_text('[simulation]\ndt = 0.01\nt_end = 0.1\n[[particles]]\nname = "p"\ncount = 3\nseed = 1\n'
                    'mass = 1.0\nradius = 0.1\nbox_min = [0, 0, 0.2]\nbox_max = [1, 1, 1]\n'
                    'angular_velocity = [0, 0, 1]\n[forces.gravity]\n[collisions]\nfriction = 0.3\n'
                    '[[collisions.planes]]\nnormal = [0.0, 0.0, 1.0]\n')
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unknown key 'angular_velocity'" in err
