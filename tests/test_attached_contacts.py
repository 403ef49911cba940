"""Springs and dampers at body-frame points in the contact solver on rigid bodies (``hung-box``).

The solver rebuilds the lever arms R(q) r at each substep's orientations, takes the centres'
acceleration there, and kicks each body's angular velocity by h I_w^-1 tau before the kernel's
velocity stage adds the gyroscopic term (physics/collision/rigid_solver_step.py). The checks here
are written out from the scene's numbers, not from steplab's forces: the energy, the lever arms and
the equations of motion that scipy's DOP853 solves.
"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import refused, run_main
from steplab.physics.scene import load_scene, parse_scene

SCENE = Path(__file__).resolve().parents[1] / "physics" / "scenes" / "hung-box.toml"
#: hung-box's numbers: the 1 kg box's edges, the corner the spring and the damper pull, the pinned
#: 1 kg anchor, the spring (N/m, m), the damper (N s/m) and gravity (m/s^2)
MASS, EDGES = 1.0, np.array([0.3, 0.2, 0.1])
CORNER = EDGES / 2
ANCHOR, ANCHOR_MASS = np.array([0.0, 0.0, 0.55]), 1.0
STIFFNESS, REST, DAMPING, G = 200.0, 0.5, 2.0, 9.81
#: the box's principal moments about its centre, kg m^2 (its edges along the body axes)
INERTIA = MASS / 12 * np.array([EDGES[1] ** 2 + EDGES[2] ** 2, EDGES[0] ** 2 + EDGES[2] ** 2,
                                EDGES[0] ** 2 + EDGES[1] ** 2])
#: the box's eight corners in its body frame
CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * CORNER


def matrix(q):
    """The rotation matrix of the unit quaternion [w, x, y, z] (written out, not steplab's)."""
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def energy(x, v, q, omega, spin=True):
    """The box's mechanical energy, J, from its centre ``x``, velocity ``v``, orientation ``q`` and world
    angular velocity ``omega``: both bodies' m g z, the centre's 1/2 m v^2, the spin's 1/2 w . I w (w in
    the body frame; left out with ``spin`` False) and the spring's 1/2 k (l - L)^2 with l from the anchor
    to the corner where the box's orientation puts it."""
    rotation = matrix(q)
    length = np.linalg.norm(x + rotation @ CORNER - ANCHOR)
    w = rotation.T @ omega
    return (G * (ANCHOR_MASS * ANCHOR[2] + MASS * x[2]) + 0.5 * MASS * v @ v + 0.5 * STIFFNESS * (length - REST) ** 2
            + (0.5 * w @ (INERTIA * w) if spin else 0.0))


def variant(*replacements):
    """hung-box with its text's (old, new) ``replacements`` made (each found once)."""
    text = SCENE.read_text()
    for old, new in replacements:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return parse_scene(text, "hung-box-variant.toml")


#: the floor 100 m down: the box never reaches it (nor its bounds) in these runs
FAR_FLOOR = ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 1.0]\noffset = -100.0")


def solver_run(scene, dt, t_end, rotation=None, substeps=None):
    """The contact solver's run of ``scene`` (its rotation method, or ``rotation``; its substeps, or
    ``substeps``): (trajectory, RotationTrajectory), the box's rotation at every step."""
    import dataclasses

    from steplab.integrators.scene_rotation import keeping, run_rotation
    from steplab.integrators.simulate import simulate

    world = scene.collisions
    rigid = dataclasses.replace(world.rigid, rotation=rotation or world.rigid.rotation)
    world = dataclasses.replace(world, rigid=rigid, solver=dataclasses.replace(
        world.solver, substeps=substeps or world.solver.substeps))
    kept = []
    traj = simulate(scene.model, "semi-implicit-euler", scene.y0, scene.t_start, t_end, dt,
                    stepper=keeping(world.stepper, kept))
    return traj, run_rotation(scene, traj, kept[0])


def coupled_run(scene, dt, t_end, rotation):
    """The coupled step without collisions (``steplab run --detector none``'s): (trajectory, RotationTrajectory)."""
    from steplab.integrators import get_rotation
    from steplab.integrators.attached import attached_stepper
    from steplab.integrators.scene_rotation import run_rotation
    from steplab.integrators.simulate import simulate

    kept = []
    traj = simulate(scene.model, "semi-implicit-euler", scene.y0, scene.t_start, t_end, dt,
                    stepper=attached_stepper(scene.rigid_bodies, get_rotation(rotation), kept))
    return traj, run_rotation(scene, traj, kept[0])


