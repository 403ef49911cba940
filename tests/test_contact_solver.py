"""The contact solver (``[collisions] method = "solver"``): against equation 4, momentum, energy,
the analytic resting column, the event loop's cradle and tunnelling, and its bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import get_integrator, simulate
from steplab.physics import Gravity, Model
from steplab.physics.collision import Box, CollisionWorld, PairProperties, Plane, impulse, remove_on_impact
from steplab.physics.collision.solver_batch import run_batch
from steplab.physics.collision.solver_settings import ContactSolver
from steplab.physics.scene import SceneError, parse_scene

from steplab.cli import main

SIE = get_integrator("semi-implicit-euler")
FLOOR = Plane(np.array([0.0, 0.0, 1.0]))


def solver_world(shapes=(), eps=1.0, mu=0.0, **settings_):
    return CollisionWorld(shapes=tuple(shapes), pair_properties=PairProperties(eps, mu), method="solver",
                          solver=ContactSolver(**settings_))


def box_walls(half):
    return (FLOOR,) + tuple(Plane(np.array(n, float), -half) for n in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]))


@pytest.mark.parametrize("masses, normal, eps", [((1.0, 2.0), (1.0, 0.0, 0.0), 0.5),
                                                 ((0.3, 5.0), (0.6, 0.0, 0.8), 1.0),
                                                 ((2.0, 2.0), (0.0, 1.0, 0.0), 0.0)])
def test_one_contact_equals_equation_4(masses, normal, eps):
    # two touching balls approaching along their normal, no forces: one contact in the step
    n = np.array(normal)
    r = np.array([0.1, 0.15])
    q = np.array([[0.0, 0.0, 0.0], n * 0.25])
    v = np.array([[0.7, -0.2, 0.1], [0.8, 0.1, -0.3]])
    v[1] -= 1.5 * n  # approaching at about 1.5 m/s
    model = Model(np.array(masses), r, [])
    traj = simulate(model, SIE, np.stack([q, v]), 0.0, dt=0.01, n_steps=1, collisions=solver_world(eps=eps))
    inv = 1 / np.array(masses)
    lam = impulse(v[0], v[1], inv[0], inv[1], n, eps)  # on body 0, the event loop's equation 4
    v_end = traj.y[-1][1]
    np.testing.assert_allclose(v_end[0], v[0] + lam * inv[0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(v_end[1], v[1] - lam * inv[1], rtol=0, atol=1e-14)
    (event,) = traj.collisions.events
    assert event.impulse == pytest.approx(np.linalg.norm(lam), rel=1e-13)


def test_ball_on_floor_touching_equals_equation_4():
    model = Model(np.array([1.0]), np.array([0.1]), [])
    y0 = np.array([[[0.0, 0.0, 0.1]], [[0.3, 0.0, -2.0]]])
    traj = simulate(model, SIE, y0, 0.0, dt=0.01, n_steps=1, collisions=solver_world([FLOOR], eps=0.6))
    np.testing.assert_allclose(traj.y[-1][1, 0], [0.3, 0.0, 1.2], rtol=0, atol=1e-14)


def random_pile(seed, n, half=0.7):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.05, 0.15, n)
    q = []
    while len(q) < n:  # apart at the start: every energy change is the solver's
        c = rng.uniform([-0.5, -0.5, 0.2], [0.5, 0.5, 1.2])
        if all(np.linalg.norm(c - p) > r[len(q)] + r[k] for k, p in enumerate(q)):
            q.append(c)
    q = np.array(q)
    q[:, 2] = np.maximum(q[:, 2], r)
    return rng, Model(rng.uniform(0.5, 2.0, n), r, [Gravity()]), np.stack([q, rng.normal(0.0, 2.0, (n, 3))])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 10), eps=st.floats(0.0, 1.0), mu=st.floats(0.0, 1.0),
       iterations=st.integers(1, 8), substeps=st.integers(1, 8), correction=st.sampled_from(["soft", "baumgarte"]))
def test_random_piles_gain_no_energy(seed, n, eps, mu, iterations, substeps, correction):
    _, model, y0 = random_pile(seed, n)
    world = solver_world(box_walls(0.7), eps, mu, iterations=iterations, substeps=substeps, correction=correction)
    traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=90, collisions=world)
    energy = np.array([model.energy(y) for y in traj.y])
    assert np.max(energy) <= energy[0] * (1 + 1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 10), eps=st.floats(0.0, 1.0), mu=st.floats(0.0, 1.0))
def test_momentum_conserved_in_body_contacts(seed, n, eps, mu):
    # no forces, no walls: only body-body contacts, each impulse equal and opposite
    rng, model, y0 = random_pile(seed, n)
    model = Model(model.masses, model.radii, [])
    y0[1] = rng.normal(0.0, 0.05, (n, 3)) - 3.0 * (y0[0] - y0[0].mean(axis=0))  # towards the middle
    traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=40, collisions=solver_world(eps=eps, mu=mu))
    assert traj.collisions.count() > 0
    p = np.einsum("i,tij->tj", model.masses, traj.y[:, 1])
    np.testing.assert_allclose(p, np.broadcast_to(p[0], p.shape), rtol=0, atol=1e-13 * np.abs(p[0]).max() + 1e-13)


def column(n=10, r=0.1):
    q = np.zeros((n, 3))
    q[:, 2] = r + 2 * r * np.arange(n)
    return Model(np.ones(n), np.full(n, r), [Gravity()]), np.stack([q, np.zeros_like(q)])


def test_resting_column_sinks_as_the_soft_contact_spring_predicts():
    # at rest each soft contact is a spring k = m_eff omega^2 carrying the weight above it:
    # the floor contact sinks by n g / omega^2 (m_eff = m), the contact under k balls by 2 k g / omega^2
    model, y0 = column()
    world = solver_world([FLOOR], eps=0.5, iterations=10)
    traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=600, save_every=600, collisions=world)
    q, v = traj.y[-1]
    omega2 = (2 * np.pi * world.solver.contact_hertz) ** 2
    depth_floor = 0.1 - q[0, 2]
    depth_between = 0.2 - np.diff(q[:, 2])
    np.testing.assert_allclose(depth_floor, 10 * 9.81 / omega2, rtol=1e-6)
    np.testing.assert_allclose(depth_between, 2 * np.arange(9, 0, -1) * 9.81 / omega2, rtol=1e-6)
    assert np.sqrt(np.mean(v**2)) < 1e-9  # no jitter
    np.testing.assert_allclose(q[:, :2], 0.0, atol=1e-15)


def test_a_float32_column_is_carried_in_float32_and_settles_as_the_float64_one():
    """The sphere solver computes in float64; a float32 run's state stays float32 from step to step
    (it came back float64 from the first step on) and agrees with the float64 run to float32's error."""
    model, y0 = column(4)
    world = solver_world([FLOOR], eps=0.5, iterations=10)
    step = world.stepper(model, SIE)
    y = y0.astype(np.float32)
    for k in range(60):
        y, _ = step(k / 60, y, 1 / 60, None)
        assert y.dtype == np.float32, k
    wide = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=60, save_every=60, collisions=world).y[-1]
    np.testing.assert_allclose(y, wide, rtol=0, atol=1e-5)


