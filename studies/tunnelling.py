"""Tunnelling study: when does overlap testing miss a thin wall, and what does not missing cost?

A sphere of radius r is shot at speed v at a static wall of thickness w, with step dt
and a random phase (where the sphere is when a step ends). Overlap testing sees the wall
only if the end of some step finds the sphere overlapping it, i.e. the centre inside the
band of width w + 2r (the Minkowski sum of the wall and the sphere, along the motion).
Steps sample the centre's path every v dt, so with a uniformly random phase it misses with
probability

    P(miss) = max(0, 1 - (w + 2r) / (v dt)),

a function of the ratio rho = v dt / (w + 2r) alone, if every overlapping sample stops the
sphere. It does not quite: the response pushes the sphere out along the contact normal,
and once the centre is past the wall's middle the nearest face is the far one, so the
normal points forward, the sphere is not approaching, and it leaves through the far side.
Only the front half of the band, (w + 2r) / 2 wide, stops it. Where the sphere is when the
collision is resolved depends on the detector (:func:`bisection_miss_rate`):

- without bisection (an engine that resolves at the end of the step, pushing out along the
  nearest face) at the first overlapping sample: ``P(miss) = max(0, 1 - 1 / (2 rho))``;
- with k >= 1 bisections at the first grid point ``m dt / 2^k`` inside the band, at most
  ``v dt / 2^k`` deep: the curve above while ``rho <= 2^(k-1)`` (16 for the lecture's 5);
  then the sphere is stopped with probability ``3 / (2 rho) - 2^-k`` up to ``rho = 2^k``,
  and ``1 / (2 rho)`` beyond, as if it did not bisect.

Intersection (swept) testing computes the time of impact instead and never misses. The study
measures the miss rates of all three for several walls and steps against these curves;
checks the lecture's design rule ("fastest object moves smaller distance than thinnest
object"); counts the sub-steps overlap testing needs to stop missing against one swept test;
and measures how bisection iterations trade the time-of-impact error for cost.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np
from steplab.integrators import simulate
from steplab.physics import Model
from steplab.physics.collision import BoundingSphere, Box, CollisionWorld, PairProperties, collide, overlaps
from steplab.physics.collision.shapes import Sphere
from steplab.physics.collision.time_of_impact import lecture_sphere_sphere, sphere_sphere

from . import plotting
from .lecture import LECTURE_ERRORS_TABLE
from .runner import Study, run_tasks

#: the integrator: exact for straight-line motion, so every miss is the detector's
INTEGRATOR = "semi-implicit-euler"
#: the lecture's bisection iterations ("in practice, usually 5 iterations is pretty close")
LECTURE_BISECTIONS = 5


def parameters(quick: bool) -> dict:
    return {
        "radius": 0.05, "seed": 20240611,
        # (wall thickness w, step dt): the miss rate should depend on v dt / (w + 2r) only
        "walls": [[0.01, 0.01], [0.1, 0.002]] if quick else [[0.01, 0.01], [0.01, 0.002], [0.1, 0.01], [0.002, 0.02]],
        # up to 50: the lecture's 5 bisections leave 1 - (w + 2r) / (v dt) above 16
        "ratios": np.round(np.geomspace(0.05, 50, 9) if quick else np.geomspace(0.015, 50, 25), 4).tolist(),
        "trials": 30 if quick else 200,
        # overlap testing with the lecture's 5 bisections, and with none (push out along the nearest face)
        "bisections": [LECTURE_BISECTIONS, 0],
        "cost_ratios": [1.5, 4.0, 12.0] if quick else [1.5, 3.0, 6.0, 12.0, 24.0],
        "cost_trials": 10 if quick else 40,
        "bisection_iterations": list(range(0, 13 if quick else 21)),
        "bisection_ratio": 0.5,
        "bisection_trials": 40 if quick else 200,
    }


class Shot(NamedTuple):
    """A sphere of radius ``r`` (m) shot at a wall of thickness ``w`` (m) with the step ``dt``
    (s), at the speed v = ``ratio`` (w + 2r) / dt."""

    ratio: float
    w: float
    dt: float
    r: float


def shoot(shot: Shot, phases, detector: str, iterations: int = 5, substeps: int = 1, batched: bool = False,
          system=None, planar: bool = False) -> dict:
    """Shoot spheres at the wall x in [-w/2, w/2] at the ``shot``'s speed, one per phase.

    ``phases`` (fractions of a step in [0, 1)) place each sphere's samples along its path.
    Each shot is its own run unless ``batched``: then all spheres fly side by side in one
    run (lanes far enough apart never to meet), and a collision of one splits the step for
    all, adding a sample of every sphere at that time. Returns the misses, each sphere's
    first collision time and its true first-touch time, and the run time. ``system`` (a
    system under test, :mod:`.system`) runs the shots instead of steplab's integrator and
    ``detector``; ``planar`` puts the lanes side by side in the plane z = 0 (a 2-D engine's).
    """
    ratio, w, dt, r = shot
    phases = np.asarray(phases, dtype=float)
    v = ratio * (w + 2 * r) / dt
    travel = v * dt
    x0 = -(0.5 * w + r) - travel * (1 + phases)  # at least one step before first touch
    steps = math.ceil((w + 2 * r) / travel + 3)
    wall_time, misses, toi = 0.0, 0, []
    for group in ([np.arange(len(phases))] if batched else [[k] for k in range(len(phases))]):
        n = len(group)
        lane = 2 * (r + travel) + 1.0
        side = n if planar else math.ceil(math.sqrt(n))
        k = np.arange(n)
        y0 = np.zeros((2, n, 3))
        y0[0, :, 0], y0[0, :, 1], y0[0, :, 2] = x0[group], lane * (k % side), lane * (k // side)
        y0[1, :, 0] = v
        middle = 0.5 * lane * (side - 1)
        wall = Box.from_center([0.0, middle, middle], [w, lane * side, lane * side], name="wall")
        world = CollisionWorld(detector, (wall,), pair_properties=PairProperties(1.0),
                               bisection_iterations=iterations, max_impacts_per_step=2 * n + 10)
        start = time.perf_counter()
        if system is None:
            traj = simulate(Model(np.ones(n), np.full(n, r)), INTEGRATOR, y0, 0.0, steps * dt, dt / substeps,
                            collisions=world, save_every=10**9)
        else:
            run = system.build(Model(np.ones(n), np.full(n, r)), world, dt / substeps, y0)
            traj = run.advance(y0, dt / substeps, steps * substeps, save_every=10**9)
        wall_time += time.perf_counter() - start
        misses += int(np.sum(traj.velocities[-1, :, 0] > 0))
        first = {}
        for event in traj.collisions.events if traj.collisions is not None else ():
            first.setdefault(event.body, event.t)
        toi += [first.get(b) for b in range(n)]
    return {"misses": misses, "trials": len(phases), "wall_time": wall_time, "toi": toi,
            "true_toi": ((-(0.5 * w + r) - x0) / v).tolist()}


def analytic_miss_rate(ratio: float) -> float:
    """The miss rate if every sample that overlaps the wall stopped the sphere: 1 - 1 / rho.

    A detector that bisects k times follows it while rho <= 2^(k-1) (:func:`bisection_miss_rate`).
    """
    return max(0.0, 1.0 - 1.0 / ratio)


def nearest_face_miss_rate(ratio: float) -> float:
    """The miss rate of overlap testing without bisection, pushing out along the nearest face.

    The collision is resolved where the first overlapping sample finds the centre: a uniformly
    random depth in [0, v dt) into the band of width w + 2r. Only the band's front half pushes
    the sphere back, so it is stopped with probability ((w + 2r) / 2) / (v dt) = 1 / (2 rho)
    (capped at 1): ``P(miss) = max(0, 1 - 1 / (2 rho))``, which starts at rho = 1/2.
    """
    return max(0.0, 1.0 - 0.5 / ratio)


def bisection_miss_rate(ratio: float, iterations: int) -> float:
    """The miss rate of overlap testing that bisects ``iterations`` = k times, at rho = v dt / (w + 2r).

    Bisection returns the first point of the grid m dt / 2^k (m = 1 .. 2^k) that overlaps, so
    with N = 2^k, and y the time the sphere enters the band in the step of its first
    overlapping sample, in grid units (uniform on [0, N] over the random phases):

    - the step's end overlaps only when the entry lies in its last N / rho (capped at the
      whole step, N): ``L = min(N, N / rho)`` of the N grid cells;
    - the sphere is resolved at ``ceil(y)``, ``(ceil(y) - y) v dt / N`` deep, and pushed back
      only when that is less than (w + 2r) / 2, i.e. ``ceil(y) - y < c = N / (2 rho)``:
      the last c (capped at 1) of each cell.

    The entries that are stopped are the last min(c, 1) of each of the floor(L) whole cells at
    the end of the step, and the last min(c, 1, frac(L)) of the one before them:
    ``P(stop) = (floor(L) min(c, 1) + min(frac(L), c, 1)) / N``. For rho <= N / 2 this is
    min(1, 1 / rho) (:func:`analytic_miss_rate`), for N / 2 < rho < N it is 3 / (2 rho) - 1 / N
    (when k >= 1), and from rho = N on 1 / (2 rho), as without bisection
    (:func:`nearest_face_miss_rate`, which is k = 0).
    """
    n = 2.0**iterations
    c = min(1.0, n / (2.0 * ratio))
    whole, part = divmod(min(n, n / ratio), 1.0)
    return max(0.0, 1.0 - (whole * c + min(part, c)) / n)


def lecture_errors(points, params) -> list[dict]:
    """The collision-detection chapter's errors and claims, checked by computation."""
    r = params["radius"]
    a, b = BoundingSphere(np.zeros(3), 1.0), BoundingSphere(np.array([1.5, 0.0, 0.0]), 1.0)
    depth = float(collide(Sphere(a.center, np.array(1.0)), Sphere(b.center, np.array(1.0))).penetration_depth)
    with np.errstate(invalid="ignore", divide="ignore"):
        still = float(lecture_sphere_sphere([0, 0, 0], [0, 0, 0], [3, 0, 0], [3, 0, 0], 1.0, 1.0))
    ours_still = float(sphere_sphere(np.zeros(3), np.zeros(3), np.array([3.0, 0, 0]), np.array([3.0, 0, 0]), 1.0, 1.0))
    apart = float(lecture_sphere_sphere([0, 0, 0], [-1, 0, 0], [3, 0, 0], [4, 0, 0], 1.0, 1.0))
    ours_apart = float(sphere_sphere(np.zeros(3), np.array([-1.0, 0, 0]), np.array([3.0, 0, 0]),
                                     np.array([4.0, 0, 0]), 1.0, 1.0))
    inside = float(lecture_sphere_sphere([0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], 1.0, 1.0))
    rule_rows = []
    for w, dt in params["walls"]:
        thinnest = min(w, 2 * r)
        rule = thinnest / (w + 2 * r)
        row = {"w": w, "dt": dt, "rule_ratio": rule}
        for bisections, suffix in ((LECTURE_BISECTIONS, ""), (0, "_no_bisection")):
            overlap = [p for p in points if p["detector"] == "overlap" and p["bisections"] == bisections
                       and p["w"] == w and p["dt"] == dt]
            row["max_miss_rate_within_rule" + suffix] = max((p["miss_rate"] for p in overlap if p["ratio"] < rule),
                                                            default=None)
            row["smallest_ratio_with_misses" + suffix] = min((p["ratio"] for p in overlap if p["miss_rate"] > 0),
                                                             default=None)
        rule_rows.append(row)
    return [
        {"where": "Complex Geometry - Bounding Volume (2 of 3)",
         "printed": "Sphere - if distance between centers less than sum of Radii then no collision",
         "correct": "if the distance between the centres is MORE than the sum of the radii, no collision "
                    "(at most the sum: they overlap)",
         "evidence": f"unit spheres with centres 1.5 m apart (less than 2): the point (0.75, 0, 0) is in both, "
                     f"the narrow phase finds them {depth:g} m deep, and the overlap test says "
                     f"{overlaps(a, b)}", "is_error": True},
        {"where": "Intersection Testing: Sphere-Sphere Collision",
         "printed": "t = (-(A.B) - sqrt((A.B)^2 - B^2 (A^2 - (rP + rQ)^2))) / B^2",
         "correct": "right for spheres apart and approaching, but it divides by B^2 and ignores t < 0 and t > 1",
         "evidence": f"no relative motion (B = 0) gives {still} (0/0); steplab's rationalised form gives "
                     f"{ours_still} (no impact). Spheres moving apart give t = {apart:g} (a collision in the past; "
                     f"steplab: {ours_apart}); spheres already overlapping give t = {inside:g} < 0 (steplab: 0)",
         "is_error": False},
        {"where": "Intersection Testing: Sphere-Sphere Collision",
         "printed": "Or, simpler: d^2 = A^2 - (A.B)^2 / B^2; if d^2 > (rP + rQ)^2, no collision",
         "correct": "a rejection test only: d is the closest distance of the infinite line, so d^2 <= (rP + rQ)^2 "
                    "does not mean a collision in this step (the closest approach may be before t = 0 or after "
                    "t = 1)",
         "evidence": "spheres moving apart along their line of centres have d = 0, yet the time of impact is "
                     f"{ours_apart} (none)", "is_error": False},
        {"where": "Overlap Testing: Limitations",
         "printed": "Design constraint on speed of objects "
                    "(fastest object moves smaller distance than thinnest object)",
         "correct": "sufficient but conservative: overlap testing that bisects cannot miss while v dt <= w + 2r "
                    "(the wall thickened by the sphere, the Minkowski sum); without bisection, pushing out along "
                    "the nearest face, it misses from v dt > (w + 2r) / 2, still above the rule's "
                    "min(w, 2r); for two moving objects the relative displacement is what counts",
         "evidence": "; ".join(
             f"w = {row['w']:g} m, dt = {row['dt']:g} s: the rule allows ratios < {row['rule_ratio']:.3g}, "
             f"largest miss rate there {row['max_miss_rate_within_rule']} ({LECTURE_BISECTIONS} bisections) and "
             f"{row['max_miss_rate_within_rule_no_bisection']} (none), first misses at ratio "
             f"{row['smallest_ratio_with_misses']} (the first tested above 1) and "
             f"{row['smallest_ratio_with_misses_no_bisection']} (the first above 1/2)" for row in rule_rows),
         "is_error": False, "rule": rule_rows},
    ]


