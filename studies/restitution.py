"""Restitution study: the lecture's drop table, reproduced by simulated drops, and checked.

The lecture dropped nine balls from H = 92 cm, measured five bounce heights each and
listed c.o.r. = sqrt(h_ave / H). Here each ball is dropped with its c.o.r. as the
restitution of the ball-floor pair, with each collision detector and a range of time
steps, and the first bounce height h gives the measured eps = sqrt(h / H): how well does
a detector reproduce the restitution it was given? Free flight is integrated with
velocity Verlet, which is exact under constant gravity, so what differs from the
lecture's value is the detector's doing. The energy kept per bounce (eps^2) is measured
over several bounces, and the lecture's table and its statements about restitution are
checked by computation (:func:`lecture_errors`).
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from steplab.integrators import simulate
from steplab.integrators.simulate import step_count
from steplab.physics import Gravity, Model
from steplab.physics.collision import CollisionWorld, PairProperties, Plane
from steplab.physics.collision.response import impulse

from . import plotting
from .lecture import LECTURE_ERRORS_TABLE
from .runner import Study, run_tasks
from .tables import Table, markdown_table

#: the lecture's drop height, cm
H_CM = 92.0
#: "Coefficient of Restitution (3 of 6)": object, h1..h5 (cm), h_ave (cm), c.o.r., as printed
LECTURE_TABLE = [
    ("range golf ball", (67, 66, 68, 68, 70), "67.8", "0.858"),
    ("tennis ball", (47, 46, 45, 48, 47), "46.6", "0.712"),
    ("billiard ball", (60, 55, 61, 59, 62), "59.4", "0.804"),
    ("hand ball", (51, 51, 52, 53, 53), "52.0", "0.752"),
    ("wooden ball", (31, 38, 36, 32, 30), "33.4", "0.603"),
    ("steel ball bearing", (32, 33, 34, 32, 33), "32.8", "0.597"),
    ("glass marble", (37, 40, 43, 39, 40), "39.8", "0.658"),
    ("ball of rubber bands", (62, 63, 64, 62, 64), "63.0", "0.828"),
    ("hollow, hard plastic ball", (47, 44, 43, 42, 42), "43.6", "0.688"),
]
#: the dropped ball (a golf ball; the bounce height does not depend on size or mass)
MASS, RADIUS = 0.0459, 0.0214
G = 9.81
#: detector variants: name -> (detector, bisection iterations)
DETECTORS = {"swept": ("swept", 5), "overlap": ("overlap", 5), "overlap, no bisection": ("overlap", 0)}


def parameters(quick: bool) -> dict:
    return {
        "H_cm": H_CM, "mass": MASS, "radius": RADIUS, "g": G, "integrator": "velocity-verlet",
        "dt": 0.001, "detectors": list(DETECTORS),
        "dts": [0.01, 0.001] if quick else [0.01, 0.003, 0.001, 0.0003],
        "objects": [name for name, *_ in LECTURE_TABLE] if not quick else
                   ["range golf ball", "wooden ball", "steel ball bearing"],
        "bounces": 3 if quick else 5, "compare_integrators": ["semi-implicit-euler", "euler"],
    }


def drop(eps: float, dt: float, detector: str, bisection: int, bounces: int, integrator: str,
         params: dict, system=None) -> dict:
    """Drop a ball from H onto the floor; the apex heights (cm) of its first ``bounces`` bounces.

    The ball's bottom starts H above the floor. Each apex is the vertex of the parabola
    through the three saved samples around the highest one (exact for velocity Verlet's
    exact free flight). ``system`` (a system under test, :mod:`.system`) drops the ball
    instead of steplab's integrator and detector; its bounces are then told apart by the
    turns of the ball's vertical velocity (an engine's contact lasts several steps), and the
    impact speeds are not recorded.
    """
    H, r, g = params["H_cm"] / 100, params["radius"], params["g"]
    model = Model([params["mass"]], [r], [Gravity(np.array([0.0, 0.0, -g]))])
    world = CollisionWorld(detector, (Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor"),),
                           pair_properties=PairProperties(eps), bisection_iterations=bisection)
    v1 = math.sqrt(2 * g * H)
    flight = math.sqrt(2 * H / g) + sum(2 * eps**k * v1 / g for k in range(1, bounces + 1))
    y0 = np.array([[[0.0, 0.0, H + r]], [[0.0, 0.0, 0.0]]])
    t_end = flight + 0.5 * eps**bounces * v1 / g
    if system is None:
        traj = simulate(model, integrator, y0, 0.0, t_end, dt, collisions=world)
        impacts = [e for e in traj.collisions.events if e.kind == "impact"]
        times = [e.t for e in impacts] + [np.inf]
    else:
        traj = system.build(model, world, dt, y0).advance(y0, dt, step_count(0.0, t_end, dt))
        impacts = []
        # a bounce begins where the ball, falling, starts to rise
        vz = traj.velocities[:, 0, 2]
        times = [float(traj.t[k]) for k in np.flatnonzero((vz[:-1] <= 0) & (vz[1:] > 0))] + [np.inf]
    z = traj.positions[:, 0, 2] - r
    apexes = []
    for a, b in zip(times[:bounces], times[1:bounces + 1]):
        inside = np.flatnonzero((traj.t > a) & (traj.t < b))
        if len(inside) < 3:
            break
        k = inside[np.argmax(z[inside])]
        k = min(max(k, inside[1]), inside[-2])
        z0, z1, z2 = z[k - 1], z[k], z[k + 1]
        curvature = z0 - 2 * z1 + z2
        apexes.append(100 * float(z1 - 0.125 * (z2 - z0) ** 2 / curvature if curvature < 0 else z1))
    first = impacts[0] if impacts else None
    return {"apex_cm": apexes, "impacts": len(impacts),
            "impact_speed": first.impact_speed if first else None,
            "speed_after": first.impulse / params["mass"] - first.impact_speed if first else None}  # V+ = V- + L/m


def lecture_table_check() -> list[dict]:
    """Recompute h_ave and c.o.r. = sqrt(h_ave / H) from the printed heights."""
    rows = []
    for name, heights, h_ave, cor in LECTURE_TABLE:
        mean = float(np.mean(heights))
        recomputed = math.sqrt(mean / H_CM)
        rows.append({
            "object": name, "h_cm": list(heights), "h_ave_printed": h_ave, "h_ave_recomputed": mean,
            "cor_printed": cor, "cor_recomputed": recomputed,
            "cor_mean_of_sqrt": float(np.mean(np.sqrt(np.array(heights) / H_CM))),
            "cor_spread": float(np.std(np.sqrt(np.array(heights) / H_CM), ddof=1)),
            "h_ave_consistent": abs(mean - float(h_ave)) <= 0.05,
            "cor_consistent": abs(recomputed - float(cor)) <= 0.0005,
        })
    return rows


class PseudocodeParticle(NamedTuple):
    """One particle of the lecture's N-particle pseudo-code at a collision: its position there
    ``p``, its ``V_init`` (the velocity at ``time_init``) and its ``mass``."""

    p: np.ndarray
    v_init: np.ndarray
    mass: float


def pseudocode_collision(i: PseudocodeParticle, j: PseudocodeParticle, eps: float, telapsed: float, g) -> dict:
    """The lecture's N-particle pseudo-code at one collision of particles ``i`` and ``j``, as
    printed, and corrected.

    As printed, the velocities at the collision (vi, vj) are used but never computed, and
    the restart ``V_init[i] += impulse / mass[i]`` keeps the *initial* velocity while
    ``p_init`` and ``time_init`` move to the collision, so the velocity gravity added
    since ``time_init`` (g telapsed) is lost. Reading vi as the velocity at the
    collision, the printed update and the corrected one (V_init = vi + impulse / m) are
    returned with the momentum just before.
    """
    m_i, m_j = i.mass, j.mass
    vi, vj = i.v_init + g * telapsed, j.v_init + g * telapsed
    normal = (j.p - i.p) / np.linalg.norm(j.p - i.p)
    lam = impulse(vi, vj, 1 / m_i, 1 / m_j, normal, eps)
    printed = (i.v_init + lam / m_i, j.v_init - lam / m_j)
    corrected = (vi + lam / m_i, vj - lam / m_j)
    return {"momentum_before": (m_i * vi + m_j * vj).tolist(),
            "momentum_after_printed": (m_i * printed[0] + m_j * printed[1]).tolist(),
            "momentum_after_corrected": (m_i * corrected[0] + m_j * corrected[1]).tolist()}


def lecture_errors(rows: list[dict], table: list[dict], params: dict) -> list[dict]:
    """The collision-response chapter's errors, each with the computation that shows it."""
    golf = next(r for r in rows if r["object"] == "range golf ball")
    v_minus, v_plus = golf["impact_speed_swept"], golf["speed_after_swept"]
    ratio = v_plus / -v_minus  # floor at rest: (V+ - 0) / (V- - 0), V- = -impact speed
    energy_ratio = golf["energy_per_bounce_swept"][0] if golf["energy_per_bounce_swept"] else None
    g = np.array([0.0, 0.0, -9.81])
    code = pseudocode_collision(PseudocodeParticle(np.array([0.0, 0, 10]), np.array([2.0, 0, 0]), 1.0),
                                PseudocodeParticle(np.array([0.2, 0, 10]), np.array([-2.0, 0, 0]), 1.0), 1.0, 0.5, g)
    errors = [
        {"where": "Coefficient of Restitution (2 of 6)",
         "printed": "eps = (V1+ - V2+) / (V1- - V2-)",
         "correct": "eps = -((V1+ - V2+) . n) / ((V1- - V2-) . n), as equation 3 says",
         "evidence": f"the simulated golf ball (eps = 0.858) hits the floor at V- = {-v_minus:.4f} m/s and "
                     f"leaves at V+ = {v_plus:+.4f} m/s: the printed ratio is {ratio:+.4f}, negative; it "
                     f"also divides vectors, which only makes sense for their normal components"},
        {"where": "Coefficient of Restitution (1 of 6)",
         "printed": "c.o.r. is how much of the kinetic energy ... remains as kinetic energy after collision",
         "correct": "the fraction of kinetic energy kept (floor, normal impact) is eps^2 = h / H, not eps",
         "evidence": (f"golf ball, eps = 0.858: energy after / before the first bounce = {energy_ratio:.4f} "
                      f"= 0.858^2 = {0.858**2:.4f}" if energy_ratio else "")},
        {"where": "Putting It All Together",
         "printed": "Have 3 equations (equation 1, 1+ and 4) and 3 unknowns",
         "correct": "equations 1 (for each body), 2 and 3; equation 4 is their solution",
         "evidence": "equation 4 follows from 1, 2 and 3 (see physics/collision/response.py); checked: "
                     "its sign is right, and it is even in n, so either normal orientation gives the same impulse"},
        {"where": "Coefficient of Restitution (6 of 6)",
         "printed": "5 different types of objects -> 10 (5 choose 2 = 10) different CORs",
         "correct": "15: the 10 pairs of different objects plus the 5 pairs of an object with its own kind "
                    "(billiard ball on billiard ball)",
         "evidence": f"len(combinations_with_replacement(range(5), 2)) = "
                     f"{len(list(itertools.combinations_with_replacement(range(5), 2)))}"},
        {"where": "Pseudocode (2 of 5) - (4 of 5)",
         "printed": "impulse *= normal.DotProduct(vi-vj); ... V_init[i] += impulse/mass[i]; time_init[i] = t_collide",
         "correct": "compute vi = V_init[i] + g telapsed (and vj) and restart with V_init[i] = vi + impulse/mass[i]",
         "evidence": "vi and vj are used but never computed, and the update keeps the initial velocity while "
                     "time_init moves to t_collide, losing g telapsed: two 1 kg balls falling 0.5 s before "
                     f"meeting have momentum {np.round(code['momentum_before'], 4).tolist()} kg m/s before; "
                     f"the printed update leaves {np.round(code['momentum_after_printed'], 4).tolist()}, the "
                     f"corrected one {np.round(code['momentum_after_corrected'], 4).tolist()}"},
        {"where": "Pseudocode (1 of 5) - (2 of 5)",
         "printed": "vector v_init[N] ... V_init[i]; float t_collide ... tcollide; float telapsed declared twice",
         "correct": "one name per variable (V_init, t_collide) and one declaration of telapsed per scope",
         "evidence": "as printed the C-like code does not compile: V_init and tcollide are undeclared and "
                     "telapsed is redeclared in the same block"},
        {"where": "Collision Response in Simulation Loop",
         "printed": "Split into two parts, t to t_c and then t_c to Delta t",
         "correct": "t to t_c, then t_c to t + Delta t",
         "evidence": "the second part ends where the step ends, at t + Delta t"},
    ]
    bad = [r for r in table if not (r["h_ave_consistent"] and r["cor_consistent"])]
    errors.append({
        "where": "Coefficient of Restitution (3 of 6), the table",
        "printed": "h_ave and c.o.r. columns",
        "correct": "checked: no misprint" if not bad else ", ".join(r["object"] for r in bad),
        "evidence": "every h_ave is the mean of h1..h5 and every c.o.r. is sqrt(h_ave / 92) to the printed "
                    "3 digits (recomputed: " + ", ".join(f"{r['cor_recomputed']:.4f}" for r in table) + "); "
                    "note it is the c.o.r. of the average height, not the average c.o.r., which differs "
                    "in the 4th digit, and the spread between drops (wooden ball: "
                    f"{next(r['cor_spread'] for r in table if r['object'] == 'wooden ball'):.3f}) is far larger",
        "is_error": bool(bad)})
    return errors


