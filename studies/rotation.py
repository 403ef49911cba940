"""Rotation study: the engines' rotation methods against the exact tumbling of a free rigid body.

Every number is checked against the exact solution or a stated invariant:

- the Dzhanibekov flip (principal moments 1, 2, 3 kg m^2, spun near the intermediate axis):
  the measured period of omega(t) against the closed form T = 4 K(m) / lambda
  (:mod:`steplab.integrators.torque_free`), and the orientation error after a few periods
  against the exact q(t), for every method and omega dt; the fitted order of that error;
- the drift of the energy and of |L| over many flips;
- the largest stable omega dt about each principal axis (stable: finite, and the energy
  never more than :data:`STABLE_ENERGY_GROWTH` above its start);
- a spin about the stable major axis and how long each method takes to make it a tumbler
  (the nutation angle between the body's axis 3 and L passing :data:`TUMBLER_ANGLE`);
- Bullet's gyroscopic demo body (a disc with a cross bar, omega = (0, 0.1, 10) rad/s);
- a heavy top's precession rate against the slow root of I1 Omega^2 cos(theta) - I3 s Omega + M g d = 0;
- the engines (:mod:`.rotation_engines`, where installed): each setting named as one of these
  methods, and its energy and |L| drift beside theirs on the flip box and the demo body.

All bodies of one experiment run together as one batch (one body per omega dt: scaling omega
scales time, so one dt covers every omega dt); the long drift runs use the compiled loop.
"""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import NullFormatter
from steplab.integrators import ROTATIONS, get_rotation
from steplab.integrators.rotation import simulate_rotation
from steplab.integrators.rotation_stability import stable_omega_dt
from steplab.integrators.torque_free import TorqueFreeMotion
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import ForceAtPoint, RotationModel, principal_inertia, rotational_energy

from . import plotting, rotation_engines
from .runner import Study
from .tables import Table, format_value, markdown_table

#: the Dzhanibekov body and its spin near the intermediate axis
INERTIA = (1.0, 2.0, 3.0)
FLIP_OMEGA = (0.05, 1.0, 0.05)
#: the game's frame step, s: every experiment runs at it (omega sets omega dt)
DT = 1 / 60
#: a method is stable at omega dt while its energy stays below (1 + this) times the start
STABLE_ENERGY_GROWTH = 0.1
#: a spin about the major axis has become a tumbler once the axis is this far from L, degrees
TUMBLER_ANGLE = 30.0
#: the perturbation of a spin about one principal axis (relative, in the other two components)
PERTURBATION = 1e-3
#: the heavy top: mass kg, centre of mass d m above the pivot, moments about the pivot kg m^2,
#: spin s rad/s, tilt theta rad (a steady precession at the slow root from the start)
TOP = {"mass": 1.0, "d": 0.1, "i1": 0.02, "i3": 0.01, "spin": 50.0, "theta": np.pi / 6, "g": 9.81}


def parameters(quick: bool) -> dict:
    common = {"methods": list(ROTATIONS), "dt": DT, "inertia": list(INERTIA), "flip_omega": list(FLIP_OMEGA),
              "engines": rotation_engines.parameters(quick)}
    if quick:
        return common | {"flip_omega_dt": [0.4, 0.2, 0.1, 0.05, 0.025, 0.0125], "period_omega_dt_min": 0.05,
                         "flip_periods": 2, "drift_omega_dt": 0.4,
                         "drift_periods": 20, "drift_backend": "numpy",
                         "stability_omega_dt": np.geomspace(0.05, 50, 19).tolist(), "stability_steps": 200,
                         "top_dts": [1 / 60, 1 / 240], "top_time": 3.0}
    return common | {"flip_omega_dt": [0.8, 0.4, 0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625], "period_omega_dt_min": 0.025,
                     "flip_periods": 3, "drift_omega_dt": 0.4,
                     "drift_periods": 5000, "drift_backend": "jax",
                     "stability_omega_dt": np.geomspace(0.05, 50, 31).tolist(), "stability_steps": 1000,
                     "top_dts": [1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960, 1 / 1920], "top_time": 3.0}


def _finite(x):
    """A float for the record, None where it is not finite (a diverged body)."""
    x = float(x)
    return x if np.isfinite(x) else None


