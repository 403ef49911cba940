"""The notebooks: generated from the tutorial (never edited by hand), run top to bottom, checked."""

from pathlib import Path

import nbformat
import numpy as np
import pytest
from nbclient import NotebookClient
from steplab.integrators import ButcherTableau, DivergenceError, get_integrator, simulate
from steplab.integrators.stable_dt import stable_steps
from steplab.physics.scene import load_scene

from steplab import exercises
from steplab.notebooks import notebook_files

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
SOLUTIONS = sorted((NOTEBOOKS / "solutions").glob("*.ipynb"))


def test_committed_notebooks_are_generated_from_the_tutorial():
    files = notebook_files(ROOT / "paper" / "tutorial.md", NOTEBOOKS / "source", NOTEBOOKS)
    assert len(files) == 2 * len(list((NOTEBOOKS / "source").glob("*.md"))) >= 10
    for path, text in files.items():
        # compared cell by cell, so that another nbformat's spelling of the same notebook passes
        assert path.exists() and _cells(nbformat.reads(text, as_version=4)) == _cells(nbformat.read(path, 4)), \
            f"{path} is stale: run python -m steplab.notebooks"
    committed = set(NOTEBOOKS.glob("*.ipynb")) | set(SOLUTIONS)
    assert committed == set(files)


def _cells(notebook):
    return [(c.cell_type, c.source, sorted(c.metadata.get("tags", []))) for c in notebook.cells]


def _tags(cell):
    return set(cell.metadata.get("tags", []))


@pytest.mark.parametrize("path", SOLUTIONS, ids=lambda p: p.stem)
def test_notebook_runs_and_its_solutions_are_correct(path, tmp_path):
    """One kernel per topic: the open exercise says "not yet", its solution "correct"."""
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    output = {tag: "".join(o.get("text", "") for c in notebook.cells if tag in _tags(c) for o in c.outputs)
              for tag in ("exercise", "solution")}
    assert output["exercise"].count("not yet:") >= 1 and "correct:" not in output["exercise"]
    assert output["solution"].count("correct:") >= 1 and "not yet:" not in output["solution"]
    # the student's notebook is the same, without the solutions
    student = nbformat.read(NOTEBOOKS / path.name, as_version=4)
    assert [c.source for c in student.cells] == [c.source for c in notebook.cells if "solution" not in _tags(c)]
    assert (tmp_path / "tutorial-figures").is_dir()  # figures where the reader runs it, not beside the notebook
    if any("savefig" in c.source for c in notebook.cells):  # and shown inline, not only saved
        assert any("image/png" in o.get("data", {}) for c in notebook.cells for o in c.get("outputs", []))


