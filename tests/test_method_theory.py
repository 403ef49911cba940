"""Each method owns its theory: linear map, spectral radius, stability limit, style.

The map is derived from the method's own ``step``; it is checked against what the
methods state (a Runge-Kutta tableau's R(z), implicit Euler's 1 / (1 - z)), against the
exact solution exp(lambda dt) of the test equation, and against closed forms of the
limits. A stepper written here, which no study knows by name, runs through the stability,
truncation and work-precision studies.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq
from steplab.integrators import (
    INTEGRATORS,
    ButcherTableau,
    ExplicitRungeKutta,
    Stepper,
    get_integrator,
    linear_stability,
)
from steplab.integrators.linear_stability import oscillator_eigenvalues

STEPPERS = [name for name, method in INTEGRATORS.items() if isinstance(method, Stepper)]
WITH_R = [name for name in STEPPERS if INTEGRATORS[name].stability_function is not None]
OMEGA_DTS = (0.1, 1.0, 2.5)


@dataclasses.dataclass(frozen=True)
class KickDriftKick(Stepper):
    """2nd order kick-drift-kick leapfrog, keeping the last acceleration (one evaluation per step).

    v_half = v + dt/2 a0;  q1 = q + dt v_half;  a1 = a(t + dt, q1, v_half + dt/2 a0);  v1 = v_half + dt/2 a1.
    A velocity-dependent force sees the predicted v1 (v_half alone would be off by O(dt) and
    leave the method 1st order on a damped oscillator).
    """

    name = "kdk"
    order = 2
    evaluations = 1
    symplectic = True

    def init(self, model, t, y):
        return model.acceleration(t, y[0], y[1])

    def step(self, model, t, y, dt, carry):
        v_half = y[1] + (0.5 * dt) * carry
        q1 = y[0] + dt * v_half
        a1 = model.acceleration(t + dt, q1, v_half + (0.5 * dt) * carry)
        return model.xp.stack([q1, v_half + (0.5 * dt) * a1]), a1


@pytest.fixture
def kdk(monkeypatch):
    monkeypatch.setitem(INTEGRATORS, "kdk", KickDriftKick())
    return "kdk"


# --- the derived map against what the methods state --------------------------------------


@pytest.mark.parametrize("zeta", [0.0, 0.1])
@pytest.mark.parametrize("name", WITH_R)
def test_derived_map_has_the_eigenvalues_of_the_stated_stability_function(name, zeta):
    """A method with R(z) maps the oscillator's eigenvectors by R(omega dt lambda)."""
    method = INTEGRATORS[name]
    for y in OMEGA_DTS:
        eigenvalues = np.sort_complex(np.linalg.eigvals(method.linear_map(y, zeta)))
        stated = np.sort_complex(np.array([complex(method.stability_function(y * lam))
                                           for lam in oscillator_eigenvalues(zeta)]))
        np.testing.assert_allclose(eigenvalues, stated, rtol=1e-12, atol=1e-14)
        assert method.spectral_radius(y, zeta) == pytest.approx(max(abs(stated)), rel=1e-12)


@pytest.mark.parametrize("name", STEPPERS + ["kdk"])
def test_derived_map_approximates_the_exact_growth_to_the_declared_order(name, kdk):
    """The map's eigenvalue nearest exp(lambda dt) is off by O(dt^(p+1)): halving dt cuts it 2^(p+1)-fold."""
    method = get_integrator(name)
    lam = oscillator_eigenvalues(0.1)[0]
    errors = []
    for y in (0.02, 0.01):
        exact = np.exp(y * lam)
        errors.append(min(abs(np.linalg.eigvals(method.linear_map(y, 0.1)) - exact)))
    assert math.log2(errors[0] / errors[1]) == pytest.approx(method.order + 1, abs=0.1)