def _batch(inertia_rows):
    return RotationModel(np.array(inertia_rows, float))


# --- the Dzhanibekov flip: period and orientation error ----------------------------------------


def crossing_times(t, omega2, rate2):
    """Upward zero crossings of omega2(t), each located by the cubic Hermite interpolant of
    (omega2, domega2/dt) on its step (error O(dt^4), below every method's own error)."""
    times = []
    for k in np.nonzero((omega2[:-1] < 0) & (omega2[1:] >= 0))[0]:
        h = t[k + 1] - t[k]
        y0, y1, m0, m1 = omega2[k], omega2[k + 1], rate2[k] * h, rate2[k + 1] * h
        coefficients = [2 * y0 - 2 * y1 + m0 + m1, -3 * y0 + 3 * y1 - 2 * m0 - m1, m0, y0]
        roots = [r.real for r in np.roots(coefficients) if abs(r.imag) < 1e-12 and -1e-12 <= r.real <= 1 + 1e-12]
        if roots:
            times.append(t[k] + h * min(roots, key=lambda r: abs(r - y0 / (y0 - y1))))
    return np.array(times)


def flip(p: dict, name: str) -> list[dict]:
    """Period error and orientation error of ``name`` at each omega dt, one body each, one run.

    The period is measured over ``flip_periods`` periods of each body with omega dt >=
    ``period_omega_dt_min``; the orientation error of every body after one flip (half its period).
    """
    inertia, base = np.array(p["inertia"]), np.array(p["flip_omega"])
    dt, method = p["dt"], get_rotation(name)
    omega0 = np.array([w / dt * base / np.linalg.norm(base) for w in p["flip_omega_dt"]])
    motions = [TorqueFreeMotion(inertia, quat.IDENTITY, w) for w in omega0]
    timed = [omega_dt >= p["period_omega_dt_min"] for omega_dt in p["flip_omega_dt"]]
    t_run = max(max(m.period * (p["flip_periods"] + 0.5) for m, c in zip(motions, timed) if c),
                max(m.period for m in motions) / 2)
    q0 = np.broadcast_to(quat.IDENTITY, (len(omega0), 4))
    t, q, omega = simulate_rotation(method, _batch([inertia] * len(omega0)), q0, omega0, dt, int(np.ceil(t_run / dt)),
                                    check=False)
    rate2 = (inertia[2] - inertia[0]) * omega[..., 2] * omega[..., 0] / inertia[1]  # Euler's equation for omega2
    rows = []
    for j, (motion, omega_dt) in enumerate(zip(motions, p["flip_omega_dt"])):
        crossings = crossing_times(t, omega[:, j, 1], rate2[:, j]) if timed[j] else []
        period = np.mean(np.diff(crossings)) if len(crossings) >= 2 else np.nan
        k = int(round(motion.period / 2 / dt))  # one flip
        error = quat.angle_between(np, q[k, j], motion.orientation(t[k])[0])
        rows.append({"method": name, "omega_dt": omega_dt, "steps_per_period": motion.period / dt,
                     "period_exact": motion.period, "period_error": _finite(abs(period / motion.period - 1)),
                     "orientation_error": _finite(error)})
    return rows


def fitted_order(rows: list[dict]) -> float | None:
    """Slope of log(orientation error) against log(omega dt) over the points between round-off and 0.3 rad."""
    pts = [(r["omega_dt"], r["orientation_error"]) for r in rows
           if r["orientation_error"] is not None and 1e-11 < r["orientation_error"] < 0.3]
    if len(pts) < 3:
        return None
    x, y = np.log(np.array(pts)).T
    return float(np.polyfit(x, y, 1)[0])


# --- drift over many flips, and the stable axis turning into a tumbler ---------------------------


