"""Bounds on the methods' settings: sweeps that would never end and tolerances that crash or stall
the solvers are refused in one line (ValueError in Python; status 2 at the command line)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import oscillator_scene, refused
from steplab.integrators import implicit_euler, position_based, references
from steplab.integrators.settings import configured
from steplab.physics.collision import solver_settings

HUGE = 99_999_999_999


def refusal(*argv):
    """stderr of ``steplab run *argv`` in a fresh process, checked to be one line, status 2."""
    done = subprocess.run([str(Path(sys.executable).parent / "steplab"), "run", *argv], capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1, done.stderr
    return done.stderr


def scene_file(tmp_path, integrator, key, value):
    """The oscillator scene stepped by ``integrator`` with ``key = value`` in its settings table."""
    path = tmp_path / "r.toml"
    path.write_text(oscillator_scene(integrator, f"\n[simulation.{integrator}]\n{key} = {value}\n"))
    return str(path)


# --- position-based sweeps ---------------------------------------------------------------------

@pytest.mark.parametrize("name", ["pbd", "xpbd", "vbd"])
@pytest.mark.parametrize("key,limit", [("substeps", "MAX_SUBSTEPS"), ("iterations", "MAX_ITERATIONS")])
def test_position_based_sweeps_have_an_upper_bound(name, key, limit):
    bound = getattr(position_based, limit)
    with pytest.raises(ValueError) as err:
        configured(name, {key: HUGE}, "here")
    assert str(err.value) == (f"here: {name}: {key} must be a whole number from 1 to {bound:,} "
                              f"(steplab.integrators.position_based.{limit}), got {HUGE}")
    assert getattr(configured(name, {key: bound, "substeps" if key == "iterations" else "iterations": 1}), key) == bound


def test_position_based_sweeps_per_step_have_an_upper_bound():
    with pytest.raises(ValueError, match=r"xpbd: substeps x iterations must be at most 100,000 sweeps a step "
                                         r"\(steplab.integrators.position_based.MAX_SWEEPS\), "
                                         r"got 1,000 x 1,000 = 1,000,000"):
        configured("xpbd", {"substeps": 1000, "iterations": 1000})
    ok = configured("xpbd", {"substeps": position_based.MAX_SUBSTEPS,
                             "iterations": position_based.MAX_SWEEPS // position_based.MAX_SUBSTEPS})
    assert ok.evaluations == position_based.MAX_SWEEPS


def test_huge_substeps_flag_is_refused_at_once():
    err = refusal("cloth", "--integrator", "xpbd", "--substeps", str(HUGE), "--steps", "1")
    assert "--substeps: xpbd: substeps must be a whole number from 1 to 10,000" in err


@pytest.mark.parametrize("integrator,key", [("xpbd", "substeps"), ("pbd", "iterations"), ("vbd", "substeps")])
def test_huge_sweeps_in_a_scene_are_one_line(capsys, tmp_path, integrator, key):
    err = refused(capsys, ["run", scene_file(tmp_path, integrator, key, HUGE)])
    assert f"[simulation.{integrator}]: {integrator}: {key} must be a whole number from 1 to 10,000" in err


# --- implicit Euler's Newton iterations and tolerances ----------------------------------------

def test_newton_iterations_have_an_upper_bound():
    with pytest.raises(ValueError, match=r"implicit-euler: newton_iterations must be a whole number from 1 to 50 "
                                         r"\(steplab.integrators.implicit_euler.MAX_NEWTON_ITERATIONS"):
        configured("implicit-euler", {"newton_iterations": HUGE})
    bound = implicit_euler.MAX_NEWTON_ITERATIONS
    assert configured("implicit-euler", {"newton_iterations": bound}).newton_iterations == bound


@pytest.mark.parametrize("key", ["rtol", "cg_rtol"])
@pytest.mark.parametrize("value", ["x", [1], True, -1, 0, 0.0, 1.0, float("nan"), float("inf"), 10**400])
def test_implicit_euler_tolerances_are_numbers_in_0_1(key, value):
    with pytest.raises(ValueError) as err:
        configured("implicit-euler", {key: value})
    assert str(err.value) == f"implicit-euler: {key} must be a number in (0, 1), or None for the default, got {value!r}"


def test_implicit_euler_tolerances_in_range_are_kept():
    stepper = configured("implicit-euler", {"rtol": 1e-300, "cg_rtol": np.float64(0.5)})
    assert (stepper.rtol, stepper.cg_rtol) == (1e-300, 0.5)


def test_a_bad_implicit_euler_rtol_is_one_line_at_the_command_line(tmp_path):
    err = refusal(scene_file(tmp_path, "implicit-euler", "rtol", '"x"'))
    assert err.endswith("[simulation.implicit-euler]: implicit-euler: rtol must be a number in (0, 1), "
                        "or None for the default, got 'x'\n")


# --- the reference solvers' tolerances ----------------------------------------------------------

REFERENCES = ["scipy-dop853", "scipy-radau", "diffrax-tsit5", "diffrax-dopri8", "diffrax-kvaerno5"]


@pytest.mark.parametrize("name", REFERENCES)
@pytest.mark.parametrize("value", ["x", [1], True, -1.0, 0.0, 1e-15, 1.0, float("nan"), float("inf")])
def test_reference_rtol_is_a_number_from_scipys_minimum_to_1(name, value):
    with pytest.raises(ValueError) as err:
        configured(name, {"rtol": value})
    assert str(err.value).startswith(f"{name}: rtol must be a number in [2.22e-14, 1) ")
    assert str(err.value).endswith(f"references.MIN_RTOL), got {value!r}")


@pytest.mark.parametrize("name", REFERENCES)
@pytest.mark.parametrize("value", ["x", [1], False, -1.0, 0.0, 1e-300, 5e-324, float("nan"), float("inf")])
def test_reference_atol_is_a_finite_number_not_below_its_minimum(name, value):
    with pytest.raises(ValueError) as err:
        configured(name, {"atol": value})
    assert str(err.value).startswith(f"{name}: atol must be a finite number >= 1e-100 "
                                     "(steplab.integrators.references.MIN_ATOL")
    assert str(err.value).endswith(f"got {value!r}")


@pytest.mark.parametrize("name", REFERENCES)
def test_reference_tolerances_at_their_bounds_are_kept(name):
    method = configured(name, {"rtol": references.MIN_RTOL, "atol": references.MIN_ATOL})
    assert (method.rtol, method.atol) == (references.MIN_RTOL, references.MIN_ATOL)
    assert configured(name, {"rtol": 1e-6, "atol": 1}).atol == 1


@pytest.mark.parametrize("integrator,key,value", [("scipy-dop853", "atol", "0.0"), ("scipy-dop853", "rtol", "nan"),
                                                  ("scipy-radau", "rtol", "-1.0"), ("diffrax-tsit5", "rtol", '"x"')])
def test_bad_reference_tolerances_in_a_scene_are_one_line(capsys, tmp_path, integrator, key, value):
    err = refused(capsys, ["run", scene_file(tmp_path, integrator, key, value)])
    assert f"[simulation.{integrator}]: {integrator}: {key} must be " in err


def test_a_stalling_reference_tolerance_is_refused_at_the_command_line(tmp_path):
    err = refusal(scene_file(tmp_path, "scipy-dop853", "atol", "0.0"))
    assert "scipy-dop853: atol must be a finite number >= 1e-100" in err


def test_a_scipy_solve_that_stops_before_the_first_saved_time_is_reported():
    # atol 1e-300 (below MIN_ATOL, so only reachable here): y / atol overflows and the first step
    # fails; solve_ivp then leaves its states as [], which used to end in an AttributeError
    def spring(t, y):
        d = y[0, 1] - y[0, 0]
        length = np.linalg.norm(d)
        a = np.zeros((2, 3))
        a[1] = -39.478 * (length - 1.0) * d / length
        return np.stack([y[1], a])

    y0 = np.zeros((2, 2, 3))
    y0[0, 1, 0] = 1.5
    with np.errstate(all="ignore"):
        sol = references.solve_adaptive(spring, np.linspace(0.0, 0.5, 6), y0, "scipy-dop853", 1e-12, 1e-300)
    assert not sol.success and sol.ys.shape == (0, 2, 2, 3) and "step size" in sol.message


class _Endless(Exception):
    """A vector field called past any sensible count: the solve was never going to stop by itself."""


def counted_oscillator(limit):
    """A 1 Hz oscillator's vector field that counts its calls (``calls[0]``) and raises past ``limit``."""
    calls = [0]

    def vector_field(t, y):
        calls[0] += 1
        if calls[0] > limit:
            raise _Endless
        return np.stack([y[1], -(2 * np.pi) ** 2 * y[0]])

    return vector_field, calls


