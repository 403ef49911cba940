"""The studies' computations (not their plots, but for the marks they share): orders, stability limits, round-off,
caching."""

import json

import numpy as np
import pytest
from steplab.integrators import INTEGRATORS, Stepper
from steplab.studies import runner
from steplab.studies.lecture import lecture_check
from steplab.studies.plotting import diverged_band, plt, save_figure
from steplab.studies.problems import oscillator_problem, true_final
from steplab.studies.stability_limits import measured_limit, oscillator_mode
from steplab.studies.truncation import error_curve, fit_order

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
    method, zeta = key
    value = INTEGRATORS[method].stability_limit(zeta)
    if THEORY[key] is None:
        assert value is None
    else:
        assert value == pytest.approx(THEORY[key], abs=1e-9)


@pytest.mark.parametrize("zeta", [0.0, 0.1])
@pytest.mark.parametrize("method", STEPPERS)
def test_measured_stability_limit_within_one_percent_of_theory(method, zeta):
    measured = measured_limit(oscillator_mode(zeta), method, 5000)["omega_dt_max"]
    theory = INTEGRATORS[method].stability_limit(zeta)
    if theory is None:
        assert measured is None
    elif theory == 0:
        assert measured == 0
    else:
        assert measured == pytest.approx(theory, rel=0.01)


# --- stiff springs, long runs and the extremes ------------------------------------------------


def test_stable_dt_falls_as_one_over_sqrt_stiffness_on_the_soft_cube():
    from steplab.studies.stiffness import stable_dt_against_stiffness

    methods = ["semi-implicit-euler", "rk4", "euler", "implicit-euler"]
    record = stable_dt_against_stiffness(methods, [100.0, 1e4], 2000, 1e-4)
    for row in record["rows"]:
        if row["integrator"] == "implicit-euler":
            assert row["dt_max"] is None and row["dt_max_theory"] is None
        elif row["integrator"] == "euler":
            assert row["dt_max"] == 0  # undamped: unstable at every dt
        else:
            assert row["dt_max"] == pytest.approx(row["dt_max_theory"], rel=0.01)
    for method in ("semi-implicit-euler", "rk4"):
        assert record["slopes"][method] == pytest.approx(-0.5, abs=0.01)
    # omega_max of the all-pairs cube, one corner pinned, from its eigenvalues: sqrt(k (4 + 2 sqrt 3)) / m
    assert record["rows"][0]["omega"] == pytest.approx(np.sqrt(100.0 * (4 + 2 * np.sqrt(3))), rel=1e-12)


def test_implicit_euler_pays_the_predicted_amplitude_per_period():
    from steplab.studies.stiffness import implicit_euler_damping

    for row in implicit_euler_damping([0.01, 0.3, 3.0, 30.0])["rows"]:
        y = row["omega_dt"]  # |R(i y)| = 1 / sqrt(1 + y^2) per step, 2 pi / y steps per period
        assert row["theory"] == pytest.approx((1 + y * y) ** (-np.pi / y), rel=1e-12)
        assert row["amplitude_kept_per_period"] == pytest.approx((1 + y * y) ** (-np.pi / y), rel=1e-6)


def test_implicit_euler_at_cloth_scale_is_stable_where_explicit_euler_is_not():
    # a cloth above DENSE_MAX_BODIES: implicit Euler's Newton steps go through CG on the
    # sparse Jacobian; semi-implicit Euler holds just below 2 / omega_max and blows up just above
    from steplab.integrators import get_integrator
    from steplab.integrators.implicit_euler import DENSE_MAX_BODIES
    from steplab.studies.stiffness import cloth, implicit_euler_at_scale

    record = implicit_euler_at_scale(15, 2000.0, 40, seed=1)
    assert record["bodies"] > DENSE_MAX_BODIES and get_integrator("implicit-euler").uses_cg(cloth(15, 2000.0)[0])
    runs = {(r["integrator"], r["dt_over_limit"]): r for r in record["runs"]}
    assert runs["semi-implicit-euler", 0.9]["diverged_at_step"] is None
    assert runs["semi-implicit-euler", 1.1]["diverged_at_step"] is not None
    for factor in (10.0, 100.0):  # undamped springs: the exact flow keeps E; implicit Euler may only lose it
        run = runs["implicit-euler", factor]
        assert run["diverged_at_step"] is None and run["largest_energy"] <= 1 + 1e-12 and run["final_energy"] < 0.5


