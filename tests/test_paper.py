"""The paper is regenerated from data, never typed; the tutorial's code runs as written."""

import json
import shutil
from pathlib import Path

import pytest

from steplab.paper import PLACEHOLDER, collect, lookup, parse_bib, render, run_tutorial, to_html, tutorial_blocks

PAPER = Path(__file__).resolve().parent.parent / "paper"


def test_committed_paper_is_rendered_from_committed_numbers():
    template = (PAPER / "paper.template.md").read_text()
    numbers = json.loads((PAPER / "data" / "numbers.json").read_text())
    assert render(template, numbers) == (PAPER / "paper.md").read_text()


def test_numbers_hold_exactly_what_the_template_uses():
    template = (PAPER / "paper.template.md").read_text()
    numbers = json.loads((PAPER / "data" / "numbers.json").read_text())
    tokens = PLACEHOLDER.findall(template)
    values = {t.split(":", 1)[0] for t in tokens if not t.startswith("table:")}
    tables = {t.removeprefix("table:") for t in tokens if t.startswith("table:")}
    assert set(numbers["values"]) == values and set(numbers["tables"]) == tables


def test_every_figure_the_paper_shows_is_committed():
    for name in ("paper.md", "tutorial.md"):
        text = (PAPER / name).read_text()
        for figure in __import__("re").findall(r"\]\((figures/[^)\s]+)\)", text):
            assert (PAPER / figure).exists(), figure


def test_collect_and_render_from_records():
    records = {"s": {"x": 1.23456, "l": [1, 2, 3], "flag": True, "none": None, "t": 0.000607}}
    template = ("x = {{s/x:.2f}}, n = {{s/l/__len__}}, second = {{s/l/1}}, {{s/flag}}, {{s/none}}, "
                "{{s/t:.2f ms}} or {{s/t:.0f us}}")
    numbers = collect(template, records)
    assert render(template, numbers).endswith("x = 1.23, n = 3, second = 2, yes, none, 0.61 ms or 607 us")
    with pytest.raises(ValueError, match="no value at 's/y'"):
        lookup(records, "s/y")


def test_a_table_names_the_study_whose_results_it_lacks():
    with pytest.raises(ValueError, match="the table 'lecture_errors' needs the results of tunnelling"):
        collect("{{table:lecture_errors}}", {"restitution": {"lecture_errors": []}})


def test_html_links_citations():
    bib = parse_bib((PAPER / "paper.bib").read_text())
    assert bib["hairer2006"]["year"] == "2006"
    html = to_html("---\ntitle: 'T'\n---\n# A\n\nAs shown [@hairer2006].\n", bib)
    assert "<h1" in html and 'href="#ref-hairer2006"' in html and "Geometric Numerical Integration" in html


def test_tutorial_runs_as_written(tmp_path):
    """Every code block of paper/tutorial.md, in order, in one session, drawing its figures."""
    (tmp_path / "figures").mkdir()
    shutil.copy(PAPER / "tutorial.md", tmp_path / "tutorial.md")
    text = (tmp_path / "tutorial.md").read_text()
    assert len(tutorial_blocks(text)) >= 8
    paths = run_tutorial(tmp_path / "tutorial.md", tmp_path)
    drawn = {p.name for p in paths}
    shown = set(__import__("re").findall(r"\]\(figures/([^)\s]+)\)", text))
    assert shown <= drawn
    # the reader's folder (git-ignored), never over the copies the Markdown shows
    assert {p.parent for p in paths} == {tmp_path / "tutorial-figures"} and not list((tmp_path / "figures").iterdir())


def test_the_build_copies_the_tutorials_figures_from_a_scratch_folder(tmp_path):
    from steplab.paper import PaperError, tutorial_figures

    block = ('```python\nfrom pathlib import Path\nfigures = Path("tutorial-figures")\nfigures.mkdir()\n'
             '(figures / "a.png").write_bytes(b"drawn")\n```\n')
    (tmp_path / "tutorial.md").write_text(block + "![A.](figures/a.png)\n")
    assert tutorial_figures(tmp_path / "tutorial.md", tmp_path / "paper") == [tmp_path / "paper" / "figures" / "a.png"]
    assert (tmp_path / "paper" / "figures" / "a.png").read_bytes() == b"drawn"
    assert not (tmp_path / "tutorial-figures").exists()  # run elsewhere, never beside the tutorial
    (tmp_path / "tutorial.md").write_text(block + "![B.](figures/b.png)\n")
    with pytest.raises(PaperError, match="shows figures/b.png, which its code does not draw"):
        tutorial_figures(tmp_path / "tutorial.md", tmp_path / "paper")


def test_a_lecture_formula_in_a_table_cell_stays_literal():
    """``a*t`` in a cell is the lecture's product, not Markdown emphasis (nor is ``|`` a new column)."""
    from steplab.studies.tables import markdown_table

    html = to_html(markdown_table(["formula", "note"], [["x = x + (v + a*t)*t", "a | b"]]), {})
    assert "x = x + (v + a*t)*t" in html and "<em>" not in html and "a | b" in html