def test_pile_at_rest_keeps_its_energy():
    # a settled pile, warm-started: its energy stays put (the issue's |dE| < 1e-6 of its potential energy)
    model, y0 = column(6)
    world = solver_world([FLOOR], eps=0.8, mu=0.5)
    step = world.stepper(model, SIE)
    (ys,) = run_batch([step], [y0], 0.0, 1 / 60, 1200, save_every=600)
    settled, end = model.energy(ys[1]), model.energy(ys[2])
    assert abs(end - settled) < 1e-6 * model.potential_energy(ys[1][0])


def test_newtons_cradle_the_solver_moves_every_ball_and_loses_energy():
    # the event loop sends the last ball off at the first one's speed; the simultaneous solve
    # cannot: restitution sees the touching balls at rest at the start of the step
    n = 5
    q = np.zeros((n, 3))
    q[:, 0] = 0.2 * np.arange(n)
    q[0, 0] -= 0.05
    v = np.zeros((n, 3))
    v[0, 0] = 1.0
    model = Model(np.ones(n), np.full(n, 0.1), [])
    event = simulate(model, SIE, np.stack([q, v]), 0.0, dt=1 / 60, n_steps=30,
                     collisions=CollisionWorld(pair_properties=PairProperties(1.0)))
    np.testing.assert_allclose(event.y[-1][1][:, 0], [0, 0, 0, 0, 1], atol=1e-12)
    traj = simulate(model, SIE, np.stack([q, v]), 0.0, dt=1 / 60, n_steps=30, collisions=solver_world(eps=1.0))
    vx = traj.y[-1][1][:, 0]
    assert np.sum(np.abs(vx) > 1e-3) >= 4
    np.testing.assert_allclose(np.sum(vx), 1.0, atol=1e-12)  # momentum kept
    assert 0.5 * np.sum(vx**2) < 0.9 * 0.5  # energy lost although eps = 1