def drift(p: dict, name: str) -> dict:
    """Energy and |L| of the flip body, and the nutation of a major-axis spin, once per period."""
    inertia, base = np.array(p["inertia"]), np.array(p["flip_omega"])
    dt, omega_dt = p["dt"], p["drift_omega_dt"]
    major = np.array([PERTURBATION, PERTURBATION, 1.0])
    omega0 = np.array([omega_dt / dt * base / np.linalg.norm(base), omega_dt / dt * major / np.linalg.norm(major)])
    period = TorqueFreeMotion(inertia, quat.IDENTITY, omega0[0]).period
    per_period = max(1, int(round(period / dt)))
    steps = per_period * p["drift_periods"]
    model = _batch([inertia, inertia])
    t, q, omega = simulate_rotation(get_rotation(name), model, np.broadcast_to(quat.IDENTITY, (2, 4)), omega0, dt,
                                    steps, save_every=per_period, backend=p["drift_backend"], check=False)
    energy = rotational_energy(np, model.inertia, omega)
    momentum = np.linalg.norm(model.inertia * omega, axis=-1)
    with np.errstate(invalid="ignore"):
        nutation = np.degrees(np.arccos(np.clip(inertia[2] * omega[:, 1, 2] / momentum[:, 1], -1, 1)))
        tumbled = np.nonzero(~(nutation < TUMBLER_ANGLE))[0]

    def relative(x):
        with np.errstate(invalid="ignore", divide="ignore"):
            return [_finite(v) for v in x / x[0] - 1]

    return {"method": name, "periods": (t / period).tolist(), "period": period, "steps_per_period": per_period,
            "energy": relative(energy[:, 0]), "momentum": relative(momentum[:, 0]),
            "nutation_deg": [_finite(v) for v in nutation], "time": t.tolist(),
            "tumbler_after_s": float(t[tumbled[0]]) if len(tumbled) else None}


# --- stability about each principal axis ---------------------------------------------------------


def stability(p: dict, name: str) -> dict:
    """Largest omega dt (on the grid) up to which a spin about each principal axis stays stable."""
    directions = np.full((3, 3), PERTURBATION) + (1 - PERTURBATION) * np.eye(3)
    limits = stable_omega_dt(get_rotation(name), p["inertia"], directions, p["stability_omega_dt"],
                             p["stability_steps"], STABLE_ENERGY_GROWTH)
    return {"method": name} | {f"axis{axis + 1}": limit for axis, limit in enumerate(limits)}


# --- Bullet's gyroscopic demo and the heavy top --------------------------------------------------


def bullet_body() -> np.ndarray:
    """Principal moments of a disc (cylinder r = 0.5 m, 0.1 m thick along z, 1 kg) with a cross bar
    (box 1.6 x 0.1 x 0.1 m along x, 0.5 kg) through its centre, our version of Bullet's demo body."""
    return principal_inertia("cylinder", 1.0, 0.5, length=0.1) + principal_inertia("box", 0.5, 0.0,
                                                                                     size=[1.6, 0.1, 0.1])


BULLET_OMEGA = (0.0, 0.1, 10.0)
BULLET_TIME = 10.0


def bullet(p: dict, name: str) -> dict:
    """Energy, |L| and orientation error of the demo body after :data:`BULLET_TIME` s at dt."""
    inertia, omega0, dt = bullet_body(), np.array([BULLET_OMEGA]), p["dt"]
    steps = int(round(BULLET_TIME / dt))
    t, q, omega = simulate_rotation(get_rotation(name), _batch([inertia]), quat.IDENTITY[None], omega0, dt, steps,
                                    save_every=steps, check=False)
    exact = TorqueFreeMotion(inertia, quat.IDENTITY, omega0[0])
    energy = rotational_energy(np, inertia, omega[:, 0])
    momentum = np.linalg.norm(inertia * omega[:, 0], axis=-1)
    return {"method": name, "energy_change": _finite(energy[-1] / energy[0] - 1),
            "momentum_change": _finite(momentum[-1] / momentum[0] - 1),
            "orientation_error": _finite(quat.angle_between(np, q[-1, 0], exact.orientation(t[-1])[0]))}


def top_precession() -> float:
    """The slow root Omega of I1 Omega^2 cos(theta) - I3 s Omega + M g d = 0 (Goldstein 5.7), rad/s."""
    c = np.cos(TOP["theta"])
    a, b, k = TOP["i1"] * c, TOP["i3"] * TOP["spin"], TOP["mass"] * TOP["g"] * TOP["d"]
    return float((b - np.sqrt(b * b - 4 * a * k)) / (2 * a))