def test_semi_implicit_euler_map_is_the_written_out_recurrence():
    """v1 = v + h (-u - 2 zeta v), u1 = u + h v1, as a matrix on (u, v)."""
    h, zeta = 0.7, 0.1
    expected = np.array([[1 - h * h, h - 2 * zeta * h * h], [-h, 1 - 2 * zeta * h]])
    np.testing.assert_allclose(INTEGRATORS["semi-implicit-euler"].linear_map(h, zeta), expected, rtol=1e-15)


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.3])
def test_semi_implicit_euler_limit_is_its_closed_form(zeta):
    # trace 2 - y^2 - 2 zeta y, det 1 - 2 zeta y: an eigenvalue reaches -1 at y^2 + 4 zeta y - 4 = 0
    assert INTEGRATORS["semi-implicit-euler"].stability_limit(zeta) == pytest.approx(
        2 * math.sqrt(1 + zeta**2) - 2 * zeta, abs=1e-9)


@pytest.mark.parametrize(("name", "limit"), [("rk4", 2 * math.sqrt(2)), ("velocity-verlet", 2.0),
                                             ("position-verlet", 2.0), ("euler", 0.0), ("implicit-euler", None)])
def test_undamped_limits_are_their_closed_forms(name, limit):
    value = INTEGRATORS[name].stability_limit(0.0)
    assert value is None if limit is None else value == pytest.approx(limit, abs=1e-9)


def _whole_grid_limit(stepper, zeta):
    """The limit the whole grid brackets, every point evaluated: what the search's coarse scan must find."""
    ys = np.geomspace(linear_stability.OMEGA_DT_MIN, linear_stability.OMEGA_DT_MAX, linear_stability.LIMIT_GRID_POINTS)
    excess = lambda y: stepper.spectral_radius(y, zeta) - 1 - linear_stability.THEORY_TOLERANCE  # noqa: E731
    stable = [excess(y) <= 0 for y in ys]
    if not stable[0]:
        return 0.0
    if all(stable):
        return None
    k = stable.index(False)
    return brentq(excess, ys[k - 1], ys[k], xtol=linear_stability.LIMIT_XTOL)


@pytest.mark.parametrize("zeta", [0.0, 0.1, 1.0])
@pytest.mark.parametrize("name", WITH_R + ["semi-implicit-euler"])
def test_the_coarse_scan_finds_the_whole_grids_limit(name, zeta):
    """Scanning every 20th point first skips no unstable window of these methods: the same limit, to the bit."""
    method = INTEGRATORS[name]
    assert linear_stability._search_limit(method, zeta) == _whole_grid_limit(method, zeta)


@pytest.mark.slow
@pytest.mark.parametrize("zeta", [0.0, 0.01, 0.1, 0.5, 1.0, 2.0])
@pytest.mark.parametrize("name", [n for n in INTEGRATORS if hasattr(INTEGRATORS[n], "spectral_radius")])
def test_the_coarse_scan_finds_the_whole_grids_limit_for_every_method(name, zeta):
    """Every method with a linear map, the position-based ones too (4,000 radii each: about 2 minutes)."""
    method = INTEGRATORS[name]
    assert linear_stability._search_limit(method, zeta) == _whole_grid_limit(method, zeta)


def test_explicit_euler_is_the_one_stage_tableau():
    euler = INTEGRATORS["euler"]
    assert isinstance(euler, ExplicitRungeKutta) and euler.tableau.stages == 1
    z = np.array([0.3 + 0.2j, -1.7, 2j])
    np.testing.assert_array_equal(euler.stability_function(z), 1 + z)


def test_every_method_has_a_style_and_a_stability_note():
    from steplab.studies.plotting import style

    assert all(INTEGRATORS[name].stability_note for name in STEPPERS)
    drawn = {(style(name)["color"], style(name)["marker"]) for name in STEPPERS}
    assert len(drawn) == len(STEPPERS)  # no two built-in methods look alike


def test_regions_group_methods_with_the_same_stability_function(monkeypatch):
    """Every 2-stage 2nd order explicit RK method has R(z) = 1 + z + z^2 / 2: one region."""
    from steplab.studies.stability import stability_regions

    @dataclasses.dataclass(frozen=True)
    class Ralston(ExplicitRungeKutta):
        name, order, evaluations = "ralston", 2, 2
        tableau = ButcherTableau(a_lower=((2 / 3,),), b=(1 / 4, 3 / 4), c=(2 / 3,))

    monkeypatch.setitem(INTEGRATORS, "ralston", Ralston())
    groups = stability_regions(STEPPERS + ["ralston"])
    assert ["heun", "midpoint", "ralston"] in groups and ["rk4"] in groups and ["implicit-euler"] in groups
    assert not any(name in sum(groups, []) for name in ("semi-implicit-euler", "velocity-verlet"))