def _bisected_limit() -> float:
    """semi-implicit Euler's largest stable dt on the soft cube by bisection in log dt, as notebook 3's
    exercise defines it (a run of 2000 steps without DivergenceError), to 0.1 %."""
    cube = load_scene("soft-cube")

    def stable(dt):
        try:
            simulate(cube.model, "semi-implicit-euler", cube.y0, 0.0, dt=dt, n_steps=2000)
        except DivergenceError:
            return False
        return True

    lo, hi = 0.005, 0.05
    while hi / lo > 1.001:
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def test_checks_accept_the_closed_forms_and_say_not_yet_otherwise(capsys):
    # closed forms, independent of the code: eps^6 H for the third bounce (eps^4 H the second); (w + 2 r) / dt
    assert exercises.check_bounce_height(0.858**6 * 0.92)
    assert exercises.check_bounce_height(np.array([0.858**6 * 0.92]))  # an answer read from a scene's arrays
    assert exercises.check_bounce_height(0.858**4 * 0.92, bounce=2)
    assert not exercises.check_bounce_height(0.858**4 * 0.92) and not exercises.check_bounce_height(0.858**2 * 0.92)
    assert exercises.check_tunnelling_speed((0.01 + 2 * 0.05) / 0.01)
    assert not exercises.check_tunnelling_speed(0.01 / 0.01)
    ralston = ButcherTableau(a_lower=((2 / 3,),), b=(1 / 4, 3 / 4), c=(2 / 3,))
    heun = ButcherTableau(a_lower=((1.0,),), b=(0.5, 0.5), c=(1.0,))
    assert exercises.check_ralston(ralston, 2.01)
    assert not exercises.check_ralston(ralston, 1.0)
    assert not exercises.check_ralston(heun, 2.0)
    assert "second order, but not Ralston's" in capsys.readouterr().out
    # the stability limit is the experiment's, to 3 %: bisected here as the exercise says (a run of 2000
    # steps without DivergenceError), and bracketed by the theory's limits from the stiffest mode
    limit = _bisected_limit()
    _, (row,) = stable_steps(load_scene("soft-cube").model, load_scene("soft-cube").y0[0],
                             [get_integrator("semi-implicit-euler")])
    assert row.dt_max_damped < limit < row.dt_max
    assert exercises.check_stability_limit(limit)
    assert "between steplab check's damped" in capsys.readouterr().out
    assert not exercises.check_stability_limit(0.005) and not exercises.check_stability_limit(0.92 * limit)
    assert capsys.readouterr().out.count("the limit is higher") == 2
    # past the limit: 50 ms, a step 3 % longer than the limit, and the undamped prediction copied
    for dt in (0.05, 1.03 * limit, row.dt_max):
        assert not exercises.check_stability_limit(dt)
        assert "past the limit" in capsys.readouterr().out
    assert exercises.check_position_verlet(get_integrator("position-verlet"), 2.0)
    assert not exercises.check_position_verlet(get_integrator("velocity-verlet"), 2.0)
    for check in (exercises.check_bounce_height, exercises.check_tunnelling_speed, exercises.check_stability_limit):
        assert not check(None)
    assert not exercises.check_ralston(None, None) and not exercises.check_position_verlet(None, None)
    # a right method with the order still blank (the exercises' starting code) is "not yet", not a TypeError
    assert not exercises.check_ralston(ralston, None)
    assert not exercises.check_position_verlet(get_integrator("position-verlet"), None)
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 9 and sum(line.startswith("not yet: ") for line in out) == 8
    # a blank answer gets guidance, not the answer: no number of the limit's interval (0.0164 s)
    blank = next(line for line in out if line.startswith("not yet: no dt yet"))
    assert not any(ch.isdigit() for ch in blank), blank


def test_a_check_called_on_what_it_cannot_judge_says_so_in_one_line():
    # scipy-dop853 ran 2000-step experiments for minutes, then said "keep bisecting upwards"; a scene
    # without the wall was "not enough values to unpack"
    for integrator in ("scipy-dop853", "implicit-euler"):
        with pytest.raises(ValueError, match=f"{integrator} has no stability limit on soft-cube"):
            exercises.check_stability_limit(0.01, integrator=integrator)
    with pytest.raises(ValueError, match="the scene 'drop' has 0 box walls"):
        exercises.check_tunnelling_speed(10.0, scene="drop")


def test_a_tableau_whose_rows_miss_their_nodes_is_named_as_the_exercise_names_it():
    # notebook 2 writes Ralston's entries as a_21, b_1, b_2, c_2 (stages from 1); Python counts from 0
    with pytest.raises(ValueError, match=r"a_lower\[0\] \(a_21\) sums to 0.5, not its node c\[0\] \(c_2\) = 0.666667"):
        ButcherTableau(a_lower=((0.5,),), b=(1 / 4, 3 / 4), c=(2 / 3,))
    with pytest.raises(ValueError, match=r"a_lower\[1\] \(a_31 .. a_32\) must have 2 entries, got 1"):
        ButcherTableau(a_lower=((0.5,), (1.0,)), b=(1 / 6, 2 / 3, 1 / 6), c=(0.5, 1.0))


def test_a_tableau_given_to_the_class_is_refused_with_the_way_that_works():
    # notebook 2 shows the step from a tableau to a method; the natural wrong way says it
    from steplab.integrators import ExplicitRungeKutta

    midpoint = ButcherTableau(a_lower=((1 / 2,),), b=(0.0, 1.0), c=(1 / 2,))
    with pytest.raises(TypeError, match=r"class MyMethod\(ExplicitRungeKutta\).*tableau = ButcherTableau"):
        ExplicitRungeKutta(tableau=midpoint)
    assert get_integrator("midpoint").tableau == midpoint  # the subclass way, as steplab's own methods
