"""``steplab report``: a static HTML site of a results folder, to browse every study.

One page per study (its summary lines, its figures, the tables the paper prints from
its record, the numbers the paper's text quotes from it, each with the words around it, and
the record's provenance), an errata page (the lecture's errors the studies
found), the bench and engines tables when ``bench.json`` is there, and an index of them all. The
pages are Markdown drawn from the records alone, turned into HTML by the paper's own
:func:`steplab.paper.to_html`; the tables are the studies' own (``Study.tables``,
studies/tables.py), so the site and the paper never disagree. Every link is relative,
so ``python -m http.server -d SITE`` (or opening ``index.html`` as a file) serves it.
Figures are the static PNGs the studies draw; the error-against-dt and work-precision plots
also come as zoomable Plotly pages (:mod:`steplab.report_figures`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from steplab import report_figures
from steplab.bench.report import collision_markdown
from steplab.core.records import write_atomic
from steplab.paper import BENCH_TABLE, PLACEHOLDER, PaperError, load_records, lookup, to_html
from steplab.studies import STUDIES
from steplab.studies.tables import format_value, markdown_table

#: the tables that list the lecture's errors (truncation: its misprinted formulas;
#: restitution and tunnelling: the response and detection chapters' errors)
ERRATA_TABLES = ("misprints", "lecture_errors")
#: where the copied figures go, inside the site
FIGURES = "figures"
#: the paper's text, whose numbers the study pages list (in a checkout; absent, they are left out)
PAPER_TEMPLATE = Path(__file__).resolve().parent.parent / "paper" / "paper.template.md"


class ReportError(ValueError):
    """A results folder the site cannot be built from (missing, empty, a figure absent)."""


def build(results: Path, out: Path) -> list[Path]:
    """Write the site of ``results`` into ``out``; return the files written (index first).

    Raises
    ------
    ReportError
        When ``results`` is not a folder, holds no study record, or a record names a
        figure the folder does not have.
    """
    results, out = Path(results), Path(out)
    if not results.is_dir():
        raise ReportError(f"--results {results}: no such folder; run `steplab reproduce --out {results}` first")
    records = load_records(results)
    studies = [(STUDIES[name], records[name]) for name in STUDIES if name in records]
    bench = records.get("bench")
    if not studies and bench is None:
        raise ReportError(f"{results}: no study results (known studies: {', '.join(STUDIES)}); "
                          f"run `steplab reproduce --out {results}` first")
    pages = {"index.html": index_page(studies, bench)}
    for study, record in studies:
        pages[f"{study.name}.html"] = study_page(study, record, results, report_figures.write(study.name, record, out))
    pages["errata.html"] = errata_page(studies)
    if bench is not None:
        pages["bench.html"] = bench_page(bench)
    written = []
    for study, record in studies:
        for figure in _pngs(record):
            source = results / figure
            if not source.exists():
                raise ReportError(f"{results / (study.name + '.json')} lists the figure {figure}, "
                                  f"which {results} does not have")
            write_atomic(out / FIGURES / figure, source.read_bytes())
            written.append(out / FIGURES / figure)
    for name, markdown_text in pages.items():
        write_atomic(out / name, to_html(markdown_text, {}).encode())
    return [out / name for name in pages] + written


# --- pages (Markdown) ---------------------------------------------------------------


def _nav(here: str) -> str:
    links = [("index.html", "index"), ("errata.html", "errata")]
    return " · ".join(text if href == here else f"[{text}]({href})" for href, text in links) + "\n\n"


def _summary_lines(study, record) -> str:
    rows = study.summary(record)
    return "\n".join(f"- {label}: {value}" for label, value in rows) + "\n" if rows else ""


def index_page(studies: list, bench: dict | None) -> str:
    text = "# steplab results\n\n" + _nav("index.html")
    text += "Every study of the results folder, with the summary `steplab reproduce` prints.\n\n"
    for study, record in studies:
        quick = " (quick run)" if _is_quick(study, record) else ""
        text += f"## [{study.name}]({study.name}.html): {record['title']}{quick}\n\n"
        text += _summary_lines(study, record) + "\n"
    text += "## [Errata](errata.html)\n\nThe lecture's errors the studies found.\n\n"
    if bench is not None:
        text += "## [Bench](bench.html)\n\nsteplab timed against its peers (`steplab bench`).\n\n"
    return text


def study_page(study, record: dict, results: Path, interactive=()) -> str:
    text = f"# {record['title']}\n\n" + _nav("") + f"Study `{study.name}`; record `{study.name}.json`.\n\n"
    summary = _summary_lines(study, record)
    if summary:
        text += "## Summary\n\n" + summary + "\n"
    figures = _pngs(record)
    if figures:
        text += "## Figures\n\n"
        for figure in figures:
            what = Path(figure).stem.removeprefix(f"{study.name}_").replace("_", " ")
            text += f"![{study.name}, figure: {what}]({FIGURES}/{figure})\n\n"
    if interactive:  # (title, link) of zoomable versions (steplab/report_figures.py)
        text += "Zoomable versions (drag to zoom, double-click to reset): " + ", ".join(
            f"[{title}]({link})" for title, link in interactive) + ".\n\n"
    drawn = [(table.name, _draw(table, record)) for table in study.tables]
    if drawn:
        text += "## Tables\n\n" + "".join(f"### {name.replace('_', ' ')}\n\n{markdown}\n\n"
                                           for name, markdown in drawn)
    quoted = quoted_numbers(study.name, record)
    if quoted:
        text += "## Numbers the paper quotes\n\n" + quoted + "\n\n"
    return text + provenance(record)


def quoted_numbers(name: str, record: dict, template: Path = PAPER_TEMPLATE) -> str:
    """The values of ``record`` the paper's text quotes (``{{name/...}}``), from this record, as the
    paper prints them, each with the words before it; "" without the template or any."""
    if not Path(template).exists():
        return ""
    text = Path(template).read_text()
    rows = []
    for match in PLACEHOLDER.finditer(text):
        path, _, spec = match.group(1).partition(":")
        if path.split("/")[0] != name:
            continue
        try:
            value = format_value(lookup({name: record}, path), spec)
        except PaperError:  # a quick run's record lacks what only the full run has
            value = "not in this record"
        before = PLACEHOLDER.sub("…", text[max(0, match.start() - 90):match.start()])
        words = " ".join(re.split(r"(?<=[.:;])\s", " ".join(before.split()))[-1].split()[-12:])
        rows.append([f"`{path}`", value, f"… {words}"])
    return markdown_table(["record path", "value", "where the paper quotes it"], rows) if rows else ""


def errata_page(studies: list) -> str:
    text = "# Errata: the lecture's errors\n\n" + _nav("errata.html")
    text += "What the studies found wrong in the lecture, each with the evidence steplab computed.\n\n"
    found = False
    for study, record in studies:
        for table in study.tables:
            if table.name in ERRATA_TABLES:
                found = True
                text += f"## [{study.name}]({study.name}.html): {table.name.replace('_', ' ')}\n\n"
                text += _draw(table, record) + "\n\n"
    if not found:
        text += "None of the studies in this results folder checks the lecture (truncation, restitution " \
                "and tunnelling do).\n"
    return text


def bench_page(bench: dict) -> str:
    text = "# Bench: steplab against its peers\n\n" + _nav("") + _draw(BENCH_TABLE, bench) + "\n\n"
    engines = collision_markdown(bench)
    if engines:
        text += "## The engines: ball pits against MuJoCo and pybullet\n" + "\n".join(engines) + "\n\n"
    return text + provenance(bench)


def provenance(record: dict) -> str:
    """The record's provenance as a list: versions, commit, CPU, date."""
    p = record.get("provenance")
    if not p:
        return "## Provenance\n\nThis record carries no provenance.\n"
    packages = ", ".join(f"{name} {version}" for name, version in sorted(p.get("packages", {}).items()))
    rows = [("steplab", p.get("steplab")), ("commit", f"`{p['git_commit']}`" if p.get("git_commit") else None),
            ("date", p.get("date")), ("CPU", p.get("cpu")), ("machine", p.get("machine")),
            ("Python", p.get("python")), ("packages", packages or None)]
    return "## Provenance\n\n" + "\n".join(f"- {label}: {value if value else 'unknown'}"
                                           for label, value in rows) + "\n"


def _draw(table, record: dict) -> str:
    # a study's own table drawn from its own record; a record from an older or quick run
    # may lack a part of it: say so on the page rather than fail the whole site
    try:
        return table.draw(table.select(record))
    except (KeyError, IndexError, TypeError, StopIteration) as err:
        return f"(this record has no data for the table {table.name!r}: {type(err).__name__} {err})"


def _is_quick(study, record: dict) -> bool:
    # a record keeps its parameters, not the flag: a quick run's are the study's quick ones
    quick = json.loads(json.dumps(study.parameters(True)))
    return record.get("parameters") == quick != json.loads(json.dumps(study.parameters(False)))


def _pngs(record: dict) -> list[str]:
    return [name for name in record.get("figures", []) if name.endswith(".png")]


def main_summary(paths: list[Path]) -> str:
    """One line for the command line: how many pages and figures, and how to serve them."""
    pages = [p for p in paths if p.suffix == ".html"]
    site = paths[0].parent
    return (f"wrote {len(pages)} pages and {len(paths) - len(pages)} figures to {site}; "
            f"browse with `python -m http.server -d {site}`")

