"""Stability at the extremes: huge dt, positions far from the origin, mass ratios across springs.

Part of the stability study.

* Huge dt: a step far beyond a method's limit must end in a reported divergence (the
  step at which it was detected), never in NaN output. The step is predicted from the
  method's growth factor per step rho: the deviation reaches the divergence limit
  after about log(limit / amplitude) / log(rho) steps.
* Far from the origin: a float has a fixed number of significant bits, so the spacing
  between representable positions grows with |x| (np.spacing). A body whose step
  v dt is under half that spacing stalls (x + v dt rounds back to x); a little above it,
  every step is rounded to a multiple of the spacing (a wrong speed); an oscillator's
  spring sees its length only to that spacing (jitter). The tiny-dt round-off floor is
  the same arithmetic seen from the other side (truncation study's V-curves).
* Mass ratios: two bodies on one spring oscillate at omega = sqrt(k (1/m1 + 1/m2)), so
  the light body sets the largest stable dt: with the heavy body fixed, dt_max falls as
  (mass ratio)^(-1/2).
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import DivergenceError, get_integrator, simulate
from steplab.integrators.simulate import divergence_limit
from steplab.physics import Model, Springs

from . import plotting
from .problems import oscillator_problem
from .stability_limits import Mode, stable_dt, worst_deviation
from .tables import Table, format_value, markdown_table

#: the game step of the far-from-origin runs, s
GAME_DT = 1 / 60
#: integrator of the far-from-origin runs: the game-physics default
FAR_INTEGRATOR = "semi-implicit-euler"
#: spring and heavy mass of the mass-ratio runs (N/m, kg)
PAIR_STIFFNESS, HEAVY_MASS = 100.0, 1.0


# --- huge dt ------------------------------------------------------------------------------


def huge_dt(methods, omega_dts, max_steps: int) -> list[dict]:
    """Step at which divergence is detected on a linear oscillator at omega dt far beyond the limits.

    The spring has rest length 0, so the force -k x is linear everywhere. (The lecture
    oscillator's 1 m spring is not: once a huge step throws the mass past its anchor the
    spring flips, and that nonlinearity can hold an unstable method on a bounded orbit:
    RK4 at omega dt = 3 never diverges there.)
    """
    omega, amplitude = 2 * np.pi, 0.5
    model = Model([1.0, 1.0], [0.05, 0.05], [Springs(np.array([0]), np.array([1]), np.array([omega**2]),
                                                     np.array([0.0]))], pinned=[True, False])
    y0 = np.zeros((2, 2, 3))
    y0[0, 1, 0] = amplitude
    limit = divergence_limit(y0, np.float64)
    rows = []
    for method in methods:
        for y in omega_dts:
            dt = y / omega
            rho = get_integrator(method).spectral_radius(y, 0.0)
            predicted = int(np.ceil(np.log(limit / amplitude) / np.log(rho))) if rho > 1 else None
            row = {"integrator": method, "omega_dt": y, "growth_factor": rho, "predicted_step": predicted,
                   "diverged_at_step": None, "message": None, "finite_output": None}
            try:
                traj = simulate(model, method, y0, 0.0, max_steps * dt, dt)
                row["finite_output"] = bool(np.all(np.isfinite(traj.y)))
            except DivergenceError as err:
                row["diverged_at_step"], row["message"] = err.step, str(err)
            rows.append(row)
    return rows


# --- far from the origin ------------------------------------------------------------------


def coasting(offsets, speeds, precisions, steps: int) -> list[dict]:
    """A force-free body at x0 moving at v for ``steps`` game steps: does it move at the right speed?"""
    model = Model([1.0], [0.1], [])
    rows = []
    for precision in precisions:
        dtype = np.dtype(precision)
        for v in speeds:
            increment = dtype.type(v) * dtype.type(GAME_DT)  # the step v dt as the integrator computes it
            for x0 in offsets:
                start = dtype.type(x0)
                y0 = np.zeros((2, 1, 3))
                y0[0, 0, 0], y0[1, 0, 0] = start, v
                traj = simulate(model, FAR_INTEGRATOR, y0, 0.0, steps * GAME_DT, GAME_DT, dtype=dtype)
                assert traj.y.dtype == dtype
                travelled = float(traj.y[-1, 0, 0, 0]) - float(start)
                spacing = float(np.spacing(start))
                rows.append({
                    "precision": precision, "speed": v, "offset": float(start), "spacing": spacing,
                    "speed_error": abs(travelled / (v * steps * GAME_DT) - 1), "stalled": travelled == 0.0,
                    # the rounding model: one step x + v dt rounds back to x, or to a multiple of the spacing
                    "predicted_stall": bool(start + increment == start),
                    "predicted_speed_error": abs(round(float(increment) / spacing) * spacing / (v * GAME_DT) - 1),
                })
    return rows


def oscillator_jitter(offsets, precisions, periods: int) -> list[dict]:
    """The oscillator moved to x0: largest deviation from the same run at the origin, in amplitudes."""
    problem = oscillator_problem(0.0)
    amplitude = abs(problem.y0[0, 1, 0] - 1.0)
    steps = int(round(periods * 2 * np.pi / problem.omega / GAME_DT))

    def run(x0, dtype):
        y0 = problem.y0.copy()
        y0[0, :, 0] += x0
        traj = simulate(problem.model, FAR_INTEGRATOR, y0, 0.0, steps * GAME_DT, GAME_DT, dtype=dtype)
        return traj.y[:, 0, 1, 0].astype(float) - float(np.asarray(x0, dtype))  # the mass, relative

    at_origin = run(0.0, np.float64)
    rows = []
    for precision in precisions:
        dtype = np.dtype(precision)
        for x0 in offsets:
            deviation = np.abs(run(x0, dtype) - at_origin).max() / amplitude
            rows.append({"precision": precision, "offset": float(dtype.type(x0)),
                         "spacing": float(np.spacing(dtype.type(x0))), "deviation": float(deviation)})
    return rows


def first_offset(rows, key, threshold=None) -> dict:
    """The smallest offset where ``key`` is true (or above ``threshold``): {precision: offset}, or
    {precision: {speed: offset}} for rows with a speed; None where it never is."""
    found = {}
    for r in sorted(rows, key=lambda r: r["offset"]):
        slot, label = (found.setdefault(r["precision"], {}), f"{r['speed']:g}") if "speed" in r \
            else (found, r["precision"])
        hit = r[key] if threshold is None else r[key] > threshold
        if slot.setdefault(label, None) is None and hit:
            slot[label] = r["offset"]
    return found


def stall_edge(speed: float, precision: str) -> float:
    """The smallest power of two from which a body moving v dt per step stalls, by the rounding model."""
    dtype = np.dtype(precision)
    increment = dtype.type(speed) * dtype.type(GAME_DT)
    return next(2.0**k for k in range(np.finfo(dtype).maxexp) if dtype.type(2.0**k) + increment == dtype.type(2.0**k))


# --- mass ratios ----------------------------------------------------------------------------


def spring_pair_mode(mass_ratio: float) -> Mode:
    """A heavy body (HEAVY_MASS) at the origin and one mass_ratio times lighter 1 m away, on one spring.

    The mode is the stretch u = x_light - x_heavy - 1 with the centre of mass at rest:
    the light body moves M / (m + M) of it, the heavy one -m / (m + M).
    """
    heavy, light = HEAVY_MASS, HEAVY_MASS / mass_ratio
    model = Model([heavy, light], [0.05, 0.05], [Springs(np.array([0]), np.array([1]), np.array([PAIR_STIFFNESS]),
                                                         np.array([1.0]))])
    equilibrium = np.zeros((2, 2, 3))
    equilibrium[0, 1, 0] = 1.0
    pattern, weights = np.zeros((2, 3)), np.zeros((2, 3))
    pattern[:, 0] = [-light / (light + heavy), heavy / (light + heavy)]
    weights[:, 0] = [-1.0, 1.0]
    omega = float(np.sqrt(PAIR_STIFFNESS * (1 / light + 1 / heavy)))
    return Mode(model, omega, equilibrium, pattern, weights)


def mass_ratio(methods, ratios, steps: int, rtol: float, progress=None) -> list[dict]:
    """Largest stable dt of each method against the mass ratio across the spring."""
    rows = []
    for ratio in ratios:
        for method in methods:
            rows.append(mass_ratio_row(ratio, method, steps, rtol))
        if progress is not None:
            progress()
    return rows


def mass_ratio_row(ratio: float, method, steps: int, rtol: float) -> dict:
    """One point of :func:`mass_ratio`: the largest stable dt of ``method`` at mass ratio ``ratio``."""
    return {"mass_ratio": ratio, "integrator": method} | stable_dt(spring_pair_mode(ratio), method, steps, rtol)


def far_offsets(params: dict) -> list[float]:
    """The distances from the origin the far-from-origin runs start at."""
    return np.geomspace(1e3, 1e7, params["far_offsets"]).tolist()


def compute(params: dict, progress=None) -> dict:
    offsets = far_offsets(params)
    coast = coasting(offsets, params["far_speeds"], params["precisions"], params["coasting_steps"])
    jitter = oscillator_jitter(offsets, params["precisions"], params["jitter_periods"])
    pairs = mass_ratio(params["sweep_integrators"], params["mass_ratios"], params["mass_ratio_steps"],
                       params["mass_ratio_rtol"], progress)
    return assemble(params, huge_dt(params["integrators"], params["huge_omega_dts"], params["huge_max_steps"]),
                    coast, jitter, pairs)


def assemble(params: dict, huge: list[dict], coast: list[dict], jitter: list[dict], pairs: list[dict]) -> dict:
    """The extremes' part of the stability record from its four sweeps."""
    return {
        "huge_dt": huge,
        "far_from_origin": {
            "dt": GAME_DT, "integrator": FAR_INTEGRATOR, "coasting": coast, "oscillator": jitter,
            "matches_rounding_model": all(
                r["stalled"] == r["predicted_stall"] and (r["stalled"] or np.isclose(
                    r["speed_error"], r["predicted_speed_error"], rtol=1e-6, atol=1e-12)) for r in coast),
            "first_stall": first_offset(coast, "stalled"),
            "stall_edge": {p: {f"{v:g}": stall_edge(v, p) for v in params["far_speeds"]} for p in params["precisions"]},
            "first_jitter_over_1_percent": first_offset(jitter, "deviation", 0.01),
            # offsets ascend within each precision: the last row of each is the farthest
            "deviation_at_largest_offset": {r["precision"]: r["deviation"] for r in jitter},
        },
        "mass_ratio": {"stiffness": PAIR_STIFFNESS, "heavy_mass": HEAVY_MASS, "rows": pairs,
                       "worst_deviation_from_theory": worst_deviation(pairs)},
    }


