"""``steplab bench --repeat N``: the same sections in N fresh processes, each ratio summarised over them.

Some ratios move between runs by more than what separates met from missed: the xpbd cloth's
against its cold memory bound moves with where a process's arrays land and with the host's
memory over minutes (docs/performance.md), so one run cannot judge it. Each repeat is a whole
``steplab bench`` of its own process, one after another, its record kept; the summary gives
each ratio's least, median and largest value over the runs and how many of them met its
target, and judges the target on the median.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from .report import rows

#: a fresh interpreter running the command line (steplab has no ``__main__``)
_CHILD = "import sys; from steplab.cli.main import main; sys.exit(main())"


def run_repeated(n: int, quick: bool, only: list[str] | None, progress) -> dict | None:
    """``n`` runs of ``steplab bench`` (``--quick``, ``--only``), each in a process of its own: their
    records (``runs``) and :func:`summary` of them; None where a run failed (its own error line, then
    one saying which run, on stderr)."""
    arguments = ["bench"] + (["--quick"] if quick else []) + [a for name in only or () for a in ("--only", name)]
    records = []
    with tempfile.TemporaryDirectory(prefix="steplab-bench-") as folder:
        for k in range(n):
            progress(f"run {k + 1} of {n}: steplab {' '.join(arguments)}")
            path = Path(folder) / f"{k}.json"
            status = subprocess.run([sys.executable, "-c", _CHILD, *arguments, "--json", str(path)],
                                    stdout=subprocess.DEVNULL).returncode
            if status != 0:
                print(f"steplab bench: error: run {k + 1} of {n} ended with status {status}", file=sys.stderr)
                return None
            records.append(json.loads(path.read_text()))
    return {"repeat": n, "arguments": arguments, "runs": records, "summary": summary(records)}


def summary(records: list[dict]) -> list[dict]:
    """Each comparison of the runs (in the first run's order): its ratios, least, median and largest, the
    target, how many runs met it, and whether the median does."""
    by_name: dict[str, list[dict]] = {}
    for record in records:
        for row in rows(record):
            by_name.setdefault(row["name"], []).append(row)
    out = []
    for name, found in by_name.items():
        ratios = [row["ratio"] for row in found]
        median, target = statistics.median(ratios), found[0]["target"]
        out.append({"name": name, "group": found[0]["group"], "runs": len(found), "ratios": ratios,
                    "min": min(ratios), "median": median, "max": max(ratios), "target": target,
                    "met_runs": None if target is None else sum(bool(row["met"]) for row in found),
                    "median_met": None if target is None else median <= target})
    return out


def format_summary(result: dict, markdown: bool = False) -> str:
    """The summary as a table for the terminal or as Markdown: a line per comparison, then what was run."""
    header = ("group", "comparison", "runs", "least", "median", "largest", "target", "met in")
    body = []
    for s in result["summary"]:
        verdict = "" if s["target"] is None else (
            f"{s['met_runs']} of {s['runs']} runs; the median {'meets' if s['median_met'] else 'misses'} it")
        target = "" if s["target"] is None else f"≤ {s['target']:g}"
        body.append((s["group"], s["name"], str(s["runs"]), *(f"{s[k]:.3g}" for k in ("min", "median", "max")),
                     target, verdict))
    cpu = result["runs"][0].get("provenance", {}).get("cpu", "?") if result["runs"] else "?"
    footer = (f"ratio = steplab / peer per run (steplab bench's table); {result['repeat']} runs of "
              f"`steplab {' '.join(result['arguments'])}`, each a process of its own, one after another; {cpu}")
    if markdown:
        return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                         + ["| " + " | ".join(row) + " |" for row in body] + ["", f"- {footer}"])
    widths = (17, 40, 4, 7, 7, 7, 8)  # the last column as long as it is

    def line(row) -> str:
        cells = [f"{cell:<{w}}" if k in (0, 1, 6) else f"{cell:>{w}}" for k, (cell, w) in enumerate(zip(row, widths))]
        return " ".join(cells + [row[-1]])

    return "\n".join([line(header)] + [line(row) for row in body] + [footer])
