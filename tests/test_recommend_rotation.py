"""``steplab recommend`` on a scene with collisions honours ``--rotation`` as it does without them."""

from __future__ import annotations

import json

import pytest

from steplab.cli import main

SCENE = """
[simulation]
integrator = "semi-implicit-euler"
dt = 0.001
t_end = 0.3

[[bodies]]
name = "die"
mass = 0.1
radius = 0.05
position = [0.0, 0.0, 0.3]
# a sphere with the moments of a 6 x 4 x 2 cm box, m/12 (b^2 + c^2, a^2 + c^2, a^2 + b^2): the event
# loop collides it as the sphere it is (boxes need the contact solver) while it tumbles as the box
inertia = [1.6666666666666667e-05, 3.3333333333333335e-05, 4.333333333333334e-05]
angular_velocity = [0.1, 40.0, 0.1]

[forces.gravity]

[collisions]
detector = "swept"

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 1.0]
offset = 0.0
"""


@pytest.mark.parametrize("rotation", ["explicit", "dlm"])
def test_recommend_with_collisions_reports_the_rotation_asked_for(tmp_path, capsys, rotation):
    path = tmp_path / "die.toml"
    path.write_text(SCENE)
    assert main(["recommend", str(path), "--tol", "1e-2", "--integrators", "semi-implicit-euler",
                 "--rotation", rotation, "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert "reference" in record  # the collision path
    assert record["rotation"]["method"] == rotation
    # spun near its intermediate axis, explicit Euler gains energy at every dt; dlm is stable at this dt
    assert record["rotation"]["stable"] == (rotation == "dlm")


def test_recommend_on_the_contact_solver_refuses_a_rotation_run_refuses(capsys):
    # the contact solver turned the boxes with the scene's rotation whatever --rotation said, and recommend
    # reported dlm 'stable at this dt' on box-column, where `steplab run --rotation dlm` is refused
    argv = ["recommend", "box-column", "--t-end", "0.05", "--tol", "0.05", "--integrators", "semi-implicit-euler"]
    assert main([*argv, "--rotation", "dlm"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "rotation method 'dlm' does not compose with it" in err
    assert main([*argv, "--rotation", "momentum-rescaled", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rotation"]["method"] == "momentum-rescaled"


def test_recommend_says_a_rotation_stable_at_no_dt_has_none_as_check_does(capsys):
    # exponential-map on the tumbling boxes grows at every omega dt of check's grid: recommend printed
    # "its dt_max: 0 s", check "none (grows ...)"
    argv = ["--rotation", "exponential-map"]
    assert main(["check", "tumbling-boxes", *argv]) == 0
    assert "none (grows at every omega dt" in capsys.readouterr().out
    assert main(["recommend", "tumbling-boxes", *argv, "--t-end", "0.05", "--tol", "0.05",
                 "--integrators", "semi-implicit-euler"]) == 0
    out = capsys.readouterr().out
    assert "rotation exponential-map: UNSTABLE at this dt (its dt_max: none (grows));" in out, out
