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

import html
import json
import re
from collections.abc import Callable
from pathlib import Path

from steplab import report_figures
from steplab.bench.report import collision_markdown
from steplab.core.records import RECORD_ERRORS, make_folder, write_atomic
from steplab.paper import BENCH_TABLE, PLACEHOLDER, PaperError, load_records, lookup, quoted, to_html
from steplab.studies import STUDIES
from steplab.studies.tables import markdown_table

#: the tables that list the lecture's errors (truncation: its misprinted formulas;
#: restitution and tunnelling: the response and detection chapters' errors)
ERRATA_TABLES = ("misprints", "lecture_errors")
#: where the copied figures go, inside the site
FIGURES = "figures"
#: the paper (in a checkout; absent, what the pages take from it is left out): its template, whose
#: numbers the study pages list; its rendered text, whose figure captions they reuse; and its
#: committed figures and numbers, which the documentation's study pages show where no records exist
PAPER = Path(__file__).resolve().parent.parent / "paper"
PAPER_TEMPLATE = PAPER / "paper.template.md"
#: a figure of the paper: ``![caption](figures/NAME)``, the caption's numbers already filled in
PAPER_FIGURE = re.compile(r"!\[([^\]]+)\]\(figures/([^)\s]+)\)")
#: the width of a figure's thumbnail on an index, in CSS pixels
THUMBNAIL_WIDTH = 320


class ReportError(ValueError):
    """A results folder the site cannot be built from (missing, empty, a figure absent)."""


def build(results: Path, out: Path) -> list[Path]:
    """Write the site of ``results`` into ``out``; return the files written (index first).

    Raises
    ------
    PaperError
        When ``results`` is not a folder, or a record there is not valid JSON, not a record or
        another study's (:func:`steplab.paper.load_records`), or a number the paper quotes is not finite.
    ReportError
        When ``results`` holds no study record, or a record names a figure the folder does not have.
    """
    results = Path(results)
    records = load_records(results)  # a --results that is not a folder is refused there
    out = make_folder(out, "site folder")  # before the pages: a file there fails first, in these words
    studies = [(STUDIES[name], records[name]) for name in STUDIES if name in records]
    bench = records.get("bench")
    if not studies and bench is None:
        raise ReportError(f"{results}: no study results (known studies: {', '.join(STUDIES)}); "
                          f"run `steplab reproduce --out {results}` first")
    # each record's own page first, so that a record the site cannot show is named (the index reads them all)
    own = {f"{study.name}.html": _shown(results / f"{study.name}.json", _study_page_with_figures,
                                        study, record, results, out) for study, record in studies}
    if bench is not None:
        own["bench.html"] = _shown(results / "bench.json", bench_page, bench)
    pages = {"index.html": index_page(studies, bench)} | own | {"errata.html": errata_page(studies)}
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


def _shown(path: Path, make: Callable[..., str], *args) -> str:
    """``make(*args)``: the page of the record at ``path``. A record without what its page needs (cut short,
    edited, or written by a steplab whose records had other fields) is refused in one line naming it."""
    try:
        return make(*args)
    except PaperError:  # a number it quotes, not finite: already one line naming it
        raise
    except RECORD_ERRORS as err:
        raise ReportError(f"{path}: not a record its page can be made from ({type(err).__name__}: {err}); "
                          "run its study (or the bench) again") from None


def _study_page_with_figures(study, record: dict, results: Path, out: Path) -> str:
    """A study's page, its interactive figures written into ``out`` first."""
    return study_page(study, record, results, report_figures.write(study.name, record, out))


# --- pages (Markdown) ---------------------------------------------------------------


def _nav(here: str) -> str:
    links = [("index.html", "index"), ("errata.html", "errata")]
    return " · ".join(text if href == here else f"[{text}]({href})" for href, text in links) + "\n\n"


def _summary_lines(study, record) -> str:
    rows = study.summary(record)
    return "\n".join(f"- {label}: {value}" for label, value in rows) + "\n" if rows else ""


def index_page(studies: list, bench: dict | None, suffix: str = ".html") -> str:
    """The index: each study's title, its first figure as a thumbnail linking to the full size, and
    its summary. ``suffix``: how a study page is linked (``.md`` inside the documentation)."""
    text = "# steplab results\n\n" + (_nav("index.html") if suffix == ".html" else "")
    text += "Every study of the results folder, with the summary `steplab reproduce` prints.\n\n"
    known = paper_captions()
    for study, record in studies:
        quick = " (quick run)" if _is_quick(study, record) else ""
        text += f"## [{study.name}]({study.name}{suffix}): {record['title']}{quick}\n\n"
        figures = _pngs(record)
        if figures:
            text += thumbnail(figures[0], caption(study.name, figures[0], known)) + "\n\n"
        text += _summary_lines(study, record) + "\n"
    text += f"## [Errata](errata{suffix})\n\nThe lecture's errors the studies found.\n\n"
    if bench is not None:
        text += f"## [Bench](bench{suffix})\n\nsteplab timed against its peers (`steplab bench`).\n\n"
    return text