# --- a stepper no study knows by name ------------------------------------------------------


def test_new_stepper_runs_through_the_stability_study(kdk):
    from steplab.studies.plotting import style
    from steplab.studies.stability_limits import measured_limit, oscillator_mode

    theory = INTEGRATORS[kdk].stability_limit(0.0)
    assert theory == pytest.approx(2.0, abs=1e-9)  # leapfrog: trace 2 - y^2, det 1
    measured = measured_limit(oscillator_mode(0.0), KickDriftKick(), 2000)["omega_dt_max"]
    assert measured == pytest.approx(theory, abs=1e-4)
    assert style(kdk) == style(kdk) and style(kdk)["label"] == kdk  # a deterministic spare style


def test_new_stepper_runs_through_the_truncation_study(kdk):
    from steplab.studies import truncation

    record = truncation.compute({"problems": ["oscillator"], "integrators": [kdk], "precisions": ["float64"],
                                 "min_log2_steps": 4, "max_log2_steps": 11})
    assert record["declared_orders"] == {kdk: 2}
    assert record["orders"]["oscillator"][kdk] == pytest.approx(2, abs=0.15)


def test_new_stepper_runs_through_the_work_precision_study(kdk):
    from steplab.studies import work_precision

    record = work_precision.compute({"scenes": ["oscillator"], "integrators": [kdk], "log2_steps": [8, 10],
                                     "rtols": [], "adaptive": []})
    points = [p for p in record["points"] if p["method"] == kdk]
    assert [p["steps"] for p in points] == [256, 1024]
    assert [p["evaluations"] for p in points] == [256, 1024]
    # second order: four times the steps, a sixteenth of the error
    assert points[0]["error"] / points[1]["error"] == pytest.approx(16, rel=0.1)


def test_a_carry_the_map_cannot_read_is_one_clear_error():
    @dataclasses.dataclass(frozen=True)
    class KeepsATuple(KickDriftKick):
        name = "keeps-a-tuple"

        def init(self, model, t, y):
            return (y[0], y[1])

    with pytest.raises(TypeError, match="keeps-a-tuple: .*override linear_map"):
        KeepsATuple().linear_map(0.5)


@pytest.mark.parametrize("zeta", [2.0, 1e10, 1e200, 1e307])
def test_overdamped_eigenvalues_are_the_roots_without_overflow(zeta):
    # lambda^2 + 2 zeta lambda + 1 = 0: the product of the roots is 1, their sum -2 zeta; zeta^2
    # overflows from 1e154, where the formula with sqrt(zeta^2 - 1) gave inf - inf = NaN
    slow, fast = oscillator_eigenvalues(zeta)
    assert slow.imag == fast.imag == 0 and math.isfinite(fast.real)
    assert slow * fast == pytest.approx(1.0, rel=1e-14)
    assert slow + fast == pytest.approx(-2 * zeta, rel=1e-14)


@pytest.mark.parametrize("name", ["euler", "semi-implicit-euler", "rk4", "heun", "implicit-euler",
                                  "exponential-damping-euler"])
def test_a_damping_ratio_near_the_float_range_is_judged_not_raised(name):
    # zeta = 8e306 (a damper of 1e308 N s/m on the 1 kg oscillator): an explicit step grows by up to
    # 1e305 or overflows (inf), never a LinAlgError from a non-finite map nor a NaN taken for stable
    method, zeta = INTEGRATORS[name], 8e306
    radius = method.spectral_radius(0.01, zeta)
    damping_implicit = name in ("implicit-euler", "exponential-damping-euler")
    assert radius <= 1 if damping_implicit else radius > 1e300
    assert (method.stability_limit(zeta) is None) if damping_implicit else method.stability_limit(zeta) == 0
