"""`steplab check`: the largest stable dt predicted from the stiffest mode, against measured limits.

Measured: bisection on long runs of the real integrator on the real (nonlinear) model,
from its stiffest mode found by the dense eigen-decomposition of ``model.jacobian``
(``studies.stability_limits``), an independent path from the prediction's matrix-free
Lanczos on autodiff products and the methods' stability functions.
"""

from __future__ import annotations

import functools
import json
from importlib import resources

import numpy as np
import pytest
from steplab.integrators import INTEGRATORS
from steplab.integrators.stable_dt import stable_step
from steplab.physics import Gravity, Model, modes
from steplab.physics.scene import load_scene, parse_scene
from steplab.studies import stability_limits

from steplab.cli import main


def small_cloth_scene():
    """A 6 x 6 cloth: the built-in scene's particles, springs and dampers, fewer of them (the
    12 x 12 one's bisections take seconds), pinned at its two top corners."""
    text = (resources.files("steplab.physics") / "scenes" / "cloth.toml").read_text()
    text = text.replace("rows = 12", "rows = 6").replace("cols = 12", "cols = 6").replace("pinned = [0, 11]",
                                                                                       "pinned = [0, 5]")
    return parse_scene(text, "small cloth", "cloth")


def without_gravity(scene):
    """The scene's model without its constant field, so that its initial state is at rest."""
    model = scene.model
    forces = [f for f in model.forces if not isinstance(f, Gravity)]
    return Model(np.asarray(model.masses), np.asarray(model.radii), forces, model.pinned), scene.y0[0]


SCENES = {"oscillator": lambda: load_scene("oscillator"), "soft-cube": lambda: load_scene("soft-cube"),
          "cloth": small_cloth_scene}


@functools.cache
def stiffest_modes(scene: str):
    """The scene's stiffest mode, predicted (Lanczos on jvp products) and measured (dense eig of
    the analytic Jacobian, what the bisections run on), at rest without gravity."""
    model, q = without_gravity(SCENES[scene]())
    if scene == "oscillator":
        q = q.copy()
        q[1, 0] = 1.0  # at rest length: the measured mode starts at equilibrium
    predicted, measured = modes.stiffest_mode(model, q), stability_limits.stiffest_mode(model, q)
    assert predicted.omega == pytest.approx(measured.omega, rel=1e-9)
    return predicted, measured


#: steps of each measuring run, and the bracket: stable at 0.99 dt_max, unstable at 1.01 dt_max
#: (just past a limit the growth per step is about 1e-2 or more, far above the 1e-7 tolerance)
STEPS, BRACKET = 1000, 0.01


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("method", ["semi-implicit-euler", "rk4"])
def test_predicted_limit_is_within_1_percent_of_the_measured_one(scene, method):
    """The real integrator on the real model is stable at 0.99 x and unstable at 1.01 x the
    predicted dt_max, so the measured limit (the bisection's) lies within 1 % of it."""
    predicted_mode, mode = stiffest_modes(scene)
    limits = stable_step(predicted_mode, INTEGRATORS[method])
    growth = stability_limits.growth_function(mode, method, STEPS)
    at = lambda factor: growth(factor * limits.dt_max_damped * mode.omega)  # noqa: E731
    assert at(1 - BRACKET) <= stability_limits.GROWTH_TOLERANCE < at(1 + BRACKET)
    if scene != "oscillator":  # the dampers matter: the undamped prediction alone misses by more
        assert predicted_mode.damping_ratio > 0.05
        assert abs(limits.dt_max / limits.dt_max_damped - 1) > 2 * BRACKET


def test_the_difference_quotient_agrees_with_autodiff_on_the_cloth():
    scene = load_scene("cloth")
    exact = modes.stiffest_mode(scene.model, scene.y0[0])
    cheap = modes.stiffest_mode(scene.model, scene.y0[0], derivative="difference")
    assert cheap.omega == pytest.approx(exact.omega, rel=1e-8)
    assert cheap.damping_ratio == pytest.approx(exact.damping_ratio, rel=1e-6)