def phases(params: dict) -> dict:
    """The random phases of every sweep, drawn in turn from the one seed (any task redraws them alike)."""
    rng = np.random.default_rng(params["seed"])
    trials, cost_trials = params["trials"], params["cost_trials"]
    # stratified random phases, one per 1/trials of a step: the miss fraction is then within
    # 1/trials of the probability (plain uniform phases scatter by sqrt(p (1 - p) / trials))
    stratified = (np.arange(trials) + rng.uniform(0.0, 1.0, trials)) / trials
    cost = (np.arange(cost_trials) + rng.uniform(0.0, 1.0, cost_trials)) / cost_trials
    return {"miss_rate": stratified, "cost": cost, "bisection": rng.uniform(0.0, 1.0, params["bisection_trials"])}


def tasks(params: dict) -> list[list]:
    """The sweep's independent shots: each wall and ratio (every detector), the batched scene per
    ratio, each bisection count, the swept reference, and the timed cost rows."""
    return ([["point", w, dt, ratio] for w, dt in params["walls"] for ratio in params["ratios"]]
            + [["batched", ratio] for ratio in params["ratios"]]
            + [["bisection", k] for k in params["bisection_iterations"]] + [["swept_toi"]]
            + [["cost", ratio] for ratio in params["cost_ratios"]])


