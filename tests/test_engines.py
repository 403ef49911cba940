"""The engine adapters (steplab.engines): each engine against closed forms, the identification,
the MJCF export, and one-line errors for what an engine cannot express.

Every test needs the engines extra (pip install -e ".[engines]") and is skipped per engine
without it.
"""

import math

import numpy as np
import pytest
from steplab.physics import Drag, Gravity, Model, Springs
from steplab.studies.problems import oscillator_problem

from steplab.cli import main
from steplab.engines import ENGINES, SETTINGS, UnsupportedFeatureError, build

G = 9.81
#: relative round-off of an engine's float type over a few hundred steps
ROUND_OFF = {"float64": 1e-12, "float32": 2e-6}
#: under constant gravity, where each steplab method's positions sit against the exact parabola,
#: in units of g dt t / 2 (sums of n kicks): semi-implicit Euler and the backward Eulers (the same
#: there) lead by one, the position-first (exponential damping) Euler lags by one, RK4 is exact
FREE_FALL_LEAD = {"semi-implicit-euler": 1, "implicit-euler": 1, "implicit-damping-euler": 1, "rk4": 0,
                  "exponential-damping-euler": -1}


def needs(engine: str):
    """The engine's package, imported; a skip where it is not installed (None: it needs none)."""
    package = ENGINES[engine].package
    return None if package is None else pytest.importorskip(package)


def precision(setting) -> str:
    return setting.adapter.precision


@pytest.mark.parametrize("key", list(SETTINGS))
def test_free_fall_is_the_parabola_plus_the_methods_known_lead(key):
    """q_n = q0 + v0 t + g t^2 / 2 + c g dt t / 2 exactly, c the lead of the steplab method the
    setting declares it steps (FREE_FALL_LEAD)."""
    setting = SETTINGS[key]
    needs(setting.engine)
    dt, n = 0.01, 50
    model = Model([2.0], [0.1], [Gravity(np.array([0.0, 0.0, -G]))])
    y0 = np.array([[[0.3, 0.0, 5.0]], [[1.5, 0.0, 4.0]]])  # in the x-z plane: the 2-D engines run it too
    traj = setting.build(model, None, dt, y0).advance(y0, dt, n)
    t = traj.t[-1]
    assert traj.steps == n and t == pytest.approx(n * dt)
    exact_z = 5.0 + 4.0 * t - 0.5 * G * t * t
    expected_z = exact_z - FREE_FALL_LEAD[setting.equals] * 0.5 * G * dt * t
    tolerance = ROUND_OFF[precision(setting)] * 10
    assert traj.positions[-1, 0, 2] == pytest.approx(expected_z, rel=tolerance)
    assert traj.positions[-1, 0, 0] == pytest.approx(0.3 + 1.5 * t, rel=tolerance)
    assert traj.velocities[-1, 0, 2] == pytest.approx(4.0 - G * t, rel=tolerance)


@pytest.mark.parametrize("key", ["mujoco-euler", "mujoco-rk4", "bullet-default", "box2d-default", "chipmunk"])
def test_oscillator_converges_to_the_cosine_at_the_methods_order(key):
    """x(t) = 1 + A cos(omega t): halving dt divides the error by 2^p (p = 4 for RK4, else 1), and
    the error is within the global bound of a p-th order method, A (omega dt)^p omega t."""
    setting = SETTINGS[key]
    needs(setting.engine)
    problem = oscillator_problem(0.0)
    errors = []
    for steps in (128, 256):
        dt = (problem.t_end - problem.t_start) / steps
        traj = setting.build(problem.model, None, dt, problem.y0).advance(problem.y0, dt, steps)
        errors.append(abs(traj.positions[-1, 1, 0] - problem.exact_final()[0, 1, 0]))
    order = 4 if key == "mujoco-rk4" else 1
    assert math.log2(errors[0] / errors[1]) == pytest.approx(order, abs=0.2)
    omega_t = problem.omega * problem.t_end
    assert errors[1] < 0.5 * (omega_t / 256) ** order * omega_t


@pytest.fixture(scope="module")
def identification():
    """The study's parameters and steplab's trajectories of the identification problems (computed once)."""
    from steplab.studies.engines import identification_problems, parameters

    params = parameters(quick=True)
    return params, identification_problems(params)


def test_every_setting_declares_the_method_it_steps():
    """Each declared name is one of steplab's fixed-step methods (the identification below checks
    it against the engine, the free-fall test against its known lead)."""
    from steplab.integrators import INTEGRATORS, Stepper

    assert all(isinstance(INTEGRATORS[setting.equals], Stepper) for setting in SETTINGS.values())


