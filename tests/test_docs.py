"""The documentation site (mkdocs.yml, docs/): it builds with every warning an error, every old
README section has a home in it, its study pages come from the records (or, on a fresh clone,
from the paper's committed figures and numbers), and in headless Chromium every page loads
without a console error, every image and internal link resolves and the search finds a word."""

import http.server
import json
import os
import re
import shutil
import subprocess
import sys
import threading
from functools import partial
from pathlib import Path

import helpers
import pytest
from steplab.studies import STUDIES, run_study

from steplab.report import DOCS_STUDIES, FROM_THE_PAPER, docs_pages, paper_captions

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"

#: every ``## `` heading of the README before it moved into the site (commit 3dbeb93); each must
#: still be a heading of a docs/ page, or be listed in MOVED with the page it went to
OLD_README_SECTIONS = (
    "Set up and run", "The command line", "Studies", "Build or buy: MuJoCo, Bullet, Box2D and Chipmunk",
    "Sweeps on a cluster (Dask)", "The paper and the tutorial", "Scene files", "Collisions", "Integrators",
    "Plugins", "Python API", "Performance", "Layout", "What steplab guarantees", "Broadphase", "License",
)
#: old sections whose text lives under another heading: section -> the page that holds it
MOVED = {}


def _headings() -> set[str]:
    found = set()
    for page in DOCS.rglob("*.md"):
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # a '#' in a code block is a comment
        found |= {m.group(1).strip() for m in re.finditer(r"^#{1,6} (.+)$", text, re.M)}
    return found


def test_every_old_readme_section_has_a_home_in_the_docs():
    headings = _headings()
    homeless = [s for s in OLD_README_SECTIONS if s not in headings and not (DOCS / MOVED.get(s, "-")).is_file()]
    assert not homeless, f"README sections with no page in docs/: {homeless}"