@pytest.mark.parametrize("method", ["scipy-dop853", "scipy-radau", "scipy-rk45"])
def test_a_hopeless_scipy_solve_ends_within_its_first_evaluations(method):
    # a span of 1e300 s takes ~1e302 evaluations: the budget alone let solve_ivp make all 12,000,000 of its
    # own (minutes of Python calls) before it said so; the rate of the first ones says it already
    vector_field, calls = counted_oscillator(100_000)
    y0 = np.zeros((2, 1, 3))
    y0[0, 0, 0] = 1.0
    sol = references.solve_adaptive(vector_field, np.array([0.0, 1e300]), y0, method, 1e-10, 1e-10)
    assert not sol.success and sol.ys.shape == (0, 2, 1, 3) and sol.steps == references.MAX_REFERENCE_STEPS
    assert sol.evaluations == calls[0] == references.BUDGET_LOOK_EVERY
    assert "reached t = " in sol.message and "of 1e+300 s" in sol.message, sol.message


def test_a_scipy_solve_on_course_stops_at_its_budget_not_before():
    # 40 s at 1e-12 take about 15,000 evaluations: inside a budget of 2,000 steps (24,000) the first look at the
    # rate lets the solve go on; a budget of 100 steps (1,200 evaluations) is spent before the first look
    vector_field, calls = counted_oscillator(100_000)
    y0 = np.zeros((2, 1, 3))
    y0[0, 0, 0] = 1.0
    sol = references.solve_adaptive(vector_field, np.array([0.0, 40.0]), y0, "scipy-dop853", 1e-12, 1e-12,
                                    max_steps=2000)
    assert sol.success and calls[0] > references.BUDGET_LOOK_EVERY
    calls[0] = 0
    sol = references.solve_adaptive(vector_field, np.array([0.0, 10.0]), y0, "scipy-dop853", 1e-12, 1e-12,
                                    max_steps=100)
    assert not sol.success and sol.evaluations == calls[0] == 1200
    assert sol.message == "it took its budget of 1,200 vector-field evaluations"


