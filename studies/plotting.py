"""Shared figure conventions and atomic figure writing (PNG for reading, SVG for the paper)."""

from __future__ import annotations

import io
import zlib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
# fixed SVG element ids: the same record gives byte-identical figures
matplotlib.rcParams["svg.hashsalt"] = "steplab"
import matplotlib.pyplot as plt  # noqa: E402
from steplab.integrators import UnknownIntegratorError, get_integrator  # noqa: E402

from steplab.core.records import write_atomic  # noqa: E402

#: colours and markers for a method that states no ``style`` (the references, a plugin, a test
#: stepper): ones steplab's own methods (tab10 and black, one each) leave free. A registered method
#: takes the next in registry order, so no two share one; any other name (a reference drawn under
#: a name of its own) one of those left, by a stable checksum of the name (not Python's hash(),
#: which is salted per process), so a figure is the same every run
SPARE_COLOURS = ("darkgoldenrod", "navy", "crimson", "teal", "magenta", "gold", "darkslategray", "sienna",
                 "deepskyblue", "olivedrab")
SPARE_MARKERS = ("h", "p", "d", "<", ">", "8", "H")


def _spare(name: str) -> tuple[str, str]:
    from steplab.integrators import INTEGRATORS

    unstyled = [n for n, method in INTEGRATORS.items() if method.style is None]
    if name in unstyled:
        k = unstyled.index(name)
        return SPARE_COLOURS[k % len(SPARE_COLOURS)], SPARE_MARKERS[k % len(SPARE_MARKERS)]
    free = SPARE_COLOURS[len(unstyled):] or SPARE_COLOURS
    k = zlib.crc32(name.encode())
    return free[k % len(free)], SPARE_MARKERS[k // len(free) % len(SPARE_MARKERS)]


def style(name: str) -> dict:
    """Keyword arguments that draw integrator ``name`` in its own colour and marker.

    The method states them (``Integrator.style``); any other name gets a spare pair.
    """
    try:
        colour_marker = get_integrator(name).style
    except UnknownIntegratorError:  # not an integrator (a reference drawn under another name)
        colour_marker = None
    colour, marker = colour_marker or _spare(name)
    return {"color": colour, "marker": marker, "label": name}


def colour(name: str) -> str:
    """Method ``name``'s colour as ``#rrggbb``: the one matplotlib draws it in, for the Plotly pages."""
    return matplotlib.colors.to_hex(style(name)["color"])


def save_figure(fig, out: Path, stem: str) -> list[str]:
    """Write ``stem.png`` and ``stem.svg`` into ``out`` atomically; return their names."""
    names = []
    for ext in ("png", "svg"):
        buffer = io.BytesIO()
        # no dates or versions in the files: the same record gives the same bytes
        fig.savefig(buffer, format=ext, dpi=150, bbox_inches="tight",
                    metadata={"Date": None} if ext == "svg" else {"Software": None})
        write_atomic(Path(out) / f"{stem}.{ext}", buffer.getvalue())
        names.append(f"{stem}.{ext}")
    plt.close(fig)
    return names


def integer_ticks(ax, values) -> None:
    """Tick a log x axis at the swept counts themselves (iterations, substeps: 1 2 4 8, not 10^0 10^1)."""
    from matplotlib.ticker import NullFormatter

    values = sorted(set(values))
    ax.set_xticks(values, [str(v) for v in values])
    ax.xaxis.set_minor_formatter(NullFormatter())


#: a diverged run's mark, in the band and in the legend
_CROSS = {"linestyle": "none", "marker": "x", "ms": 8, "mew": 1.5}


def diverged_band(ax, lost: list[tuple[list, str]]) -> None:
    """Mark runs that diverged as crosses in a band above a panel's curves (its top sixth, on a log or linear axis).

    ``lost`` holds, for each method with diverged runs, (its x values, its colour); each method's crosses
    sit at a height of their own, so none hides another's. A diverged run has no error to draw (or
    only the blow-up's size, which would squash the other curves), yet leaving it out reads as
    "not run": the cross says it ran and failed. Call it after the curves, which set the y range.
    """
    low, high = ax.get_ylim()
    top = high * (high / low) ** 0.2 if ax.get_yscale() == "log" else high + 0.2 * (high - low)
    ax.set_ylim(low, top)
    ax.axhspan(high, top, color="0.93", zorder=0, lw=0)  # shaded: off the scale, not a value
    step = min(0.04, 0.1 / max(len(lost), 1))  # the heights (axes fraction) stay within the band, 0.83 to 1
    for n, (xs, colour) in enumerate(lost):
        ax.plot(xs, [0.94 - step * n] * len(xs), transform=ax.get_xaxis_transform(), color=colour, **_CROSS)


def diverged_key(ax, label: str) -> None:
    """The legend's entry for :func:`diverged_band`'s crosses (a black one), under ``label``."""
    ax.plot([], [], color="k", label=label, **_CROSS)


def stable_dt_panel(ax, rows: list[dict], x: str, theory_label: str, slopes: dict | None = None) -> None:
    """Largest stable dt against ``x`` per integrator: measured (markers), theory (lines), 1/60 s.

    ``rows`` hold ``integrator``, ``x``, ``dt_max`` and ``dt_max_theory`` (None: no limit,
    0: unstable at every dt; such methods get a legend entry only).
    """
    for method in dict.fromkeys(r["integrator"] for r in rows):
        mine = [r for r in rows if r["integrator"] == method]
        entry = style(method)
        if all(r["dt_max"] is None for r in mine) or all(r["dt_max"] == 0 for r in mine):
            verdict = "stable at every dt" if mine[0]["dt_max"] is None else "unstable at every dt (undamped)"
            ax.plot([], [], linestyle="none", color=entry["color"], marker=entry["marker"],
                    label=f"{method}: {verdict}")
            continue
        if slopes and method in slopes:
            entry["label"] += f" (slope {slopes[method]:.3f})"
        xs = [r[x] for r in mine]
        ax.loglog(xs, [r["dt_max"] for r in mine], linestyle="none", ms=7, mfc="none", **entry)
        ax.loglog(xs, [r["dt_max_theory"] for r in mine], color=entry["color"], lw=0.8, alpha=0.7)
    ax.axhline(1 / 60, color="k", lw=0.8, ls=":")
    ax.text(min(r[x] for r in rows), 1 / 60 * 1.15, "dt = 1/60 s", fontsize=8)
    ax.plot([], [], color="gray", lw=0.8, label=theory_label)
    ax.set_ylabel("largest stable dt (s)")
    ax.grid(True, which="both", alpha=0.3)

