"""The bench's report: one row per comparison, as a table for the terminal or as Markdown.

Below it, the ball pits of the collision section and the box pits of the stacking section: one
row per pit and contender, with the real-time factor (simulated seconds per wall second) and its
target.
"""

from __future__ import annotations

from .startup import footer as startup_footer


def rows(record: dict) -> list[dict]:
    """One row per comparison, in the order run: name, group, what, peer, medians, ratio, target."""
    out = []
    for name in record["order"]:
        s = record["seconds"][name]
        target = record["targets"].get(name) or next(
            (t for t in record["targets"].values() if t.get("alias_of") == name), None)
        out.append({"name": name, "group": s["group"], "what": s["what"], "peer": s["peer_name"],
                    "steplab": s["steplab"], "peer_seconds": s["peer"], "ratio": record["ratios"][name],
                    "ratio_of_minimums": s.get("ratio_of_minimums"),
                    "clock": s.get("clock", "wall"), "ratio_wall": s.get("ratio_wall"),
                    "steplab_spread": s.get("steplab_spread"), "peer_spread": s.get("peer_spread"),
                    "ratio_stable": s.get("ratio_stable"), "stability_note": s.get("stability_note"),
                    "target": None if target is None else target["target"],
                    "met": None if target is None else target["met"]})
    return out


def collision_rows(record: dict) -> list[dict]:
    """One row per ball pit and contender: per-step cost, real-time factor, the target on it."""
    out = []
    for label, pit in record.get("collisions", {}).items():
        targets = {"steplab": record["targets"].get(f"real_time_{label}"),
                   "steplab_solver": record["targets"].get(f"solver_real_time_{label}")}
        for name, c in pit["contenders"].items():
            mine = name in targets
            out.append({"pit": label, "balls": pit["balls"], "steps": pit["steps"], "contender": c["settings"],
                        "per_step": c["per_step_seconds"], "real_time_factor": c["real_time_factor"],
                        # the crowded pit times its contenders only: no count of balls or impacts
                        "target": targets.get(name), "balls_inside": c.get("balls_inside"),
                        "impacts": f"{c['impacts']:,}" if mine and "impacts" in c else ""})
        for note in pit["not_compared"].values():
            out.append({"pit": label, "balls": pit["balls"], "steps": pit["steps"], "contender": note,
                        "per_step": None, "real_time_factor": None, "target": None, "balls_inside": None,
                        "impacts": ""})
    return out


def box_pit_rows(record: dict) -> list[dict]:
    """One row per box pit and contender (the 2-core run of steplab its own row): the cores it ran
    on, its real-time factor, and the real-time target where the row is the run that judged it."""
    out = []
    for label, pit in record.get("stacking", {}).items():
        if not label.startswith("box_pit_"):
            continue
        target = record["targets"].get(f"real_time_{label}")
        settings = dict(pit["settings"])
        child = pit.get("on_cores", {})
        if "settings" in child:
            each = [f"{run['real_time_factor']:.3g}" for run in child.get("processes", ()) if "real_time_factor" in run]
            settings[f"steplab_{child['cores']}_cores"] = child["settings"] + (
                f" (the median of {len(each)} processes: {', '.join(each)}x real time)" if len(each) > 1 else "")
        for name, factor in pit["real_time_factor"].items():
            cores = pit.get("cores", {}).get(name, 1)
            judged = target is not None and target.get("cores", 1) == cores and name.startswith("steplab")
            out.append({"pit": label, "boxes": pit["boxes"], "steps": pit["steps"], "contender": settings[name],
                        "cores": cores, "real_time_factor": factor, "target": target if judged else None})
        for name, note in pit["not_compared"].items():
            out.append({"pit": label, "boxes": pit["boxes"], "steps": pit["steps"], "contender": f"{name}: {note}",
                        "cores": None, "real_time_factor": None, "target": None})
    return out


