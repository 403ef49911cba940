"""Broadphase scaling: every method against n on five distributions, cKDTree as the peer.

For n from 10^2 to 10^6 and each distribution, every method finds the overlapping
pairs; the record keeps the median wall time of several runs, the pair count and the
peak memory, and checks that all methods (and the peer) return the same pairs. Fitted
log-log slopes say how each method scales. A second experiment moves the bodies a
little for 100 frames and compares, per frame, a fresh sort and sweep with the
coherent one (and a BVH refitted against one rebuilt). The issue's performance targets
are evaluated from these same-run measurements and recorded, never asserted.

Peak memory is ``tracemalloc``'s peak over the first call at each point: every allocation
through Python's allocators, which includes all NumPy arrays and all of Numba's (NRT
allocates through ``PyMem_RawMalloc``, which tracemalloc traces), so for steplab's
methods it is their whole working memory, output included. scipy's cKDTree builds its
tree in C++ ``std::vector`` storage that tracemalloc does not see: its figure counts
only the arrays it returns and the filtering, a lower bound.
"""

from __future__ import annotations

import gc
import math
import time
import tracemalloc

import numpy as np
from scipy.spatial import cKDTree
from steplab.physics.broadphase import METHODS as BROADPHASE_METHODS
from steplab.physics.broadphase import BoundingVolumeHierarchy, CoherentSortAndSweep, find_pairs
from steplab.physics.broadphase.common import as_spheres, bounds, padding
from steplab.physics.broadphase.sweep_and_prune import sweep_axis

from . import plotting
from .runner import Study
from .tables import Table, markdown_table

DISTRIBUTIONS = ("uniform", "clustered", "one-cell", "layer", "mixed")
#: the peer, with the same output (filtered to the exact test, sorted), and its raw query alone
PEERS = ("ckdtree", "ckdtree-query")
#: how many per-axis standard deviations of a Gaussian blob lie between blob centres
CLUSTER_SPACING = 8.0
#: the layer's thickness, in radii
LAYER_THICKNESS = 0.2

COLOURS = {"brute": ("tab:gray", "x"), "grid": ("tab:blue", "o"), "hash": ("tab:cyan", "s"),
           "sap": ("tab:orange", "^"), "sap-coherent": ("tab:red", "v"), "bvh": ("tab:green", "D"),
           "bvh-refit": ("tab:olive", "d"), "ckdtree": ("black", "*"), "ckdtree-query": ("black", "+")}


def timed_methods() -> list[str]:
    """The methods timed against n: every registered one but those that say they are
    ``frame_coherent`` ("sap-coherent", timed in the coherence experiment, where it has frames
    to be coherent across; a single call is a plain sort and sweep)."""
    return [name for name, pairs in BROADPHASE_METHODS.items() if not getattr(pairs, "frame_coherent", False)]


def parameters(quick: bool) -> dict:
    sizes = [100, 300, 1_000, 3_000]
    if not quick:
        sizes += [10_000, 30_000, 100_000, 300_000, 1_000_000]
    return {
        "distributions": list(DISTRIBUTIONS), "methods": timed_methods(), "peers": list(PEERS),
        "sizes": sizes,
        "repeats": 3 if quick else 5,  # the median of this many calls...
        "point_budget_s": 0.5 if quick else 2.0,  # ...unless they already took this long (then at least one)
        "time_limit_s": 10.0,  # a method stops where its next call is predicted to pass this
        "max_pairs": 1_000_000 if quick else 10_000_000,  # no size whose answer is predicted longer
        "radius": 1.0,
        "neighbours": 1.5,        # mean overlapping neighbours per body (uniform, layer, mixed)
        "cluster_size": 500, "cluster_neighbours": 8.0,
        "radius_span": 100.0,     # mixed sizes: radii log-uniform over [r, span r]
        "slope_from": 1_000,      # slopes are fitted on n >= this (smaller n measure overheads)
        "seed": 20250604,
        "coherence": {"distribution": "uniform", "n": 5_000 if quick else 20_000, "frames": 100,
                      "motion": 0.02,  # per-axis standard deviation of each body's step, in radii per frame
                      "motion_sweep": [0.002, 0.02, 0.2, 1.0], "sweep_frames": 5 if quick else 10},
    }