@pytest.mark.parametrize("ratio", [0.5, 2.0, 10.0, 50.0])
def test_speculative_contacts_never_tunnel(ratio):
    # v dt / (w + 2 r) = ratio through a thin wall: overlap testing misses at 1 - 1/ratio, the solver never
    w, r, dt = 0.02, 0.05, 1 / 60
    speed = ratio * (w + 2 * r) / dt
    wall = Box(np.array([1.0, -5.0, -5.0]), np.array([1.0 + w, 5.0, 5.0]))
    offsets = np.linspace(0.0, speed * dt, 7, endpoint=False)  # where in its step the ball meets the wall
    q = np.zeros((7, 3))
    q[:, 0] = 1.0 - r - offsets - 1e-9
    q[:, 1] = np.arange(7) * 0.5
    v = np.zeros((7, 3))
    v[:, 0] = speed
    model = Model(np.ones(7), np.full(7, r), [])
    # at the defaults (one iteration) the balls' ghost contacts with each other (their swept
    # bounds overlap, normals from the start of the step) may leave a ball sunk into the wall
    # after one sweep, never through it; four sweeps hold every ball at the surface
    for iterations, deepest in ((1, w), (4, 1e-9)):
        traj = simulate(model, SIE, np.stack([q, v]), 0.0, dt=dt, n_steps=3,
                        collisions=solver_world([wall], eps=0.0, iterations=iterations))
        assert np.all(traj.y[-1][0][:, 0] <= 1.0 - r + deepest)


def test_batch_equals_runs_one_at_a_time():
    model, y0 = column(4)
    worlds = [solver_world([FLOOR], eps=0.7, iterations=i, substeps=s) for i, s in [(1, 1), (3, 2), (8, 5)]]
    y0 = y0.copy()
    y0[0, :, 2] += 0.3 * np.arange(4)  # falling apart, bouncing
    out = run_batch([w.stepper(model, SIE) for w in worlds], [y0] * 3, 0.0, 1 / 60, 90, save_every=30)
    for world, ys in zip(worlds, out):
        traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=90, save_every=30, collisions=world)
        np.testing.assert_array_equal(traj.y, ys)


def test_events_triggers_and_epilogues():
    goal = Box(np.array([-1.0, -1.0, 0.5]), np.array([1.0, 1.0, 0.6]), name="goal", trigger=True)
    model = Model(np.array([1.0]), np.array([0.1]), [Gravity()])
    y0 = np.array([[[0.0, 0.0, 1.5]], [[0.0, 0.0, 0.0]]])
    world = solver_world([FLOOR, goal], eps=0.2)  # bouncing back below the goal
    traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=90, collisions=world)
    kinds = [(e.kind, e.other_name) for e in traj.collisions.events]
    assert kinds[0] == ("trigger", "goal") and kinds.count(("trigger", "goal")) == 1  # reported once
    assert ("impact", "plane") in kinds  # and it fell through the goal onto the floor
    assert traj.y[-1][0][0, 2] < 0.5
    removing = CollisionWorld(shapes=(FLOOR,), method="solver", epilogues=(remove_on_impact("plane"),))
    traj = simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=150, collisions=removing)
    assert traj.collisions.count() == 1 and traj.y[-1][0][0, 2] < 0  # bounced once, then fell through


def test_log_taken_as_columns_equals_the_events_an_epilogue_sees():
    # with nobody to tell, impacts are logged as columns (ImpactBlock) and made into events
    # when read: the same events, in the same order, as an epilogue sees one by one
    _, model, y0 = random_pile(3, 8)
    seen = []
    quiet = solver_world(box_walls(0.7), eps=0.6)
    told = CollisionWorld(shapes=quiet.shapes, pair_properties=quiet.pair_properties, method="solver",
                          epilogues=(lambda event, log: seen.append(event.as_row()),))
    logs = [simulate(model, SIE, y0, 0.0, dt=1 / 60, n_steps=60, collisions=w).collisions for w in (quiet, told)]
    assert logs[0].count() == len(seen) > 8
    assert logs[0].summary() == logs[1].summary()
    assert [e.as_row() for e in logs[0].events] == [e.as_row() for e in logs[1].events] == seen
    others = {type(e.other) for e in logs[0].events}
    assert others == {int, str}  # body-body and body-wall impacts both went through the columns
    for e in logs[0].events:  # each column landed in its field
        assert e.kind == "impact" and e.impulse > 0 and e.bracket[0] <= e.t <= e.bracket[1]
        assert e.body_name == model.names[e.body] and abs(np.linalg.norm(e.normal) - 1) < 1e-12
        if isinstance(e.other, int):
            assert e.other_name == model.names[e.other] and e.body < e.other
        else:
            assert e.other_name == e.other == "plane" and not e.trigger