def paper_captions(paper: Path = PAPER) -> dict[str, str]:
    """Figure file name -> the caption the paper gives it (what the figure shows, with the paper's
    numbers); {} without the paper."""
    path = Path(paper) / "paper.md"
    if not path.exists():
        return {}
    return {name: " ".join(text.split()) for text, name in PAPER_FIGURE.findall(path.read_text())}


def caption(study: str, figure: str, known: dict[str, str]) -> str:
    """What ``figure`` shows: the paper's caption, or for a figure the paper does not show, its
    study and the name the study gave it."""
    if figure in known:
        return known[figure]
    what = Path(figure).stem.removeprefix(study).strip("_").replace("_", " ").replace("-", " ")
    return f"The {study.replace('_', ' ')} study: {what or 'its figure'}."


def thumbnail(figure: str, text: str) -> str:
    """A small copy of ``figure`` linking to the full size (raw HTML: Markdown has no image width)."""
    alt = html.escape(text)
    return (f'<a href="{FIGURES}/{figure}"><img src="{FIGURES}/{figure}" alt="{alt}" title="{alt}" '
            f'width="{THUMBNAIL_WIDTH}"></a>')


def _figure(figure: str, text: str) -> str:
    # the figure full size, a link to the file itself (to zoom in the browser), the caption below
    return f"[![{text}]({FIGURES}/{figure})]({FIGURES}/{figure})\n\n*{text}*\n\n"


def study_page(study, record: dict, results: Path, interactive=(), nav: bool = True) -> str:
    """A study's page: summary, figures full size with captions, tables, quoted numbers, provenance.
    ``nav``: the report's links between pages (the documentation has its own navigation)."""
    text = f"# {record['title']}\n\n" + (_nav("") if nav else "")
    text += f"Study `{study.name}`; record `{study.name}.json`.\n\n"
    summary = _summary_lines(study, record)
    if summary:
        text += "## Summary\n\n" + summary + "\n"
    figures = _pngs(record)
    if figures:
        text += "## Figures\n\n"
        known = paper_captions()
        for figure in figures:
            text += _figure(figure, caption(study.name, figure, known))
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
    return _quoted(name, lambda path: lookup({name: record}, path), template)


def _quoted(name: str, value_of, template: Path) -> str:
    # value_of(path) -> the value at a placeholder's path (PaperError: not there)
    if not Path(template).exists():
        return ""
    text = Path(template).read_text()
    rows = []
    for match in PLACEHOLDER.finditer(text):
        path, _, spec = match.group(1).partition(":")
        if path.split("/")[0] != name:
            continue
        try:
            value = value_of(path)
        except PaperError:  # a quick run's record lacks what only the full run has
            value = "not in this record"
        else:
            value = quoted(value, spec, path)  # a non-finite number or a wrong type: refused, never "nan"
        before = PLACEHOLDER.sub("…", text[max(0, match.start() - 90):match.start()])
        words = " ".join(re.split(r"(?<=[.:;])\s", " ".join(before.split()))[-1].split()[-12:])
        rows.append([f"`{path}`", value, f"… {words}"])
    return markdown_table(["record path", "value", "where the paper quotes it"], rows) if rows else ""


def errata_page(studies: list, suffix: str = ".html") -> str:
    """The lecture's errors the studies' records list; ``suffix`` as for :func:`index_page`."""
    text = "# Errata: the lecture's errors\n\n" + (_nav("errata.html") if suffix == ".html" else "")
    text += "What the studies found wrong in the lecture, each with the evidence steplab computed.\n\n"
    found = False
    for study, record in studies:
        for table in study.tables:
            if table.name in ERRATA_TABLES:
                found = True
                text += f"## [{study.name}]({study.name}{suffix}): {table.name.replace('_', ' ')}\n\n"
                text += _draw(table, record) + "\n\n"
    if not found:
        text += "None of the studies in this results folder checks the lecture (truncation, restitution " \
                "and tunnelling do).\n"
    return text


def bench_page(bench: dict, nav: bool = True) -> str:
    text = "# Bench: steplab against its peers\n\n" + (_nav("") if nav else "") + _draw(BENCH_TABLE, bench) + "\n\n"
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


# --- the documentation site's study pages ---------------------------------------------


#: where the documentation's study pages go, inside docs/ (the figures in ``studies/figures/``)
DOCS_STUDIES = "studies"


