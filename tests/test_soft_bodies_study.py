"""The soft-bodies study's measurements, each against an independent closed form or brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from steplab.integrators import VBD, XPBD, simulate
from steplab.studies import STUDIES, builtin_studies
from steplab.studies import soft_bodies as sb


def test_the_lowest_mode_is_an_eigenmode_and_scales_as_the_root_of_k():
    scene = sb.cloth_scene(side=6, damping=0.0, gravity=False)
    omega, shape = sb.lowest_mode(scene)
    # independently of the Jacobian: a small displacement along the shape is pulled back by omega^2 times it
    q0 = np.asarray(scene.y0[0])
    eps = 1e-7
    accel = [np.asarray(scene.model.acceleration(0.0, q0 + s * eps * shape, np.zeros_like(q0))) for s in (1, -1)]
    np.testing.assert_allclose((accel[0] - accel[1]) / (2 * eps), -omega**2 * shape, atol=1e-5 * omega**2)
    stiffer, _ = sb.lowest_mode(sb.cloth_scene(side=6, stiffness=400.0, damping=0.0, gravity=False))
    assert stiffer / omega == pytest.approx(2.0, rel=1e-10)  # omega_1 = c sqrt(k / m)


def test_converged_xpbd_and_vbd_turn_the_lowest_mode_as_implicit_euler_does():
    # implicit Euler multiplies a linear mode by 1 / (1 - i omega dt) a step: it turns by atan(omega dt),
    # so the measured omega is that angle over dt, not omega; converged, an xpbd or a vbd step is
    # implicit Euler's on the springs
    scene = sb.cloth_scene(side=6, damping=0.0, gravity=False)
    omega, shape = sb.lowest_mode(scene)
    y0 = np.array(scene.y0)
    y0[0] += sb.MODE_AMPLITUDE * shape
    dt = 1 / 60
    theory = math.atan(omega * dt) / dt
    assert abs(theory / omega - 1) > 0.01  # far enough from omega for the check to tell them apart
    for method in (XPBD(1, 200), VBD(1, 200)):
        traj = simulate(scene.model, method, y0, 0.0, 3 * 2 * np.pi / omega, dt)
        assert sb.measured_omega(traj, shape) == pytest.approx(theory, rel=1e-4)


def test_the_equal_time_claim_interpolates_implicit_euler_in_log_log():
    rows = [{"method": "implicit-euler", "dt": 0.01, "seconds": 1.0, "position_error": 1.0},
            {"method": "implicit-euler", "dt": 0.0001, "seconds": 100.0, "position_error": 0.01},
            {"method": "xpbd", "settings": {"substeps": 8}, "seconds": 10.0, "position_error": 0.005},
            {"method": "xpbd", "settings": {"substeps": 2}, "seconds": 0.1, "position_error": 2.0}]
    claim = sb.equal_time_claim(rows)
    inside, outside = claim["ratios"]
    assert inside["implicit_euler_error"] == pytest.approx(0.1) and inside["ratio"] == pytest.approx(0.05)
    assert inside["inside"] and not outside["inside"] and outside["ratio"] == pytest.approx(2.0)
    assert claim["best_ratio"] == pytest.approx(0.05) and claim["holds"]
    # the slowest xpbd run (10 s) is not faster than implicit Euler's cheapest (1 s, dt = 0.01)
    assert claim["slowest_xpbd"] is inside and claim["cheapest_implicit_euler"]["dt"] == 0.01
    assert claim["xpbd_always_faster"] is False
    slower = [r | {"seconds": 50 * r["seconds"]} if r["method"] == "implicit-euler" else r for r in rows]
    assert sb.equal_time_claim(slower)["xpbd_always_faster"] is True


def test_xpbd_makes_energy_under_heavy_dampers_only_while_its_iterations_have_not_converged():
    # c = 10 N s/m at a frame: gamma = c / (k h) = 6. The model's energy cannot grow (its dampers take it
    # out); ten iterations leave the sweep unconverged and the cloth gains energy, converged it loses it
    scene = sb.cloth_scene(damping=10.0)
    start = scene.model.energy(scene.y0)

    def change(iterations):
        y = simulate(scene.model, XPBD(1, iterations), scene.y0, 0.0, 0.25, sb.FRAME).y[-1]
        return scene.model.energy(y) - start

    converged = change(1000)
    assert change(10) > 0.1 and converged < -0.1 and abs(change(200) - converged) < 1e-3


def test_damping_findings_pick_the_least_damping_that_makes_energy():
    rows = [{"method": m, "damping": c, "gamma": g, "energy_change": e}
            for m, c, g, e in (("xpbd 1x10", 1.0, 0.6, -0.2), ("xpbd 1x10", 10.0, 6.0, 3.0),
                               ("xpbd 1x10", 100.0, 60.0, 11.0), ("xpbd 10x1", 1.0, 6.0, 0.1),
                               ("xpbd 10x1", 100.0, 600.0, None), ("implicit Euler", 100.0, None, -0.5),
                               ("implicit Euler", 1000.0, None, None))]
    for r in rows:
        r["finite"] = r["energy_change"] is not None
    f = sb.damping_findings(rows)
    assert (f["xpbd_1x10_first_gain_damping"], f["xpbd_1x10_first_gain_gamma"]) == (10.0, 6.0)
    assert (f["xpbd_10x1_first_gain_damping"], f["xpbd_10x1_first_gain_gamma"]) == (1.0, 6.0)
    assert (f["xpbd_1x10_energy_change_at_100"], f["xpbd_10x1_energy_change_at_100"],
            f["implicit_euler_energy_change_at_100"]) == (11.0, None, -0.5)
    assert f["implicit_euler_first_failed_damping"] == 1000.0


def test_the_study_is_registered_and_reproduced():
    assert STUDIES["soft-bodies"] is sb.STUDY and sb.STUDY in builtin_studies()


@pytest.mark.slow
def test_the_quick_study_runs_and_plots(tmp_path):
    params = sb.parameters(True)
    record = sb.compute(params) | {"parameters": params}
    assert len(sb.plot(record, tmp_path)) == 10
    f = record["findings"]
    # XPBD's converged iterations keep k; PBD's make the cloth about as many times stiffer as it iterates
    assert abs(f["xpbd_stiffness_ratio_small_dt"] - 1) < 0.01 and f["pbd_stiffness_ratio_small_dt"] > 3
    assert f["xpbd_substeps_error"] < f["xpbd_iterations_error"]  # small steps beat many iterations
    assert f["inextensible_stretch_xpbd_10x1"] < 0.05
    # heavy dampers: unconverged xpbd makes energy, implicit Euler does not
    assert f["xpbd_1x10_first_gain_damping"] is not None and f["implicit_euler_energy_change_at_100"] < 0
