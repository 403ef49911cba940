"""Which translation integrator and rotation method compose on springs at body-frame points, and what the
others do: the coupled step's order against an independent solution, and the growth that `run` warns
about and `check` reports, against what the runs themselves do."""

import json

import numpy as np
import pytest
from helpers import run_main
from spring_pendulum_reference import independent_errors
from steplab.integrators import INTEGRATORS, get_integrator
from steplab.integrators.coupled_stability import coupled_growth, pair_growth
from steplab.integrators.rotation import METHODS
from steplab.integrators.rotation_registry import get_rotation
from steplab.physics.scene import load_scene


@pytest.fixture(scope="module")
def pendulum():
    return load_scene("spring-pendulum")


def test_every_rotation_method_composes_with_registered_integrators():
    for method in METHODS:
        assert method.composes_with and all(name in INTEGRATORS for name in method.composes_with), method.name


@pytest.mark.parametrize("integrator, rotation, order", [("rk4", "rk4", 4),
                                                         ("velocity-verlet", "implicit-midpoint", 2)])
def test_a_composing_pair_converges_at_its_order_to_the_coupled_equations(pendulum, integrator, rotation, order):
    # rk4 with rk4 takes its four stages on (x, v, q, omega) together (it held each system while stepping the
    # other: 7e-3 m at 100 steps, falling at order 0.4); the implicit midpoint rule's free rotation sits in
    # velocity Verlet's Strang splitting as dlm's does (held beside semi-implicit Euler, the pair grows as dlm's).
    # The errors against DOP853 over 0.1 s, centres and lever arms.
    errors = np.array([max(independent_errors(pendulum, integrator, rotation, n, 0.1)) for n in (100, 200, 400)])
    slopes = np.log2(errors[:-1] / errors[1:])
    assert np.all(np.abs(slopes - order) < 0.25), (errors, slopes)
    assert errors[-1] < {4: 1e-9, 2: 1e-7}[order]


COMPOSING = [("semi-implicit-euler", "exponential-map"), ("semi-implicit-euler", "implicit-gyroscopic"),
             ("velocity-verlet", "dlm"), ("velocity-verlet", "implicit-midpoint"), ("rk4", "rk4")]
APART = [("semi-implicit-euler", "dlm"), ("velocity-verlet", "exponential-map"), ("rk4", "exponential-map"),
         ("rk4", "dlm")]


def growth(scene, integrator, rotation, dt):
    return coupled_growth(scene.model, scene.rigid_bodies, get_integrator(integrator), get_rotation(rotation),
                          scene.y0, dt)


def energy_change(capsys, integrator, rotation, dt, t_end):
    """The relative energy change of `steplab run spring-pendulum` and the warnings it printed."""
    status, out, err = run_main(capsys, ["run", "spring-pendulum", "--integrator", integrator, "--rotation", rotation,
                                         "--dt", str(dt), "--t-end", str(t_end), "--json"])
    assert status == 0, err
    summary = json.loads(out)
    return abs(summary["energy_end"] / summary["energy_start"] - 1), summary["warnings"], err


def test_pairs_that_compose_keep_the_linearised_step_on_the_unit_circle(pendulum):
    # symplectic Euler, the Strang splittings and RK4 on the whole system: rho = 1 to the physics' slow growth
    for integrator, rotation in COMPOSING:
        assert abs(growth(pendulum, integrator, rotation, 1e-3) - 1) < 1e-6, (integrator, rotation)


def test_a_pair_apart_grows_as_the_square_of_omega_dt(pendulum):
    # each system stepped with the other held: rho - 1 = c (omega_max dt)^2, 2.1e-2 at 1 ms
    for integrator, rotation in APART:
        rho = [growth(pendulum, integrator, rotation, dt) - 1 for dt in (1e-3, 3e-4, 1e-4)]
        assert rho[0] > 0.02, (integrator, rotation, rho)
        assert rho[1] / rho[2] == pytest.approx(9, rel=0.05), (integrator, rotation, rho)


def test_run_warns_about_the_pairs_that_grow_and_they_do(capsys):
    # 1000 steps of 1 ms: a pair apart grows 1e9-fold linearised; the run's energy grows 50-fold or more
    for integrator, rotation in APART:
        change, warnings, err = energy_change(capsys, integrator, rotation, 1e-3, 1.0)
        assert change > 50, (integrator, rotation, change)
        assert len(warnings) == 1 and "their stages do not match" in warnings[0] and warnings[0] in err
        assert f"pair {rotation} with " in warnings[0] and "-fold over the run's 1000 steps" in warnings[0]
    for integrator, rotation in COMPOSING[:3]:
        change, warnings, err = energy_change(capsys, integrator, rotation, 1e-3, 1.0)
        assert change < 1e-5 and warnings == [] and "warning" not in err, (integrator, rotation, change)


def test_a_short_step_keeps_a_pair_apart_quiet(capsys, pendulum):
    # at 0.1 ms rho = 1.0002: 1.2-fold over 1000 steps, under the warning's factor 2, and the run keeps its energy
    record = pair_growth(pendulum.model, pendulum.rigid_bodies, get_integrator("semi-implicit-euler"),
                         get_rotation("dlm"), pendulum.y0, 1e-4, 1000)
    assert record["verdict"] == "stays" and 0 < record["log10_growth_over_run"] < np.log10(2)
    change, warnings, _ = energy_change(capsys, "semi-implicit-euler", "dlm", 1e-4, 0.1)
    assert change < 1e-3 and warnings == []


def test_check_reports_each_pair_with_the_scenes_rotation(capsys):
    status, out, _ = run_main(capsys, ["check", "spring-pendulum", "--rotation", "dlm", "--json"])
    assert status == 0
    rows = {r["integrator"]: r for r in json.loads(out)["integrators"]}
    assert rows["velocity-verlet"]["coupled"]["verdict"] == "composes" and rows["velocity-verlet"]["stable"]
    apart = rows["semi-implicit-euler"]
    assert apart["coupled"]["verdict"] == "grows" and not apart["stable"]  # within its own limit: 0.37 dt_max
    assert apart["dt_max"] > 2.5e-3 and apart["coupled"]["growth_per_step"] > 1.02
    status, out, _ = run_main(capsys, ["check", "spring-pendulum", "--rotation", "dlm"])
    line = next(row for row in out.splitlines() if row.strip().startswith("semi-implicit-euler"))
    assert "UNSTABLE (the pair grows" in line and "a step" in line
    # the implicit midpoint rule held beside semi-implicit Euler: its Newton iteration solves the stiff torque
    # (the torque's derivative in its matrix), so the pair grows as the splitting does, as dlm's pair
    status, out, _ = run_main(capsys, ["check", "spring-pendulum", "--rotation", "implicit-midpoint", "--json"])
    held = next(r for r in json.loads(out)["integrators"] if r["integrator"] == "semi-implicit-euler")
    assert held["coupled"]["verdict"] == "grows" and not held["stable"]
    assert held["coupled"]["growth_per_step"] == pytest.approx(apart["coupled"]["growth_per_step"], abs=1e-3)


def test_check_without_springs_at_body_points_has_no_pair_column(capsys):
    status, out, _ = run_main(capsys, ["check", "dzhanibekov", "--json"])
    assert status == 0 and all("coupled" not in r for r in json.loads(out)["integrators"])