@pytest.mark.parametrize("key", list(SETTINGS))
def test_identification_names_the_method_each_engine_steps(key, identification):
    from steplab.studies.engines import identify
    from steplab.studies.system import engine_system

    setting = SETTINGS[key]
    needs(setting.engine)
    params, problems = identification
    result = identify(engine_system(setting), params, problems)
    assert result["nearest"] == setting.equals and setting.equals in result["equals"]
    assert result["difference"] <= {"float64": 1e-12, "float32": 1e-5}[precision(setting)]
    others = [max(d.values()) for m, d in result["differences"].items() if m not in result["equals"]]
    assert min(others) > 1e-4  # every other method is measurably different


def test_a_system_that_diverges_is_judged_on_the_problems_it_ran(identification):
    # a divergence made every method's worst difference inf, and the nearest whichever came first
    from steplab.integrators import DivergenceError
    from steplab.studies.engines import identify, verdict
    from steplab.studies.system import SteplabRun, SystemUnderTest

    class Diverging(SteplabRun):
        def advance(self, y0, dt, n_steps, t_start=0.0, save_every=1):
            if self.model.forces and any(type(f).__name__ == "Springs" for f in self.model.forces):
                raise DivergenceError("fake", dt, 1, t_start + dt)
            return super().advance(y0, dt, n_steps, t_start, save_every)

    params, problems = identification
    system = SystemUnderTest("diverges on springs", lambda model, collisions, dt, y0: Diverging(
        model, "semi-implicit-euler"))
    result = identify(system, params, problems)
    oscillators = [label for label in problems if label.startswith("oscillator")]
    assert result["diverged"] == oscillators and result["equals"] == []
    assert result["nearest"] == "semi-implicit-euler" and result["difference"] == 0.0
    assert all(result["differences"][m][label] is None for m in params["integrators"] for label in oscillators)
    assert verdict(result) == f"none (nearest semi-implicit-euler, 0.0e+00; diverged on {', '.join(oscillators)})"
    # the paper's table reads the same verdict from its slice of the record
    from steplab.studies.engines import engines_table, select_engines

    row = {"label": "diverging", "order": 1.0, "omega_dt_max": {"0": 2.0, "0.1": 2.0}, "identification": result,
           "energy": {"max_relative_energy_error": 0.1}, "miss_rates": {}, "drops": {}, "cost": {"planar": {}}}
    table = engines_table(select_engines({"rows": [row], "steplab": {"cost": {}}}))
    assert f"| diverging | {verdict(result)} |" in table


def test_mujoco_euler_and_rk4_differ_from_steplab_by_round_off_not_bits():
    """"bit for bit" was never true of the oscillator: MuJoCo computes the tendon's length and
    force in its own order; free fall (no tendon) is exact."""
    from steplab.integrators import simulate

    needs("mujoco")
    problem = oscillator_problem(0.1)
    dt = 0.1 / problem.omega
    for integrator, method in (("Euler", "semi-implicit-euler"), ("RK4", "rk4")):
        ours = simulate(problem.model, method, problem.y0, 0.0, dt=dt, n_steps=100).y
        theirs = build("mujoco", problem.model, None, dt, problem.y0, integrator=integrator).advance(
            problem.y0, dt, 100).y
        assert 0 < np.max(np.abs(theirs - ours)) < 1e-14


@pytest.mark.parametrize("engine", [key for key, cls in ENGINES.items() if cls.contacts])
def test_engine_contacts_come_back_as_a_collision_log(engine):
    needs(engine)
    from steplab.physics.scene import load_scene

    scene = load_scene("drop")
    traj = build(engine, scene.model, scene.collisions, scene.dt, scene.y0).advance(scene.y0, scene.dt, 600)
    first = next(e for e in traj.collisions.events if e.kind == "contact")
    assert (first.body_name, first.other_name) == ("ball", "floor")
    fall = math.sqrt(2 * 0.92 / G)  # the bottom starts 0.92 m above the floor
    assert first.t == pytest.approx(fall, abs=3 * scene.dt)
    assert first.impact_speed == pytest.approx(G * fall, rel=0.02)
    np.testing.assert_allclose(first.normal, [0.0, 0.0, -1.0], atol=1e-6)  # from the ball towards the floor


