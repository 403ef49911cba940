"""The studies' computations (not their plots): orders, stability limits, round-off, caching."""

import json

import numpy as np
import pytest

from integrators import INTEGRATORS, Stepper
from studies import runner
from studies.lecture import lecture_check
from studies.plotting import plt, save_figure
from studies.problems import oscillator_problem, true_final
from studies.stability import measured_limit, theoretical_limit
from studies.truncation import error_curve, fit_order

STEPPERS = [name for name, method in INTEGRATORS.items() if isinstance(method, Stepper)]


@pytest.mark.parametrize("method", STEPPERS)
def test_truncation_fitted_order_matches_declared(method):
    problem = oscillator_problem()
    truth, _ = true_final(problem)
    points = error_curve(problem, method, "float64", truth, 4, 13)
    noise = 1e4 * np.finfo(float).eps * 1.5
    assert fit_order(points, noise) == pytest.approx(INTEGRATORS[method].order, abs=0.15)


def test_float32_has_a_roundoff_floor():
    """In float32, RK4's error stops falling: its smallest error is not at the smallest dt."""
    problem = oscillator_problem()
    truth, _ = true_final(problem)
    points = error_curve(problem, "rk4", "float32", truth, 2, 16)
    errors = [p["error"] for p in points]
    best = int(np.argmin(errors))
    assert best < len(errors) - 1  # the curve turned up again
    assert max(errors[best + 1:]) > 3 * errors[best]
    assert errors[best] > 1e-9  # far above float64 round-off: the float32 floor
    f64 = error_curve(problem, "rk4", "float64", truth, 2, 12)
    assert min(p["error"] for p in f64) < 1e-3 * errors[best]


def test_lecture_one_step_table_and_misprints():
    record = lecture_check()
    by_dt = {row["dt"]: row for row in record["lecture_table"]}
    # z = 2 + 29 dt numerically; exact 2 + 29 dt - 9.81 dt^2 / 2; error 9.81 dt^2 / 2
    for dt in (0.2, 0.1, 0.01):
        assert by_dt[dt]["z_numerical"] == pytest.approx(2 + 29 * dt, rel=1e-14)
        assert by_dt[dt]["error"] == pytest.approx(9.81 * dt**2 / 2, rel=1e-9)
    where = {m["where"] for m in record["misprints"]}
    assert "one step, dt = 0.1 s, numerical mV_z" in where  # 72.0476 printed, 70.0475 computed
    assert "one step, dt = 0.1 s, exact p_x" in where  # 10.1536 printed, 10.768 computed
    assert "t = 10.4 s, p_x" in where  # 51.48 printed, 51.472 computed
    assert "t = 5.4 s, p_z" not in where  # 13.21: correct to its digits
    computed = {m["where"]: m["computed"] for m in record["misprints"]}
    assert computed["one step, dt = 0.1 s, numerical mV_z"] == pytest.approx(72.5 - 0.1 * 24.525)


THEORY = {  # closed forms, undamped and zeta = 0.1
    ("euler", 0.0): 0.0, ("heun", 0.0): 0.0, ("midpoint", 0.0): 0.0,
    ("semi-implicit-euler", 0.0): 2.0, ("velocity-verlet", 0.0): 2.0, ("position-verlet", 0.0): 2.0,
    ("rk4", 0.0): 2 * np.sqrt(2), ("implicit-euler", 0.0): None,
    ("euler", 0.1): 0.2, ("semi-implicit-euler", 0.1): 2 * np.sqrt(1 + 0.01) - 0.2,
}


@pytest.mark.parametrize("key", THEORY)
def test_theoretical_limit_matches_closed_form(key):
    value = theoretical_limit(*key)
    if THEORY[key] is None:
        assert value is None
    else:
        assert value == pytest.approx(THEORY[key], abs=1e-9)


@pytest.mark.parametrize("zeta", [0.0, 0.1])
@pytest.mark.parametrize("method", STEPPERS)
def test_measured_stability_limit_within_one_percent_of_theory(method, zeta):
    measured = measured_limit(method, zeta, 5000)["omega_dt_max"]
    theory = theoretical_limit(method, zeta)
    if theory is None:
        assert measured is None
    elif theory == 0:
        assert measured == 0
    else:
        assert measured == pytest.approx(theory, rel=0.01)