def _real_time_verdict(target) -> str:
    if target is None:
        return ""
    return f"≥ {target['real_time_target']:g}x: {'met' if target['met'] else 'missed'}"


def _pit_lines(rows_: list[dict], columns: tuple, markdown: bool) -> list[str]:
    """A pit table's lines, none without rows: ``columns`` are (terminal heading, its width as a format
    spec, Markdown heading, the row's cell); Markdown sets the first cell, the pit's label, as code."""
    if not rows_:
        return []
    if markdown:
        def line(r):
            label, *cells = (c[3](r) for c in columns)
            return " | ".join([f"| `{label}`", *cells]) + " |"
        return ["", "| " + " | ".join(c[2] for c in columns) + " |", "|" + "---|" * len(columns), *map(line, rows_)]
    return ["", "  ".join(f"{c[0]:{c[1]}}" for c in columns).rstrip(),
            *("  ".join(f"{c[3](r):{c[1]}}" for c in columns).rstrip() for r in rows_)]


def _real_time(r) -> str:
    return _optional(r["real_time_factor"], "{:.3g}".format)


def _pit_columns(pit: str, bodies: str, contender_width: str, middle: tuple, target_width: str, after=()) -> tuple:
    """A pit table's columns (:func:`_pit_lines`): the pit, its ``bodies`` (the rows' key and the
    heading), the steps and the contender, then ``middle``, the real-time factor and its target,
    then ``after``; each column (terminal heading, terminal format, Markdown heading, cell of a row)."""
    return (
        (pit, "<15", pit, lambda r: r["pit"]), (bodies, ">7", bodies, lambda r: f"{r[bodies]:,}"),
        ("steps", ">5", "steps", lambda r: str(r["steps"])),
        ("contender", contender_width, "contender", lambda r: r["contender"]), *middle,
        ("x real time", ">11", "simulated s per wall s", _real_time),
        ("target", target_width, "target", lambda r: _real_time_verdict(r["target"])), *after)


#: the ball pits' columns
BALL_PIT_COLUMNS = _pit_columns(
    "ball pit", "balls", "<58.58", (("per step", ">9", "per step", lambda r: _optional(r["per_step"], _seconds)),),
    "<14", (("impacts", "<27", "impacts", lambda r: r["impacts"]),
            ("inside", "", "balls inside", lambda r: _optional(r["balls_inside"], "{:,}".format))))
#: the box pits' columns
BOX_PIT_COLUMNS = _pit_columns("box pit", "boxes", "<72.72",
                               (("cores", ">5", "cores", lambda r: _optional(r["cores"], str)),), "")


def collision_markdown(record: dict) -> list[str]:
    """The ball-pit table (steplab against the physics engines) as Markdown lines; none without pits."""
    return _pit_lines(collision_rows(record), BALL_PIT_COLUMNS, markdown=True)


def box_pit_markdown(record: dict) -> list[str]:
    """The box-pit table (steplab on one core and on the target's cores, beside the engines) as
    Markdown lines; none without box pits."""
    return _pit_lines(box_pit_rows(record), BOX_PIT_COLUMNS, markdown=True)


def _optional(value, form) -> str:
    return "–" if value is None else form(value)