def test_long_run_energy_on_the_kepler_orbit():
    from steplab.studies.problems import kepler_problem
    from steplab.studies.stability import energy_history

    problem = kepler_problem()
    verlet = energy_history(problem, "velocity-verlet", 20_000, 1e-3)  # 20 orbits
    euler = energy_history(problem, "euler", 20_000, 1e-3)
    rk4 = energy_history(problem, "rk4", 20_000, 1e-3)
    assert verlet["max_relative_energy_error"] < 1e-3 and verlet["diverged_at_step"] is None
    assert euler["final_relative_energy_error"] > 0.1  # explicit Euler gains energy orbit after orbit
    assert rk4["final_relative_energy_error"] < 1e-7
    # symplectic: the error at the end is no larger than within the first orbit (bounded, no drift)
    first_orbit = [e for t, e in zip(verlet["t"], verlet["relative_energy_error"]) if t <= 1.0]
    assert verlet["final_relative_energy_error"] <= 1.01 * max(first_orbit)
    # the envelope of the compiled run is the energy after every step of the NumPy run
    short = energy_history(problem, "velocity-verlet", 5000, 1e-3)
    assert short["max_relative_energy_error"] == pytest.approx(
        max(e for t, e in zip(verlet["t"], verlet["relative_energy_error"]) if t <= 5.0), rel=1e-3)


def test_huge_dt_is_reported_as_divergence_at_the_predicted_step():
    from steplab.studies.extremes import huge_dt

    rows = huge_dt(STEPPERS, [3.0, 100.0], 1000)
    for row in rows:
        if row["integrator"] == "implicit-euler":
            assert row["diverged_at_step"] is None and row["finite_output"] is True
        else:
            assert row["diverged_at_step"] is not None and "diverged" in row["message"]
            assert abs(row["diverged_at_step"] - row["predicted_step"]) <= max(2, 0.1 * row["predicted_step"])


def test_far_from_the_origin_stalls_exactly_where_rounding_predicts():
    from steplab.studies.extremes import coasting, first_offset, oscillator_jitter, stall_edge

    offsets = np.geomspace(1e3, 1e7, 9).tolist()
    rows = coasting(offsets, [1e-3, 1e-2, 1.0], ["float32", "float64"], 30)
    for row in rows:
        assert row["stalled"] == row["predicted_stall"]
        if not row["stalled"]:
            assert row["speed_error"] == pytest.approx(row["predicted_speed_error"], rel=1e-6, abs=1e-12)
    first = first_offset(rows, "stalled")
    # float32: a 1 cm/s body (v dt = 1/6000 m) stalls where the spacing exceeds 2 v dt: 2^12 m and beyond
    assert stall_edge(0.01, "float32") == 2.0**12
    assert 2.0**12 <= first["float32"]["0.01"] <= 1e4
    assert stall_edge(1.0, "float32") == 2.0**19  # the spacing passes 1/30 m at 2^19 m
    assert first["float32"]["1"] == pytest.approx(1e6)
    assert all(first["float64"][f"{v:g}"] is None for v in (1e-3, 1e-2, 1.0))
    assert stall_edge(1e-3, "float64") == 2.0**38
    jitter = {(r["precision"], r["offset"]): r["deviation"]
              for r in oscillator_jitter([1e5, 1e7], ["float32", "float64"], 2)}
    assert jitter[("float32", 1e5)] > 0.01  # over 1 % of the amplitude
    assert jitter[("float64", 1e7)] < 1e-6


def test_the_light_body_sets_the_stable_dt_across_mass_ratios():
    from steplab.studies.extremes import mass_ratio

    rows = mass_ratio(["semi-implicit-euler", "rk4"], [1.0, 1e6], 2000, 1e-4)
    for row in rows:
        assert row["dt_max"] == pytest.approx(row["dt_max_theory"], rel=0.01)
    by = {(r["integrator"], r["mass_ratio"]): r["dt_max"] for r in rows}
    # omega = sqrt(k (1/m1 + 1/m2)): 10^6 times lighter shrinks dt by sqrt((1 + 10^6) / 2)
    assert by["rk4", 1.0] / by["rk4", 1e6] == pytest.approx(np.sqrt((1 + 1e6) / 2), rel=0.01)


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
    monkeypatch.setattr(runner, "source_hash", lambda *args, **kwargs: "different code")
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


@pytest.fixture(scope="module")
def drag_projectile():
    """recommend's drag projectile and its true final state (an adaptive reference solve of seconds)."""
    from steplab.studies.problems import scene_problem

    problem = scene_problem("drag-projectile", 2.0, "drag")
    return problem, true_final(problem)


@pytest.fixture
def solved_once(drag_projectile, monkeypatch):
    """The drag projectile, whose reference recommend takes from its fixture rather than solving it again on
    every call: the same deterministic solve of the same problem (any other problem is solved as before)."""
    from steplab.studies import recommend as rec

    problem, solved = drag_projectile
    monkeypatch.setattr(rec, "true_final", lambda p: solved if p is problem else true_final(p))
    return problem, solved