def test_every_docs_page_is_in_the_navigation():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = [p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")]
    assert pages and not [p for p in pages if f" {p}" not in nav], "a page the navigation does not list"


# --- the study pages -------------------------------------------------------------------


def test_without_records_the_study_pages_show_the_papers_figures_and_numbers(tmp_path):
    pages = docs_pages(tmp_path)  # an empty folder: a fresh clone
    numbers = json.loads((ROOT / "paper" / "data" / "numbers.json").read_text())
    for name in STUDIES:
        text = pages[f"{DOCS_STUDIES}/{name}.md"].decode()
        # a study newer than the paper (no figure, table or number of it there) says how to compute it
        assert FROM_THE_PAPER in text or (f"`steplab study {name}` computes it" in text and "## " not in text
                                          and not any((ROOT / "paper" / "figures").glob(f"{name}_*.png")))
    stability = pages[f"{DOCS_STUDIES}/stability.md"].decode()
    # the paper's figure, full size, its caption the paper's, and the byte-identical file
    regions = "stability_regions.png"
    assert f"](figures/{regions})" in stability and paper_captions()[regions] in stability
    assert pages[f"{DOCS_STUDIES}/figures/{regions}"] == (ROOT / "paper" / "figures" / regions).read_bytes()
    # a number the paper quotes, as the paper prints it
    assert f"{numbers['values']['stability/omega_dt_max/rk4']:.4f}" in stability
    index = pages[f"{DOCS_STUDIES}/results.md"].decode()
    assert re.search(r'<a href="figures/(stability_\w+\.png)"><img src="figures/\1"', index)  # a thumbnail


@pytest.fixture(scope="module")
def results(tmp_path_factory, quick_records):
    out = quick_records(tmp_path_factory.mktemp("results"), ["frame_rate"])
    run_study(STUDIES["frame_rate"], out, quick=True)  # cached
    return out


def test_with_records_the_study_pages_are_the_reports(results):
    pages = docs_pages(results)
    record = json.loads((results / "frame_rate.json").read_text())
    text = pages[f"{DOCS_STUDIES}/frame_rate.md"].decode()
    assert FROM_THE_PAPER not in text and record["title"] in text
    assert f"{record['final_state_spread']['naive']:.2f}" in text  # a number the paper quotes, from this record
    for figure in (f for f in record["figures"] if f.endswith(".png")):
        assert pages[f"{DOCS_STUDIES}/figures/{figure}"] == (results / figure).read_bytes()
    # the studies this folder lacks still have a page, saying how to compute them
    assert "`steplab study truncation` computes it" in pages[f"{DOCS_STUDIES}/truncation.md"].decode()


# --- the built site in a browser -----------------------------------------------------


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built strictly as CI builds it, from no records (a fresh clone's pages)."""
    out = tmp_path_factory.mktemp("site")
    empty = tmp_path_factory.mktemp("no-results")
    env = os.environ | {"STEPLAB_RESULTS": str(empty), "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-f", str(ROOT / "mkdocs.yml"),
                          "-d", str(out)], capture_output=True, text=True, env=env, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-3000:]
    return out


def test_the_site_builds_strictly_with_a_page_per_study(site):
    from steplab.integrators import INTEGRATORS, ROTATIONS

    for name in STUDIES:
        assert (site / DOCS_STUDIES / f"{name}.html").is_file()
    assert "restitution" in (site / "search" / "search_index.json").read_text()
    # the integrators page is the registry's: a section per method, RK4's tableau (b = 1/6, 1/3, ...)
    page = (site / "integrators.html").read_text()
    assert all(f'id="{name}"' in page for name in INTEGRATORS)
    # and the rotation methods', each with its class data (anchors apart: rk4 is in both registries)
    assert all(f'id="rotation-{name}"' in page for name in ROTATIONS)
    assert ROTATIONS["dlm"].source.split(",")[0] in page and "velocity-verlet" in page
    assert "<td>b</td>\n<td>0.166667</td>\n<td>0.333333</td>" in page


@pytest.fixture(scope="module")
def server(site):
    """The site over HTTP (its search runs in a web worker, which a file:// page may not start)."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), partial(_QuietHandler, directory=str(site)))
    server.search_index = None  # bytes: sent for search/search_index.json in place of the file (_QuietHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server
    server.shutdown()


@pytest.fixture(scope="module")
def browser(server):
    browser, driver = shutil.which("chromium") or shutil.which("chromium-browser"), shutil.which("chromedriver")
    if browser is None or driver is None:
        helpers.browser_missing()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1280,1600",
                 "--disable-background-networking", "--disable-component-update", "--no-first-run"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    chrome = webdriver.Chrome(options=options, service=Service(executable_path=driver))  # no driver download
    chrome.set_page_load_timeout(60)
    yield chrome, f"http://127.0.0.1:{server.server_address[1]}/"
    chrome.quit()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    """The site's files; search/search_index.json never cached by the browser, and replaced by
    ``server.search_index`` where that is set."""

    def _is_search_index(self) -> bool:
        return Path(self.translate_path(self.path)) == Path(self.directory) / "search" / "search_index.json"

    def do_GET(self):
        stub = self.server.search_index
        if stub is None or not self._is_search_index() or not Path(self.translate_path(self.path)).is_file():
            return super().do_GET()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(stub)))
        self.end_headers()
        self.wfile.write(stub)

    def end_headers(self):
        if self._is_search_index():  # each page's worker fetches what the server sends now
            self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, *args):
        pass


#: what a page must not log in the console: errors, and resources that failed to load
def _console_errors(chrome) -> list[str]:
    return [entry["message"] for entry in chrome.get_log("browser") if entry["level"] == "SEVERE"]


@pytest.fixture
def one_page_search_index(site, server):
    """The search index cut to its first page while a test loads every page: each page's search worker
    still fetches it (a wrong URL still fails) and builds an index with it, but not the whole site's
    (over a megabyte: most of the CPU time of loading the pages, the same work on every one). The
    whole index is built and searched, and the console checked, in test_the_search_finds_restitution."""
    index = json.loads((site / "search" / "search_index.json").read_text())
    server.search_index = json.dumps(index | {"docs": index["docs"][:1]}).encode()
    yield
    server.search_index = None


def test_every_page_loads_without_console_errors_and_its_images_and_links_resolve(site, browser,
                                                                                  one_page_search_index):
    chrome, base = browser
    pages = sorted(p.relative_to(site).as_posix() for p in site.rglob("*.html") if p.name != "404.html")
    assert len(pages) > 30
    for page in pages:
        chrome.get(base + page)
        assert chrome.title, f"{page} has no title"
        broken = chrome.execute_script(
            "return [...document.images].filter(i => !i.complete || i.naturalWidth === 0).map(i => i.src)")
        assert not broken, f"{page}: images that do not load: {broken}"
        links = chrome.execute_script("return [...document.querySelectorAll('a[href]')].map(a => a.href)")
        for link in links:
            if link.startswith(base):
                target = site / link.removeprefix(base).split("#")[0].split("?")[0]
                assert target.is_file() or (target / "index.html").is_file(), f"{page}: link {link} resolves to no file"
        assert not _console_errors(chrome), f"{page}: {_console_errors(chrome)}"


def test_the_search_finds_restitution(browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions
    from selenium.webdriver.support.ui import WebDriverWait

    chrome, base = browser
    chrome.get(base + "index.html")
    # mkdocs-material's search is client-side (a web worker over search_index.json): type into
    # the header's box, as a reader would, and wait for the worker's results
    box = WebDriverWait(chrome, 30).until(expected_conditions.element_to_be_clickable((By.CSS_SELECTOR,
                                                                                       "input.md-search__input")))
    box.click()
    box.send_keys("restitution")
    hits = WebDriverWait(chrome, 60).until(
        lambda c: c.find_elements(By.CSS_SELECTOR, ".md-search-result__item") or False)
    assert any("restitution" in hit.text.lower() for hit in hits)
    assert not _console_errors(chrome)


def test_a_screenshot_of_the_index(browser, tmp_path):
    chrome, base = browser
    chrome.get(base + "index.html")
    shot = tmp_path / "index.png"
    chrome.save_screenshot(str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 10_000