def heavy_top(p: dict, name: str) -> list[dict]:
    """The precession rate of the body axis about the vertical, fitted over the run, at each dt."""
    big_omega = top_precession()
    theta, spin = TOP["theta"], TOP["spin"]
    inertia = np.array([TOP["i1"], TOP["i1"], TOP["i3"]])
    model = RotationModel(inertia[None], (ForceAtPoint(np.array([0.0, 0.0, TOP["d"]]),
                                                       np.array([0.0, 0.0, -TOP["mass"] * TOP["g"]])),))
    q0 = quat.from_axis_angle(np, np.array([[1.0, 0.0, 0.0]]), theta)  # axis 3 tilted by theta
    # steady precession: omega = Omega e_z (world) + psi' e3, with the spin s = omega3 = psi' + Omega cos(theta)
    axis = quat.rotate(np, q0, np.array([[0.0, 0.0, 1.0]]))
    omega_world = big_omega * np.array([[0.0, 0.0, 1.0]]) + (spin - big_omega * np.cos(theta)) * axis
    omega0 = quat.rotate_inverse(np, q0, omega_world)
    rows = []
    for dt in p["top_dts"]:
        steps = int(round(p["top_time"] / dt))
        t, q, _ = simulate_rotation(get_rotation(name), model, q0, omega0, dt, steps, check=False)
        body_axis = quat.rotate(np, q[:, 0], np.array([0.0, 0.0, 1.0]))
        with np.errstate(invalid="ignore"):
            azimuth = np.unwrap(np.arctan2(body_axis[:, 1], body_axis[:, 0]))
        rate = np.polyfit(t, azimuth, 1)[0] if np.all(np.isfinite(azimuth)) else np.nan
        rows.append({"method": name, "dt": dt, "rate": _finite(rate), "error": _finite(abs(rate / big_omega - 1))})
    return rows


# --- the study -----------------------------------------------------------------------------------


def compute(p: dict, progress=None) -> dict:
    record = {"flip": [], "drift": [], "stability": [], "bullet": [], "heavy_top": [], "orders": {}}
    for name in p["methods"]:
        with np.errstate(over="ignore", invalid="ignore"):  # diverging bodies are measured, not warned about
            rows = flip(p, name)
            record["flip"] += rows
            record["orders"][name] = fitted_order(rows)
            record["drift"].append(drift(p, name))
            record["stability"].append(stability(p, name))
            record["bullet"].append(bullet(p, name))
            record["heavy_top"] += heavy_top(p, name)
        if progress is not None:
            progress()
    record["methods"] = p["methods"]  # in the registry's order (the record's dicts are written with sorted keys)
    record["declared_orders"] = {name: get_rotation(name).order for name in p["methods"]}
    record["period_closed_form"] = TorqueFreeMotion(p["inertia"], quat.IDENTITY, p["flip_omega"]).period
    record["top_precession"] = top_precession()
    record["bullet_inertia"] = bullet_body().tolist()
    record |= {"inertia": p["inertia"], "drift_omega_dt": p["drift_omega_dt"],
               "stability_grid_min": min(p["stability_omega_dt"]), "stability_grid_max": max(p["stability_omega_dt"])}
    with np.errstate(over="ignore", invalid="ignore"):
        record["engines"] = rotation_engines.measure(p["engines"], (bullet_body().tolist(), list(BULLET_OMEGA)),
                                                     p["drift_backend"])
    return record


