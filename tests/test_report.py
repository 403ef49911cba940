"""``steplab report``: the site of a small results folder parses, every link and image
resolves, and it loads in a real headless browser (Debian's chromium) without errors."""

import dataclasses
import html
import json
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import helpers
import pytest
from steplab.studies import STUDIES, run_study

from steplab.cli import main
from steplab.report import build

#: the cheapest real studies that between them have figures, tables and lecture errors
SITE_STUDIES = ("frame_rate", "restitution", "truncation")
#: their quick parameters, but truncation on the oscillator alone: every method's curves in both precisions,
#: a figure, a zoomable page and the numbers the paper quotes from it (quick's projectile adds a second figure
#: and page of the same kind, and half the study's run time)
FEWER = {"truncation": {"problems": ["oscillator"]}}
#: a bench record written by hand: the bench page must print its ratio and both times
BENCH = {"order": ["step"], "ratios": {"step": 0.5}, "targets": {},
         "seconds": {"step": {"what": "one oscillator step", "group": "oscillator", "peer_name": "scipy",
                              "steplab": 0.002, "peer": 0.004, "ratio_stable": False,
                              "stability_note": "peer's median 33% above its minimum in this run",
                              "steplab_spread": {"min": 0.0019, "median": 0.002, "max": 0.0025, "rounds": 5},
                              "peer_spread": {"min": 0.003, "median": 0.004, "max": 0.007, "rounds": 5}}},
         "collisions": {"pit": {"balls": 10, "steps": 6, "not_compared": {}, "contenders": {"mujoco": {
             "settings": "MuJoCo, PGS", "per_step_seconds": 0.003, "real_time_factor": 5.5, "balls_inside": 10,
             "impacts": 0}}}}}


@pytest.fixture(scope="module")
def results(tmp_path_factory, quick_records):
    out = quick_records(tmp_path_factory.mktemp("results"), [name for name in SITE_STUDIES if name not in FEWER])
    for name in SITE_STUDIES:  # those copied, cached
        study = STUDIES[name]
        if name in FEWER:
            study = dataclasses.replace(study, parameters=lambda quick, study=study: study.parameters(quick)
                                        | FEWER[study.name])
        run_study(study, out, quick=True)
    (out / "bench.json").write_text(json.dumps(BENCH))
    return out


@pytest.fixture(scope="module")
def site(results, tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    build(results, out)
    return out


class _Page(HTMLParser):
    """The title, links and images of one page (html.parser raises on nothing; we check what it finds)."""

    def __init__(self):
        super().__init__()
        self.title, self.links, self.images, self._in_title = "", [], [], False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self._in_title = tag == "title"
        if tag == "a" and "href" in attrs:
            self.links.append(attrs["href"])
        if tag == "img":
            self.images.append((attrs.get("src"), attrs.get("alt")))

    def handle_data(self, data):
        if self._in_title:
            self.title += data

    def handle_endtag(self, tag):
        self._in_title = False


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text())
    page.close()
    return page


def test_every_link_and_image_resolves_inside_the_site(site, results):
    pages = sorted(site.glob("*.html"))
    assert {p.name for p in pages} == {"index.html", "errata.html", "bench.html"} | {f"{s}.html" for s in SITE_STUDIES}
    for path in pages:
        page = _parse(path)
        assert page.title, f"{path.name} has no title"
        for href in page.links:
            target = href.split("#")[0]
            assert "://" not in href and not href.startswith("/"), f"{path.name}: link {href} is not relative"
            assert not target or (site / target).is_file(), f"{path.name}: link {href} resolves to no file"
        for src, alt in page.images:
            assert alt, f"{path.name}: image {src} has no alt text"
            assert (site / src).is_file(), f"{path.name}: image {src} resolves to no file"
            # the PNG the study drew, copied unchanged
            assert (site / src).read_bytes() == (results / Path(src).name).read_bytes()
    index = _parse(site / "index.html")
    assert {f"{s}.html" for s in SITE_STUDIES} | {"errata.html", "bench.html"} <= set(index.links)
    for name in SITE_STUDIES:
        record = json.loads((results / f"{name}.json").read_text())
        shown = {Path(src).name for src, _ in _parse(site / f"{name}.html").images}
        assert shown == {f for f in record["figures"] if f.endswith(".png")}
        text = html.unescape((site / f"{name}.html").read_text())
        for value in (record["provenance"]["git_commit"], record["provenance"]["cpu"], record["provenance"]["date"]):
            assert value in text


def test_errata_and_bench_pages_print_the_records(site, results):
    errata = html.unescape((site / "errata.html").read_text())
    errors = json.loads((results / "restitution.json").read_text())["lecture_errors"]
    listed = [e for e in errors if e.get("is_error", True) and not e["correct"].startswith("checked")]
    assert listed and all(e["where"] in errata for e in listed)
    # a check the lecture passed is not an erratum
    assert all(e["where"] not in errata for e in errors if e["correct"].startswith("checked"))
    bench = (site / "bench.html").read_text()
    # steplab 2 ms against the peer's 4 ms: ratio 0.5
    assert "2 ms" in bench and "4 ms" in bench and "<td>0.5</td>" in bench
    # each side's fastest and slowest round beside its median, and the ratio marked as moving
    assert "2 ms (1.9 ms-2.5 ms)" in bench and "4 ms (3 ms-7 ms)" in bench
    assert "no: peer's median 33% above its minimum in this run" in bench
    # and the engines' ball pit: 3 ms a step, 5.5 simulated seconds per wall second
    assert "<td>MuJoCo, PGS</td>" in bench and "<td>3 ms</td>" in bench and "<td>5.5</td>" in bench