# --- figure -----------------------------------------------------------------------------------


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    fig, axes = plt.subplots(2, 2, figsize=(13, 10))
    far = record["far_from_origin"]
    linestyles = {"float32": "-", "float64": "--"}

    ax = axes[0, 0]
    speeds = sorted({r["speed"] for r in far["coasting"]})
    colours = dict(zip(speeds, plt.cm.viridis(np.linspace(0, 0.85, len(speeds)))))
    for (precision, v) in {(r["precision"], r["speed"]): None for r in far["coasting"]}:
        rows = [r for r in far["coasting"] if r["precision"] == precision and r["speed"] == v]
        x = [r["offset"] for r in rows]
        ax.loglog(x, [max(r["speed_error"], 1e-17) for r in rows], linestyles[precision], color=colours[v],
                  marker="o", ms=3, label=f"{precision}, v = {v:g} m/s")
        stalled = [r["offset"] for r in rows if r["stalled"]]
        ax.loglog(stalled, [1.0] * len(stalled), "x", color=colours[v], ms=8)
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.text(1.1e3, 2.0, "stalled (x): x + v dt rounds back to x", fontsize=8)
    ax.set_xlabel("distance from the origin x0 (m)")
    ax.set_ylabel("relative speed error |travelled / (v t) - 1|")
    ax.set_title(f"A coasting body far from the origin ({FAR_INTEGRATOR}, dt = 1/60 s, 1 s)\n"
                 "every point equals the rounding model: steps of round(v dt / spacing) spacings", fontsize=10)
    ax.set_ylim(1e-13, 30)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="lower right")

    ax = axes[0, 1]
    amplitude = 0.5
    for precision in linestyles:
        rows = [r for r in far["oscillator"] if r["precision"] == precision]
        if not rows:
            continue
        x = [r["offset"] for r in rows]
        ax.loglog(x, [max(r["deviation"], 1e-17) for r in rows], linestyles[precision], marker="o", ms=4,
                  color="tab:blue" if precision == "float32" else "tab:orange", label=f"{precision}: measured")
        ax.loglog(x, [r["spacing"] / amplitude for r in rows], ":", color="tab:blue" if precision == "float32"
                  else "tab:orange", label=f"{precision}: position spacing / amplitude")
    ax.axhline(0.01, color="k", lw=0.6, ls=":")
    ax.text(1.5e5, 0.0065, "1 % of the amplitude", fontsize=8, va="top")  # clear of both curves
    ax.set_xlabel("distance of the oscillator from the origin x0 (m)")
    ax.set_ylabel("largest deviation from the run at the origin / amplitude")
    ax.set_title("Jitter: the 0.5 m oscillator moved to x0 (5 periods, dt = 1/60 s)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)

    ax = axes[1, 0]
    plotting.stable_dt_panel(ax, record["mass_ratio"]["rows"], "mass_ratio", "theory: limit / sqrt(k (1/m1 + 1/m2))")
    ax.set_xlabel("mass ratio m_heavy / m_light (heavy body 1 kg)")
    ax.set_title(f"Two bodies on one spring (k = {record['mass_ratio']['stiffness']:g} N/m): "
                 "the light body sets dt", fontsize=10)
    ax.legend(fontsize=7)

    ax = axes[1, 1]
    huge = record["huge_dt"]
    for method in dict.fromkeys(r["integrator"] for r in huge):
        mine = [r for r in huge if r["integrator"] == method and r["diverged_at_step"]]
        if not mine:
            continue
        style = plotting.style(method)
        ax.loglog([r["omega_dt"] for r in mine], [r["diverged_at_step"] for r in mine], linestyle="none", ms=8,
                  mfc="none", **style)
        ax.loglog([r["omega_dt"] for r in mine], [r["predicted_step"] for r in mine], color=style["color"], lw=0.8)
    stable = sorted({r["integrator"] for r in huge if r["diverged_at_step"] is None})
    ax.plot([], [], color="gray", lw=0.8, label="predicted: log(limit / amplitude) / log(rho)")
    ax.set_xlabel("omega dt (linear oscillator)")
    ax.set_ylabel("step at which divergence is detected")
    ax.set_yticks([2, 5, 10, 20, 50, 100])
    ax.yaxis.set_major_formatter(plotting.matplotlib.ticker.ScalarFormatter())
    ax.yaxis.set_minor_formatter(plotting.matplotlib.ticker.NullFormatter())
    ax.set_title("Huge dt on the oscillator: divergence reported, never NaN output\n"
                 f"(no divergence: {', '.join(stable) or 'none'})", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return plotting.save_figure(fig, out, "stability_extremes")


# --- the paper's tables -------------------------------------------------------------


def huge_dt_table(data: list[dict]) -> str:
    """The step each method diverges at, per omega dt, and (in brackets) the step rho predicts."""
    ys = list(dict.fromkeys(r["omega_dt"] for r in data))
    cells = {(r["integrator"], r["omega_dt"]): "no divergence" if r["diverged_at_step"] is None
             else f"{r['diverged_at_step']} ({r['predicted_step']})" for r in data}
    methods = list(dict.fromkeys(r["integrator"] for r in data))
    return markdown_table(["integrator"] + [f"omega dt = {y:g}" for y in ys],
                          [[m] + [cells[m, y] for y in ys] for m in methods])


def far_from_origin_table(data: dict) -> str:
    """Where a coasting float32 body first stalls, per speed, against the rounding model."""
    edges = data["stall_edge"]
    rows = [[f"{speed} m/s", f"{float(speed) / 60:.2g} m", format_value(first, ".3g"),
             f"2^{np.log2(edges['float32'][speed]):.0f} m"] for speed, first in data["first_stall"]["float32"].items()]
    slowest = min(edges["float64"], key=float)
    stalls64 = [x for x in data["first_stall"]["float64"].values() if x is not None]
    note = (f"float64 stalls at {min(stalls64):.0e} m" if stalls64 else "float64 stalls nowhere up to 10^7 m") + \
        f"; at {slowest} m/s the rounding model puts its edge at 2^{np.log2(edges['float64'][slowest]):.0f} m."
    return markdown_table(["speed", "step v dt", "first stalled x0 of 1e3..1e7 m", "rounding model: stalls from"],
                          rows) + f"\n\n(float32, dt = 1/60 s; {note})"


def mass_ratio_table(data: list[dict]) -> str:
    """Largest stable dt, measured and theory, at the smallest, middle and largest mass ratio."""
    ratios = sorted({r["mass_ratio"] for r in data})
    shown = sorted({ratios[0], ratios[len(ratios) // 2], ratios[-1]})
    cells = {(r["integrator"], r["mass_ratio"]): r for r in data}
    methods = list(dict.fromkeys(r["integrator"] for r in data))

    def cell(m, ratio):
        r = cells[m, ratio]
        if r["dt_max"] is None or r["dt_max"] == 0:
            return "any dt" if r["dt_max"] is None else "none"
        return f"{r['dt_max']:.3g} s ({r['dt_max_theory']:.3g})"

    return markdown_table(["integrator"] + [f"mass ratio {x:g}" for x in shown],
                          [[m] + [cell(m, x) for x in shown] for m in methods]) + \
        "\n\n(largest stable dt measured (theory); none: unstable at every dt; any dt: no limit.)"


#: the tables of the extremes' record (``record["extremes"]`` of the stability study)
TABLES = (
    Table("huge_dt", lambda r: [{k: row[k] for k in ("integrator", "omega_dt", "diverged_at_step", "predicted_step")}
                                for row in r["huge_dt"]], huge_dt_table),
    Table("far_from_origin", lambda r: {k: r["far_from_origin"][k] for k in ("first_stall", "stall_edge")},
          far_from_origin_table),
    Table("mass_ratio", lambda r: r["mass_ratio"]["rows"], mass_ratio_table),
)