# --- scenes -----------------------------------------------------------------------------


def scene(distribution: str, n: int, params: dict, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3) and radii (n,) of one test scene, drawn from ``rng``.

    - uniform: radius r in a cube sized for ``neighbours`` overlaps per body on average;
    - clustered: Gaussian blobs of ``cluster_size`` bodies, ``cluster_neighbours`` overlaps
      per body inside a blob, blob centres uniform and about 8 standard deviations apart;
    - one-cell: all centres in one cube of edge 2r, one grid cell (nearly every pair overlaps);
    - layer: a flat layer 0.2 r thick, sized for ``neighbours`` overlaps per body;
    - mixed: radii log-uniform over [r, 100 r], uniform in a cube sized for ``neighbours``.
    """
    r0, nu = params["radius"], params["neighbours"]
    contact = 4 / 3 * math.pi * (2 * r0) ** 3  # volume within which two radius-r0 spheres overlap
    if distribution == "uniform":
        side = (n * contact / nu) ** (1 / 3)
        return rng.uniform(0, side, (n, 3)), np.full(n, r0)
    if distribution == "clustered":
        m = params["cluster_size"]
        # two blob members are N(0, 2 sigma^2) apart: P(overlap) ~ contact / (4 pi sigma^2)^(3/2)
        sigma = ((m - 1) * contact / params["cluster_neighbours"]) ** (1 / 3) / math.sqrt(4 * math.pi)
        blobs = -(-n // m)
        centres = rng.uniform(0, CLUSTER_SPACING * sigma * blobs ** (1 / 3), (blobs, 3))
        return centres[np.arange(n) // m] + rng.normal(0, sigma, (n, 3)), np.full(n, r0)
    if distribution == "one-cell":
        return rng.uniform(0, 2 * r0, (n, 3)), np.full(n, r0)
    if distribution == "layer":
        side = math.sqrt(n * math.pi * (2 * r0) ** 2 / nu)
        c = rng.uniform(0, side, (n, 3))
        c[:, 2] *= LAYER_THICKNESS * r0 / side
        return c, np.full(n, r0)
    if distribution == "mixed":
        r = r0 * params["radius_span"] ** rng.uniform(0, 1, n)
        mean_cube = 2 * np.mean(r**3) + 6 * np.mean(r**2) * np.mean(r)  # E[(r_i + r_j)^3]
        side = (n * 4 / 3 * math.pi * mean_cube / nu) ** (1 / 3)
        return rng.uniform(0, side, (n, 3)), r
    raise ValueError(f"unknown distribution {distribution!r}; valid: {', '.join(DISTRIBUTIONS)}")


# --- the peer ---------------------------------------------------------------------------


def ckdtree_query(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """cKDTree's candidate pairs: centres within 2 r_max (slightly widened), unordered."""
    reach = 2 * float(r.max()) * (1 + 1e-9) + 2 * padding(c, r)
    return cKDTree(c).query_pairs(reach, output_type="ndarray")