def box(traj, rotation):
    """The box's (x, v, q, omega) at every saved state (body 1; the rotation's only body)."""
    return traj.positions[:, 1], traj.velocities[:, 1], rotation.orientations[:, 0], rotation.angular_velocities[:, 0]


def test_the_scene_is_the_box_these_tests_write_out():
    scene = load_scene("hung-box")
    np.testing.assert_array_equal(scene.y0[0, 0], ANCHOR)
    corner = scene.y0[0, 1] + matrix(scene.rigid_bodies.orientations[0]) @ CORNER
    np.testing.assert_allclose(corner, ANCHOR + [REST, 0.0, 0.0], atol=1e-15)  # level, at its rest length
    np.testing.assert_allclose(scene.rigid_bodies.inertia[0], INERTIA, rtol=1e-15)
    assert scene.collisions.method == "solver" and scene.collisions.rigid.rotation == "implicit-gyroscopic"
    assert float(scene.model.energy(scene.y0, scene.rigid_bodies)) == pytest.approx(
        energy(scene.y0[0, 1], scene.y0[1, 1], scene.rigid_bodies.orientations[0], np.zeros(3)), rel=1e-15)


def test_without_contact_one_substep_is_the_coupled_step_of_its_stage_order():
    """With the floor out of reach and one substep, the solver's step is the coupled step without
    collisions where their stage orders are the same, and first order apart where they are not.

    The solver kicks omega by h I^-1 tau, then its kernel adds the gyroscopic term to the kicked
    omega: ``implicit-gyroscopic``'s order (torque explicit, then one Newton step), so the two agree
    to round-off over 250 steps of a 3-D tumble. ``exponential-map`` takes the torque and the
    gyroscopic term both at omega: the gyroscopic term at the kicked omega differs by
    h^2 I^-1 (d(omega x I omega)/d omega) I^-1 tau a step, so the runs are O(dt) apart (the
    difference halves with dt), not round-off."""
    scene = variant(FAR_FLOOR)
    t_end = 0.25
    solved, turned = solver_run(scene, 1e-3, t_end, "implicit-gyroscopic", substeps=1)
    assert solved.collisions.summary()["impacts"] == 0
    coupled, coupled_turned = coupled_run(scene, 1e-3, t_end, "implicit-gyroscopic")
    assert np.abs(solved.y - coupled.y).max() < 1e-10  # m, m/s: every step
    np.testing.assert_allclose(turned.orientations, coupled_turned.orientations, rtol=0, atol=1e-10)
    np.testing.assert_allclose(turned.angular_velocities, coupled_turned.angular_velocities, rtol=0, atol=1e-9)
    assert np.abs(turned.angular_velocities[-1]).max() > 1.0  # it turns: the torque is in both
    # each substep takes the forces and the torque at its own orientations: 4 substeps of a 4 ms step are
    # the 1 ms steps' (every fourth state)
    substepped, substepped_turned = solver_run(scene, 4e-3, t_end, "implicit-gyroscopic", substeps=4)
    assert np.abs(substepped.y - coupled.y[::4]).max() < 1e-10
    np.testing.assert_allclose(substepped_turned.angular_velocities, coupled_turned.angular_velocities[::4], rtol=0,
                               atol=1e-9)

    apart = []  # rad/s, the angular velocities' at the end
    for dt in (2e-3, 1e-3):
        _, turned = solver_run(scene, dt, t_end, "exponential-map", substeps=1)
        _, coupled_turned = coupled_run(scene, dt, t_end, "exponential-map")
        apart.append(np.abs(turned.angular_velocities[-1] - coupled_turned.angular_velocities[-1]).max())
    assert apart[1] > 1e-4 and 1.8 < apart[0] / apart[1] < 2.2, apart