@pytest.mark.parametrize("scene", ["oscillator", "drop", "tunnelling", "billiards", "soft-cube", "cloth"])
def test_exported_mjcf_loads_in_mujoco_with_the_scenes_start(scene, tmp_path, capsys):
    from steplab.physics.scene import load_scene

    mujoco = needs("mujoco")
    path = tmp_path / f"{scene}.xml"
    assert main(["export", scene, "--to", "mjcf", "--out", str(path)]) == 0
    loaded = load_scene(scene)
    model = mujoco.MjModel.from_xml_path(str(path))
    moving = ~np.asarray(loaded.model.pinned)
    assert model.nbody - 1 == moving.sum() and model.opt.timestep == loaded.dt
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    np.testing.assert_array_equal(data.qpos.reshape(-1, 7)[:, :3], loaded.y0[0, moving])
    np.testing.assert_array_equal(data.qvel.reshape(-1, 6)[:, :3], loaded.y0[1, moving])
    if scene == "oscillator":  # one Euler step of the file is one semi-implicit Euler step
        mujoco.mj_step(model, data)
        k, m, x = 4 * math.pi**2, 1.0, 1.5
        v1 = -loaded.dt * k * (x - 1.0) / m
        assert data.qvel[0] == pytest.approx(v1, rel=1e-12) and data.qpos[0] == pytest.approx(x + loaded.dt * v1)


def test_export_bad_input_is_one_line_with_status_2(capsys):
    for argv, expected in ((["export", "drag-projectile", "--to", "mjcf"], "the drag force has no counterpart in MuJoCo"
                                                                           ),
                           (["export", "kepler", "--to", "mjcf"], "the central_gravity force"),
                           (["export", "no-such-scene", "--to", "mjcf"], "unknown scene")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err
    with pytest.raises(SystemExit) as exit_:  # argparse's own errors end the process, with one line
        main(["export", "oscillator", "--to", "urdf"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "invalid choice: 'urdf'" in err and err.count("\n") == 1


def test_what_an_engine_cannot_express_is_one_line_naming_it():
    needs("bullet")
    needs("box2d")
    drag = Model([1.0], [0.1], [Drag.from_coefficients([0.1])])
    with pytest.raises(UnsupportedFeatureError, match="the drag force has no counterpart in Bullet"):
        build("bullet", drag, None, 0.01)
    flying = np.array([[[0.0, 0.0, 0.0]], [[1.0, 1.0, 1.0]]])  # moves along all three axes
    with pytest.raises(UnsupportedFeatureError, match="a 3-D scene: Box2D simulates bodies in a plane"):
        build("box2d", Model([1.0], [0.1]), None, 0.01, flying)
    damped = oscillator_problem(0.1)
    model = Model([1.0, 1.0], [0.05, 0.05], [f for f in damped.model.forces if not isinstance(f, Springs)],
                  pinned=[True, False])
    with pytest.raises(UnsupportedFeatureError, match="a damper without a spring"):
        build("box2d", model, None, 0.01, damped.y0)
    with pytest.raises(ValueError, match="unknown engine 'havok'"):
        build("havok", drag)


@pytest.mark.parametrize("engine", ["mujoco", "bullet", "box2d", "chipmunk"])
def test_advance_refuses_a_step_a_save_and_a_state_it_cannot_take(engine):
    # dt = 0 or NaN: MuJoCo and Box2D returned the start, Bullet and Chipmunk stepped backwards at dt < 0;
    # save_every = 2.5 kept uninitialised memory as states; a state of another scene ran on
    needs(engine)
    problem = oscillator_problem()
    run = build(engine, problem.model, None, 0.01, problem.y0)
    for dt in (0.0, -0.01, float("nan")):
        with pytest.raises(ValueError, match="dt must be a step > 0 s"):
            run.advance(problem.y0, dt, 10)
    with pytest.raises(ValueError, match="save_every must be a whole number"):
        run.advance(problem.y0, 0.01, 10, save_every=2.5)
    with pytest.raises(ValueError, match=r"y0 must have shape \(2, 2, 3\)"):
        run.advance(np.zeros((2, 5, 3)), 0.01, 10)
    assert run.advance(problem.y0, 0.01, 10, save_every=5).y.shape == (3, 2, 2, 3)


def test_engines_study_says_how_to_install_the_extra(monkeypatch, capsys):
    import steplab.engines
    from steplab import studies

    monkeypatch.setattr(steplab.engines, "missing", lambda: ["Box2D"])
    assert main(["study", "engines", "--quick", "--out", "unused"]) == 2
    err = capsys.readouterr().err
    assert 'pip install -e ".[engines]"' in err and "Box2D" in err and err.count("\n") == 1
    monkeypatch.setattr(studies, "builtin_studies", lambda: [studies.STUDIES["engines"]])
    assert main(["reproduce", "--quick", "--out", "unused"]) == 0
    out, err = capsys.readouterr()
    assert "engines: skipped: the engines study needs Box2D" in out + err
