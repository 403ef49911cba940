"""Bad input at the fringes of the command line: an empty item in a comma list, a spring whose ends start
at one point, a body so light that its stiffness overflowed on the way, an unbounded --repeat. Each is
one line naming what, where and what is allowed, status 2, or (a model whose numbers are all finite) the
answer itself; never a traceback or a vague "overflowing forces?". Each case is ``main`` in this process."""

import numpy as np
import pytest
from helpers import refused, run_main

#: a pinned anchor and a mass on a spring; format with the mass, its position and the spring's table
SPRING_SCENE = """\
[simulation]
integrator = "semi-implicit-euler"
dt = 0.01
t_end = 1.0

[[bodies]]
name = "anchor"
mass = 1.0
radius = 0.05
position = [0.0, 0.0, 0.0]
pinned = true

[[bodies]]
name = "mass"
mass = {mass}
radius = 0.05
position = [{x}, 0.0, 0.0]

[[forces.springs]]
bodies = ["anchor", "mass"]
stiffness = {stiffness}
{rest}
"""


def spring_scene(tmp_path, mass=1.0, x=1.5, stiffness=10.0, rest="rest_length = 1.0") -> str:
    path = tmp_path / "spring.toml"
    path.write_text(SPRING_SCENE.format(mass=mass, x=x, stiffness=stiffness, rest=rest))
    return str(path)


# --- 1. an empty item of a comma list is refused, never dropped -------------------------------------------


@pytest.mark.parametrize(("value", "message"), [
    ("rk4,,euler", "argument --integrators: item 2 of 3 in 'rk4,,euler' is empty"),
    ("rk4,", "argument --integrators: item 2 of 2 in 'rk4,' is empty"),
    (" , ", "argument --integrators: item 1 of 2 in ' , ' is empty"),
])
def test_recommend_refuses_an_empty_item_of_its_integrators(capsys, value, message):
    """``rk4,,euler`` ran rk4 and euler as if nothing had been typed between the commas (an empty list:
    tests/test_cli_refusals_more.py)."""
    err = refused(capsys, ["recommend", "projectile", "--tol", "0.01", "--integrators", value])
    assert err.startswith("steplab recommend: error: ") and message in err, err
    assert "names separated by single commas" in err


def test_a_comma_list_strips_each_name():
    from steplab.cli.args import comma_list

    assert comma_list("rk4, euler ,heun") == ["rk4", "euler", "heun"]
    assert comma_list("rk4") == ["rk4"]


# --- 2. springs with no direction; stiffness that overflows only on the way ----------------------------------


@pytest.mark.parametrize(("x", "where"), [("0.0", "start at the same point"),
                                          ("1e-300", "start 1e-300 m apart, too close for their distance")])
def test_a_spring_with_a_rest_length_and_no_direction_is_refused_at_its_table(capsys, tmp_path, x, where):
    """Its ends at one point (or so close that the squared distance underflows) and rest_length > 0: check
    said "not finite (overflowing forces?)", and run held the mass there for ever (no force)."""
    path = spring_scene(tmp_path, x=x)
    for command in ("check", "run"):
        err = refused(capsys, [command, path])
        assert f"{path}: forces.springs[0]: the spring's ends, bodies 'anchor' and 'mass', {where}" in err, err
        assert "place the ends apart, or give rest_length = 0" in err
        assert "overflowing forces?" not in err


def test_a_zero_length_spring_with_its_ends_at_one_point_still_loads(tmp_path):
    from steplab.physics.scene import load_scene

    for rest in ("", "rest_length = 0.0"):  # the default rest length: the initial distance, 0
        assert load_scene(spring_scene(tmp_path, x="0.0", rest=rest)).model.forces[0].rest_length[0] == 0


def test_check_predicts_the_mode_of_a_light_body_whose_stiffness_is_finite(capsys, tmp_path):
    """A mass of 1e-300 kg on k = 10 N/m: omega^2 = 1e301 s^-2, finite, but D z = 1e150 overflowed on the way
    (status 2, "overflowing forces?"). Now the answer: omega_max = sqrt(1e301), every explicit method unstable."""
    status, out, err = run_main(capsys, ["check", spring_scene(tmp_path, mass="1e-300")])
    assert status == 0, err
    assert "stiffest mode omega_max = 3.16228e+150 rad/s" in out
    assert "6.325e-151" in out and "UNSTABLE" in out


def test_check_names_the_body_whose_stiffness_over_mass_overflows(capsys, tmp_path):
    """k / m = 1e10 / 1e-300 is beyond float64: one line naming the body, its mass, and what overflows."""
    err = refused(capsys, ["check", spring_scene(tmp_path, mass="1e-300", stiffness="1e10")])
    assert "not finite at body 'mass' (mass 1e-300 kg): the stiffness of its forces over its mass, k / m, " \
           "overflows float64" in err, err
    assert "overflowing forces?" not in err


def test_the_damping_ratio_of_a_light_body_is_not_lost_to_overflow():
    """zeta's product J_v (D z) overflowed as S z did: the ratio came out 0 (or inf). c / (2 m omega)."""
    from steplab.physics import Dampers, Model, Springs
    from steplab.physics.modes import stiffest_mode

    one = np.array([0]), np.array([1])
    model = Model([1.0, 1e-300], [0.1, 0.1], [Springs(*one, np.array([10.0]), np.array([1.0])),
                                              Dampers(*one, np.array([1e-150]))], pinned=[True, False])
    q = np.array([[0.0, 0, 0], [1.0, 0, 0]])  # at rest length
    mode = stiffest_mode(model, q)
    assert mode.omega == pytest.approx(np.sqrt(1e301), rel=1e-12)
    assert mode.damping_ratio == pytest.approx(1e-150 / (2 * 1e-300 * np.sqrt(1e301)), rel=1e-9)


# --- 3. a tiny moment of inertia under the contact solver: a run that diverges, status 1 ---------------------


def test_a_tiny_moment_of_inertia_under_the_contact_solver_stops_in_one_line(capsys, tmp_path):
    """Not refused when read: 1 / I r^2 = 1e298 is finite, and the solver already diverges at I = 1e-12 kg m^2
    (I / m r^2 = 1e-10) with dt, substeps and friction deciding where. A run that diverges: status 1, one line."""
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "physics" / "scenes" / "rolling-sphere.toml").read_text()
    path = tmp_path / "light-ball.toml"
    path.write_text(text.replace('shape = "sphere"', 'shape = "sphere"\ninertia = [1e-300, 1e-300, 1e-300]'))
    status, _, err = run_main(capsys, ["run", str(path), "--t-end", "0.1"])
    assert status == 1 and "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith("steplab run: error: "), err
    assert "became non-finite at body 'ball' in the step from" in err, err  # which body, of a scene of many


# --- 4. bench --repeat has a bound -------------------------------------------------------------------------


def test_bench_repeat_is_bounded(capsys):
    """--repeat 99999999 started that many whole benches, one after another."""
    # with --from, so that a steplab without the bound refuses it for another reason instead of running benches
    err = refused(capsys, ["bench", "--from", "no-such.json", "--repeat", "101"])
    assert "argument --repeat: must be at most 100 (each run is a whole bench" in err and "got 101" in err, err
    from steplab.cli.bench import MAX_REPEAT, repeat_count

    assert MAX_REPEAT == 100 and repeat_count("100") == 100