def docs_pages(results: Path | None, paper: Path = PAPER) -> dict[str, bytes]:
    """The study pages of the documentation site (mkdocs, docs/hooks/generate.py): path inside
    docs/ -> content. One page per registered study, a results index with thumbnails, the errata
    and the bench.

    From the records in ``results`` where it holds any: the pages ``steplab report`` writes, as
    Markdown. Otherwise (a fresh clone) from the paper's committed figures and numbers
    (``paper/figures``, ``paper/data/numbers.json``), each page saying so and how to see your own.
    """
    records = load_records(results) if results is not None and any(Path(results).glob("*.json")) else {}
    studies = [(STUDIES[name], records[name]) for name in STUDIES if name in records]
    if not studies:
        return _paper_pages(Path(paper))
    pages = {"results.md": index_page(studies, records.get("bench"), suffix=".md")}
    for study, record in studies:
        pages[f"{study.name}.md"] = study_page(study, record, results, nav=False)
        for figure in _pngs(record):
            pages[f"{FIGURES}/{figure}"] = (Path(results) / figure).read_bytes()
    pages["errata.md"] = errata_page(studies, suffix=".md")
    bench = records.get("bench")
    pages["bench.md"] = (bench_page(bench, nav=False) if bench is not None else
                         "# Bench: steplab against its peers\n\nThis results folder has no `bench.json`: "
                         "`steplab bench --json results/bench.json` writes it.\n")
    missing = [s.name for s in STUDIES.values() if s.name not in records]
    for name in missing:
        pages[f"{name}.md"] = f"# {STUDIES[name].title}\n\nThe results folder has no `{name}.json`: " \
                              f"`steplab study {name}` computes it.\n"
    return {f"{DOCS_STUDIES}/{path}": text.encode() if isinstance(text, str) else text
            for path, text in pages.items()}


#: the notice on every study page built from the paper rather than from records
FROM_THE_PAPER = ("!!! note \"The paper's results\"\n    No results records were found when this site was built, "
                  "so this page shows the figures and numbers of the paper (`paper/figures/`, "
                  "`paper/data/numbers.json`). Run `steplab reproduce` (or `steplab study NAME`) and "
                  "build the site again to see your own.\n\n")


def _paper_pages(paper: Path) -> dict[str, bytes]:
    # the paper's numbers: {"values": {path: value}, "tables": {name: slice}} (steplab.paper.collect)
    from steplab.paper import paper_tables

    numbers = json.loads((paper / "data" / "numbers.json").read_text())
    tables = paper_tables()
    known = paper_captions(paper)
    figures = sorted(p.name for p in (paper / "figures").glob("*.png"))
    pages, index = {}, "# steplab results\n\n" + FROM_THE_PAPER
    for study in STUDIES.values():
        mine = [f for f in figures if re.match(rf"{re.escape(study.name)}(_|\.png)", f)]
        text = f"# {study.title}\n\n" + FROM_THE_PAPER + f"Study `{study.name}`; record `{study.name}.json`.\n\n"
        index += f"## [{study.name}]({study.name}.md): {study.title}\n\n"
        if mine:
            index += thumbnail(mine[0], caption(study.name, mine[0], known)) + "\n\n"
            text += "## Figures\n\n" + "".join(_figure(f, caption(study.name, f, known)) for f in mine)
            pages.update({f"{FIGURES}/{f}": (paper / "figures" / f).read_bytes() for f in mine})
        drawn = [(name, tables[name][1].draw(part)) for name, part in numbers["tables"].items()
                 if name in tables and study.name in tables[name][0]]
        if drawn:
            text += "## Tables\n\n" + "".join(f"### {name.replace('_', ' ')}\n\n{markdown}\n\n"
                                               for name, markdown in drawn)

        def value_of(path):
            if path not in numbers["values"]:
                raise PaperError(path)
            return numbers["values"][path]

        quoted = _quoted(study.name, value_of, paper / "paper.template.md")
        if quoted:
            text += "## Numbers the paper quotes\n\n" + quoted + "\n"
        if not (mine or drawn or quoted):  # a study newer than the paper: nothing of it to show
            text = (f"# {study.title}\n\nThe paper does not cover this study yet, and no results records "
                    f"were found when this site was built: `steplab study {study.name}` computes it "
                    f"(record `{study.name}.json`); build the site again to see it.\n")
        pages[f"{study.name}.md"] = text
    errata = [(name, tables[name][1].draw(numbers["tables"][name])) for name in ERRATA_TABLES
              if name in numbers["tables"]]
    pages["errata.md"] = "# Errata: the lecture's errors\n\n" + FROM_THE_PAPER + "".join(
        f"## {name.replace('_', ' ')}\n\n{markdown}\n\n" for name, markdown in errata)
    pages["bench.md"] = "# Bench: steplab against its peers\n\n" + FROM_THE_PAPER + (
        BENCH_TABLE.draw(numbers["tables"]["bench"]) + "\n" if "bench" in numbers["tables"] else "")
    pages["results.md"] = index + "## [Errata](errata.md)\n\nThe lecture's errors the studies found.\n\n" \
        "## [Bench](bench.md)\n\nsteplab timed against its peers (`steplab bench`).\n"
    return {f"{DOCS_STUDIES}/{path}": text.encode() if isinstance(text, str) else text
            for path, text in pages.items()}


def main_summary(paths: list[Path]) -> str:
    """One line for the command line: how many pages and figures, and how to serve them."""
    pages = [p for p in paths if p.suffix == ".html"]
    site = paths[0].parent
    return (f"wrote {len(pages)} pages and {len(paths) - len(pages)} figures to {site}; "
            f"browse with `python -m http.server -d {site}`")