def test_without_contact_the_solver_and_the_coupled_step_converge_to_the_equations_at_first_order():
    """Both steps against scipy's DOP853 on the coupled equations written out here: m x'' = m g + F,
    I w' = R^T ((R r) x F) - w x I w (body frame), q' = q (0, w) / 2, F the spring's and the damper's
    force at the corner x + R r (the damper's along the spring, with the corner's velocity
    v + omega x R r). The position error at 0.25 s halves when dt halves."""
    from scipy.integrate import solve_ivp

    scene = variant(FAR_FLOOR)
    t_end = 0.25

    def rates(_, s):
        x, v, q, w = s[:3], s[3:6], s[6:10], s[10:]
        rotation = matrix(q)
        arm = rotation @ CORNER
        d = x + arm - ANCHOR
        u = d / np.linalg.norm(d)
        force = (-STIFFNESS * (np.linalg.norm(d) - REST) * u
                 - DAMPING * np.dot(v + np.cross(rotation @ w, arm), u) * u)
        qw, qv = q[0], q[1:]
        turn = 0.5 * np.concatenate([[-qv @ w], qw * w + np.cross(qv, w)])
        spin = (rotation.T @ np.cross(arm, force) - np.cross(w, INERTIA * w)) / INERTIA
        return np.concatenate([v, force / MASS + [0.0, 0.0, -G], turn, spin])

    start = np.concatenate([scene.y0[0, 1], scene.y0[1, 1], scene.rigid_bodies.orientations[0], np.zeros(3)])
    exact = solve_ivp(rates, (0.0, t_end), start, method="DOP853", rtol=1e-12, atol=1e-12).y[:3, -1]
    for run in (lambda dt: solver_run(scene, dt, t_end, "implicit-gyroscopic", substeps=1),
                lambda dt: solver_run(scene, dt, t_end, "exponential-map", substeps=1),
                lambda dt: coupled_run(scene, dt, t_end, "exponential-map")):
        errors = [np.abs(run(dt)[0].positions[-1, 1] - exact).max() for dt in (2e-3, 1e-3)]
        assert errors[1] < 2e-3 and 1.8 < errors[0] / errors[1] < 2.2, errors


def test_the_solver_kicks_with_the_forces_and_torques_at_the_orientations_now():
    """Mid-swing, after 60 substeps that each turned the step's own model in place: the centres'
    acceleration is that of a model built afresh at the orientations and spins now, bit for bit, and
    the angular acceleration is R diag(1/I) R^T tau with tau = (R r) x F summed over the spring and
    the damper, R the rotation matrix written out here (a pinned anchor gets none)."""
    from steplab.integrators.scene_rotation import keeping
    from steplab.integrators.simulate import simulate
    from steplab.physics import attachments

    scene = load_scene("hung-box")
    kept = []
    traj = simulate(scene.model, "semi-implicit-euler", scene.y0, scene.t_start, 0.25, scene.dt,
                    stepper=keeping(scene.collisions.stepper, kept))
    step, (x, v) = kept[0], traj.y[-1]
    assert step.log.summary()["impacts"] == 0 and np.linalg.norm(step.omega[1]) > 1  # swinging, turning
    a, alpha, _ = step.attached_rates(0.25, x, v)
    fresh = attachments.model_at(scene.model, step.orientation, step.omega)
    np.testing.assert_array_equal(a, fresh.acceleration(0.25, x, v))
    rotation, torque = matrix(step.orientation[1]), np.zeros(3)
    for f in attachments.attached_forces(fresh):
        arm = rotation @ CORNER
        assert np.allclose(f.attachment.offsets[0, 1], CORNER) and np.allclose(f.attachment.arms[0, 1], arm)
        torque -= np.cross(arm, f.pair_force(np, x, v)[0])  # the box is each pair's second end
    np.testing.assert_allclose(alpha[1], rotation @ ((rotation.T @ torque) / INERTIA), rtol=1e-12, atol=1e-12)
    assert np.all(alpha[0] == 0)


