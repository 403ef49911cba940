"""More bad input at the command line (study, reproduce, paper, report, recommend, animate, export, bench):
one line naming what, where and what is allowed, status 2; never a traceback, a silent default in place of
an empty argument, or "nan" printed where the paper quotes a number. Each case is the command line's
``main`` in this process, as in tests/test_cli_refusals.py."""

import json
from pathlib import Path

import pytest
from helpers import run_main

#: a results folder's records: folder name -> {file name: JSON text}
RESULTS = {
    # another study's record under truncation's name (it failed on a missing key, naming none)
    "wrong-study": {"truncation.json": json.dumps({"study": "stability", "omega_dt_max": {}})},
    "a-list": {"truncation.json": "[]"},
    # a number the paper quotes, not finite (it printed "nan" into paper.md, status 0)
    "nan-value": {"truncation.json": '{"study": "truncation", "x": NaN}'},
    # a list where the paper quotes a number (a traceback from format)
    "list-value": {"truncation.json": json.dumps({"study": "truncation", "x": [1, 2]})},
    # a table's rows cut short (a traceback: KeyError 'where')
    "short-table": {"truncation.json": json.dumps({"study": "truncation", "x": 1.0, "misprints": [{}]})},
}

#: name -> (argv, what the one line of error says); paths are made by the fixture in its folder
REFUSALS = {
    # an empty path was the current folder: report wrote its 16 pages there, status 0
    "report-out-empty": (["report", "--results", "wrong-study", "--out", ""], "argument --out: must not be empty"),
    "paper-results-empty": (["paper", "--results", "", "--paper-dir", "paper"],
                            "argument --results: must not be empty"),
    "export-out-empty": (["export", "projectile", "--to", "mjcf", "--out", ""], "argument --out: must not be empty"),
    "bench-from-empty": (["bench", "--from", ""], "argument --from: must not be empty"),
    # what only a run takes, with --from (which runs nothing): --json wrote no file and --only chose nothing
    "bench-from-json": (["bench", "--from", "bench.json", "--json", "copy.json"],
                        "--json is for a run of the bench and --from prints a record without running"),
    "bench-from-only": (["bench", "--from", "bench.json", "--only", "stacking"],
                        "--only is for a run of the bench and --from prints a record without running"),
    "study-out-empty": (["study", "truncation", "--quick", "--out", ""], "argument --out: must not be empty"),
    "animate-out-empty": (["animate", "projectile", "--out", ""], "argument --out: must not be empty"),
    # an empty name was "not given": the default ran instead (a local run, the scene's integrator)
    "study-scheduler-empty": (["study", "truncation", "--quick", "--scheduler", "", "--out", "a-file"],
                              "argument --scheduler: must not be empty"),
    "animate-integrator-empty": (["animate", "projectile", "--integrator", "", "--out", "o/a.txt"],
                                 "argument --integrator: must not be empty"),
    "animate-compare-empty": (["animate", "projectile", "--compare", " ", "--out", "o/a.txt"],
                              "argument --compare: must not be empty"),
    "run-integrator-empty": (["run", "projectile", "--integrator", ""], "argument --integrator: must not be empty"),
    "run-out-empty": (["run", "projectile", "--out", ""], "argument --out: must not be empty"),
    "check-integrator-empty": (["check", "oscillator", "--integrator", " "],
                               "argument --integrator: must not be empty"),
    "recommend-integrators-empty": (["recommend", "projectile", "--tol", "0.01", "--integrators", ""],
                                    "argument --integrators: must not be empty"),
    "recommend-rotation-empty": (["recommend", "projectile", "--tol", "0.01", "--rotation", ""],
                                 "argument --rotation: must not be empty"),
    # a file given as a folder: "no such folder", "no study results", "a-file/interactive: Not a directory"
    "report-results-file": (["report", "--results", "a-file", "--out", "site"],
                            "--results a-file: a file, not a folder"),
    "paper-results-file": (["paper", "--results", "a-file", "--paper-dir", "paper", "--no-tutorial"],
                           "--results a-file: a file, not a folder"),
    "report-out-file": (["report", "--results", "nan-value", "--out", "a-file"],
                        "site folder a-file: a file, not a folder"),
    # records that are not their study's
    "report-wrong-study": (["report", "--results", "wrong-study", "--out", "site"],
                           "truncation.json: the record of the study 'stability', not of 'truncation'"),
    "paper-a-list": (["paper", "--results", "a-list", "--paper-dir", "paper", "--no-tutorial"],
                     "truncation.json: not a record (a JSON object), but a JSON list"),
    # what the paper quotes or tabulates, not there as a number
    "paper-nan-value": (["paper", "--results", "nan-value", "--paper-dir", "paper", "--no-tutorial"],
                        "the results' value at 'truncation/x' is nan, not a finite number"),
    "paper-list-value": (["paper", "--results", "list-value", "--paper-dir", "paper", "--no-tutorial"],
                         "the results' value at 'truncation/x' is [1, 2], which the format '.2f' cannot print"),
    "paper-short-table": (["paper", "--results", "short-table", "--paper-dir", "table-paper", "--no-tutorial"],
                          "the table 'misprints': the results of truncation lack what it needs (KeyError: 'where')"),
}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("refusals-more")
    for name, files in RESULTS.items():
        (folder / name).mkdir()
        for file, text in files.items():
            (folder / name / file).write_text(text)
    (folder / "a-file").write_text("not a folder\n")
    (folder / "bench.json").write_text(json.dumps({"order": [], "seconds": {}, "ratios": {}, "targets": {}}))
    for paper, template in (("paper", "x = {{truncation/x:.2f}}\n"), ("table-paper", "{{table:misprints}}\n")):
        (folder / paper).mkdir()
        (folder / paper / "paper.template.md").write_text(template)
    return folder


