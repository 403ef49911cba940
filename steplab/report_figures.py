"""Interactive figures for ``steplab report``: zoomable error-against-dt and work-precision plots.

The static PNGs say what the studies found; on the site, the two plots a reader most wants
to zoom into (many methods over many decades) are also drawn with Plotly from the same
record: the truncation study's global error against dt, one figure per problem, and the
work-precision study's error against wall time, one per scene. Hovering names a point's
method, dt and error; drag to zoom, double-click to go back. Each figure is a page of its
own beside the site's pages, sharing one copy of plotly.min.js (written by Plotly next to
them, so the site needs no network). Every method is drawn in the colour the static figures give
it (:func:`steplab.studies.plotting.colour`). A point whose error is not a finite number (None in the
record, or NaN or inf: the run diverged) cannot be drawn on a log axis: its method's legend entry says
where it diverged instead.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

from steplab.studies.plotting import colour  # each method in its colour of the static figures

#: where the interactive pages go, inside the site
INTERACTIVE = "interactive"


def figures(name: str, record: dict) -> list[tuple[str, str, object]]:
    """``(stem, title, plotly Figure)`` for each interactive figure of study ``name`` (none for most)."""
    if name == "truncation":
        return _error_against_dt(record)
    if name == "work_precision":
        return _work_precision(record)
    return []


def write(name: str, record: dict, out: Path) -> list[tuple[str, str]]:
    """Write the interactive pages of study ``name`` into ``out / INTERACTIVE``; ``(title, link)`` each."""
    written = []
    for stem, title, fig in figures(name, record):
        folder = Path(out) / INTERACTIVE
        folder.mkdir(parents=True, exist_ok=True)
        fig.write_html(folder / f"{stem}.html", include_plotlyjs="directory", full_html=True,
                       config={"displaylogo": False})
        written.append((title, f"{INTERACTIVE}/{stem}.html"))
    return written


def _log_figure(title: str, x_title: str, y_title: str):
    import plotly.graph_objects as go

    fig = go.Figure()
    fig.update_layout(title=title, template="plotly_white", hovermode="closest", legend_title_text="method",
                      xaxis={"type": "log", "title": x_title, "exponentformat": "power"},
                      yaxis={"type": "log", "title": y_title, "exponentformat": "power"})
    return fig


def _drawn(error) -> bool:
    """Whether a point's error can be drawn on a log axis: a finite number above 0."""
    return isinstance(error, (int, float)) and math.isfinite(error) and error > 0


def _diverged(error) -> bool:
    """Whether a point's error says its run diverged: None (the studies' record of a divergence), NaN or inf."""
    return error is None or (isinstance(error, float) and not math.isfinite(error))


def _name(method: str, points: list[dict]) -> str:
    """A method's legend entry: its name, and where its runs diverged (points not drawn)."""
    lost = sorted(p["dt"] for p in points if _diverged(p.get("error")) and p.get("dt") is not None)
    if not lost:
        return method
    drawn = [p["dt"] for p in points if _drawn(p.get("error")) and p.get("dt") is not None]
    if not drawn or lost[0] > max(drawn):  # every step from the smallest that diverged up
        return f"{method} (diverged at dt >= {lost[0]:.3g} s)"
    return f"{method} (diverged at {len(lost)} of its dt)"


def _error_against_dt(record: dict):
    import plotly.graph_objects as go

    by_problem = defaultdict(list)
    for curve in record["curves"]:
        if curve.get("precision", "float64") == "float64":
            by_problem[(curve["problem"], curve.get("title", curve["problem"]))].append(curve)
    out = []
    for (problem, title), curves in by_problem.items():
        fig = _log_figure(f"Global error at the end time against dt: {title} (float64)", "dt, s",
                          "global position error, m")
        for curve in curves:
            points = [p for p in curve["points"] if _drawn(p["error"])]
            fig.add_trace(go.Scatter(x=[p["dt"] for p in points], y=[p["error"] for p in points],
                                     mode="lines+markers", name=_name(curve["integrator"], curve["points"]),
                                     marker_color=colour(curve["integrator"]), line_color=colour(curve["integrator"]),
                                     hovertemplate="dt = %{x:.3g} s<br>error = %{y:.3g} m"))
        out.append((f"truncation_{problem}", f"error against dt, {title}", fig))
    return out


def _work_precision(record: dict):
    import plotly.graph_objects as go

    by_scene = defaultdict(lambda: defaultdict(list))
    for point in record["points"]:  # every point, drawn or diverged, for the legend to say which diverged
        by_scene[point["scene"]][point["method"]].append(point)
    out = []
    for scene, methods in by_scene.items():
        fig = _log_figure(f"Work against precision: {scene}", "compiled wall time per run, s", "final error")
        for method, every in methods.items():
            points = sorted((p for p in every if _drawn(p.get("error")) and _drawn(p.get("seconds"))),
                            key=lambda p: p["seconds"])
            name = _name(method, every)
            if not points and name == method:  # only untimed points: nothing to draw, nothing diverged
                continue
            fig.add_trace(go.Scatter(
                x=[p["seconds"] for p in points], y=[p["error"] for p in points], mode="lines+markers", name=name,
                marker_color=colour(method), line_color=colour(method),
                text=[f"dt = {p['dt']:.3g} s" if p.get("dt") else "adaptive" for p in points],
                hovertemplate="%{text}<br>time = %{x:.3g} s<br>error = %{y:.3g}"))
        out.append((f"work_precision_{scene}", f"work against precision, {scene}", fig))
    return out
