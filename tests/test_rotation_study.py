"""The rotation study: its measurements against exact answers, and its figures from the record alone."""

from __future__ import annotations

import json

import numpy as np
import pytest
from steplab.studies import STUDIES
from steplab.studies import rotation as study


def test_crossing_times_are_exact_to_the_interpolants_order():
    t = np.linspace(0.0, 20.0, 401)  # dt = 0.05
    crossings = study.crossing_times(t, np.sin(t), np.cos(t))
    np.testing.assert_allclose(crossings, 2 * np.pi * np.arange(1, 4), atol=1e-7)


def test_the_slow_root_solves_the_precession_equation():
    top, omega = study.TOP, study.top_precession()
    c = np.cos(top["theta"])
    residual = top["i1"] * omega**2 * c - top["i3"] * top["spin"] * omega + top["mass"] * top["g"] * top["d"]
    assert abs(residual) < 1e-12
    fast = top["i3"] * top["spin"] / (top["i1"] * c) - omega  # the other root: the sum of the roots
    assert 0 < omega < fast
    # the fast-top expansion: Omega = Omega0 (1 + e + 2 e^2 + 5 e^3 + ...) (Catalan numbers), Omega0 = M g d / (I3 s),
    # e = I1 M g d cos(theta) / (I3 s)^2 (0.068 here)
    omega0 = top["mass"] * top["g"] * top["d"] / (top["i3"] * top["spin"])
    e = top["i1"] * top["mass"] * top["g"] * top["d"] * c / (top["i3"] * top["spin"]) ** 2
    assert omega == pytest.approx(omega0 * (1 + e + 2 * e * e), rel=10 * e**3)


@pytest.fixture(scope="module")
def record():
    p = study.parameters(True) | {"methods": ["explicit", "implicit-gyroscopic", "implicit-midpoint", "rk4"],
                                  "drift_periods": 10, "stability_steps": 100}
    p["engines"] = p["engines"] | {"settings": []}  # the engines' part: tests/test_engines_rotation.py
    return json.loads(json.dumps(study.compute(p)))  # what the runner writes


def test_record_claims(record):
    orders = record["orders"]
    for name, declared in record["declared_orders"].items():
        assert orders[name] == pytest.approx(declared, abs=0.1), name
    drift = {d["method"]: d for d in record["drift"]}
    assert max(abs(e) for e in drift["implicit-midpoint"]["energy"]) < 1e-12
    assert max(abs(e) for e in drift["implicit-midpoint"]["momentum"]) < 1e-12
    assert all(e <= 0 for e in drift["implicit-gyroscopic"]["energy"])  # damps, never gains
    assert drift["explicit"]["tumbler_after_s"] is not None and drift["rk4"]["tumbler_after_s"] is None
    rk4 = [r for r in record["flip"] if r["method"] == "rk4" and r["period_error"] is not None]
    assert min(r["period_error"] for r in rk4) < 1e-7  # the closed form, to the method's error
    top = [r for r in record["heavy_top"] if r["method"] == "rk4"]
    assert min(r["error"] for r in top) < 1e-3
    stability = {s["method"]: s for s in record["stability"]}
    assert stability["implicit-midpoint"]["axis1"] is None  # stable on the whole grid about the minor axis
    assert 0 < stability["explicit"]["axis2"] < stability["explicit"]["axis1"]


def test_figures_from_the_record_alone(record, tmp_path):
    names = study.plot(record, tmp_path)
    assert {n for n in names if n.endswith(".png")} == {"rotation_flip.png", "rotation_drift.png",
                                                        "rotation_stability_top.png"}
    assert "| explicit | 1 |" in study.rotation_table(record)
    assert STUDIES["rotation"] is study.STUDY


def test_each_engine_setting_has_a_colour_and_a_marker_of_its_own():
    """MuJoCo's four settings share the engine's blue: each gets a shade of it and a marker of its own."""
    from matplotlib import colors
    from steplab.studies.rotation_engines import scale_top, setting_styles

    settings = ["mujoco-euler", "mujoco-implicitfast", "mujoco-implicit", "mujoco-rk4", "bullet-default"]
    engine = {"bullet-default": "tab:orange"} | {k: "tab:blue" for k in settings[:4]}
    styles = setting_styles(settings, engine)
    shades = [styles[k]["color"] for k in settings]
    assert len(set(shades)) == len(settings) and len({styles[k]["marker"] for k in settings[:4]}) == 4
    blue = np.array(colors.to_rgb("tab:blue"))
    for k in settings[:4]:  # a shade of the engine's colour: the same hue, darker or lighter
        shade = np.array(styles[k]["color"])
        assert np.all(shade >= 0) and np.all(shade <= 1)
        assert np.argmax(shade) == np.argmax(blue)
    assert styles["bullet-default"]["color"] == colors.to_rgb("tab:orange")  # alone: the engine's own colour
    assert scale_top([[(1.0, 1e-5)], [(1.0, 150.0)]]) == 1e3 and scale_top([[(1.0, 0.5)]]) == 10.0