def tasks(params: dict) -> list[list]:
    """One drop per ball, detector and dt (several bounces at the main dt), and one per ball and
    compared integrator."""
    return ([["drop", name, label, dt] for name in params["objects"] for label in params["detectors"]
             for dt in params["dts"]]
            + [["integrator", name, integrator] for name in params["objects"]
               for integrator in params["compare_integrators"]])


def task(params: dict, item: list) -> dict:
    """One drop of :func:`tasks`: its apex heights (and first impact)."""
    eps = {name: float(c) for name, _, _, c in LECTURE_TABLE}[item[1]]
    if item[0] == "integrator":
        return drop(eps, params["dt"], "swept", 5, 1, item[2], params)
    _, _, label, dt = item
    detector, bisection = DETECTORS[label]
    return drop(eps, dt, detector, bisection, params["bounces"] if dt == params["dt"] else 1,
                params["integrator"], params)


def reduce(params: dict, results: list) -> dict:
    """The record from the drops: each ball's measured c.o.r. per detector, the dt sweep, the checks."""
    table = lecture_table_check()
    cor = {name: float(c) for name, _, _, c in LECTURE_TABLE}
    drops = {tuple(item): result for item, result in zip(tasks(params), results)}
    rows, sweep = [], []
    for name in params["objects"]:
        eps = cor[name]
        row = {"object": name, "cor_lecture": eps, "cor_measured": {}, "h_cm": {}, "energy_per_bounce": {}}
        for label in params["detectors"]:
            for dt in params["dts"]:
                result = drops["drop", name, label, dt]
                h = result["apex_cm"][0]
                measured = math.sqrt(h / params["H_cm"])
                sweep.append({"object": name, "detector": label, "dt": dt, "h_cm": h, "cor_measured": measured,
                              "relative_error": abs(measured - eps) / eps})
                if dt == params["dt"]:
                    row["cor_measured"][label] = measured
                    row["h_cm"][label] = h
                    heights = [params["H_cm"]] + result["apex_cm"]
                    row["energy_per_bounce"][label] = [b / a for a, b in zip(heights, heights[1:])]
                    row["apex_cm_" + label] = result["apex_cm"]
                    if label == "swept":
                        row["impact_speed_swept"] = result["impact_speed"]
                        row["speed_after_swept"] = result["speed_after"]
                        row["energy_per_bounce_swept"] = row["energy_per_bounce"][label]
        for integrator in params["compare_integrators"]:
            result = drops["integrator", name, integrator]
            row.setdefault("cor_measured_by_integrator", {})[integrator] = math.sqrt(
                result["apex_cm"][0] / params["H_cm"])
        rows.append(row)
    return {"dt": params["dt"], "rows": rows, "dt_sweep": sweep, "lecture_table": table,
            "lecture_errors": lecture_errors(rows, table, params)}


