"""pbd and xpbd: the springs as distance constraints, against closed forms and implicit Euler."""

from __future__ import annotations

import json
import math
import sys
import warnings

import numpy as np
import pytest
from helpers import oscillator, spring_net
from steplab.integrators import PBD, XPBD, get_integrator, simulate
from steplab.integrators.settings import scene_integrator
from steplab.physics import Drag, Gravity, Model, Springs
from steplab.physics.constraints import InextensibleSpringError, NotConstraintsError
from steplab.physics.scene import load_scene, parse_scene
from steplab.physics.scene_library import SCENES

from steplab.cli import main

CLOTH = load_scene("cloth")


def measured_period(traj) -> float:
    """Mean time between successive downward crossings of the spring's rest length (linear interpolation)."""
    s = np.linalg.norm(traj.positions[:, 1] - traj.positions[:, 0], axis=1) - 1.0
    k = np.flatnonzero((s[:-1] > 0) & (s[1:] <= 0))
    crossings = traj.t[k] + s[k] / (s[k] - s[k + 1]) * traj.dt
    return float(np.mean(np.diff(crossings)))


@pytest.mark.parametrize("settings", [dict(substeps=1, iterations=4), dict(substeps=4, iterations=1)])
def test_xpbd_period_tends_to_the_spring_period_and_pbd_does_not(settings):
    # k = 4 pi^2 N/m, m = 1 kg: the period is exactly 1 s
    p = oscillator(amplitude=0.2)
    errors = {}
    for method in (XPBD(**settings), PBD(**settings)):
        errors[method.name] = [abs(measured_period(simulate(p.model, method, p.y0, 0.0, 3.5, dt)) - 1.0)
                               for dt in (1e-2, 1e-3)]
    assert errors["xpbd"][1] < 0.01 and errors["xpbd"][1] < errors["xpbd"][0]
    if settings["iterations"] > 1:  # pbd's spring is about n times stiffer: period 1 / sqrt(n)
        assert min(errors["pbd"]) > 0.4
    else:  # one iteration: pbd's one projection is xpbd's, the same step
        assert errors["pbd"] == errors["xpbd"]


def implicit_euler_map(h, zeta):
    """Implicit Euler on u'' = -u - 2 zeta u': x1 - h v1 = x, h x1 + (1 + 2 zeta h) v1 = v."""
    return np.linalg.inv(np.array([[1.0, -h], [h, 1.0 + 2.0 * zeta * h]]))


@pytest.mark.parametrize("zeta", [0.0, 0.3])
@pytest.mark.parametrize("omega_dt", [0.1, 1.0, 5.0])
def test_xpbd_substep_is_implicit_euler_with_its_damper(omega_dt, zeta):
    # one linear constraint converges in one iteration, to implicit Euler on the spring and,
    # with gamma = alpha beta / h (Macklin 2016 eq. 26), on the damper beside it
    for substeps, iterations in ((1, 1), (4, 3)):
        expected = np.linalg.matrix_power(implicit_euler_map(omega_dt / substeps, zeta), substeps)
        np.testing.assert_allclose(XPBD(substeps, iterations).linear_map(omega_dt, zeta), expected,
                                   rtol=0, atol=1e-12)
    assert XPBD().stability_limit() is None


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("method", [XPBD(1, 1), XPBD(4, 1), XPBD(1, 10)])
def test_undamped_xpbd_never_gains_energy(seed, method):
    # the energy is kinetic plus the constraints' potential C^2 / (2 alpha) = k C^2 / 2 (the
    # springs' potential): XPBD, implicit Euler on it, may only dissipate it
    model, y0 = spring_net(seed)
    traj = simulate(model, method, y0, 0.0, n_steps=10_000, dt=1e-2)
    energy = np.array([model.energy(y) for y in traj.y])
    assert energy.max() <= energy[0] * (1 + 1e-12)
    assert energy[-1] < 0.9 * energy[0]  # and it does dissipate: the check sees the energy move