def test_the_restitution_budget_counts_the_work_of_both_kicks_so_a_step_without_contact_took_nothing(monkeypatch):
    """The restitution pass returns at most the kinetic energy a step took, D = E0 + W - E1: its energy
    at the start plus the forces' work, less its energy before the pass. A 0.2 m cube hung at its
    corner, far above the floor, has no contact and no gyroscopic term (equal moments), so its kinetic
    energy changes only by the kicks, v -> v + h a and omega -> omega + h I^-1 tau: counted as the
    work they do, D is 0 at every step, E0 + W being the energy at the step's end, 1/2 m v^2 +
    1/2 I |omega|^2, written out here from the trajectory. Before, the centre's work was the last
    substep's force times the whole step's move, m a . dq, a spring's force of one substep for the
    move of four (D was up to 0.17 J off on hung-box at e = 1), and without the torques' work a
    torque that slowed a spin counted as energy the contacts took, for the bounce to give back."""
    from steplab.physics.collision import rigid_solver as rs

    side = 0.2
    text = SCENE.read_text()
    for old, new, count in (("size = [0.3, 0.2, 0.1]", f"size = [{side}, {side}, {side}]", 1),
                            ("[0.15, 0.1, 0.05]]", f"[{side / 2}, {side / 2}, {side / 2}]]", 2),
                            ("position = [0.35, -0.1, 0.5]", "position = [0.4, -0.1, 0.45]", 1), FAR_FLOOR + (1,)):
        assert text.count(old) == count, old
        text = text.replace(old, new)
    scene = parse_scene(text, "hung-cube.toml")
    budgets, finish = [], rs.finish

    def kept_finish(bodies, contacts, sub, layout):  # the cube's E0 + W as the pass's limit counts it
        budgets.append(bodies.energy[1] + MASS * bodies.accel[1] @ bodies.dq[1])
        return finish(bodies, contacts, sub, layout)

    monkeypatch.setattr(rs, "finish", kept_finish)
    traj, rotation = solver_run(scene, scene.dt, 0.2)
    inertia = MASS * side ** 2 / 6
    omega = rotation.angular_velocities[1:, 0]
    assert len(budgets) == len(traj.t) - 1 and np.abs(omega).max() > 1 and np.ptp(omega) > 1  # turning, spun up
    for energy_and_work, v, w in zip(budgets, traj.velocities[1:, 1], omega):
        assert energy_and_work == pytest.approx(0.5 * MASS * v @ v + 0.5 * inertia * w @ w, rel=1e-12, abs=1e-12)


def test_the_box_strikes_the_floor_loses_energy_and_comes_to_rest_lying():
    """The scene with restitution 0: it reaches the floor at about 0.28 s, never sinks into it more than
    the solver's slop (0) and 2 mm, its energy (the springs at the lever arms, the spin) never rises
    from one step to the next beyond round-off, and by 3 s it lies on its largest face, at rest.

    The energy's fall is the contacts' doing: with the floor out of reach, semi-implicit Euler's swing
    gains energy on some steps (h^2/2 v^T K v on a spring, K its stiffness across the swing) from
    about 0.48 s on, after this box has struck the floor."""
    scene = variant(("restitution = 0.2", "restitution = 0.0"))
    traj, rotation = solver_run(scene, scene.dt, scene.t_end)
    x, v, q, omega = box(traj, rotation)
    energies = np.array([energy(*state) for state in zip(x, v, q, omega)])
    lowest = np.array([(xk + CORNERS @ matrix(qk).T)[:, 2].min() for xk, qk in zip(x, q)])
    assert traj.collisions.summary()["impacts"] > 0
    assert 0.25 < traj.t[np.argmax(lowest < 1e-3)] < 0.3
    assert lowest.min() > -(scene.collisions.solver.slop + 2e-3)
    assert np.diff(energies).max() <= 1e-12 * energies[0]
    assert energies[-1] < 0.6 * energies[0]
    assert np.linalg.norm(v[-1]) < 1e-6 and np.linalg.norm(omega[-1]) < 1e-5
    assert abs(x[-1, 2] - EDGES[2] / 2) < 2e-3 and abs(matrix(q[-1])[2, 2]) > 0.999  # on its 0.3 x 0.2 face

    free, free_rotation = solver_run(variant(FAR_FLOOR), scene.dt, 1.0)
    free_energies = np.array([energy(*state) for state in zip(*box(free, free_rotation))])
    assert np.diff(free_energies).max() > 1e-3  # the integrator alone does rise


def run_json(capsys, *argv) -> dict:
    status, out, err = run_main(capsys, ["run", *argv, "--json"])
    assert status == 0, err
    return json.loads(out)


def final_energy(summary, spin=True, orientation=None):
    """The energy at the end of ``steplab run --json``'s final state (the box, body 1), written out."""
    q = summary["final_orientations"][1] if orientation is None else orientation
    return energy(np.array(summary["final_positions"][1]), np.array(summary["final_velocities"][1]), q,
                  np.array(summary["final_angular_velocities"][1]), spin)