def compute(params: dict, progress=None) -> dict:
    """Every drop in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    rows, labels = record["rows"], record["parameters"]["detectors"]
    colours = {"swept": "tab:blue", "overlap": "tab:orange", "overlap, no bisection": "tab:red"}
    markers = {"swept": "o", "overlap": "s", "overlap, no bisection": "^"}
    figures = []

    # 1. the table: lecture c.o.r. against measured, and the relative error per detector
    fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(12, 0.45 * len(rows) + 2.6), sharey=True,
                                     gridspec_kw={"width_ratios": [1.2, 1]})
    ys = np.arange(len(rows))
    ax.scatter([r["cor_lecture"] for r in rows], ys, s=140, facecolors="none", edgecolors="k", lw=1.5,
               label="lecture c.o.r. = sqrt(h_ave / H)", zorder=3)
    for k, label in enumerate(labels):
        offset = (k - (len(labels) - 1) / 2) * 0.18
        ax.scatter([r["cor_measured"][label] for r in rows], ys + offset, marker=markers[label],
                   color=colours[label], s=30, label=f"measured, {label}", zorder=4)
        errors = [max(abs(r["cor_measured"][label] - r["cor_lecture"]) / r["cor_lecture"], 1e-12) * 100
                  for r in rows]
        ax_err.scatter(errors, ys + offset, marker=markers[label], color=colours[label], s=30, label=label)
    ax.set_yticks(ys, [r["object"] for r in rows])
    ax.invert_yaxis()
    ax.set_xlabel("coefficient of restitution eps = sqrt(h / H)")
    ax.set_title(f"Drop from H = {record['parameters']['H_cm']:g} cm, dt = {record['dt'] * 1e3:g} ms")
    ax.grid(True, alpha=0.3)
    ax_err.set_xscale("log")
    ax_err.axvline(1.0, color="gray", ls="--", lw=1)
    ax_err.text(1.0, 0.01, " 1 %", color="gray", va="bottom", fontsize=8, transform=ax_err.get_xaxis_transform())
    ax_err.set_xlabel("|measured - lecture| / lecture (%)")
    ax_err.set_title("Relative error of the recovered eps")
    ax_err.grid(True, which="major", alpha=0.3)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.legend(*ax.get_legend_handles_labels(), loc="lower center", ncol=len(labels) + 1, fontsize=8)
    figures += plotting.save_figure(fig, out, "restitution_table")

    # 2. error against dt, worst over the objects, per detector
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    sweep = record["dt_sweep"]
    for label in labels:
        dts = sorted({p["dt"] for p in sweep if p["detector"] == label})
        worst = [max(max(p["relative_error"] for p in sweep if p["detector"] == label and p["dt"] == dt), 1e-12)
                 for dt in dts]
        ax.loglog(dts, [100 * w for w in worst], marker=markers[label], color=colours[label], label=label)
    ax.axhline(1.0, color="gray", ls="--", lw=1, label="1 %")
    ax.set_xlabel("time step dt (s)")
    ax.set_ylabel("worst relative error of eps over the balls (%)")
    ax.set_title("Recovered restitution against time step\n"
                 "(velocity Verlet: free flight exact, error is the detector's)")
    ax.legend(fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "restitution_dt")

    # 3. energy kept per bounce against eps^2
    fig, ax = plt.subplots(figsize=(8.4, 4.6))
    for r in rows:
        kept = r["energy_per_bounce"]["swept"]
        ax.plot(np.arange(1, len(kept) + 1), kept, marker="o", ms=4, lw=1, label=r["object"])
        colour = ax.lines[-1].get_color()
        ax.axhline(r["cor_lecture"] ** 2, color=colour, ls=":", lw=0.8)
        ax.axhline(r["cor_lecture"], color=colour, ls="--", lw=0.8, alpha=0.5)
    ax.set_xlabel("bounce number")
    ax.set_ylabel("energy after / energy before the bounce (h_k+1 / h_k)")
    ax.set_title("Energy kept per bounce (swept detector): eps^2 (dotted),\n"
                 "not eps (dashed) as 'Coefficient of Restitution (1 of 6)' suggests", fontsize=10)
    ax.set_xticks(np.arange(1, len(rows[0]["energy_per_bounce"]["swept"]) + 1))
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "restitution_energy")
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    out = []
    for label in record["parameters"]["detectors"]:
        worst = max(abs(r["cor_measured"][label] - r["cor_lecture"]) / r["cor_lecture"] for r in record["rows"])
        out.append((f"worst eps error at dt = {record['dt'] * 1e3:g} ms, {label}", f"{100 * worst:.3g} %"))
    errors = [e for e in record["lecture_errors"] if e.get("is_error", True)]
    out.append(("lecture errors found (response chapter)", str(len(errors))))
    return out


# --- the paper's tables -------------------------------------------------------------


def restitution_table(data: dict) -> str:
    """The lecture's coefficient of restitution of each ball against each detector's measurement."""
    rows = [[r["object"], f"{r['cor_lecture']:.3f}"] + [f"{r['cor_measured'][d]:.4f}" for d in data["detectors"]]
            for r in data["rows"]]
    return markdown_table(["ball", "lecture c.o.r."] + [f"measured, {d}" for d in data["detectors"]], rows)


TABLES = (
    Table("restitution", lambda r: {"rows": [{k: row[k] for k in ("object", "cor_lecture", "cor_measured")}
                                             for row in r["rows"]],
                                    "detectors": list(r["rows"][0]["cor_measured"])}, restitution_table),
    LECTURE_ERRORS_TABLE,
)


STUDY = Study("restitution", "Restitution: the lecture's drop table reproduced by each collision detector",
              parameters, compute, plot, summary, tables=TABLES,
              tasks=tasks, task=task, reduce=reduce)