def test_xpbd_conserves_linear_momentum_to_round_off():
    # every projection moves its pair by equal and opposite impulses, m_i w_i dlambda = dlambda
    model, y0 = spring_net(4)
    traj = simulate(model, XPBD(2, 5), y0, 0.0, n_steps=1000, dt=1e-2)
    momentum = np.einsum("n,knd->kd", np.asarray(model.masses), traj.velocities)
    scale = float(np.sum(np.asarray(model.masses)[:, None] * np.abs(y0[1])))
    assert np.abs(momentum - momentum[0]).max() < 1e-12 * scale


def hanging_chain(links=10, length=0.1):
    """A chain of inextensible links pinned at one end, released horizontal under gravity."""
    n = links + 1
    q = np.zeros((n, 3))
    q[:, 0] = length * np.arange(n)
    i = np.arange(links)
    springs = Springs(i, i + 1, np.full(links, np.inf), np.full(links, length))
    model = Model(np.full(n, 0.1), np.full(n, 0.01), [springs, Gravity()], pinned=np.arange(n) == 0)
    return model, np.stack([q, np.zeros_like(q)])


@pytest.mark.parametrize("name", ["pbd", "xpbd"])
def test_inextensible_chain_holds_its_lengths(name):
    model, y0 = hanging_chain()
    traj = simulate(model, type(get_integrator(name))(substeps=10, iterations=10), y0, 0.0, n_steps=1000, dt=1e-3)
    q = traj.positions
    stretch = np.abs(np.linalg.norm(q[:, 1:] - q[:, :-1], axis=2) - 0.1)
    assert stretch.max() < 1e-6
    assert np.ptp(q[:, -1, 2]) > 0.5  # it swung down, the constraints were not idle
    assert np.isfinite(model.energy(traj.y[-1]))  # an enforced constraint's potential counts 0