def test_run_reports_the_energy_with_the_spin_and_the_turned_lever_arm(capsys):
    summary = run_json(capsys, "hung-box", "--t-end", "0.25")  # tumbling down, before the strike
    assert summary["method"] == "solver" and summary["rotation"] == "implicit-gyroscopic"
    expected = final_energy(summary)
    assert summary["energy_end"] == pytest.approx(expected, rel=1e-12)
    assert expected - final_energy(summary, spin=False) > 0.05  # J: the spin counts
    start = load_scene("hung-box").rigid_bodies.orientations[0]
    assert abs(expected - final_energy(summary, orientation=start)) > 0.05  # and the arm where the box turned it

    summary = run_json(capsys, "hung-box")
    assert summary["energy_end"] == pytest.approx(final_energy(summary), rel=1e-12)
    assert summary["collisions"]["impacts"] > 0 and np.linalg.norm(summary["final_velocities"][1]) < 1e-6


def test_what_cannot_step_springs_at_body_frame_points_with_collisions_is_one_line(capsys, tmp_path):
    event = tmp_path / "hung-box-event.toml"
    event.write_text(SCENE.read_text().replace('method = "solver"', 'method = "event"'))
    for argv in (["run", "hung-box", "--method", "event"], ["run", str(event)]):
        err = refused(capsys, argv)
        assert 'not the event loop; use [collisions] method = "solver", or --detector none' in err
    err = refused(capsys, ["recommend", "hung-box", "--tol", "1e-3"])
    assert "without collisions only; use --detector none" in err


def test_the_library_refuses_what_would_freeze_the_lever_arms():
    """simulate with a collision world that cannot turn the lever arms (the event loop, which takes a
    spinning ball), or with the detector "none" and no attached step, is one line: either would keep
    the springs' points where they started."""
    from steplab.integrators import simulate

    scene = variant(('shape = "box"\nsize = [0.3, 0.2, 0.1]', 'shape = "sphere"\nangular_velocity = [0.0, 0.0, 0.1]'))
    for world in (dataclasses.replace(scene.collisions, method="event"), scene.collisions.with_detector("none")):
        with pytest.raises(ValueError, match="body-frame points") as err:
            simulate(scene.model, "semi-implicit-euler", scene.y0, 0.0, dt=scene.dt, n_steps=2, collisions=world)
        assert "\n" not in str(err.value)


def test_animate_draws_the_solver_run_with_the_energy_run_reports(capsys, tmp_path, drawn):
    from PIL import Image

    out = tmp_path / "x.gif"
    status, text, err = run_main(capsys, ["animate", "hung-box", "--t-end", "0.3", "--fps", "5", "--out", str(out)])
    assert status == 0, err
    assert "contact solver" in text and "rotation: implicit-gyroscopic" in text
    with Image.open(out) as gif:
        assert gif.n_frames == 19  # 18 steps of 1/60 s
    [[energies]] = drawn["energies"]
    summary = run_json(capsys, "hung-box", "--t-end", "0.3")
    assert energies[0] == pytest.approx(summary["energy_start"], rel=1e-12)
    assert energies[-1] == pytest.approx(summary["energy_end"], rel=1e-12)


def test_the_bounds_reach_as_far_as_the_torque_turns_a_body_within_the_step():
    """A force couple and no net force: two springs (3000 N/m, 0.1 m stretched) pull the box's opposite
    corners apart level, turning it at some 3600 rad/s^2 about y from rest 3 cm above the floor. Its
    centre does not move and its spin starts at zero, so only what the torque adds in the step (dt
    |alpha| in the bounds) brings the floor's points into the step: without it its far corners sink
    2.2 cm into the floor in the first 1/60 s."""
    text = SCENE.read_text().split("[[bodies]]")[0] + """
[[bodies]]
name = "right"
mass = 1.0
radius = 0.01
position = [0.65, 0.1, 0.13]
pinned = true

[[bodies]]
name = "left"
mass = 1.0
radius = 0.01
position = [-0.65, -0.1, 0.03]
pinned = true

[[bodies]]
name = "box"
mass = 1.0
radius = 0.18708286933869708
position = [0.0, 0.0, 0.08]
shape = "box"
size = [0.3, 0.2, 0.1]

[[forces.springs]]
bodies = ["right", "box"]
stiffness = 3000.0
rest_length = 0.4
offsets = [[0.0, 0.0, 0.0], [0.15, 0.1, 0.05]]

[[forces.springs]]
bodies = ["left", "box"]
stiffness = 3000.0
rest_length = 0.4
offsets = [[0.0, 0.0, 0.0], [-0.15, -0.1, -0.05]]

[collisions]
method = "solver"
restitution = 0.0

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 1.0]
"""
    scene = parse_scene(text.replace("t_end = 3.0", "t_end = 0.05"), "couple.toml")
    traj, rotation = solver_run(scene, scene.dt, scene.t_end)
    lowest = [(x + CORNERS @ matrix(q).T)[:, 2].min()
              for x, q in zip(traj.positions[:, 2], rotation.orientations[:, 0])]
    assert lowest[0] == pytest.approx(0.03)
    assert min(lowest) > -1e-3
    assert traj.collisions.summary()["impacts"] > 0