def ckdtree_pairs(centers, radii) -> np.ndarray:
    """What a user of scipy would write for :func:`find_pairs`'s answer: query, filter, sort."""
    c, r = as_spheres(centers, radii)
    if len(c) < 2:
        return np.empty((0, 2), dtype=np.int64)
    pairs = ckdtree_query(c, r).astype(np.int64, copy=False)
    i, j = pairs[:, 0], pairs[:, 1]
    d = c[i, 0] - c[j, 0]  # the same operations, in the same order, as the broadphase's test
    d2 = d * d
    d = c[i, 1] - c[j, 1]
    d2 += d * d
    d = c[i, 2] - c[j, 2]
    d2 += d * d
    s = r[i] + r[j]
    pairs = pairs[d2 <= s * s]
    pairs.sort(axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def run_method(method: str, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    if method == "ckdtree":
        return ckdtree_pairs(c, r)
    if method == "ckdtree-query":
        return ckdtree_query(c, r)
    return find_pairs(c, r, method)


# --- measurement ------------------------------------------------------------------------


def timed(call) -> tuple[float, object]:
    """Wall time of one call, with the cyclic garbage collector held off while it runs."""
    gc.disable()
    try:
        t = time.perf_counter()
        out = call()
        return time.perf_counter() - t, out
    finally:
        gc.enable()


def traced(call) -> tuple[float, int, object]:
    """Wall time, tracemalloc's peak (see the module docstring for what it sees) and result of one call.

    Tracing costs per allocation, and these methods make a handful of large ones, so the
    time is close to an untraced call's; it is used only for calls too slow to repeat.
    """
    gc.disable()
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        t = time.perf_counter()
        out = call()
        seconds = time.perf_counter() - t
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
        gc.enable()
    return seconds, int(peak), out


def predict(points: list[tuple[int, float]], n: int) -> float | None:
    """Extrapolate (n, value) points to ``n`` with the local log-log slope (at least 1)."""
    if not points:
        return None
    if len(points) == 1:
        return points[-1][1] * n / points[-1][0]
    (n1, v1), (n2, v2) = points[-2], points[-1]
    slope = max(1.0, math.log(max(v2, 1e-9) / max(v1, 1e-9)) / math.log(n2 / n1))
    return v2 * (n / n2) ** slope


def fit_slope(points: list[tuple[int, float]]) -> float | None:
    if len(points) < 2:
        return None
    x, y = np.log([p[0] for p in points]), np.log([p[1] for p in points])
    return float(np.polyfit(x, y, 1)[0])


def warm_up() -> None:
    """Compile (or load from Numba's cache) every kernel before anything is timed."""
    rng = np.random.default_rng(0)
    c, r = rng.uniform(0, 3, (64, 3)), rng.uniform(0.1, 0.5, 64)
    for method in ("grid", "hash", "sap", "sap-coherent", "bvh", "brute"):
        find_pairs(c, r, method)
    sweep = CoherentSortAndSweep()
    sweep.update(c, r)
    sweep.update(c + 0.01, r)
    BoundingVolumeHierarchy(c, r).refit(c + 0.01, r)


def compute(params: dict, progress=None) -> dict:
    warm_up()
    series, skipped, mismatches = [], [], []
    for d, distribution in enumerate(params["distributions"]):
        history: dict[str, list[tuple[int, float]]] = {}
        pair_counts: list[tuple[int, float]] = []
        for n in params["sizes"]:
            expected = predict(pair_counts, n)
            if expected is not None and expected > params["max_pairs"]:
                skipped.append({"distribution": distribution, "n": n, "method": "all",
                                "reason": f"about {expected:.2g} pairs predicted, over max_pairs"})
                continue
            c, r = scene(distribution, n, params, np.random.default_rng([params["seed"], d, n]))
            reference = None
            for method in params["methods"] + params["peers"]:
                guess = predict(history.get(method, []), n)
                if guess is not None and guess > params["time_limit_s"]:
                    skipped.append({"distribution": distribution, "n": n, "method": method,
                                    "reason": f"predicted {guess:.3g} s, over the time limit"})
                    continue
                # the first call runs under tracemalloc (peak memory) and warms the caches; a call
                # slower than the point budget is timed there and not repeated, faster ones are
                # timed afresh, untraced, ``repeats`` times
                first, peak, pairs = traced(lambda: run_method(method, c, r))  # noqa: B023
                times = [first] if first > params["point_budget_s"] else []
                while len(times) < params["repeats"] and (not times or sum(times) < params["point_budget_s"]):
                    seconds, pairs = timed(lambda: run_method(method, c, r))  # noqa: B023
                    times.append(seconds)
                row = {"method": method, "distribution": distribution, "n": n,
                       "seconds": float(np.median(times)), "repeats": len(times), "pairs": int(len(pairs)),
                       "peak_bytes": peak, "output_bytes": int(pairs.nbytes)}
                if method != "ckdtree-query":
                    if reference is None:
                        reference = pairs
                    elif not np.array_equal(pairs, reference):
                        mismatches.append({"distribution": distribution, "n": n, "method": method})
                history.setdefault(method, []).append((n, row["seconds"]))
                series.append(row)
                del pairs
            if reference is not None:
                pair_counts.append((n, max(1, len(reference))))
        gc.collect()
        if progress is not None:
            progress()
    slopes = {}
    for method in params["methods"] + params["peers"]:
        for distribution in params["distributions"]:
            pts = [(s["n"], s["seconds"]) for s in series if s["method"] == method
                   and s["distribution"] == distribution and s["n"] >= params["slope_from"]]
            slopes.setdefault(method, {})[distribution] = fit_slope(pts)
    coherence = coherence_experiment(params)
    record = {"series": series, "slopes": slopes, "skipped": skipped, "mismatches": mismatches,
              "coherence": coherence}
    record["targets"] = targets(record, params)
    return record


def coherence_experiment(params: dict) -> dict:
    """Frames of small random motion: per frame, fresh against coherent sort and sweep.

    Each body moves with its own constant random velocity (per-axis standard deviation
    ``motion`` radii per frame). Per frame: a fresh ``sap``; its sort alone (NumPy
    argsort of the sweep axis, what the lecture calls the time-consuming part); the
    coherent sort and sweep and its swaps; the grid; a BVH refitted (built on frame 0)
    and one rebuilt. All must give the same pairs.
    """
    p = params["coherence"]
    d = params["distributions"].index(p["distribution"])
    rng = np.random.default_rng([params["seed"], d, p["n"], 1])
    c0, r = scene(p["distribution"], p["n"], params, rng)

    def run(motion, frames, everything):
        v = rng.normal(0.0, motion * float(np.mean(r)), c0.shape)
        c = c0.copy()
        sweep = CoherentSortAndSweep()
        sweep.update(c, r)
        tree = BoundingVolumeHierarchy(c, r)
        rows = {k: [] for k in ("fresh", "fresh_sort", "coherent", "swaps", "grid", "bvh_refit", "bvh_rebuild")}
        agree = True
        for _ in range(frames):
            c = c + v
            t, fresh = timed(lambda: find_pairs(c, r, "sap"))  # noqa: B023
            rows["fresh"].append(t)
            t, coherent = timed(lambda: sweep.update(c, r))  # noqa: B023
            rows["coherent"].append(t)
            rows["swaps"].append(sweep.swaps)
            agree &= bool(np.array_equal(fresh, coherent))
            if everything:
                lo = bounds(*as_spheres(c, r), padding(c, r))[0]
                axis = sweep_axis(c)
                rows["fresh_sort"].append(timed(lambda: np.argsort(lo[:, axis]))[0])  # noqa: B023
                rows["grid"].append(timed(lambda: find_pairs(c, r, "grid"))[0])  # noqa: B023

                def refit():
                    tree.refit(c, r)  # noqa: B023
                    return tree.pairs()

                t, refitted = timed(refit)
                rows["bvh_refit"].append(t)
                rows["bvh_rebuild"].append(timed(lambda: BoundingVolumeHierarchy(c, r).pairs())[0])  # noqa: B023
                agree &= bool(np.array_equal(fresh, refitted))
        return {k: v for k, v in rows.items() if v}, agree, sweep.full_sorts

    frames, agree, full_sorts = run(p["motion"], p["frames"], everything=True)
    medians = {k: float(np.median(v)) for k, v in frames.items()}
    sweep_rows = []
    for motion in p["motion_sweep"]:
        rows, ok, sorts = run(motion, p["sweep_frames"], everything=False)
        agree &= ok
        sweep_rows.append({"motion": motion, "fresh": float(np.median(rows["fresh"])),
                           "coherent": float(np.median(rows["coherent"])),
                           "swaps": float(np.median(rows["swaps"])), "full_sorts": sorts - 1})
    return {"distribution": p["distribution"], "n": p["n"], "motion": p["motion"], "frames": frames,
            "median": medians, "coherent_over_fresh": medians["coherent"] / medians["fresh"],
            "sort_share_of_fresh": medians["fresh_sort"] / medians["fresh"],
            "refit_over_rebuild": medians["bvh_refit"] / medians["bvh_rebuild"],
            "agree": agree, "fallback_full_sorts": full_sorts - 1, "motion_sweep": sweep_rows}


def targets(record: dict, params: dict) -> dict:
    """The issue's performance targets, from this run's measurements (None where not measured)."""
    def at(distribution, n):
        return {s["method"]: s for s in record["series"] if s["distribution"] == distribution and s["n"] == n}

    out = {}
    row = at("uniform", 100_000)
    ours = {m: s for m, s in row.items() if m in params["methods"]}
    if ours and "ckdtree" in row:
        best = min(ours, key=lambda m: ours[m]["seconds"])
        out["fastest_over_ckdtree_at_1e5_uniform"] = {
            "target": 0.5, "method": best, "seconds": ours[best]["seconds"],
            "ckdtree_seconds": row["ckdtree"]["seconds"],
            "ratio": ours[best]["seconds"] / row["ckdtree"]["seconds"],
            "ratio_to_query_only": ours[best]["seconds"] / row["ckdtree-query"]["seconds"],
            "met": ours[best]["seconds"] <= 0.5 * row["ckdtree"]["seconds"]}
    largest = max((s["n"] for s in record["series"] if s["distribution"] == "uniform"), default=0)
    if largest >= 1_000_000:
        row = {m: s for m, s in at("uniform", largest).items() if m in params["methods"]}
        best = min(row, key=lambda m: row[m]["seconds"])
        slope = record["slopes"][best]["uniform"]
        out["slope_of_fastest_uniform_1e3_to_1e6"] = {"target": 1.1, "method": best, "slope": slope,
                                                      "met": slope is not None and slope <= 1.1}
        out["peak_memory_beyond_output_at_1e6_uniform"] = {
            "target_bytes": 2**30, "method": best,
            "peak_bytes": row[best]["peak_bytes"], "output_bytes": row[best]["output_bytes"],
            "beyond_output_bytes": row[best]["peak_bytes"] - row[best]["output_bytes"],
            "largest_of_any_method": max(s["peak_bytes"] - s["output_bytes"] for s in row.values()),
            "met": row[best]["peak_bytes"] - row[best]["output_bytes"] <= 2**30}
    coherence = record["coherence"]
    out["coherent_over_fresh_per_frame"] = {"target": 0.5, "ratio": coherence["coherent_over_fresh"],
                                            "n": coherence["n"], "motion": coherence["motion"],
                                            "met": coherence["coherent_over_fresh"] <= 0.5}
    return out


# --- figures ----------------------------------------------------------------------------


def _style(method: str) -> dict:
    colour, marker = COLOURS.get(method, ("tab:gray", "."))
    dashed = method in ("ckdtree-query", "bvh-refit")
    return {"color": colour, "marker": marker, "label": method, "ls": "--" if dashed else "-"}


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []
    distributions = list(dict.fromkeys(s["distribution"] for s in record["series"]))
    methods = list(dict.fromkeys(s["method"] for s in record["series"]))
    for quantity, label, stem, scale in (("seconds", "wall time per call (s)", "broadphase_scaling", 1.0),
                                         ("peak_bytes", "peak traced memory (MiB)", "broadphase_memory", 2**-20)):
        fig, axes = plt.subplots(2, 3, figsize=(15, 9), squeeze=False)
        for ax, distribution in zip(axes.flat, distributions):
            for method in methods:
                pts = [s for s in record["series"] if s["method"] == method and s["distribution"] == distribution]
                if not pts or (quantity == "peak_bytes" and method == "ckdtree-query"):  # its tree is not traced
                    continue
                style = _style(method)
                slope = record["slopes"].get(method, {}).get(distribution)
                if quantity == "seconds" and slope is not None:
                    style["label"] += f" (slope {slope:.2f})"
                ax.loglog([s["n"] for s in pts], [max(s[quantity] * scale, 1e-6) for s in pts], ms=4, lw=1.2,
                          **style)
            if quantity == "seconds":
                _guides(ax, [s for s in record["series"] if s["distribution"] == distribution])
            ax.set_title(distribution)
            ax.set_xlabel("bodies n")
            ax.set_ylabel(label)
            ax.grid(True, which="major", alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
        axes.flat[-1].axis("off")
        axes.flat[-1].text(0.0, 0.95, _caption(record, quantity), va="top", fontsize=9, family="monospace",
                           transform=axes.flat[-1].transAxes)
        title = ("Broadphase wall time against n (median of repeats; legend: log-log slope for n >= 1000)"
                 if quantity == "seconds" else
                 "Broadphase peak memory against n (tracemalloc; cKDTree's C++ tree not included)")
        fig.suptitle(title)
        fig.tight_layout()
        figures += plotting.save_figure(fig, out, stem)
    figures += _plot_coherence(record["coherence"], out)
    return figures


def _guides(ax, rows) -> None:
    """Grey reference lines for O(n) and O(n^2) from the fastest smallest point, up to the slowest time."""
    first = min(rows, key=lambda s: (s["n"], s["seconds"]))
    top = max(s["seconds"] for s in rows)
    for power, text in ((1, "O(n)"), (2, "O(n²)")):
        n_end = min(max(s["n"] for s in rows), first["n"] * (top / first["seconds"]) ** (1 / power))
        n = np.array([first["n"], n_end], dtype=float)
        y = first["seconds"] * (n / first["n"]) ** power
        ax.loglog(n, y, color="0.7", lw=0.8, ls=":", zorder=0)
        ax.annotate(text, (n[-1], y[-1]), fontsize=7, color="0.45", ha="right", va="bottom")


def _caption(record: dict, quantity: str) -> str:
    lines = ["targets (same run):"]
    for name, t in record["targets"].items():
        value = t.get("ratio", t.get("slope", t.get("beyond_output_bytes")))
        if name.startswith("peak"):
            value = f"{value / 2**20:.0f} MiB"
        elif value is not None:
            value = f"{value:.3g}"
        lines.append(f"  {name}:\n    {value} ({'met' if t['met'] else 'NOT met'})")
    if record["mismatches"]:
        lines.append(f"MISMATCHES: {len(record['mismatches'])}")
    else:
        lines.append("all methods returned identical pairs")
    return "\n".join(lines)


def _plot_coherence(coh: dict, out) -> list[str]:
    plt = plotting.plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.8))
    frames = np.arange(1, len(coh["frames"]["fresh"]) + 1)
    for key, method in (("fresh", "sap"), ("coherent", "sap-coherent"), ("grid", "grid"),
                        ("bvh_rebuild", "bvh"), ("bvh_refit", "bvh-refit")):
        style = _style(method)
        style["label"] = {"fresh": "sap (fresh sort and sweep)", "coherent": "sap-coherent (repair)",
                          "bvh_rebuild": "bvh (rebuilt)", "bvh_refit": "bvh (refitted)"}.get(key, method)
        left.semilogy(frames, coh["frames"][key], lw=1, ms=2, markevery=10, **style)
    left.semilogy(frames, coh["frames"]["fresh_sort"], color="tab:orange", ls=":", lw=1,
                  label="its sort alone (argsort)")
    left.set_xlabel("frame")
    left.set_ylabel("wall time per frame (s)")
    left.set_title(f"{coh['distribution']}, n = {coh['n']:,}, motion {coh['motion']} r per frame")
    left.grid(True, which="major", alpha=0.3)
    left.legend(fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.13))
    rows = coh["motion_sweep"]
    motion = [row["motion"] for row in rows]
    right.loglog(motion, [row["fresh"] for row in rows], **_style("sap"))
    right.loglog(motion, [row["coherent"] for row in rows], **_style("sap-coherent"))
    right.set_xlabel("motion per frame (radii, per-axis standard deviation)")
    right.set_ylabel("median wall time per frame (s)")
    right.set_title("coherence pays while bodies move little")
    right.grid(True, which="major", alpha=0.3)
    twin = right.twinx()
    repaired = [row for row in rows if not row["full_sorts"]]
    twin.loglog([row["motion"] for row in repaired], [max(row["swaps"], 1) for row in repaired], color="0.5",
                ls=":", marker=".", label="swaps per frame (right axis)")
    for row in rows:
        if row["full_sorts"]:
            right.annotate("repair abandoned,\nfull re-sort", (row["motion"], row["coherent"]), fontsize=7,
                           textcoords="offset points", xytext=(-8, -4), ha="right", va="top")
    twin.set_ylabel("insertion-sort swaps per frame")
    handles = right.get_legend_handles_labels()
    extra = twin.get_legend_handles_labels()
    right.legend(handles[0] + extra[0], handles[1] + extra[1], fontsize=7, loc="upper left")
    fig.suptitle(f"Frame coherence: coherent / fresh = {coh['coherent_over_fresh']:.2f} per frame; "
                 f"the sort is {100 * coh['sort_share_of_fresh']:.0f}% of a fresh sort and sweep")
    fig.tight_layout()
    return plotting.save_figure(fig, out, "broadphase_coherence")