def _style(name: str) -> dict:
    colour, marker = get_rotation(name).style
    return {"color": colour, "marker": marker, "label": name}


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    methods = record["methods"]
    figures = []

    fig, (left, right) = plt.subplots(1, 2, figsize=(12.4, 4.8))
    for name in methods:
        rows = [r for r in record["flip"] if r["method"] == name]
        style = _style(name)
        pts = [(r["omega_dt"], r["period_error"]) for r in rows if r["period_error"]]
        if pts:
            left.loglog(*zip(*pts), ms=5, lw=1.2, **style)
        pts = [(r["omega_dt"], r["orientation_error"]) for r in rows if r["orientation_error"]]
        order = record["orders"][name]
        if pts:
            right.loglog(*zip(*pts), ms=5, lw=1.2, **(style | {"label": f"{name} (slope {order:.2f})"
                                                              if order is not None else name}))
    left.set_ylabel("|measured period / closed-form period - 1|")
    left.set_title("Dzhanibekov flip: period of omega(t), T = 4K(m)/lambda")
    right.set_ylabel("orientation error after one flip (rad)")
    right.set_title("orientation against the exact q(t); fitted order")
    for ax in (left, right):
        ax.set_xlabel("|omega| dt (rad per step), dt = 1/60 s")
        ax.xaxis.set_minor_formatter(NullFormatter())  # decades only: no overlap
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "rotation_flip")

    fig, (left, right, third) = plt.subplots(1, 3, figsize=(16.5, 4.6))
    floor = 1e-17  # an exact invariant plotted on the axis floor
    for ax, key in ((left, "energy"), (right, "momentum")):
        curves = [[(x, max(abs(y), floor)) for x, y in zip(d["periods"][1:], d[key][1:]) if y is not None]
                  for d in record["drift"]]
        top = rotation_engines.scale_top(curves)
        for n, (d, pts) in enumerate(zip(record["drift"], curves)):
            # markers evenly spaced along the line, staggered, so that the curves that coincide stay visible
            style = _style(d["method"]) | {"ms": 4, "markevery": (0.1 * (n % 8) / 8, 0.1)}
            if pts:
                ax.loglog(*zip(*pts), lw=1.2, **style)
            if None in d[key]:  # where the run diverged, on the top edge
                ax.plot([d["periods"][d[key].index(None)]], [top / 2], marker="x", ms=7, color=style["color"],
                        ls="none")
        ax.set_ylim(floor / 2, top)
        ax.set_xlabel("periods of omega(t) (two flips each)")
        ax.grid(True, which="major", alpha=0.3)
    for d in record["drift"]:
        pts = [(x, y) for x, y in zip(d["time"], d["nutation_deg"]) if y is not None and y > 0]
        if pts:
            third.semilogy(*zip(*pts), lw=1.2, **(_style(d["method"]) | {"marker": None}))
    left.set_ylabel("|E / E0 - 1|")
    left.set_title(f"energy drift, flip body at |omega| dt = {record['drift_omega_dt']:g} (x: diverged)")
    right.set_ylabel("| |L| / |L0| - 1 |")
    right.set_title("drift of |L| (floor 1e-17: kept exactly; x: diverged)")
    third.axhline(TUMBLER_ANGLE, color="k", lw=0.8, ls=":")
    third.set_xlabel("time (s)")
    third.set_ylabel("nutation: angle between body axis 3 and L (degrees)")
    third.set_title(f"spin about the stable major axis (a tumbler above {TUMBLER_ANGLE:g} degrees)")
    third.grid(True, which="major", alpha=0.3)
    handles, labels = left.get_legend_handles_labels()
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)  # hiding no curve
    figures += plotting.save_figure(fig, out, "rotation_drift")

    fig, (left, right) = plt.subplots(1, 2, figsize=(12.4, 4.6))
    width, hatched = 0.8 / 3, []
    for axis in range(3):
        values = [s[f"axis{axis + 1}"] for s in record["stability"]]
        # stable on the whole grid: a bar to its top, hatched; unstable at its smallest point: a stub, crossed
        heights = [record["stability_grid_max"] if v is None else v or record["stability_grid_min"] for v in values]
        bars = left.bar(np.arange(len(values)) + (axis - 1) * width, heights, width, label=f"about axis {axis + 1}"
                        f" (I = {record['inertia'][axis]:g} kg m^2)")
        hatched += [(bar, "//" if v is None else "xx") for bar, v in zip(bars, values) if v is None or v == 0]
    left.set_yscale("log")
    left.set_xticks(np.arange(len(methods)), methods, rotation=35, ha="right", fontsize=8)
    left.set_ylabel("largest stable |omega| dt (rad per step)")
    left.set_title(f"stability: energy within +{100 * STABLE_ENERGY_GROWTH:g} % over the run\n"
                   "(//: stable on the whole grid; xx: unstable at its smallest omega dt)", fontsize=10)
    left.set_ylim(record["stability_grid_min"] / 2, record["stability_grid_max"] * 2)
    left.legend(fontsize=7)
    for bar, hatch in hatched:  # after the legend, whose entries stay plain
        bar.set_hatch(hatch)
    left.grid(True, axis="y", which="major", alpha=0.3)
    for name in methods:
        pts = [(r["dt"], r["error"]) for r in record["heavy_top"] if r["method"] == name and r["error"]]
        if pts:
            right.loglog(*zip(*pts), ms=5, lw=1.2, **_style(name))
    right.set_xlabel("time step dt (s)")
    right.set_ylabel("|precession rate / slow root - 1|")
    right.set_title(f"heavy top: slow root Omega = {record['top_precession']:.4f} rad/s")
    right.grid(True, which="major", alpha=0.3)
    right.legend(fontsize=7)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "rotation_stability_top")
    if "engines" in record:
        figures += rotation_engines.plot(record["engines"], out, _style)
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    rows = [("Dzhanibekov period, closed form", f"{record['period_closed_form']:.6g} s")]
    rows.append(("fitted orientation orders", ", ".join(f"{m} {format_value(s, '.2f')}"
                                                          for m, s in record["orders"].items())))
    engines = record.get("engines")
    if engines is not None:
        named = [f"{r['label']} = {', '.join(r['equals']) or 'none'}" for r in engines["identification"]]
        rows.append(("engines' rotation", "; ".join(named) + (f" ({engines['missing']})" if engines["missing"]
                                                             else "") if named else engines["missing"] or "none"))
    return rows