def test_a_box_that_overflows_is_the_body_the_one_line_names(capsys, tmp_path):
    """A 1e-300 kg box (moments of 1e-302 kg m^2): the spring's first torque kicks spin it up to 1e294
    rad/s and the third overflows. The line names the box and its angular velocity, the quantity the kick
    changes before the kernel carries it into the velocities and positions; not the pinned anchor, whose
    zero inverse inertia times the overflowed reaction torque was NaN (a body that does not turn gets no
    kick at all)."""
    path = tmp_path / "light-hung-box.toml"
    text = SCENE.read_text()
    assert text.count('name = "box"\nmass = 1.0') == 1
    path.write_text(text.replace('name = "box"\nmass = 1.0', 'name = "box"\nmass = 1e-300'))
    status, _, err = run_main(capsys, ["run", str(path), "--steps", "3"])
    assert status == 1 and "Traceback" not in err, err
    line = err.splitlines()[-1]
    assert line.startswith("steplab run: error: the contact solver's state became non-finite at body 'box' in the "
                           "step from t = 0 s (its angular velocity;"), line


def test_another_integrator_is_refused_in_one_line_before_any_warning_about_its_run(capsys):
    """Explicit Euler on hung-box is beyond its stable dt (a warning before a run), but the contact solver
    steps with semi-implicit Euler only: the refusal alone, one line, not the warning and then the refusal."""
    err = refused(capsys, ["run", str(SCENE), "--integrator", "euler", "--steps", "20"])
    assert err == ("steplab run: error: the contact solver integrates with semi-implicit-euler (velocities, contacts, "
                   "then positions, per substep), not 'euler'; use integrator 'semi-implicit-euler'\n"), err


def test_a_float32_run_carries_the_solvers_bodies_in_float32_from_step_to_step(capsys, tmp_path, monkeypatch):
    """The contact solver computes in float64; a float32 run's positions, velocities, orientations and
    angular velocities are rounded to float32 after every step (they ran in float64 from the second step
    on and only the saved positions were rounded), and agree with the float64 run to float32's error."""
    from steplab.physics.collision.rigid_solver_step import RigidSolverStep

    seen = []
    advance = RigidSolverStep._advance

    def recording(self, t, y, dt, carry):
        state, carry = advance(self, t, y, dt, carry)
        seen.append((np.asarray(y).dtype, state.dtype, self.omega.astype(np.float32).astype(float) - self.omega))
        return state, carry

    monkeypatch.setattr(RigidSolverStep, "_advance", recording)
    runs = {}
    for precision in ("float32", "float64"):
        out = tmp_path / f"{precision}.npz"
        status, _, err = run_main(capsys, ["run", "hung-box", "--steps", "20", "--precision", precision,
                                           "--out", str(out)])
        assert status == 0, err
        runs[precision] = dict(np.load(out))
    float32 = seen[:20]
    assert all(y == np.float32 and state == np.float32 for y, state, _ in float32)
    assert all(np.all(rounded == 0.0) for *_, rounded in float32)  # the carried spin is float32's
    for name in ("positions", "velocities", "orientations", "angular_velocities"):
        assert runs["float32"][name].dtype == np.float32, name
        wide = runs["float64"][name]
        np.testing.assert_allclose(runs["float32"][name], wide, rtol=0, atol=1e-4 * np.abs(wide).max(), err_msg=name)