@pytest.mark.parametrize("name", REFUSALS)
def test_bad_input_is_one_line_and_status_2(folder, capsys, monkeypatch, name):
    argv, message = REFUSALS[name]
    monkeypatch.chdir(folder)
    status, out, err = run_main(capsys, argv)
    assert status == 2, (status, out[-500:], err[-2000:])
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith(f"steplab {argv[0]}: error: "), err
    assert message in err, err
    assert not (folder / "index.html").exists()  # nothing written into the current folder
    paper = folder / "paper" / "paper.md"
    assert not paper.exists() or "nan" not in paper.read_text()


def test_the_report_refuses_a_quoted_number_that_is_not_finite(tmp_path):
    """The report's study page lists the numbers the paper quotes: a NaN there is refused, a path the record
    lacks (a quick run's) still reads "not in this record"."""
    from steplab.paper import PaperError
    from steplab.report import quoted_numbers

    template = tmp_path / "paper.template.md"
    template.write_text("a is {{truncation/a:.2f}}, b is {{truncation/b:.2f}}\n")
    assert "not in this record" in quoted_numbers("truncation", {"a": 1.0}, template)
    with pytest.raises(PaperError, match="'truncation/a' is nan, not a finite number"):
        quoted_numbers("truncation", {"a": float("nan")}, template)


def test_a_report_page_that_cannot_format_its_record_names_the_record():
    """A string where a study's table formats a number: the page's ValueError names the record
    (it was "Unknown format code 'g' for object of type 'str'", naming nothing)."""
    from steplab.report import ReportError, _shown

    with pytest.raises(ReportError, match=r"^x/truncation.json: not a record its page can be made from \(ValueError"):
        _shown(Path("x/truncation.json"), lambda: format("abc", "g"))


def test_a_cached_record_cut_of_its_fields_is_run_again(tmp_path, capsys, monkeypatch):
    """A record with its cache key but without the fields its study's summary reads (edited, or cut by a
    tool) is no cache: the study runs again (it printed a traceback, KeyError 'fixed_bit_identical')."""
    monkeypatch.chdir(tmp_path)
    argv = ["study", "frame_rate", "--quick", "--out", "out"]
    assert run_main(capsys, argv)[0] == 0
    path = tmp_path / "out" / "frame_rate.json"
    record = json.loads(path.read_text())
    path.write_text(json.dumps({k: record[k] for k in ("cache_key", "figures", "study", "title", "parameters")}))
    status, out, err = run_main(capsys, argv)
    assert status == 0 and "Traceback" not in err, err
    assert "frame_rate: computed" in out and "fixed-step final states bit-identical" in out