def _seconds(s: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if s >= scale:
            return f"{s / scale:.3g} {unit}"
    return f"{s:.2g} s"


def _spread(spread) -> str:
    """``min / median / max`` of a side's rounds; empty for a record written before they were kept."""
    if spread is None:
        return ""
    return " / ".join(_optional(spread[key], _seconds) for key in ("min", "median", "max"))


def _stability(row) -> str:
    if row["ratio_stable"] is None:
        return ""
    return "yes" if row["ratio_stable"] else f"no: {row['stability_note']}"


def _verdict(row) -> str:
    if row["target"] is None:
        return ""
    return f"≤ {row['target']:g}: {'met' if row['met'] else 'missed'}"


def format_table(record: dict) -> str:
    lines = [f"{'group':<17} {'comparison':<40} {'peer':<44} {'steplab':>9} {'peer':>9} {'clock':>5} {'ratio':>7} "
             f"{'(min)':>7} {'(wall)':>7}  {'target on the ratio':<20} stable (spread of the rounds within 15 %)"]
    for r in rows(record):
        lines.append(f"{r['group']:<17} {r['name']:<40} {r['peer'][:44]:<44} {_seconds(r['steplab']):>9} "
                     f"{_seconds(r['peer_seconds']):>9} {r['clock']:>5} {r['ratio']:>7.3g} "
                     f"{_ratio(r['ratio_of_minimums']):>7} {_ratio(r['ratio_wall']):>7}  {_verdict(r):<20} "
                     f"{_stability(r)}")
    lines += _pit_lines(collision_rows(record), BALL_PIT_COLUMNS, markdown=False)
    lines += _pit_lines(box_pit_rows(record), BOX_PIT_COLUMNS, markdown=False)
    lines += _footer(record)
    return "\n".join(lines)


def format_markdown(record: dict) -> str:
    lines = ["| comparison | what | peer | steplab | peer | clock | ratio | ratio of minimums | wall-time ratio | "
             "target | steplab min / median / max | peer min / median / max | ratio stable |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows(record):
        lines.append(f"| `{r['name']}` | {r['what']} | {r['peer']} | {_seconds(r['steplab'])} | "
                     f"{_seconds(r['peer_seconds'])} | {r['clock']} | {r['ratio']:.3g} | "
                     f"{_ratio(r['ratio_of_minimums'])} | {_ratio(r['ratio_wall'])} | "
                     f"{_verdict(r)} | {_spread(r['steplab_spread'])} | {_spread(r['peer_spread'])} | "
                     f"{_stability(r)} |")
    lines += collision_markdown(record)
    lines += box_pit_markdown(record)
    lines.append("")
    lines += [f"- {line}" for line in _footer(record)]
    return "\n".join(lines)


def _ratio(value) -> str:
    return "" if value is None else f"{value:.3g}"


def _footer(record: dict) -> list[str]:
    out = []
    c = record["targets"].get("compile_seconds_max")
    if c is not None:
        out.append(f"JIT compile time, slowest built-in scene: {c['seconds']:.3g} s ({c['scene']}); "
                   f"target ≤ {c['target']:g} s: {'met' if c['met'] else 'missed'}")
    others = {k: v for k, v in record["compile_seconds"].items() if not k.startswith("scene ")}
    if others:
        out.append("JIT compile time, " + ", ".join(f"{k}: {v:.3g} s" for k, v in others.items()))
    tighter = [f"{name} {s['compiled_stream']['ratio']:.3g}x" for name, s in record["seconds"].items()
               if "compiled_stream" in s]
    if tighter:
        out.append("against a tighter memory bound, the same bytes moved in one compiled pass instead of NumPy's "
                   f"two (the targets stay on NumPy's): {', '.join(tighter)}")
    out += startup_footer(record)
    prov = record.get("provenance", {})
    mode = "quick" if record["quick"] else "full"
    only = record["details"].get("only")
    if only:
        mode += f" (only {', '.join(only)})"
    pinned = record["details"].get("threads", {}).get("pinned")
    out.append(f"ratio = steplab median / peer median (below 1: steplab faster), on the clock shown: CPU "
               f"seconds where both sides ran on one thread (what the wall time is on an idle core, and "
               f"hardly moved by other processes), else wall seconds; (min) the same of the fastest rounds, "
               f"(wall) of the wall-time medians; {mode} run, "
               f"{record['config']['repeats']} to {record['config'].get('max_rounds', record['config']['repeats'])} "
               f"interleaved rounds (until the minimums settle), "
               f"{'one thread per side' if pinned else 'threads not pinned'}"
               f"; {prov.get('cpu', '?')}, "
               f"jax {prov.get('packages', {}).get('jax', '?')}, commit {str(prov.get('git_commit'))[:10]}")
    return out