@pytest.mark.parametrize("make", [lambda tmp: tmp / "absent", lambda tmp: tmp])
def test_a_missing_or_empty_results_folder_is_one_line_and_status_2(tmp_path, capsys, make):
    status = main(["report", "--results", str(make(tmp_path)), "--out", str(tmp_path / "site")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "steplab report: error:" in err
    assert not (tmp_path / "site").exists()


@pytest.mark.parametrize("record", [{"study": "truncation"}, {"title": "Truncation", "curves": 3}])
def test_a_record_its_page_cannot_be_made_from_is_named_in_one_line(tmp_path, capsys, record):
    """A study record cut short, edited, or from a steplab whose records had other fields."""
    results = tmp_path / "results"
    results.mkdir()
    (results / "truncation.json").write_text(json.dumps(record))
    status = main(["report", "--results", str(results), "--out", str(tmp_path / "site")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert f"{results / 'truncation.json'}: not a record its page can be made from" in err


def _chromium(*args, cwd):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        helpers.browser_missing()
    return subprocess.run([browser, "--headless", "--disable-gpu", "--no-sandbox", "--no-first-run",
                           "--disable-background-networking", "--disable-component-update",
                           f"--user-data-dir={cwd / 'profile'}", "--enable-logging=stderr", "--v=0", *args],
                          capture_output=True, text=True, timeout=120, check=True)


def test_every_page_loads_in_chromium_without_console_errors(site, tmp_path):
    interactive = sorted((site / "interactive").glob("*.html"))
    assert interactive and (site / "interactive" / "plotly.min.js").is_file()  # truncation's zoomable figures
    for path in sorted(site.glob("*.html")) + interactive:
        run = _chromium("--dump-dom", path.resolve().as_uri(), cwd=tmp_path)
        assert html.escape(_parse(path).title, quote=False) in run.stdout, f"{path.name}: its title is not in the DOM"
        console = [line for line in run.stderr.splitlines() if "Uncaught" in line or "Failed to load resource" in line]
        assert not console, f"{path.name}: {console}"
    shot = tmp_path / "index.png"
    _chromium("--window-size=1200,1600", f"--screenshot={shot}", (site / "index.html").resolve().as_uri(), cwd=tmp_path)
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_study_page_lists_the_numbers_the_paper_quotes_from_its_record(site, results):
    # the paper quotes frame_rate/final_state_spread/naive with :.2f: the page prints the record's value so
    record = json.loads((results / "frame_rate.json").read_text())
    page = (site / "frame_rate.html").read_text()
    assert "Numbers the paper quotes" in page
    assert f"<td>{record['final_state_spread']['naive']:.2f}</td>" in page
    assert "frame_rate/final_state_spread/naive" in page


def test_every_method_has_its_own_colour_and_keeps_it_on_the_plotly_pages(site, results):
    from steplab.integrators import INTEGRATORS
    from steplab.studies.plotting import colour

    colours = {name: colour(name) for name in INTEGRATORS}  # fixed-step methods, references, exact
    assert len(set(colours.values())) == len(colours), f"methods sharing a colour: {colours}"
    # the zoomable error-against-dt page draws each method in its static figures' colour
    record = json.loads((results / "truncation.json").read_text())
    page = next((site / "interactive").glob("truncation_*.html")).read_text()
    drawn = {c["integrator"] for c in record["curves"]}
    assert drawn and all(f'"color":"{colours[m]}"' in page for m in drawn if m in colours)


def test_provenance_names_the_cpus_family_model_and_vector_width(tmp_path):
    # two VMs that both call their CPU "AMD EPYC" are told apart by family, model and vector width
    from steplab.studies.runner import _cpu_name

    info = tmp_path / "cpuinfo"
    block = "processor\t: {n}\ncpu family\t: 25\nmodel\t\t: 1\nmodel name\t: AMD EPYC\nflags\t\t: fpu {flags}\n"
    info.write_text(block.format(n=0, flags="avx avx2") + "\n" + block.format(n=1, flags="avx avx2 avx512f"))
    assert _cpu_name(info) == "AMD EPYC (family 25 model 1, AVX2)"  # the first processor's block
    info.write_text(block.format(n=0, flags="avx avx2 avx512f"))
    assert _cpu_name(info) == "AMD EPYC (family 25 model 1, AVX-512)"
    info.write_text("processor\t: 0\nmodel name\t: Some CPU\n")
    assert _cpu_name(info) == "Some CPU"


def test_a_zoomable_figure_says_where_a_method_diverged():
    """A point whose error is not a finite number (None, as the truncation study records a divergence, or
    NaN or inf) cannot go on a log axis: the method's legend says where it diverged, not nothing."""
    from steplab import report_figures

    inf, nan = float("inf"), float("nan")
    # euler diverged at the two largest steps (None, as the truncation study records it, or inf)
    points = [{"dt": 0.5, "error": None, "diverged_at_step": 3}, {"dt": 0.25, "error": inf},
              {"dt": 0.125, "error": 0.1}, {"dt": 0.0625, "error": nan}, {"dt": 0.03125, "error": 0.01}]
    curves = [{"problem": "oscillator", "integrator": "euler", "points": points},
              {"problem": "oscillator", "integrator": "rk4", "points": [{"dt": 0.5, "error": 1e-3}]}]
    (_, _, figure), = report_figures.figures("truncation", {"curves": curves})
    euler, rk4 = figure.data
    assert euler.name == "euler (diverged at 3 of its dt)" and rk4.name == "rk4"
    assert list(euler.x) == [0.125, 0.03125] and list(euler.y) == [0.1, 0.01]
    points[3]["error"] = 0.05  # only the largest steps diverged: from which dt on
    (_, _, figure), = report_figures.figures("truncation", {"curves": curves})
    assert figure.data[0].name == "euler (diverged at dt >= 0.25 s)"