# --- the contact solver's sweeps ----------------------------------------------------------------

def test_contact_solver_sweeps_per_step_have_an_upper_bound():
    with pytest.raises(ValueError, match=r"contact solver: iterations x substeps must be at most 100,000 sweeps a "
                                         r"step \(steplab.physics.collision.solver_settings.MAX_SWEEPS\), "
                                         r"got 1,000,000 x 1,000,000 = 1,000,000,000,000"):
        solver_settings.ContactSolver(iterations=10**6, substeps=10**6)
    bound = solver_settings.MAX_SWEEPS
    assert solver_settings.ContactSolver(iterations=bound, substeps=1).iterations == bound
    assert solver_settings.ContactSolver(iterations=100, substeps=bound // 100).substeps == bound // 100


def test_contact_solver_flags_within_their_caps_but_not_together_are_refused(capsys):
    err = refused(capsys, ["run", "box-column", "--iterations", "1000000", "--substeps", "1000000", "--steps", "1"])
    assert "contact solver: iterations x substeps must be at most 100,000 sweeps a step" in err


def test_contact_solver_scene_settings_are_bounded_together(capsys, tmp_path):
    text = (Path(__file__).parents[1] / "physics" / "scenes" / "box-column.toml").read_text()
    assert "[collisions.solver]" not in text
    path = tmp_path / "column.toml"
    path.write_text(text + "\n[collisions.solver]\niterations = 1000\nsubsteps = 1000\n")
    err = refused(capsys, ["run", str(path), "--steps", "1"])
    assert "collisions.solver.iterations: iterations x substeps must be at most 100,000 sweeps a step" in err


def test_a_reference_out_of_steps_says_its_budget_not_diffraxs_advice(capsys, monkeypatch):
    # diffrax's own words were "Try increasing `max_steps`", which no command line can do
    monkeypatch.setattr(references, "MAX_REFERENCE_STEPS", 20)
    from steplab.cli import main

    assert main(["run", "oscillator", "--integrator", "diffrax-tsit5", "--t-end", "10"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "max_steps" not in err
    assert "diffrax-tsit5 failed: it took its budget of 20 steps (steplab.integrators.references." in err
