"""The stiffest mode of springs at body-frame points counts the bodies' turns: check's and run's
stability limit on such a scene is the one its runs meet."""

import json

import numpy as np
import pytest
from helpers import run_main


def test_a_cube_hung_at_its_corner_has_the_transverse_mode_its_turn_allows():
    """A spring of rest length 0 at a corner r of a cube (isotropic inertia I = m a^2 / 6) pulls the
    corner as a point of effective mass 1 / (1/m + |r|^2 / I) across r: omega = sqrt(k (1/m + |r|^2/I)),
    2.3 times the sqrt(k / m) the translation alone gives (its lever arm held)."""
    from steplab.integrators.stable_dt import scene_mode
    from steplab.physics.modes import stiffest_mode
    from steplab.physics.scene import load_scene

    scene = load_scene("spring-pendulum")
    k, m, a = 1e5, 1.0, 0.1
    r2 = 3 * (a / 2) ** 2
    exact = np.sqrt(k * (1 / m + r2 / (m * a * a / 6)))
    mode = scene_mode(scene.model, scene.y0[0], scene.rigid_bodies)
    assert mode.omega == pytest.approx(exact, rel=1e-3)  # the spring's tension m g adds 4e-4
    assert stiffest_mode(scene.model, scene.y0[0]).omega == pytest.approx(np.sqrt(k / m), rel=1e-9)


@pytest.mark.parametrize("fraction, stable", [(0.95, True), (1.05, False)])
def test_runs_meet_the_predicted_limit(capsys, fraction, stable):
    """Semi-implicit Euler (omega dt <= 2) on the hung cube: just under the predicted dt its energy stays
    within 1e-4 over 0.5 s, just over it the run blows up, and run warns there only."""
    from steplab.integrators.stable_dt import scene_mode
    from steplab.physics.scene import load_scene

    scene = load_scene("spring-pendulum")
    dt = fraction * 2 / scene_mode(scene.model, scene.y0[0], scene.rigid_bodies).omega
    status, out, err = run_main(capsys, ["run", "spring-pendulum", "--dt", repr(dt), "--t-end", "0.5", "--json"])
    summary = json.loads(out)
    assert status == 0 and (abs(summary["energy_relative_change"]) < 1e-4) == stable, summary
    assert ("exceeds the largest stable dt of semi-implicit-euler" in err) == (not stable), err