def test_check_prints_each_limit_and_says_when_the_model_sets_none(capsys):
    assert main(["check", "oscillator", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    rows = {r["integrator"]: r for r in report["integrators"]}
    omega = 2 * np.pi  # k = 4 pi^2 N/m on 1 kg
    assert report["omega_max"] == pytest.approx(omega, rel=1e-12) and report["damping_ratio"] == 0
    assert rows["semi-implicit-euler"]["dt_max"] == pytest.approx(2 / omega, rel=1e-12)
    assert rows["rk4"]["dt_max"] == pytest.approx(2 * np.sqrt(2) / omega, rel=1e-12)
    assert rows["implicit-euler"]["dt_max"] is None and rows["euler"]["dt_max"] == 0
    assert all(r["stable"] for r in rows.values() if r["dt_max"])  # the scene's dt = 0.01 s
    assert main(["check", "oscillator", "--dt", "0.4", "--json"]) == 0  # between 2 / omega and 2.83 / omega
    rows = {r["integrator"]: r for r in json.loads(capsys.readouterr().out)["integrators"]}
    assert not rows["semi-implicit-euler"]["stable"] and rows["rk4"]["stable"] and rows["implicit-euler"]["stable"]
    assert main(["check", "projectile"]) == 0
    assert "no oscillating mode" in capsys.readouterr().out
    assert main(["check", "oscillator", "--integrator", "scipy-dop853"]) == 2
    assert "not a fixed-step integrator" in capsys.readouterr().err


def test_run_warns_when_dt_exceeds_the_limit(capsys):
    """``--dt 16`` (milliseconds meant) on the oscillator: 16 s > 2 / omega = 0.318 s."""
    status = main(["run", "oscillator", "--dt", "16", "--t-end", "32"])
    err = capsys.readouterr().err.splitlines()
    assert status == 0 and len(err) == 1  # two steps: not yet diverged
    assert err[0].startswith("steplab run: warning: dt = 16 s exceeds the largest stable dt of "
                             "semi-implicit-euler on this scene, 0.318 s") and "--dt 0.016" in err[0]
    assert main(["run", "oscillator", "--dt", "0.3", "--t-end", "1"]) == 0  # just inside 0.3183 s
    assert capsys.readouterr().err == ""


def test_a_damper_near_the_float_range_is_checked_and_warned_in_one_line(tmp_path, monkeypatch, capsys):
    # a damper of 1e308 N s/m (damping ratio 8e306): check printed NumPy's "Array must not contain
    # infs or NaNs", run a traceback (OverflowError squaring the growth factor of 1e306)
    from helpers import oscillator_scene

    monkeypatch.chdir(tmp_path)
    (tmp_path / "heavy.toml").write_text(oscillator_scene("semi-implicit-euler", '\n[[forces.dampers]]\n'
                                                          'bodies = ["anchor", "mass"]\ndamping = 1e308\n'))
    assert main(["check", "heavy.toml", "--json"]) == 0
    rows = {r["integrator"]: r for r in json.loads(capsys.readouterr().out)["integrators"]}
    assert not rows["rk4"]["stable"] and not rows["semi-implicit-euler"]["stable"]
    assert rows["implicit-euler"]["stable"] and rows["exponential-damping-euler"]["stable"]
    assert main(["run", "heavy.toml"]) == 1  # it diverges, as the warning says
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("steplab run: warning: dt = 0.01 s exceeds the largest stable dt of "
                             "semi-implicit-euler on this scene: there is none") and "its energy by inf" in err[0]
    assert len(err) == 2 and "diverged" in err[1]


def test_a_zero_length_spring_of_rest_length_0_is_checked(tmp_path, monkeypatch, capsys):
    # the mass resting on its anchor, rest length 0: the force k x is smooth there, but jax.jvp of the spring's
    # length |x| is NaN at 0, and check refused the scene blaming "a rest length > 0" (the input audit's fuzz)
    from helpers import OSCILLATOR_SCENE

    text = OSCILLATOR_SCENE.read_text()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "resting.toml").write_text(text.replace("position = [1.5, 0.0, 0.0]", "position = [0.0, 0.0, 0.0]")
                                           .replace("rest_length = 1.0", "rest_length = 0.0"))
    assert main(["check", "resting.toml", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(report["omega_max"], 2 * np.pi, rtol=1e-8)  # sqrt(k / m), k = 4 pi^2 N/m


def test_check_of_a_position_based_method_prints_json_and_refuses_what_run_refuses(capsys):
    # `check SCENE --integrator xpbd --json` printed its sentence, not JSON; and on springs at body-frame
    # points, where `run --integrator xpbd` is refused, it said xpbd was stable at every dt on springs
    assert main(["check", "cloth", "--integrator", "xpbd", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    (row,) = report["integrators"]
    assert report["scene"] == "cloth" and row["integrator"] == "xpbd"
    assert row["dt_max"] is None and row["stable"] and "position-based" in row["note"]
    assert main(["check", "cloth", "--integrator", "xpbd"]) == 0
    assert "xpbd is position-based" in capsys.readouterr().out
    for argv in (["--json"], ["--rotation", "dlm"]):
        assert main(["check", "spring-pendulum", "--integrator", "xpbd", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "need a fixed-step integrator that evaluates their forces, not 'xpbd'" in err


@pytest.mark.parametrize("argv, message", [
    (["--rotation", "dlm"], "rotation method 'dlm' does not compose with it; use one of exponential-map"),
    (["--integrator", "rk4"], "the contact solver integrates with semi-implicit-euler (velocities, contacts, then "
                              "positions, per substep), not 'rk4'"),
])
def test_check_on_the_contact_solver_refuses_what_run_refuses(capsys, argv, message):
    # check hung-box --rotation dlm (or --integrator rk4) reported a stability `run` never reaches: run refuses
    # both in one line, the solver's substeps being semi-implicit Euler's
    for command in (["check", "hung-box"], ["run", "hung-box", "--steps", "1"]):
        assert main([*command, *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and message in err, (command, err)