@pytest.mark.parametrize("settings_, message", [
    ({"iterations": 0}, "iterations must be an integer >= 1"),
    ({"substeps": -1}, "substeps must be an integer >= 1"),
    ({"correction": "magic"}, "unknown correction 'magic'"),
    ({"baumgarte": 1.5}, "baumgarte must be in (0, 1]"),
    ({"contact_hertz": 0.0}, "contact_hertz must be > 0"),
])
def test_bad_settings(settings_, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("]", r"\]")):
        ContactSolver(**settings_)


SCENE = """
[simulation]
integrator = "semi-implicit-euler"
dt = 0.01
t_end = 0.1
[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 1.0]
[forces.gravity]
[collisions]
method = "solver"
{extra}
[[collisions.planes]]
normal = [0.0, 0.0, 1.0]
"""


@pytest.mark.parametrize("extra, message", [
    ("[collisions.solver]\niterations = 0", "collisions.solver.iterations: must be between 1"),
    ("[collisions.solver]\ncorrection = \"magic\"", "collisions.solver.correction: must be one of soft"),
    ("[collisions.solver]\nbaumgarte = 2.0", "collisions.solver.baumgarte: must be in (0, 1]"),
    ("[collisions.solver]\nsweeps = 3", "collisions.solver: unknown key 'sweeps'"),
])
def test_bad_scene_settings(extra, message):
    with pytest.raises(SceneError) as err:
        parse_scene(SCENE.format(extra=extra), "s.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_cli_runs_the_solver_and_refuses_bad_input(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(SCENE.format(extra="[collisions.solver]\nsubsteps = 2"))

    def run(*extra):
        code = main(["run", str(path), *extra])
        out, err = capsys.readouterr()
        return code, out, err

    code, out, _ = run()
    assert code == 0 and "contact solver, 2 substeps x 1 iteration," in out
    for extra, message in [(("--method", "event", "--iterations", "3"), "add --method solver"),
                           (("--integrator", "rk4"), "integrates with semi-implicit-euler")]:
        code, _, err = run(*extra)
        assert code == 2 and message in err and err.count("\n") == 1


@pytest.mark.parametrize("mu", [0.1, 0.6])
def test_ball_on_an_oriented_ramp_slides_by_coulomb(mu):
    # a (spinless) ball on a ramp tilted 20 degrees: it slides at g (sin - mu cos) while
    # mu < tan 20 deg = 0.364, and static friction holds it at rest above that
    from steplab.physics.collision import OrientedBox, rotation_matrix

    angle = np.radians(20.0)
    ramp = OrientedBox(np.zeros(3), np.array([5.0, 5.0, 0.5]), rotation_matrix([0, 1, 0], 20.0))
    up = ramp.to_world_vector(np.array([0.0, 0.0, 1.0]))
    down = np.array([0.0, 0.0, -1.0]) - up * -up[2]  # gravity's direction along the slope
    down /= np.linalg.norm(down)
    model = Model(np.array([1.0]), np.array([0.1]), [Gravity()])
    y0 = np.stack([(up * (0.5 + 0.1))[None], np.zeros((1, 3))])
    dt, n = 1 / 60, 60
    traj = simulate(model, SIE, y0, 0.0, dt=dt, n_steps=n, collisions=solver_world([ramp], 0.0, mu))
    v = traj.y[-1][1, 0]
    expected = max(9.81 * (np.sin(angle) - mu * np.cos(angle)), 0.0) * n * dt
    np.testing.assert_allclose(v @ down, expected, rtol=1e-6, atol=1e-9)
    assert abs(v @ up) < 1e-9  # it stays on the surface


def test_contacts_are_the_narrow_phases_in_key_order():
    # The compiled pass (body pairs and planes) and the shapes' narrow phase, against a brute
    # force over every swept sphere and the narrow phase's functions, contact by contact.
    from steplab.physics.collision import OrientedBox, rotation_matrix
    from steplab.physics.collision.contact_buffer import BodyState, Materials, find_contacts
    from steplab.physics.collision.narrow_phase import collide, collide_sphere_sphere
    from steplab.physics.collision.shapes import Sphere

    rng = np.random.default_rng(11)
    n, dt, margin = 80, 0.05, 0.02
    q, v = rng.uniform(-1.0, 1.0, (n, 3)), rng.normal(0.0, 2.0, (n, 3))
    a = np.tile([0.0, 0.0, -9.81], (n, 1))
    radii, inverse_masses = rng.uniform(0.05, 0.2, n), rng.uniform(0.5, 2.0, n)
    inverse_masses[:3] = 0.0  # pinned: pairs of two pinned bodies, and their shape contacts, are left out
    shapes = (Plane(np.array([0.0, 0.0, 1.0]), -0.9), Box(np.array([-0.3, -0.3, -0.3]), np.array([0.2, 0.3, 0.1])),
              Plane(np.array([-0.6, 0.0, 0.8]), 0.5),
              OrientedBox(np.array([0.6, 0.5, 0.0]), np.array([0.3, 0.2, 0.1]), rotation_matrix([1, 1, 0], 30.0)))
    world = CollisionWorld(shapes=shapes, pair_properties=PairProperties(0.7, 0.3), method="solver")
    q1 = q + dt * (v + dt * a)
    c = find_contacts(world, Materials.of(world, n), BodyState(q, v, a, radii, inverse_masses), q1, margin=margin)
    centre, reach = 0.5 * (q + q1), radii + 0.5 * np.linalg.norm(q1 - q, axis=1) + margin
    expected = []  # (key, normal, separation, approach speed) in key order
    stride = n + len(shapes)
    for i in range(n):
        for j in range(i + 1, n):
            if np.linalg.norm(centre[i] - centre[j]) <= reach[i] + reach[j] and inverse_masses[[i, j]].any():
                hit = collide_sphere_sphere(Sphere(q[i], radii[i]), Sphere(q[j], radii[j]))
                expected.append((i * stride + j, hit.normal, -hit.penetration_depth, (v[j] - v[i]) @ hit.normal))
        for k, shape in enumerate(shapes):
            if inverse_masses[i] == 0:
                continue
            if isinstance(shape, Plane):
                near = centre[i] @ shape.normal - shape.offset <= reach[i]
            else:  # the swept sphere reaches the shape's bounding box
                lo, hi = shape.bounds()
                near = np.linalg.norm(np.clip(centre[i], lo, hi) - centre[i]) <= reach[i]
            if near:
                hit = collide(Sphere(q[i], radii[i]), shape)
                expected.append((i * stride + n + k, hit.normal, -hit.penetration_depth, -v[i] @ hit.normal))
    assert c.key.tolist() == [e[0] for e in expected]
    assert {"box", "oriented-box"} <= {shapes[k].kind for k in c.shape[c.shape >= 0]}  # every kind was tested
    np.testing.assert_allclose(c.normal, [e[1] for e in expected], rtol=0, atol=1e-12)
    np.testing.assert_allclose(c.separation, [e[2] for e in expected], rtol=0, atol=1e-12)
    np.testing.assert_allclose(c.normal_speed, [e[3] for e in expected], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(c.mass, 1.0 / (inverse_masses[c.i] + np.where(c.j >= 0, inverse_masses[c.j], 0.0)))
    assert np.all(c.restitution == 0.7) and np.all(c.friction == 0.3)


def test_kernels_are_loaded_before_a_run_starts():
    # In a fresh process: building the solver's step loads every kernel its step calls, so a
    # run's wall time holds no Numba cache loads (the first step at 10^4 balls was 4x the others)
    import subprocess
    import sys

    code = """
import numpy as np
from steplab.integrators import get_integrator
from steplab.physics import Gravity, Model
from steplab.physics.broadphase import cells
from steplab.physics.collision import CollisionWorld, Plane, contact_buffer, sequential_impulses
kernels = (cells._column_grid, contact_buffer._pair_and_plane_contacts, contact_buffer.previous_rows,
           contact_buffer.warm_start, contact_buffer.newly_hit, sequential_impulses.step_members)
assert not any(k.signatures for k in kernels)
world = CollisionWorld(shapes=(Plane(np.array([0.0, 0.0, 1.0])),), method="solver")
world.stepper(Model(np.ones(3), np.full(3, 0.1), [Gravity()]), get_integrator("semi-implicit-euler"))
print([k.__name__ for k in kernels if not k.signatures])
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"