def timed(item: list) -> bool:
    """The cost rows measure run time (sub-stepped overlap testing against swept testing)."""
    return item[0] == "cost"


def task(params: dict, item: list):
    """One task of :func:`tasks`: the shots it names, as part of the record."""
    r, trials = params["radius"], params["trials"]
    w, dt = params["walls"][0]  # the batched, cost and bisection sweeps use the first wall
    kind, drawn = item[0], phases(params)
    if kind == "point":
        _, w, dt, ratio = item
        points = []
        for detector, iterations in [("overlap", k) for k in params["bisections"]] + [("swept", None)]:
            swept = iterations is None  # the swept detector does not bisect
            shot = shoot(Shot(ratio, w, dt, r), drawn["miss_rate"], detector, 0 if swept else iterations)
            points.append({"detector": detector, "bisections": iterations, "ratio": ratio,
                           "miss_rate": shot["misses"] / trials, "trials": trials, "w": w, "dt": dt,
                           "speed": ratio * (w + 2 * r) / dt,
                           "analytic_miss_rate": 0.0 if swept else bisection_miss_rate(ratio, iterations),
                           "sampling_miss_rate": 0.0 if swept else analytic_miss_rate(ratio)})
        return points
    if kind == "batched":
        ratio = item[1]
        shot = shoot(Shot(ratio, w, dt, r), drawn["miss_rate"], "overlap", batched=True)
        return {"ratio": ratio, "miss_rate": shot["misses"] / trials, "trials": trials, "w": w, "dt": dt}
    if kind == "cost":
        ratio, some = item[1], drawn["cost"]
        substeps = math.ceil(ratio)
        sub = shoot(Shot(ratio, w, dt, r), some, "overlap", substeps=substeps)
        single = shoot(Shot(ratio, w, dt, r), some, "overlap")
        swept = shoot(Shot(ratio, w, dt, r), some, "swept")
        return {"ratio": ratio, "substeps": substeps, "trials": len(some),
                "miss_rate_overlap": single["misses"] / len(some),
                "miss_rate_overlap_substepped": sub["misses"] / len(some),
                "miss_rate_swept": swept["misses"] / len(some),
                "tests_per_step_overlap": substeps, "tests_per_step_swept": 1,
                "wall_time_overlap_substepped": sub["wall_time"], "wall_time_swept": swept["wall_time"]}
    some = drawn["bisection"]
    if kind == "bisection":
        iterations = item[1]
        shot = shoot(Shot(params["bisection_ratio"], w, dt, r), some, "overlap", iterations, batched=True)
        errors = np.array([t - true for t, true in zip(shot["toi"], shot["true_toi"]) if t is not None])
        return {"iterations": iterations, "toi_error": float(np.mean(np.abs(errors))),
                "toi_error_max": float(np.max(np.abs(errors))), "bound": dt * 2.0**-iterations,
                "detected": int(len(errors)), "overlap_tests_per_collision": iterations + 1}
    shot = shoot(Shot(params["bisection_ratio"], w, dt, r), some, "swept", batched=True)  # "swept_toi"
    return max(abs(t - true) for t, true in zip(shot["toi"], shot["true_toi"]))