def summary(record: dict) -> list[tuple[str, str]]:
    rows = []
    t = record["targets"]
    if "fastest_over_ckdtree_at_1e5_uniform" in t:
        x = t["fastest_over_ckdtree_at_1e5_uniform"]
        rows.append(("fastest / cKDTree at n = 1e5, uniform",
                     f"{x['ratio']:.2f} ({x['method']} {x['seconds'] * 1e3:.1f} ms, cKDTree "
                     f"{x['ckdtree_seconds'] * 1e3:.1f} ms; target 0.5)"))
    if "slope_of_fastest_uniform_1e3_to_1e6" in t:
        x = t["slope_of_fastest_uniform_1e3_to_1e6"]
        rows.append(("slope of fastest, uniform, 1e3..1e6", f"{x['slope']:.2f} ({x['method']}; target 1.1)"))
    if "peak_memory_beyond_output_at_1e6_uniform" in t:
        x = t["peak_memory_beyond_output_at_1e6_uniform"]
        rows.append(("peak memory beyond output, n = 1e6", f"{x['beyond_output_bytes'] / 2**20:.0f} MiB "
                     f"({x['method']}; target 1024 MiB)"))
    x = t["coherent_over_fresh_per_frame"]
    rows.append(("coherent / fresh sort and sweep per frame",
                 f"{x['ratio']:.2f} (n = {x['n']}, motion {x['motion']} r; target 0.5)"))
    largest = max(s["n"] for s in record["series"])
    best = sorted((s for s in record["series"] if s["n"] == largest and s["distribution"] == "uniform"),
                  key=lambda s: s["seconds"])
    if best:
        rows.append((f"fastest at n = {largest:,}, uniform", ", ".join(
            f"{s['method']} {s['seconds'] * 1e3:.0f} ms" for s in best[:4])))
    rows.append(("methods agree", "yes" if not record["mismatches"] else f"NO: {record['mismatches'][:3]}"))
    return rows


# --- the paper's tables -------------------------------------------------------------


def targets_table(data: dict) -> str:
    """Each broadphase target: what was measured, its limit, and whether it was met."""
    rows = []
    for name, t in data.items():
        if "target_bytes" in t:
            value, limit = f"{t['beyond_output_bytes'] / 2**20:.0f} MiB", f"{t['target_bytes'] / 2**20:.0f} MiB"
        else:
            value, limit = f"{t.get('ratio', t.get('slope')):.2f}", f"{t['target']:g}"
        method = f" ({t['method']})" if "method" in t else ""
        rows.append([name.replace("_", " ") + method, value, limit, "met" if t.get("met") else "missed"])
    return markdown_table(["target", "measured", "limit", ""], rows)


TABLES = (Table("broadphase_targets", lambda r: r["targets"], targets_table),)


STUDY = Study("broadphase", "Broadphase: brute force, grid, hash, sort and sweep, BVH against n; cKDTree as peer",
              parameters, compute, plot, summary, tables=TABLES)