def rotation_table(data: dict) -> str:
    header = ["method", "order", "fitted", "period error", "energy drift", "|L| drift", "stable omega dt (1, 2, 3)",
              "tumbler after (s)", "heavy top error", "Bullet demo energy"]
    rows = []
    for name in data["methods"]:
        declared = data["declared_orders"][name]
        flip_rows = [r for r in data["flip"] if r["method"] == name]
        coarse = max(flip_rows, key=lambda r: r["omega_dt"] if r["period_error"] is not None else -1)
        d = next(d for d in data["drift"] if d["method"] == name)
        s = next(s for s in data["stability"] if s["method"] == name)
        top = min((r for r in data["heavy_top"] if r["method"] == name), key=lambda r: r["dt"])
        demo = next(b for b in data["bullet"] if b["method"] == name)
        rows.append([name, str(declared), format_value(data["orders"][name], ".2f"),
                     f"{format_value(coarse['period_error'], '.1e')} at {coarse['omega_dt']:g}",
                     _or(d["energy"][-1], ".1e", "diverged"), _or(d["momentum"][-1], ".1e", "diverged"),
                     ", ".join("below grid" if s[f"axis{k}"] == 0 else _or(s[f"axis{k}"], ".2g", "whole grid")
                               for k in (1, 2, 3)),
                     _or(d["tumbler_after_s"], ".3g", "never"), _or(top["error"], ".1e", "diverged"),
                     _or(demo["energy_change"], "+.1e", "diverged")])
    return markdown_table(header, rows) + (
        "\n\n(period error of omega(t) at the largest omega dt measured; drifts relative, at the end of the drift "
        "run; stable omega dt about each principal axis, \"whole grid\": stable at every omega dt tried, \"below "
        "grid\": unstable at the smallest; heavy top at the smallest dt; Bullet demo: relative energy change after "
        f"{BULLET_TIME:g} s at dt = 1/60 s.)")


def _or(value, spec: str, missing: str) -> str:
    return missing if value is None else format(value, spec)


def _table_slice(record: dict) -> dict:
    """What :func:`rotation_table` draws from, and no more: each drift run's last values (the paper's
    numbers file stays small)."""
    drift = [{"method": d["method"], "energy": d["energy"][-1:], "momentum": d["momentum"][-1:],
              "tumbler_after_s": d["tumbler_after_s"]} for d in record["drift"]]
    return {k: record[k] for k in ("methods", "declared_orders", "orders", "flip", "stability", "heavy_top",
                                   "bullet")} | {"drift": drift}


TABLES = (Table("rotation", _table_slice, rotation_table),
          rotation_engines.TABLE.within("engines"))

STUDY = Study("rotation", "Rotation: the engines' rotation methods against the exact tumbling of a rigid body",
              parameters, compute, plot, summary, tables=TABLES)