def test_recommend_meets_the_tolerance_when_run_independently(solved_once):
    """Re-run what `recommend` picks on the NumPy path: the error stays under the tolerance."""
    from steplab.integrators import simulate
    from steplab.studies.recommend import recommend

    problem, (truth, _) = solved_once
    for tol in (1e-3, 1e-7):
        choice = recommend(problem, tol)
        traj = simulate(problem.model, choice["integrator"], problem.y0, problem.t_start, problem.t_end,
                        choice["dt"])
        assert traj.t[-1] == pytest.approx(problem.t_end)
        assert np.max(np.abs(traj.positions[-1] - truth[0])) <= tol
        assert choice["error"] <= tol and choice["seconds"] > 0


def test_recommend_times_every_answer_in_the_same_interleaved_rounds(monkeypatch, solved_once):
    # timed one after another, a burst of load on one answer made a slower method the cheapest
    from steplab.studies import recommend as rec

    rounds = []

    def interleaved(calls, repeats):
        rounds.append(sorted(calls))
        return {m: 1.0 if m == "heun" else 2.0 for m in calls}  # heun the cheapest in these rounds

    monkeypatch.setattr(rec, "interleaved_medians", interleaved)
    problem, _ = solved_once
    choice = rec.recommend(problem, 1e-3, integrators=["rk4", "midpoint", "heun"])
    assert rounds == [["heun", "midpoint", "rk4"]] and choice["integrator"] == "heun" and choice["seconds"] == 1.0


def test_recommend_names_the_reference_when_no_fixed_step_gets_there():
    from steplab.studies.recommend import recommend

    choice = recommend(oscillator_problem(t_end=0.3), 1e-12)
    assert choice["integrator"] in ("rk4", "diffrax-dopri8")
    if choice["integrator"] == "diffrax-dopri8":
        assert "no fixed-step method reaches" in choice["note"]


def test_pareto_front():
    from steplab.studies.work_precision import pareto

    points = [{"error": 1.0, "seconds": 1.0}, {"error": 0.5, "seconds": 2.0}, {"error": 2.0, "seconds": 3.0},
              {"error": None, "seconds": 0.1}]
    assert pareto(points, "seconds") == [0, 1]


def test_frame_rate_fixed_step_is_bit_identical_and_naive_is_not():
    from steplab.studies.frame_rate import compute, parameters

    record = compute(parameters(quick=True))
    assert record["fixed_bit_identical"]
    assert len({r["fixed_steps"] for r in record["runs"]}) == 1
    assert record["final_state_spread"]["fixed"] == 0.0
    assert record["final_state_spread"]["naive"] > 1e-3


@pytest.mark.parametrize("methods", [2, 6])
@pytest.mark.parametrize("scale", ["log", "linear"])
def test_diverged_runs_are_crosses_in_a_band_above_every_curve(scale, methods):
    """A diverged run is drawn as a cross in a shaded band above the curves, each method at its own
    height, so it can neither be read as a value nor hide another method's cross."""
    fig, ax = plt.subplots()
    ax.plot([1, 2, 4], [1e-3, 1e-2, 1e-1])
    ax.set_yscale(scale)
    top_of_curves = ax.get_ylim()[1]
    lost = [([1, 4], "tab:red"), ([2], "tab:blue"), ([1], "tab:green"), ([4], "k"), ([2, 4], "tab:pink"), ([1], "y")]
    diverged_band(ax, lost[:methods])
    # the height, as a fraction of the axes, where the curves' range ends
    band_starts = ax.transAxes.inverted().transform(ax.transData.transform((1, top_of_curves)))[1]
    assert 0.75 < band_starts < 0.9
    crosses = [line for line in ax.lines if line.get_marker() == "x"]
    assert [list(line.get_xdata()) for line in crosses] == [xs for xs, _ in lost[:methods]]
    heights = [set(line.get_ydata()) for line in crosses]
    assert all(len(h) == 1 and band_starts < min(h) < 1 for h in heights)
    assert len(set.union(*heights)) == methods
    shaded = [p for p in ax.patches if p.get_facecolor()[:3] != (1.0, 1.0, 1.0)]
    assert len(shaded) == 1
    plt.close(fig)


def test_the_oscillator_problem_is_the_underdamped_one_its_exact_solution_is():
    # zeta = 1 gave w_d = 0 and an exact solution of NaN, with only RuntimeWarnings; 2 an imaginary w_d
    for zeta in (1.0, 2.0, -0.1, float("nan"), "0.1"):
        with pytest.raises(ValueError, match=r"damping_ratio must be in \[0, 1\)"):
            oscillator_problem(zeta)
    assert np.all(np.isfinite(true_final(oscillator_problem(0.99))[0]))