def _toy_study(calls, name="toy", scale=1.0, fail=False):
    def compute(params, progress=None):
        if fail:
            raise KeyboardInterrupt
        calls.append(params)
        return {"value": params["n"] * params["scale"]}

    def plot(record, out):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, record["value"]])
        return save_figure(fig, out, name)

    return runner.Study(name, "toy", lambda quick: {"n": 2 if quick else 3, "scale": scale}, compute, plot)


def test_cache_skips_unchanged_and_reruns_changed(tmp_path, monkeypatch):
    calls = []
    first = runner.run_study(_toy_study(calls), tmp_path, quick=True)
    assert not first["cached"] and first["value"] == 2 and len(calls) == 1
    assert runner.run_study(_toy_study(calls), tmp_path, quick=True)["cached"] and len(calls) == 1
    # changed parameters
    assert runner.run_study(_toy_study(calls, scale=2.0), tmp_path, quick=True)["value"] == 4
    assert len(calls) == 2
    # quick and full differ
    runner.run_study(_toy_study(calls, scale=2.0), tmp_path, quick=False)
    assert len(calls) == 3
    # changed code
    monkeypatch.setattr(runner, "source_hash", lambda: "different code")
    runner.run_study(_toy_study(calls, scale=2.0), tmp_path, quick=False)
    assert len(calls) == 4
    # a missing figure invalidates the cache too
    (tmp_path / "toy.png").unlink()
    runner.run_study(_toy_study(calls, scale=2.0), tmp_path, quick=False)
    assert len(calls) == 5


def test_interrupted_run_leaves_no_partial_files_and_resumes(tmp_path):
    calls = []
    runner.run_study(_toy_study(calls, name="a"), tmp_path)
    with pytest.raises(KeyboardInterrupt):
        runner.run_study(_toy_study(calls, name="b", fail=True), tmp_path)
    assert not (tmp_path / "b.json").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary files left
    # the next run resumes: "a" is cached, "b" is computed
    assert runner.run_study(_toy_study(calls, name="a"), tmp_path)["cached"]
    assert not runner.run_study(_toy_study(calls, name="b"), tmp_path)["cached"]
    assert json.loads((tmp_path / "b.json").read_text())["value"] == 3


def test_recommend_meets_the_tolerance_when_run_independently():
    """Re-run what `recommend` picks on the NumPy path: the error stays under the tolerance."""
    from integrators import simulate
    from studies.problems import scene_problem
    from studies.work_precision import recommend

    problem = scene_problem("drag-projectile", 2.0, "drag")
    truth, _ = true_final(problem)
    for tol in (1e-3, 1e-7):
        choice = recommend(problem, tol)
        traj = simulate(problem.model, choice["integrator"], problem.y0, problem.t_start, problem.t_end,
                        choice["dt"])
        assert traj.t[-1] == pytest.approx(problem.t_end)
        assert np.max(np.abs(traj.positions[-1] - truth[0])) <= tol
        assert choice["error"] <= tol and choice["seconds"] > 0


def test_recommend_names_the_reference_when_no_fixed_step_gets_there():
    from studies.work_precision import recommend

    choice = recommend(oscillator_problem(t_end=0.3), 1e-12)
    assert choice["integrator"] in ("rk4", "diffrax-dopri8")
    if choice["integrator"] == "diffrax-dopri8":
        assert "no fixed-step method reaches" in choice["note"]


def test_pareto_front():
    from studies.work_precision import pareto

    points = [{"error": 1.0, "seconds": 1.0}, {"error": 0.5, "seconds": 2.0}, {"error": 2.0, "seconds": 3.0},
              {"error": None, "seconds": 0.1}]
    assert pareto(points, "seconds") == [0, 1]


def test_frame_rate_fixed_step_is_bit_identical_and_naive_is_not():
    from studies.frame_rate import compute, parameters

    record = compute(parameters(quick=True))
    assert record["fixed_bit_identical"]
    assert len({r["fixed_steps"] for r in record["runs"]}) == 1
    assert record["final_state_spread"]["fixed"] == 0.0
    assert record["final_state_spread"]["naive"] > 1e-3