def reduce(params: dict, results: list) -> dict:
    """The record from the results of :func:`tasks`, in their order."""
    by_kind = {}
    for item, result in zip(tasks(params), results):
        by_kind.setdefault(item[0], []).append(result)
    points = [point for row in by_kind["point"] for point in row]
    return {"points": points, "batched": by_kind["batched"], "bisection": by_kind["bisection"],
            "swept_toi_error": by_kind["swept_toi"][0], "cost": by_kind["cost"],
            "lecture_errors": lecture_errors(points, params)}


def compute(params: dict, progress=None) -> dict:
    """Every task in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []
    params = record["parameters"]
    r = params["radius"]

    # 1. miss rate against v dt / (w + 2r); right: the fraction stopped, where the models part
    fig, (ax, stop) = plt.subplots(1, 2, figsize=(12.4, 6.4), width_ratios=(1.25, 1))
    grid = np.geomspace(min(params["ratios"]), max(params["ratios"]), 600)
    lecture = LECTURE_BISECTIONS
    curves = [(f"{lecture} bisections (model)", [bisection_miss_rate(x, lecture) for x in grid], "-", "k"),
              ("no bisection, nearest face: 1 - (w + 2r) / (2 v dt)", [nearest_face_miss_rate(x) for x in grid],
               "--", "tab:purple"),
              ("every overlapping sample stops it: 1 - (w + 2r) / (v dt)", [analytic_miss_rate(x) for x in grid],
               ":", "gray")]
    for label, miss, ls, color in curves:
        ax.plot(grid, miss, ls=ls, color=color, lw=1.5 if color == "k" else 1.2, label=label)
        stop.loglog(grid, 1.0 - np.asarray(miss), ls=ls, color=color, lw=1.5 if color == "k" else 1.2)
    markers = ["o", "s", "^", "D", "v"]
    series = [(f"overlap, {lecture} bisections", lambda p: p["detector"] == "overlap" and p["bisections"] == lecture,
               "tab:orange", "none", 7),
              ("overlap, no bisection", lambda p: p["detector"] == "overlap" and p["bisections"] == 0,
               "tab:purple", "none", 5),
              ("swept", lambda p: p["detector"] == "swept", "tab:blue", None, 4)]
    for k, (w, dt) in enumerate(params["walls"]):
        pts = [p for p in record["points"] if p["w"] == w and p["dt"] == dt]
        for label, chosen, color, mfc, ms in series:
            sel = [p for p in pts if chosen(p)]
            ax.plot([p["ratio"] for p in sel], [p["miss_rate"] for p in sel], ls="none", marker=markers[k % 5],
                    color=color, mfc=mfc, ms=ms, label=f"measured: {label}" if k == 0 else None)
            if mfc == "none":  # overlap: the fraction stopped, where some were
                seen = [p for p in sel if p["miss_rate"] < 1 and p["ratio"] > 0.3]
                stop.plot([p["ratio"] for p in seen], [1 - p["miss_rate"] for p in seen], ls="none",
                          marker=markers[k % 5], color=color, mfc=mfc, ms=ms)
        ax.plot([], [], ls="none", marker=markers[k % 5], color="gray", mfc="none",
                label=f"  marker: w = {w * 100:g} cm, dt = {dt * 1e3:g} ms")
    batched = record["batched"]
    w0, dt0 = params["walls"][0]
    ax.plot([p["ratio"] for p in batched], [p["miss_rate"] for p in batched], ls=":", marker="x", color="tab:red",
            lw=0.8, label=f"overlap, all {params['trials']} shots in one scene (w = {w0 * 100:g} cm, "
                          f"dt = {dt0 * 1e3:g} ms):\nother shots' impacts split the step and add samples")
    ax.axvline(1.0, color="gray", ls="--", lw=1)
    ax.text(1.03, 0.45, "v dt = w + 2r", color="gray", fontsize=8, rotation=90, va="top")
    for w, _ in params["walls"]:
        rule = min(w, 2 * r) / (w + 2 * r)
        ax.axvline(rule, color="tab:green", ls=":", lw=1)
    ax.text(min(w / (w + 2 * r) for w, _ in params["walls"]) * 1.03, 0.35,
            "lecture's rule:\nv dt = thinnest object", color="tab:green", fontsize=8, va="top")
    ax.set_xscale("log")
    ax.set_xlabel("distance per step / wall thickened by the sphere,  v dt / (w + 2r)")
    ax.set_ylabel(f"fraction of shots through the wall ({params['trials']} stratified random phases)")
    ax.set_ylim(-0.03, 1.03)
    ax.set_title("Tunnelling: overlap testing misses as modelled, swept testing never", fontsize=11)
    # below the axes, in two columns: inside, it would cover the measured points
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False)
    ax.grid(True, which="major", alpha=0.3)
    # each line tagged at the top, what it marks said in the empty lower left (the data falls
    # from the top left to the lower right, so labels there would cover points or leave the axes)
    for x, tag in ((2.0 ** (lecture - 1), "2^(k-1)"), (2.0**lecture, "2^k")):
        stop.axvline(x, color="gray", ls="--", lw=0.8)
        stop.text(x / 1.04, 1.3, tag, color="gray", fontsize=7, va="top", ha="right")
    stop.text(0.03, 0.03, "dashed lines, v dt / (w + 2r) =\n2^(k-1): the bracket v dt / 2^k reaches the wall's "
              "middle\n2^k: every shot as if without bisection", transform=stop.transAxes, color="gray",
              fontsize=7, va="bottom", ha="left")
    stop.set_xlim(0.3, max(params["ratios"]) * 1.1)
    stop.set_ylim(min(0.5 / params["trials"], 0.25 / max(params["ratios"])), 1.5)
    stop.set_xlabel("v dt / (w + 2r)")
    stop.set_ylabel("fraction of shots stopped by the wall")
    stop.set_title(f"Where bisection stops helping (k = {lecture})", fontsize=11)
    stop.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "tunnelling_miss_rate")

    # 2. bisection: time-of-impact error against iterations
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    b = record["bisection"]
    its = [p["iterations"] for p in b]
    ax.semilogy(its, [p["toi_error_max"] for p in b], "o-", color="tab:orange", ms=4, label="largest error")
    ax.semilogy(its, [p["toi_error"] for p in b], "s--", color="tab:orange", ms=3, mfc="none", label="mean error")
    ax.semilogy(its, [p["bound"] for p in b], color="k", lw=1, label="bracket width dt / 2^k")
    ax.axvline(5, color="gray", ls=":", lw=1)
    ax.text(5.2, b[0]["bound"] * 0.5, "lecture's 5 iterations:\nbracket dt / 32", fontsize=8, color="gray", va="top")
    ax.axhline(max(record["swept_toi_error"], 1e-18), color="tab:blue", lw=1, label="swept (closed form)")
    ax.set_xlabel("bisection iterations k (overlap tests per collision: k + 1)")
    ax.set_ylabel("time-of-impact error (s)")
    ax.set_title(f"Bisection: error halves per iteration (dt = {params['walls'][0][1] * 1e3:g} ms)")
    ax.legend(fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "tunnelling_bisection")

    # 3. cost of not missing
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    c = record["cost"]
    ratios = [p["ratio"] for p in c]
    ax.loglog(ratios, [p["tests_per_step_overlap"] for p in c], "o-", color="tab:orange",
              label="overlap: sub-steps needed, ceil(v dt / (w + 2r))")
    ax.loglog(ratios, [p["tests_per_step_swept"] for p in c], "s-", color="tab:blue", label="swept: one test per step")
    speedup = [p["wall_time_overlap_substepped"] / p["wall_time_swept"] for p in c]
    ax.loglog(ratios, speedup, "^--", color="tab:gray", label="measured run time, overlap sub-stepped / swept")
    ax.set_xticks(ratios, [f"{x:g}" for x in ratios])
    ax.minorticks_off()
    ax.set_xlabel("v dt / (w + 2r)")
    ax.set_ylabel("narrow-phase tests per step  (or time ratio)")
    ax.set_title("The cost of never missing: sub-stepping against one swept test\n"
                 f"(miss rate with sub-steps: {max(p['miss_rate_overlap_substepped'] for p in c):g}, "
                 f"swept: {max(p['miss_rate_swept'] for p in c):g})", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "tunnelling_cost")
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    swept = [p for p in record["points"] if p["detector"] == "swept"]
    rows = [("swept misses (all speeds)", f"{sum(p['miss_rate'] for p in swept):g}")]
    for k in record["parameters"]["bisections"]:
        overlap = [p for p in record["points"] if p["detector"] == "overlap" and p["bisections"] == k]
        worst = max(abs(p["miss_rate"] - p["analytic_miss_rate"]) for p in overlap)
        rows.append((f"overlap, {k} bisections: worst vs model", f"{worst:.3f}"))
    five = next(p for p in record["bisection"] if p["iterations"] == 5)
    return rows + [("time-of-impact error after 5 bisections",
                    f"{five['toi_error_max']:.3g} s (bound {five['bound']:.3g})"),
                   ("lecture errors found (detection chapter)",
                    str(sum(1 for e in record["lecture_errors"] if e["is_error"])))]


STUDY = Study("tunnelling", "Tunnelling: overlap testing against swept testing, and bisection",
              parameters, compute, plot, summary, tables=(LECTURE_ERRORS_TABLE,),
              tasks=tasks, task=task, reduce=reduce, timed=timed)