def test_an_inextensible_spring_is_refused_by_force_based_methods():
    model, y0 = hanging_chain()
    # implicit Euler's conjugate gradients build their forces without model.acceleration, and
    # implicit-damping Euler asks for the Jacobian first: each is refused all the same, before any inf * 0
    cg = type(get_integrator("implicit-euler"))(linear_solver="cg")
    for name in ("semi-implicit-euler", "rk4", "implicit-euler", cg, "implicit-damping-euler"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no RuntimeWarning of an inf * 0 on the way to the refusal
            with pytest.raises(InextensibleSpringError, match="only the position-based integrators"):
                simulate(model, name, y0, 0.0, n_steps=1, dt=1e-3)


def test_the_cloth_runs_under_xpbd_from_its_scene_settings():
    text = (SCENES["cloth"].read_text()
            .replace('integrator = "semi-implicit-euler"', 'integrator = "xpbd"')
            + "\n[simulation.xpbd]\nsubsteps = 4\niterations = 1\n")
    scene = parse_scene(text)
    method = scene_integrator(scene)
    assert method == XPBD(substeps=4, iterations=1)
    assert scene_integrator(scene, "pbd") == PBD()  # another method: its own defaults
    traj = simulate(scene.model, method, scene.y0, 0.0, 0.5, scene.dt)
    c = scene.model.distance_constraints()
    assert len(c.i) == len(CLOTH.model.forces[0].i) and np.all(c.damping == 0.05)
    q = traj.positions[-1]
    assert np.all(q[[0, 11]] == scene.y0[0, [0, 11]])  # pinned corners
    assert q[:, 2].min() < scene.y0[0, :, 2].min() - 0.01  # it fell
    stretch = np.linalg.norm(q[c.j] - q[c.i], axis=1) / c.rest_length - 1
    assert np.abs(stretch).max() < 0.5  # a cloth, not a spaghetti


def run(capsys, *argv):
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def cloth_file(tmp_path, replace=(), extra=""):
    text = SCENES["cloth"].read_text()
    for old, new in replace:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "c.toml"
    path.write_text(text + extra)
    return str(path)


@pytest.mark.parametrize("replace,extra,argv,message", [
    ([("stiffness = 100.0", "stiffness = -100.0")], "", ["--integrator", "xpbd"], "stiffness: must be > 0"),
    ([("stiffness = 100.0", "stiffness = inf")], "", ["--integrator", "semi-implicit-euler"],
     "only the position-based integrators (pbd, xpbd) can step them"),
    ([], "[forces.drag]\n", ["--integrator", "xpbd"], "this model also has 'drag'"),
    ([], "", ["--integrator", "vbd", "--backend", "jax"], "vbd runs on the NumPy backend only"),
    ([], "", ["--integrator", "xpbd", "--substeps", "0"], "--substeps: must be a positive integer, got 0"),
    ([], "", ["--integrator", "pbd", "--iterations", "-3"], "--iterations: must be a positive integer, got -3"),
    ([], "", ["--integrator", "semi-implicit-euler", "--substeps", "2"],
     "set a position-based integrator's sweeps (pbd, xpbd, vbd) or the contact solver"),
])
def test_bad_input_is_one_line_status_2(capsys, tmp_path, replace, extra, argv, message):
    path = cloth_file(tmp_path, replace, "\n" + extra)
    with pytest.raises(SystemExit) as exit_:
        sys.exit(main(["run", path, "--t-end", "0.01", *argv]))
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("name,settings,message", [
    ("xpbd", "substeps = 0", "xpbd: substeps must be a whole number >= 1, got 0"),
    ("pbd", "iterations = -2", "pbd: iterations must be a whole number >= 1, got -2"),
    ("xpbd", "substeps = 1.5", "xpbd: substeps must be a whole number >= 1, got 1.5"),
    ("xpbd", "sweeps = 2", "'sweeps' is not a setting of xpbd (its settings: iterations, substeps)"),
])
def test_bad_scene_settings_are_one_line(tmp_path, name, settings, message):
    path = cloth_file(tmp_path, [('"semi-implicit-euler"', f'"{name}"')], f"\n[simulation.{name}]\n{settings}\n")
    with pytest.raises(ValueError) as err:
        scene_integrator(load_scene(path))
    assert str(err.value) == f"scene c: [simulation.{name}]: {message}"


def test_an_inextensible_cloth_runs_at_the_command_line(capsys, tmp_path):
    path = cloth_file(tmp_path, [("stiffness = 100.0", "stiffness = inf")])
    status, out, err = run(capsys, "run", path, "--integrator", "xpbd", "--t-end", "0.1", "--json")
    assert status == 0, err
    summary = json.loads(out)
    assert summary["integrator"] == "xpbd" and math.isfinite(summary["energy_end"])
    assert summary["energy_end"] < summary["energy_start"]  # gravity's work, partly dissipated


def test_bad_settings_and_forces_in_python_are_one_line():
    with pytest.raises(ValueError, match="substeps must be a whole number >= 1, got 0"):
        XPBD(substeps=0)
    with pytest.raises(ValueError, match="iterations must be a whole number >= 1, got True"):
        PBD(iterations=True)
    p = oscillator()
    with pytest.raises(ValueError, match="Springs: stiffness must be >= 0, got -1"):  # refused where it is built
        Springs(np.array([0]), np.array([1]), np.array([-1.0]), np.array([1.0]))
    dragged = Model([1.0, 1.0], [0.05, 0.05], [*p.model.forces, Drag(np.array([0.0, 0.5]))], pinned=[True, False])
    with pytest.raises(NotConstraintsError, match="this model also has 'drag'"):
        simulate(dragged, "xpbd", p.y0, 0.0, n_steps=1, dt=1e-3)


def test_the_same_inputs_give_the_same_bytes():
    model, y0 = spring_net(3)
    a, b = (simulate(model, XPBD(2, 3), y0, 0.0, n_steps=200, dt=1e-2).y for _ in range(2))
    assert a.tobytes() == b.tobytes()
    assert math.isfinite(float(a.sum()))


def test_steplab_run_applies_the_scenes_integrator_settings(tmp_path, capsys):
    """``[simulation.xpbd] substeps = 4, iterations = 1`` reaches ``steplab run``: its final state is
    XPBD(4, 1)'s, not the defaults'; ``--integrator pbd`` takes pbd's own defaults instead."""
    path = cloth_file(tmp_path, [('integrator = "semi-implicit-euler"', 'integrator = "xpbd"')],
                      "\n[simulation.xpbd]\nsubsteps = 4\niterations = 1\n")
    scene = parse_scene((tmp_path / "c.toml").read_text())
    finals = {}
    for argv, method in ((["--steps", "50"], XPBD(substeps=4, iterations=1)),
                         (["--steps", "50", "--integrator", "pbd"], PBD())):
        status, out, _ = run(capsys, "run", path, "--json", *argv)
        assert status == 0
        expected = simulate(scene.model, method, scene.y0, 0.0, n_steps=50, dt=scene.dt).positions[-1]
        finals[method] = np.array(json.loads(out)["final_positions"])
        assert np.array_equal(finals[method], expected)
    default = simulate(scene.model, XPBD(), scene.y0, 0.0, n_steps=50, dt=scene.dt).positions[-1]
    assert not np.array_equal(finals[XPBD(substeps=4, iterations=1)], default)


def test_steplab_run_takes_substeps_and_iterations_for_a_position_based_method(tmp_path, capsys):
    """``--substeps 4 --iterations 1`` beat the scene's [simulation.xpbd] table: XPBD(4, 1)'s final state."""
    path = cloth_file(tmp_path, [('integrator = "semi-implicit-euler"', 'integrator = "xpbd"')],
                      "\n[simulation.xpbd]\nsubsteps = 2\niterations = 7\n")
    status, out, err = run(capsys, "run", path, "--json", "--steps", "30", "--substeps", "4", "--iterations", "1")
    assert status == 0, err
    expected = simulate(CLOTH.model, XPBD(substeps=4, iterations=1), CLOTH.y0, 0.0, n_steps=30, dt=CLOTH.dt)
    assert np.array_equal(np.array(json.loads(out)["final_positions"]), expected.positions[-1])


def test_check_says_a_position_based_method_has_no_dt_limit(capsys):
    status, out, err = run(capsys, "check", "cloth", "--integrator", "xpbd")
    assert status == 0 and err == "" and "stable at every dt" in out
    assert XPBD().stability_limit() is None  # what the line says is the class's theory


def test_the_benchmark_step_is_the_integrators_step_in_place():
    from steplab.integrators.colouring import greedy_edge_colouring
    from steplab.integrators.constraint_projection import LANES
    from steplab.integrators.position_based import cloth_benchmark_step
    from steplab.physics.soft_body import grid

    from steplab.bench.systems import cloth_model

    assert len(grid(160, 160, 1 / 160).edges) == 101_442  # the cloth: 25,600 particles
    model, y0, springs = cloth_model(20)
    for method in (XPBD(1, 1), PBD(3, 2)):
        step = cloth_benchmark_step(model, y0, 5e-4, method)
        step.advance(7)
        expected = simulate(model, method, y0, 0.0, n_steps=7, dt=5e-4).y[-1]
        assert step.y.tobytes() == expected.tobytes() and not np.array_equal(step.y, y0)
    # the state read and written; read: 2 uint32 indices and 3 coefficients (rest length, gamma, the
    # denominator) per constraint, the start of each segment (a colour within a band), 1/m and a_ext per body
    segments = len(XPBD(1, 1).init(model, 0.0, y0).segments)
    assert greedy_edge_colouring(400, *model.distance_constraints()[:2]).max() + 1 <= segments - 1
    assert step.bytes_read_and_written == 2 * 400 * 3 * 8
    blocks = sum(np.diff(XPBD(1, 1).init(model, 0.0, y0).segments) // LANES)  # a byte each: its kind
    assert step.bytes_read == springs * (2 * 4 + 3 * 8) + segments * 8 + blocks + 400 * 8 + 400 * 3 * 8
    # the bench's tighter bound reads the arrays counted above (their sum as integers, wrapping) and writes
    # the state back unchanged
    carry = PBD(3, 2).init(model, 0.0, y0).for_substep(PBD(3, 2).substeps_of(5e-4).h)
    sweep = carry.sweep._replace(alpha_tilde=np.empty(0))  # read only where the multipliers are carried
    before = step.state.copy()
    assert step.stream() == integer_sum([carry.external[:, :400], carry.inverse_mass, *sweep])
    assert step.state.tobytes() == before.tobytes()


def integer_sum(arrays) -> int:
    """The arrays' values summed as unsigned integers modulo 2^64: 8-byte values as their bit patterns."""
    total = 0
    for a in map(np.ascontiguousarray, arrays):
        total += int((a.view(np.uint64) if a.itemsize == 8 else a).sum(dtype=np.uint64))
    return total % 2**64


def test_the_benchmark_steps_table_points_at_the_carry_with_multipliers_carried():
    # the bench's step calls the kernel on one table of addresses (position_based_entry): with the
    # multipliers carried (xpbd, several iterations) it is still simulate's step to the byte; arrays
    # the kernel is not compiled for are refused in one line
    from steplab.integrators.constraint_projection import workspace
    from steplab.integrators.position_based import cloth_benchmark_step
    from steplab.integrators.position_based_entry import stream_at, table

    from steplab.bench.systems import cloth_model

    model, y0, _ = cloth_model(20)
    method = XPBD(2, 3)
    step = cloth_benchmark_step(model, y0, 5e-4, method)
    step.advance(5)
    expected = simulate(model, method, y0, 0.0, n_steps=5, dt=5e-4).y[-1]
    assert step.y.tobytes() == expected.tobytes() and not np.array_equal(step.y, y0)
    carry = method.init(model, 0.0, y0).for_substep(2.5e-4)
    steps = method.substeps_of(5e-4)
    # carried, the multipliers' alpha_tilde is read: counted, and read by the tighter bound's pass, which
    # writes each coordinate row of q and v over its N bodies and leaves the rows' padding alone
    assert step.bytes_read == sum(a.nbytes for a in carry.sweep) + 400 * 8 + 400 * 3 * 8
    t = table(carry.external, carry.inverse_mass, carry.sweep, steps, carry.work)
    carry.work.state[...] = np.random.default_rng(0).normal(size=carry.work.state.shape)  # padding included
    state = carry.work.state.copy()
    assert stream_at(t, 2.0) == integer_sum([carry.external[:, :400], carry.inverse_mass, *carry.sweep])
    assert np.array_equal(carry.work.state[..., :400], 2.0 * state[..., :400])
    assert np.array_equal(carry.work.state[..., 400:], state[..., 400:])
    with pytest.raises(ValueError, match="^advance_at: inverse_mass must be C-contiguous float64, got float32$"):
        table(carry.external, carry.inverse_mass.astype(np.float32), carry.sweep, steps, carry.work)
    with pytest.raises(ValueError, match="do not fit 400 bodies"):
        table(carry.external, carry.inverse_mass, carry.sweep, steps, workspace(380, len(carry.sweep.i)))


def sequential_sweep(dx, x_prev, inverse_mass, c, h, iterations, carried):
    """Macklin et al.'s projection (eq. 18 with eq. 26's damping), one constraint after another in
    the order of ``c``, in plain Python: the sequential Gauss-Seidel sweep, written independently."""
    lam = np.zeros(len(c.i))
    for _ in range(iterations):
        for p in range(len(c.i)):
            a, b = c.i[p], c.j[p]
            w = inverse_mass[a] + inverse_mass[b]
            u = [dx[b, k] - dx[a, k] for k in range(3)]
            d = [x_prev[b, k] - x_prev[a, k] + u[k] for k in range(3)]
            squared = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            if w == 0.0 or squared == 0.0:
                continue
            length = np.sqrt(squared)
            alpha_tilde = c.compliance[p] * ((1.0 / h) * (1.0 / h))
            gamma = c.compliance[p] * c.damping[p] * (1.0 / h)
            rest = c.rest_length[p] - length - (alpha_tilde * lam[p] if carried else 0.0)
            s = (rest * length - gamma * (d[0] * u[0] + d[1] * u[1] + d[2] * u[2])) / (
                ((1.0 + gamma) * w + alpha_tilde) * squared)
            lam[p] += s * length
            for k in range(3):
                dx[a, k] -= inverse_mass[a] * s * d[k]
                dx[b, k] += inverse_mass[b] * s * d[k]


def damped_cloth_net(seed):
    """:func:`spring_net` (40 bodies, 120 springs) with dampers on every spring, gravity and two pinned bodies."""
    from steplab.physics import Dampers

    model, y0 = spring_net(seed, n=40, p=120)
    springs = model.forces[0]
    dampers = Dampers(springs.i, springs.j, np.full(len(springs.i), 0.3))
    pinned = np.isin(np.arange(40), [0, 1])
    y0[1, pinned] = 0.0
    return Model(model.masses, model.radii, [springs, dampers, Gravity()], pinned=pinned), y0


@pytest.mark.parametrize("iterations", [1, 4])
def test_the_sweep_by_colour_is_the_sequential_gauss_seidel_sweep(iterations):
    # the kernel gathers a colour, solves its projections together and scatters them: exact only
    # because no two constraints of a colour share a body; a plain sequential loop gives the same bytes
    from steplab.integrators.constraint_projection import bodies, coordinates, project

    model, y = damped_cloth_net(3)
    h = 2e-3
    method = XPBD(1, iterations)
    carry = method.init(model, 0.0, None).for_substep(h)
    steps = method.substeps_of(h)
    assert len(carry.segments) > 3  # several colours: the order between them matters
    (q, v), a_ext = carry.in_rows(y)
    expected = h * (v + h * a_ext)
    dx = coordinates(expected)
    sequential_sweep(expected, q, carry.inverse_mass, carry.constraints, h, iterations, steps.carried)
    project(dx, coordinates(q), carry.inverse_mass, carry.sweep, iterations, steps.carried, carry.work)
    n = len(q)
    assert np.ascontiguousarray(bodies(dx, n)).tobytes() == expected.tobytes() and not dx[:, n:].any()
    assert np.abs(expected - h * (v + h * a_ext)).max() > 1e-4  # the sweep moved the bodies


@pytest.mark.parametrize(("band", "iterations"), [(64, 1), (256, 1), (256, 3)])
def test_the_sweep_in_bands_is_the_sweep_colour_by_colour(band, iterations):
    # the wavefront reorders the constraints across colours, band by band, keeping each body's
    # projections in colour order: the bytes of the plain colour-by-colour sequential sweep; the
    # kernel projects eight constraints of a segment at once (projection_block), the rest one by one,
    # with the multipliers carried or held at 0
    from steplab.integrators.constraint_projection import (
        EQUAL_MASSES,
        LANES,
        RUN,
        advance,
        bodies,
        coordinates,
        ordered,
        project,
        sweep_columns,
        wavefront,
        workspace,
    )

    from steplab.bench.systems import cloth_model

    model, (q, v), _ = cloth_model(40)  # 1,600 bodies, 6,162 springs with dampers, reach 41, 8 colours
    h, method = 1 / 600, XPBD(1, iterations)
    c, external, inverse_mass = method.constraints(model)
    c, colours = ordered(c, model.n_bodies)
    banded, segments = wavefront(c, colours, band)
    pair = lambda constraints: constraints.i.astype(np.int64) * model.n_bodies + constraints.j
    by_pair = np.argsort(pair(c))
    where = by_pair[np.searchsorted(pair(c)[by_pair], pair(banded))]  # each banded constraint's place in c
    assert np.array_equal(np.sort(where), np.arange(len(c.i)))  # the same constraints, ...
    colour = np.repeat(np.arange(len(colours) - 1), np.diff(colours))
    assert np.diff(colour[where]).min() < 0  # ... the colours starting over in each band
    expected = h * (v + h * external)
    dx = coordinates(expected)
    carried = method.substeps_of(h).carried
    sequential_sweep(expected, q, inverse_mass, c, h, iterations, carried)
    sweep, work = sweep_columns(banded, segments, inverse_mass, h), workspace(model.n_bodies, len(c.i))
    assert np.diff(segments).mean() >= 2 * LANES  # mostly blocks, and a tail in most segments
    kinds = sweep.kinds
    assert set(np.unique(kinds % EQUAL_MASSES)) == {0, RUN}  # blocks read each way (in the grid numbering),
    assert 0 < np.count_nonzero(kinds & EQUAL_MASSES) < len(kinds)  # with equal masses and not (pinned)
    project(dx, coordinates(q), inverse_mass, sweep, iterations, carried, work)
    n = model.n_bodies
    assert np.ascontiguousarray(bodies(dx, n)).tobytes() == expected.tobytes()
    y = work.state  # and the whole step, on the coordinate rows of q, v
    bodies(y, n)[...] = q, v
    advance(y[0], y[1], coordinates(external), inverse_mass, sweep, method.substeps_of(h), work)
    assert np.ascontiguousarray(bodies(y, n)).tobytes() == np.stack([q + expected, expected / h]).tobytes()
    assert not y[..., n:].any()


def plain_kinds(i, j, segments, lanes, mass=None):
    """Each block's layout written out (the blocks of a segment from its start, lanes at a time): 1 where in each
    half of the lanes both ends advance by 1 from lane to lane, else 0; plus 4 where ``mass`` is given and equal
    at both ends in every lane."""
    out, half = [], lanes // 2
    for lo, hi in zip(segments[:-1], segments[1:]):
        for k in range(lo, hi - lanes + 1, lanes):
            run = all(int(i[k + n]) - int(i[k + n // half * half]) == n % half
                      == int(j[k + n]) - int(j[k + n // half * half]) for n in range(lanes))
            equal = mass is not None and all(mass[i[k + n]] == mass[j[k + n]] for n in range(lanes))
            out.append(int(run) + (4 if equal else 0))
    return out


def test_the_block_kinds_are_the_runs_of_bodies_and_equal_masses():
    # a block is read as a run only where in each half of its lanes both ends' bodies advance by 1 from lane
    # to lane (the two halves anywhere); anything else (another stride, runs by 2 as a grid's row gives them
    # before integrators/arrangement.py lays the row out, a broken run, different strides at the two ends)
    # is read by index; its two ends move by one product only where their inverse masses are equal in
    # every lane
    from steplab.integrators.constraint_projection import EQUAL_MASSES, LANES, RUN, block_kinds, layouts

    assert (RUN, EQUAL_MASSES) == (1, 4)  # as plain_kinds writes them
    rng = np.random.default_rng(5)
    run = lambda start, s: start + s * np.arange(LANES)
    i = np.concatenate([run(0, 1), run(40, 2), run(100, 3), run(200, 1), rng.permutation(50)[:LANES],
                        run(300, 1), run(500, 2), run(600, 1), [7, 9, 11]]).astype(np.uint32)
    j = np.concatenate([run(20, 1), run(41, 2), run(120, 3), run(260, 2), rng.permutation(50)[:LANES] + 60,
                        run(310, 1), run(540, 2), run(700, 1), [8, 10, 12]]).astype(np.uint32)
    j[5 * LANES + 3] += 1  # a broken run at j
    segments = np.array([0, 2 * LANES, 5 * LANES, 8 * LANES + 3], np.int64)
    got = layouts(i, j, segments)
    assert got.dtype == np.uint8 and list(got) == [RUN, 0, 0, 0, 0, 0, 0, RUN]
    assert list(got) == plain_kinds(i, j, segments, LANES)
    halves = np.concatenate([800 + np.arange(LANES // 2), 900 + np.arange(LANES // 2)])  # two runs of four
    for broken, kind in ((None, RUN), (LANES - 1, 0)):
        i, j = halves.astype(np.uint32), (halves + 20).astype(np.uint32)
        if broken is not None:
            j[broken] += 1
        assert list(layouts(i, j, np.array([0, LANES], np.int64))) == [kind]
    # random segments of a random order, with some unequal masses: the same as written out
    for seed in range(5):
        r = np.random.default_rng(seed)
        p = int(r.integers(0, 200))
        i = (np.cumsum(r.integers(1, 3, p)) * r.integers(1, 3)).astype(np.uint32)  # runs of 1s and 2s
        j = (i + r.choice([1, 2, 20])).astype(np.uint32)
        segments = np.unique(np.concatenate([[0, p], r.integers(0, p + 1, 6)])).astype(np.int64)
        assert list(layouts(i, j, segments)) == plain_kinds(i, j, segments, LANES)
        mass = r.choice([0.0, 0.5, 1.0], size=int(j.max(initial=0)) + 1, p=[0.05, 0.05, 0.9])
        assert list(block_kinds(i, j, mass, segments)) == plain_kinds(i, j, segments, LANES, mass)


@pytest.mark.parametrize("iterations", [1, 3])
def test_the_vector_block_is_its_python_twin(monkeypatch, iterations):
    # the compiled sweep projects eight constraints of a segment in LLVM vector lanes
    # (projection_block); interpreted, the same sweep runs the block's plain-Python twin, the
    # projections one after another: the same bytes, on segments long enough for many blocks
    from steplab.integrators import constraint_projection
    from steplab.integrators.constraint_projection import LANES, bodies, coordinates, project

    from steplab.bench.systems import cloth_model

    model, y, _ = cloth_model(20)
    h, method = 1 / 600, XPBD(1, iterations)
    carry = method.init(model, 0.0, None).for_substep(h)
    assert np.diff(carry.segments).mean() >= 3 * LANES
    (q, v), a_ext = carry.in_rows(y)
    runs = []
    for kernel in (project, project.py_func):
        dx = coordinates(h * (v + h * a_ext))
        with monkeypatch.context() as patch:
            if kernel is project.py_func:
                patch.setattr(constraint_projection, "_segment", constraint_projection._segment.py_func)
            kernel(dx, coordinates(q), carry.inverse_mass, carry.sweep, iterations, iterations > 1, carry.work)
        runs.append(dx)
    assert runs[0].tobytes() == runs[1].tobytes()
    assert np.abs(bodies(runs[0], len(q)) - h * (v + h * a_ext)).max() > 1e-5  # the sweep moved the bodies


@pytest.mark.parametrize("method", [XPBD(1, 1), XPBD(3, 3), PBD(1, 4)], ids=["xpbd-1x1", "xpbd-3x3", "pbd-1x4"])
def test_the_jax_path_is_the_numba_sweep(method):
    # the same Gauss-Seidel sweep in the same colour order, traced: equal to round-off (XLA may fuse
    # a multiply and an add), on a damped net with pinned bodies
    model, y0 = damped_cloth_net(5)
    runs = [simulate(model, method, y0, 0.0, n_steps=30, dt=2e-3, backend=backend).y for backend in ("numpy", "jax")]
    scale = np.abs(runs[0]).max()
    assert np.abs(runs[1] - runs[0]).max() <= 1e-12 * scale
    assert np.abs(runs[0][-1] - y0).max() > 1e-2 * scale  # the run went somewhere


def test_both_sweeps_evaluate_the_one_projection():
    # the projection and its per-substep factors are written once (projection_law): the Numba
    # sweep compiles them (its scalar step) and evaluates them on vector lanes (its block), the JAX
    # path evaluates them on a colour's columns
    import ast
    import inspect

    from steplab.integrators import (
        constraint_projection,
        constraint_projection_jax,
        projection_block,
        projection_law,
    )

    for module, names in ((constraint_projection, {"factors"}), (projection_block, {"_projection", "projection"}),
                          (constraint_projection_jax, {"projection", "factors"})):
        tree = ast.parse(inspect.getsource(module))
        used = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
        assert names <= used, module.__name__
    # the law's text appears once, in projection itself
    assert inspect.getsource(projection_law).count("* length - gamma") == 1
    for module in (constraint_projection, constraint_projection_jax, projection_block):
        assert "* length - gamma" not in inspect.getsource(module), module.__name__
    assert projection_law._projection.py_func is projection_law.projection


def test_the_sweeps_prefetch_compiles_to_a_prefetch_that_changes_nothing():
    # the sweep's software prefetch (integrators/prefetch.py): compiled, it is the CPU's prefetch
    # instruction (its plain-Python twin, a no-op, would pass every byte test), and a prefetch past the
    # end of an array, as the sweep's last constraints make, neither faults nor changes a result
    import platform

    from numba import njit
    from steplab.integrators.constraint_projection import PREFETCH_AHEAD
    from steplab.integrators.prefetch import prefetch

    @njit
    def summed_with_prefetch(a, ahead):
        total = 0.0
        for k in range(a.shape[0]):
            prefetch(a, k + ahead)
            total += a[k]
        return total

    a = np.arange(1000.0)
    for ahead in (PREFETCH_AHEAD, 2**22):  # 2**22 elements: 32 MB past the end
        assert summed_with_prefetch(a, ahead) == 499500.0
    assert prefetch(a, 10) is None
    instruction = {"x86_64": "prefetcht0", "AMD64": "prefetcht0", "aarch64": "prfm", "arm64": "prfm"}.get(
        platform.machine())
    if instruction is not None:
        assert instruction in summed_with_prefetch.inspect_asm(summed_with_prefetch.signatures[0])
