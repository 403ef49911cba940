"""The command line: outputs as a user sees them, and one-line errors with status 2."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import TWO_BODY_SCENE

from steplab.cli import main


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_lecture_one_step_json(capsys):
    status, out, _ = run(capsys, "run", "projectile", "--integrator", "euler", "--dt", "0.2",
                         "--t-end", "5.2", "--json")
    assert status == 0
    s = json.loads(out)
    assert s["integrator"] == "euler" and s["dt"] == 0.2 and s["steps"] == 1
    assert s["t_end"] == pytest.approx(5.2, abs=1e-12)
    # hand-derived: p = p0 + dt V0, mV = mV0 + dt F (F_z = -2.5 * 9.81 = -24.525 N)
    np.testing.assert_allclose(s["final_positions"], [[10 + 0.2 * 7.68, 0, 2 + 0.2 * 29.0]], rtol=1e-15)
    np.testing.assert_allclose(np.multiply(s["final_velocities"], 2.5), [[19.2, 0, 72.5 - 0.2 * 24.525]],
                               rtol=1e-15)


def test_integrators_lists_required_methods(capsys):
    status, out, _ = run(capsys, "integrators", "--json")
    rows = {r["name"]: r for r in json.loads(out)}
    for name in ("euler", "semi-implicit-euler", "velocity-verlet", "position-verlet", "rk4",
                 "implicit-euler", "exact", "diffrax-dopri8", "diffrax-kvaerno5", "scipy-dop853",
                 "scipy-radau"):
        assert name in rows
    assert rows["rk4"]["order"] == 4 and rows["rk4"]["evaluations_per_step"] == 4
    assert rows["velocity-verlet"]["symplectic"] and rows["implicit-euler"]["implicit"]
    assert rows["diffrax-dopri8"]["rtol"] == 1e-12
    status, out, _ = run(capsys, "integrators")
    assert status == 0 and "velocity-verlet" in out and "symplectic" in out


def test_scenes_lists_builtins(capsys):
    status, out, _ = run(capsys, "scenes")
    assert status == 0 and "soft-cube" in out and "cloth" in out


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_trajectory_files_are_byte_identical_across_runs(capsys, tmp_path, suffix):
    paths = [tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"]
    for path in paths:
        status, out, _ = run(capsys, "run", "soft-cube", "--t-end", "0.1", "--out", str(path))
        assert status == 0 and str(path) in out
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_npz_and_csv_content(capsys, tmp_path):
    run(capsys, "run", "oscillator", "--t-end", "0.05", "--out", str(tmp_path / "t.npz"),
        "--integrator", "rk4")
    run(capsys, "run", "oscillator", "--t-end", "0.05", "--out", str(tmp_path / "t.csv"),
        "--integrator", "rk4")
    data = np.load(tmp_path / "t.npz")
    assert data["positions"].shape == (6, 2, 3)
    np.testing.assert_allclose(data["t"], np.arange(6) * 0.01)
    assert json.loads(str(data["metadata"]))["integrator"] == "rk4"
    lines = (tmp_path / "t.csv").read_text().splitlines()
    assert lines[0] == "t,body,x,y,z,vx,vy,vz" and len(lines) == 1 + 6 * 2
    last = lines[-1].split(",")
    assert last[1] == "mass"
    np.testing.assert_array_equal([float(x) for x in last[2:5]], data["positions"][-1, 1])


def test_jax_backend_and_float32(capsys):
    s64 = json.loads(run(capsys, "run", "oscillator", "--t-end", "1", "--json")[1])
    s32 = json.loads(run(capsys, "run", "oscillator", "--t-end", "1", "--json", "--backend", "jax",
                         "--precision", "float32")[1])
    assert s32["backend"] == "jax" and s32["precision"] == "float32"
    np.testing.assert_allclose(s32["final_positions"], s64["final_positions"], atol=1e-4)


def test_divergence_is_one_line_status_1(capsys):
    status, _, err = run(capsys, "run", "oscillator", "--integrator", "euler", "--dt", "0.5",
                         "--t-end", "1000")
    assert status == 1
    warning, error = err.splitlines()  # euler grows at every dt: warned before the run, then the one-line error
    assert warning.startswith("steplab run: warning: ") and "grows at every dt" in warning
    assert "'euler' diverged with dt = 0.5 s" in error and "step" in error and "t = " in error


def write(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


BAD_INPUTS = [
    (["run", "projectile", "--integrator", "nope"], "unknown integrator 'nope'; valid: euler,"),
    (["run", "no-such-scene"], "unknown scene 'no-such-scene'"),
    (["run", "projectile", "--dt", "0"], "--dt: must be > 0"),
    (["run", "projectile", "--dt", "-0.1"], "--dt: must be > 0"),
    (["run", "projectile", "--dt", "inf"], "--dt: must be finite"),
    (["run", "projectile", "--t-end", "nan"], "--t-end: must be finite"),
    (["run", "projectile", "--t-end", "4"], "must be later than the scene's t_start = 5"),
    (["run", "projectile", "--out", "x.txt"], "unknown trajectory format '.txt'"),
    (["run", "projectile", "--backend", "cuda"], "invalid choice: 'cuda'"),
    (["run", "oscillator", "--integrator", "exact"], "integrator 'exact' needs a constant total force"),
    (["run", "projectile", "--dt", "1e-9"], "exceed the limit of 10000000"),
    (["run", "oscillator", "--max-steps", "10"], "exceed the limit of 10"),
    (["frobnicate"], "invalid choice"),
]


@pytest.mark.parametrize("argv,message", BAD_INPUTS)
def test_bad_input_one_line_status_2(capsys, argv, message):
    with pytest.raises(SystemExit) as exit_:
        sys.exit(main(argv))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1 and "Traceback" not in err


BAD_SCENES = [
    ("[simulation]\ndt = 0.1\nt_end = = 2\n", "malformed TOML"),
    (b"[simulation]\n\xff = 1\n", "not UTF-8"),
    (TWO_BODY_SCENE.replace("mass = 1.0", "mass = -2.0", 1), "bodies[0].mass: must be > 0, got -2"),
    (TWO_BODY_SCENE.replace("radius = 0.1", "radius = 0", 1), "bodies[0].radius: must be > 0"),
    (TWO_BODY_SCENE.replace("dt = 0.01", "dt = 0"), "simulation.dt: must be > 0"),
    (TWO_BODY_SCENE.replace("t_end = 1.0", "t_end = -1.0"), "simulation.t_end: must be later than t_start"),
    (TWO_BODY_SCENE.replace("t_end = 1.0", "t_end = nan"), "simulation.t_end: must be finite"),
    (TWO_BODY_SCENE.replace('name = "a"', "name = 5"), "bodies[0].name: must be a string, got an integer"),
    (TWO_BODY_SCENE.replace("dt = 0.01\n", ""), "simulation.dt: missing required key"),
    (TWO_BODY_SCENE + '[[forces.springs]]\nbodies = ["a", "z"]\nstiffness = 1.0\n',
     "forces.springs[0].bodies: names unknown body 'z'"),
    (TWO_BODY_SCENE + "[forces.gravty]\n", "forces: unknown key 'gravty'"),
]


@pytest.mark.parametrize("text,message", BAD_SCENES)
def test_bad_scene_file_one_line_status_2(capsys, tmp_path, text, message):
    path = write(tmp_path, text)
    status, out, err = run(capsys, "run", path)
    assert status == 2
    assert err.startswith(f"steplab run: error: {path}: ")
    assert message in err and err.count("\n") == 1


def test_unreadable_scene(capsys, tmp_path):
    status, _, err = run(capsys, "run", str(tmp_path / "missing.toml"))
    assert status == 2 and "cannot read" in err


def test_console_script_end_to_end():
    """The installed entry point, in a fresh process: the lecture's step and a bad input."""
    steplab = str(Path(sys.executable).parent / "steplab")
    ok = subprocess.run([steplab, "run", "projectile", "--integrator", "euler",
                         "--dt", "0.2", "--t-end", "5.2", "--json"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["final_positions"][0][2] == pytest.approx(7.8, rel=1e-15)
    bad = subprocess.run([steplab, "run", "projectile", "--integrator", "x"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and bad.stderr.count("\n") == 1


def test_study_command_writes_results(capsys, tmp_path):
    status, out, _ = run(capsys, "study", "scenes", "--quick", "--out", str(tmp_path))
    assert status == 0
    record = json.loads((tmp_path / "scenes.json").read_text())
    assert record["parameters"]["fraction"] == 0.1 and record["provenance"]["packages"]["jax"]
    rows = record["rows"]
    assert {r["scene"] for r in rows} >= {"projectile", "cloth"}
    # the two backends agree to round-off on every scene
    assert max(r["backend_difference"] for r in rows if r["backend_difference"] is not None) < 1e-9
    # the guarantee that holds over long chaotic runs too: within 10x of what a 1e-15 perturbation
    # of the start makes in NumPy alone, or 1e-12 (m, m/s) where neither grows (studies/scene_tour.py)
    for r in (r for r in rows if r["backend_difference"] is not None):
        for kind in ("position", "velocity", "orientation", "angular_velocity"):  # the last two: rotating bodies
            if r[f"{kind}_difference"] is not None:
                assert r[f"{kind}_difference"] <= max(10 * r[f"perturbed_{kind}_difference"], 1e-12), r
    # scenes with collisions run them: the dropped ball bounces instead of falling through the floor
    drop = [r for r in rows if r["scene"] == "drop"]
    assert [r["backend"] for r in drop] == ["numpy"] and drop[0]["detector"] != "none"
    status, out, _ = run(capsys, "study", "scenes", "--quick", "--out", str(tmp_path))
    assert status == 0 and "scenes (cached)" in out
    assert f"record: {tmp_path / 'scenes.json'}" in out  # the record's path, not a pattern
    status, out, _ = run(capsys, "study", "--list")
    assert {"truncation", "stability", "work_precision", "frame_rate", "scenes"} <= set(out.split())


def test_a_study_whose_folder_cannot_be_made_stops_before_computing(capsys, tmp_path, monkeypatch):
    """A study without tasks computes its whole record before writing it: an --out under a file
    must be refused first, in one line, not after minutes of work."""
    from steplab.studies import soft_bodies

    def compute(*args, **kwargs):
        raise AssertionError("computed before the folder was made")

    monkeypatch.setitem(vars(soft_bodies.STUDY), "compute", compute)  # a frozen dataclass's field
    (tmp_path / "file").write_text("")
    for out, message in ((tmp_path / "file", "results folder " + str(tmp_path / "file") + ": a file, not a folder"),
                         (tmp_path / "file" / "results", "Not a directory")):
        status, _, err = run(capsys, "study", "soft-bodies", "--quick", "--out", str(out))
        assert status == 2 and message in err and err.count("\n") == 1


def test_the_cloths_backends_differ_by_amplified_round_off_over_its_whole_run():
    """1,500 steps: NumPy and JAX differ by centimetres, as NumPy does from a start moved by 1e-15."""
    from steplab.studies import scene_tour

    [numpy_row, jax_row] = scene_tour.task({"backends": ["numpy", "jax"], "fraction": 1.0}, "cloth")
    assert jax_row["steps"] == 1500 and jax_row["position_difference"] > 1e-6  # far beyond one step's round-off
    for kind in ("position", "velocity"):
        assert jax_row[f"{kind}_difference"] <= 10 * jax_row[f"perturbed_{kind}_difference"]


def test_animate_writes_a_gif_side_by_side(capsys, tmp_path):
    from PIL import Image

    out = tmp_path / "a.gif"
    status, text, _ = run(capsys, "animate", "oscillator", "--compare", "euler,velocity-verlet", "--t-end", "0.2",
                          "--fps", "5", "--out", str(out))
    assert status == 0 and "oscillator: euler" in text and "oscillator: velocity-verlet" in text
    with Image.open(out) as gif:
        assert gif.n_frames == 21 and gif.size[0] > gif.size[1]  # two panels side by side
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_animate_marks_the_attracting_mass_of_central_gravity(capsys, tmp_path):
    from PIL import Image

    out = tmp_path / "k.gif"
    status, _, _ = run(capsys, "animate", "kepler", "--t-end", "0.02", "--fps", "5", "--view", "xy", "--out", str(out))
    assert status == 0
    with Image.open(out) as gif:
        frame = np.asarray(gif.convert("RGB"), dtype=int)
    # the star is drawn in tab:orange (255, 127, 14); nothing else in the frame is orange
    orange = (np.abs(frame - [255, 127, 14]).sum(axis=-1) < 60).sum()
    assert orange > 20


@pytest.mark.parametrize("argv,message", [
    (["animate", "oscillator", "--out", "a.txt"], "unknown animation format '.txt'"),
    (["animate", "oscillator", "--compare", "euler", "--out", "a.gif"], "--compare needs at least two"),
    (["animate", "oscillator", "--compare", "euler,nope", "--out", "a.gif"], "unknown integrator 'nope'"),
    (["recommend", "oscillator", "--tol", "-1"], "--tol: must be > 0"),
    (["recommend", "drop", "--tol", "1e-3", "--dt-max", "-1"], "--dt-max: must be > 0"),
    (["recommend", "drop", "--tol", "1e-3", "--detector", "bogus"], "invalid choice: 'bogus'"),
    (["recommend", "drop", "--tol", "1e-3", "--integrators", "nope"], "unknown integrator 'nope'"),
    (["recommend", "drop", "--tol", "1e-3", "--integrators", "exact"], "exact is not a fixed-step integrator"),
    (["study", "nope"], "unknown study 'nope'"),
])
def test_more_bad_input_status_2(capsys, argv, message):
    with pytest.raises(SystemExit) as exit_:
        sys.exit(main(argv))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


#: three 1 kg balls in a row, no gravity: "a" (1 m/s) hits "b" at t = 0.05 s, and "b", touching
#: "c", passes the impulse on in the same step of 0.1 s: two impacts in one step
CHAIN_SCENE = """description = "a Newton's-cradle chain of three"
[simulation]
integrator = "velocity-verlet"
dt = 0.1
t_end = 0.3
[[bodies]]
name = "a"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 0.0]
velocity = [1.0, 0.0, 0.0]
[[bodies]]
name = "b"
mass = 1.0
radius = 0.1
position = [0.25, 0.0, 0.0]
[[bodies]]
name = "c"
mass = 1.0
radius = 0.1
position = [0.45, 0.0, 0.0]
[collisions]
detector = "swept"
restitution = 1.0
max_impacts_per_step = CAP
"""


def test_impact_cap_stops_the_run_in_text_and_json(capsys, tmp_path):
    """A step holding more impacts than the cap: status 1, one line; --json names it as error and warning."""
    scene = tmp_path / "chain.toml"
    scene.write_text(CHAIN_SCENE.replace("CAP", "1"))
    status, out, err = run(capsys, "run", str(scene))
    assert status == 1 and err.count("\n") == 1 and "max_impacts_per_step" in err and not out
    status, out, err = run(capsys, "run", str(scene), "--json")
    s = json.loads(out)
    assert status == 1 and "max_impacts_per_step" in err
    assert "max_impacts_per_step" in s["error"] and s["error"] in s["warnings"] and s["collisions"]["impacts"] == 1


def test_run_json_has_warnings_and_the_energy_change(capsys, tmp_path):
    """Elastic equal balls swap velocities: the chain ends with "c" at 1 m/s and the energy unchanged."""
    scene = tmp_path / "chain.toml"
    scene.write_text(CHAIN_SCENE.replace("CAP", "2"))
    status, out, _ = run(capsys, "run", str(scene), "--json")
    s = json.loads(out)
    assert status == 0 and s["warnings"] == [] and s["collisions"]["impacts"] == 2
    assert s["energy_start"] == 0.5 and abs(s["energy_relative_change"]) <= 1e-14
    # "c" leaves at t = 0.05 s at 1 m/s: x = 0.45 + 0.25 m at t = 0.3 s
    assert s["final_positions"][2][0] == pytest.approx(0.70, abs=1e-12)
    # rk4 on the 1 Hz oscillator is stable up to omega dt = 2 sqrt(2) (its interval on the imaginary axis)
    status, out, _ = run(capsys, "run", "oscillator", "--integrator", "rk4", "--dt", "0.5", "--t-end", "1", "--json")
    assert status == 0 and [w for w in json.loads(out)["warnings"] if "largest stable dt of rk4" in w]


def test_run_reports_the_energy_lost_in_bounces(capsys):
    """Three bounces at eps = 0.858 keep eps^6 of the drop's energy (velocity Verlet: exact in flight)."""
    status, out, _ = run(capsys, "run", "drop", "--integrator", "velocity-verlet", "--json")
    s = json.loads(out)
    assert status == 0 and s["collisions"]["impacts"] == 3
    assert s["energy_relative_change"] == pytest.approx(0.858**6 - 1, abs=2e-3)
    assert s["energy_change"] == pytest.approx(s["energy_end"] - s["energy_start"])


def test_run_summary_counts_in_words(capsys):
    # the golf ball of `drop` first reaches the floor at t = sqrt(2 H / g) = 0.43 s: one impact by 0.5 s
    status, out, _ = run(capsys, "run", "drop", "--t-end", "0.5")
    assert status == 0 and "1 impact," in out and "1 impacts" not in out


# --- output that explains itself (issue 29) ----------------------------------------------------


def test_euler_is_warned_though_it_has_no_stable_dt(capsys):
    """Explicit Euler on the undamped oscillator grows at every dt: rho = sqrt(1 + (omega dt)^2) per step."""
    status, out, err = run(capsys, "run", "oscillator", "--integrator", "euler", "--t-end", "1", "--json")
    [warning] = json.loads(out)["warnings"]
    omega_dt = 2 * np.pi * 0.01  # the scene's dt
    assert status == 0 and "grows at every dt" in warning and warning in err
    assert f"{np.sqrt(1 + omega_dt**2):.4g}" in warning


def test_a_growth_factor_near_one_is_printed_as_one_plus_its_excess(capsys):
    """Explicit Euler on kepler's orbit (omega_max 17.77 rad/s, dt 1 ms) grows by sqrt(1 + (omega dt)^2) =
    1.000158 a step: four digits printed it as "multiplies its amplitude by 1, its energy by 1"."""
    status, out, err = run(capsys, "run", "kepler", "--integrator", "euler", "--steps", "5", "--json")
    [warning] = json.loads(out)["warnings"]
    assert status == 0 and "grows at every dt" in warning
    assert "multiplies its amplitude by 1 + 0.000158, its energy by 1 + 0.000316)" in warning, warning


def test_check_says_none_where_no_dt_is_stable(capsys):
    status, out, _ = run(capsys, "check", "oscillator")
    [euler] = [line for line in out.splitlines() if line.split()[0] == "euler"]
    assert status == 0 and "none (grows)" in euler and "grows at every dt" in euler and "0 (any dt)" not in out
    [implicit] = [line for line in out.splitlines() if line.split()[0] == "implicit-euler"]
    assert "no limit" in implicit


def columns(out: str, header: str) -> tuple[int, list[str]]:
    """Where the last column of a table starts in its header, and the rows under it."""
    lines = out.splitlines()
    top = next(k for k, line in enumerate(lines) if header in line)
    return lines[top].index(header), lines[top + 1:]


def test_integrators_table_says_what_the_class_data_says(capsys):
    """Only Newton's method evaluates per iteration; implicit damping is linearly implicit, exponential
    damping no solve at all; every description starts in the same column."""
    from steplab.integrators import INTEGRATORS, ROTATIONS

    status, out, _ = run(capsys, "integrators")
    start, rows = columns(out, "description")
    rows = rows[:rows.index("")]  # the table, not the rotation methods' stages below it
    assert {row.split()[1] for row in rows if row.split()[0] in ROTATIONS} >= {"rotation"}
    for row in rows:  # every description in the same column, the rotation methods' too
        assert row[start - 2:start] == "  " and row[start] != " "
    rows = {row.split()[0]: row for row in rows if row.split()[1] != "rotation"}
    assert status == 0 and set(rows) == set(INTEGRATORS)
    assert rows["implicit-euler"].split()[3:6] == ["1/iter", "no", "yes"]
    assert rows["implicit-damping-euler"].split()[3:6] == ["1", "yes", "linearly"]
    assert rows["exponential-damping-euler"].split()[3:7] == ["1", "yes", "no", "(exp)"]
    for name, row in rows.items():
        assert row[start:] == INTEGRATORS[name].describe()["description"]
    assert {r["name"]: r["scheme"] for r in json.loads(run(capsys, "integrators", "--json")[1])}["rk4"] == "explicit"


def test_tables_align_for_any_name_length(capsys):
    from steplab.cli.table import table

    text = table([("a", "1", "x"), ("a-very-long-integrator-name", "12345", "y")], ("name", "n", "what"), right=(1,))
    lines = text.splitlines()  # 27 + 2 + 5 + 2 columns before the last
    assert [line.rindex(" ") + 1 for line in lines] == [36, 36, 36]
    assert lines[1].split() == ["a", "1", "x"] and lines[1][33] == "1"  # a number, right-aligned
    for argv, header in ((["scenes"], "description"), (["check", "cloth"], "at this dt")):
        status, out, _ = run(capsys, *argv)
        start, rows = columns(out, header)
        assert status == 0 and rows and all(row[start - 2:start] == "  " and row[start] != " " for row in rows)


def test_a_dt_longer_than_the_run_is_one_line_that_says_what_to_pass(capsys):
    """The command-line page's `--dt 16` (milliseconds meant) on the oscillator, whose run lasts 10 s."""
    status, out, err = run(capsys, "run", "oscillator", "--dt", "16")
    assert status == 2 and not out and err.count("\n") == 1
    assert "longer than the run" in err and "--t-end 16 or later" in err and "--dt 0.016" in err


def test_integrator_from_a_python_file(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my_euler.py").write_text(
        "from steplab.integrators import SemiImplicitEuler\n\n\nclass Mine(SemiImplicitEuler):\n"
        "    name = 'mine'\n")
    status, out, _ = run(capsys, "run", "projectile", "--integrator", "my_euler.py:Mine", "--json")
    assert status == 0 and json.loads(out)["integrator"] == "mine"
    status, _, err = run(capsys, "run", "projectile", "--integrator", "nofile.py:Mine")
    assert status == 2 and "without .py" in err and err.count("\n") == 1


def test_study_list_has_every_study_with_its_title(capsys):
    from steplab.studies import STUDIES

    status, out, _ = run(capsys, "study", "--list")
    lines = out.splitlines()
    assert status == 0 and len(lines) == len(STUDIES)
    for line, (name, study) in zip(lines, STUDIES.items()):
        assert line.split()[0] == name and line.endswith(study.title)


def test_a_study_prints_a_line_as_it_finishes_when_not_a_terminal(capsys, tmp_path):
    """One task study run by name: its tasks reach the progress callback, and the line comes before the summary."""
    from steplab.studies import STUDIES
    from steplab.studies.runner import Study

    seen = []
    toy = Study("toy-progress", "a toy of three tasks", lambda quick: {"n": 3}, lambda p, progress=None: {},
                lambda record, out: [],
                tasks=lambda p: list(range(p["n"])), task=lambda p, item: seen.append(item) or item * item,
                reduce=lambda p, results: {"squares": results})
    STUDIES.register(toy)
    try:
        status, out, _ = run(capsys, "study", "toy-progress", "--out", str(tmp_path))
    finally:
        del STUDIES["toy-progress"]
    lines = out.splitlines()
    assert status == 0 and seen == [0, 1, 2]
    # the study's own wall and CPU seconds, then the time since the start
    assert re.fullmatch(r"\[1/1\] toy-progress: computed in \d+\.\d s \(\d+\.\d s CPU\), \d+ s since the start",
                        lines[0]), lines[0]
    assert lines[1].startswith("toy-progress (computed)")
    assert json.loads((tmp_path / "toy-progress.json").read_text())["squares"] == [0, 1, 4]


def test_pybullet_prints_nothing_when_an_engine_loads_it():
    pytest.importorskip("pybullet")
    done = subprocess.run([sys.executable, "-c", "from steplab.engines.base import require\n"
                           "require('pybullet', 'Bullet')\nprint('loaded')"], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (0, "loaded\n", "")


def test_the_contact_solvers_residual_is_printed_with_its_unit_and_meaning(capsys):
    """The drop on the contact solver: three bounces, each converged in its one iteration (residual ~ 0)."""
    status, out, _ = run(capsys, "run", "drop", "--method", "solver")
    [line] = [line for line in out.splitlines() if "largest residual" in line]
    residual = float(line.split("largest residual: ")[1].split()[0])
    assert status == 0 and residual < 1e-12 and "m/s (the worst contact's complementarity residual" in line


# --- rotation on the command line (issue 25): the dzhanibekov scene, a free 0.2 kg box 0.3 x 0.2 x 0.1 m
DZHANIBEKOV_INERTIA = 0.2 / 12 * np.array([0.2**2 + 0.1**2, 0.3**2 + 0.1**2, 0.3**2 + 0.2**2])  # m (b^2 + c^2) / 12
DZHANIBEKOV_OMEGA = np.array([0.05, 2 * np.pi, 0.05])  # rad/s, world = body frame at the identity orientation


@pytest.mark.parametrize("rotation, atol", [("rk4", 2e-5), ("dlm", 5e-3)])
def test_dzhanibekov_run_json_against_the_exact_tumbling(capsys, rotation, atol):
    from steplab.integrators.torque_free import TorqueFreeMotion
    from steplab.physics import quaternion as quat

    status, out, _ = run(capsys, "run", "dzhanibekov", "--rotation", rotation, "--json")
    assert status == 0
    s = json.loads(out)
    assert s["rotation"] == rotation and s["rotating_bodies"] == ["box"]
    # the rotational kinetic energy 1/2 omega . I omega (the box does not move)
    assert s["energy_start"] == pytest.approx(0.5 * DZHANIBEKOV_INERTIA @ DZHANIBEKOV_OMEGA**2, rel=1e-14)
    np.testing.assert_allclose(s["angular_momentum_start"], DZHANIBEKOV_INERTIA * DZHANIBEKOV_OMEGA, rtol=1e-14)
    # the exact torque-free motion (Jacobi elliptic functions) at t_end, world frame
    motion = TorqueFreeMotion(DZHANIBEKOV_INERTIA, quat.IDENTITY, DZHANIBEKOV_OMEGA)
    q_exact = motion.orientation(np.array([s["t_end"]]))
    omega_world = quat.rotate(np, q_exact, motion.angular_velocity(np.array([s["t_end"]])))[0]
    np.testing.assert_allclose(s["final_angular_velocities"][0], omega_world, atol=atol * 2 * np.pi)
    assert quat.angle_between(np, np.array(s["final_orientations"]), q_exact)[0] < atol
    if rotation == "dlm":  # dlm keeps the vector L in space to round-off
        np.testing.assert_allclose(s["angular_momentum_end"], s["angular_momentum_start"], rtol=1e-12)


def test_rotation_summary_in_words_with_units(capsys):
    status, out, _ = run(capsys, "run", "dzhanibekov")
    assert status == 0
    assert "rotation: dlm" in out  # the scene's [simulation] rotation
    assert "angular velocity (rad/s, world)" in out and "orientation [w, x, y, z]" in out
    assert "angular momentum (about the centre of mass):" in out and "kg m^2/s" in out
    _, out, _ = run(capsys, "run", "projectile")
    assert "rotation" not in out and "angular" not in out  # no rotating bodies: as before
    _, out, _ = run(capsys, "run", "projectile", "--json")
    assert "final_orientations" not in json.loads(out)


def test_npz_has_the_orientations_and_angular_velocities(capsys, tmp_path):
    path = tmp_path / "d.npz"
    status, out, _ = run(capsys, "run", "dzhanibekov", "--rotation", "implicit-midpoint", "--save-every", "10",
                         "--out", str(path), "--json")
    assert status == 0
    s, data = json.loads(out), np.load(path)
    assert data["orientations"].shape == (61, 1, 4) and data["angular_velocities"].shape == (61, 1, 3)
    np.testing.assert_allclose(np.linalg.norm(data["orientations"], axis=-1), 1, atol=1e-12)
    np.testing.assert_allclose(data["angular_velocities"][0, 0], DZHANIBEKOV_OMEGA, rtol=1e-15)
    np.testing.assert_array_equal(data["orientations"][-1], s["final_orientations"])
    assert json.loads(str(data["metadata"]))["rotation"] == "implicit-midpoint"
    # the implicit midpoint rule keeps the energy, rotational included, to round-off
    assert s["energy_end"] == pytest.approx(s["energy_start"], rel=1e-12)


@pytest.mark.parametrize("command", [["run"], ["check"], ["recommend", "--tol", "1"]])
def test_unknown_rotation_is_one_line_status_2(capsys, command):
    status, out, err = run(capsys, command[0], "dzhanibekov", *command[1:], "--rotation", "euler")
    assert status == 2 and out == ""
    assert err.strip().count("\n") == 0
    assert "unknown rotation method 'euler'; valid: explicit" in err


def test_a_diverging_rotation_is_one_line_status_1(capsys):
    status, out, err = run(capsys, "run", "dzhanibekov", "--rotation", "explicit", "--dt", "0.5", "--t-end", "500")
    assert status == 1 and out == ""
    assert err.strip().count("\n") == 0 and "'explicit' diverged with dt = 0.5 s" in err


def test_check_predicts_the_rotation_limit_that_a_run_shows(capsys):
    status, out, _ = run(capsys, "check", "dzhanibekov", "--json")
    limit = json.loads(out)["rotation"]
    assert status == 0 and limit["method"] == "dlm" and limit["stable"] and limit["dt_max"] > 1 / 60
    # the claims hold in runs of the measurement's length (1000 steps, energy within +10 %)
    for dt, stable in ((0.9 * limit["dt_max"], True), (1.3 * limit["dt_max"], False)):
        _, out, _ = run(capsys, "run", "dzhanibekov", "--dt", f"{dt!r}", "--steps", "1000", "--json")
        change = json.loads(out)["energy_relative_change"]
        assert (change < 0.1) == stable, (dt, change)
    # the engines' exponential map is unstable about the intermediate axis at any dt on the grid
    _, out, _ = run(capsys, "check", "dzhanibekov", "--rotation", "exponential-map", "--json")
    assert json.loads(out)["rotation"] == {"method": "exponential-map", "dt_max": 0.0, "stable": False}
    _, out, _ = run(capsys, "run", "dzhanibekov", "--rotation", "exponential-map", "--steps", "1000", "--json")
    assert json.loads(out)["energy_relative_change"] > 0.1
    _, out, _ = run(capsys, "check", "dzhanibekov", "--rotation", "exponential-map")
    assert "rotation exponential-map" in out and "none (grows at every omega dt from 0.05 to 50)" in out


def test_integrators_lists_the_rotation_methods(capsys):
    from steplab.integrators import ROTATIONS

    _, out, _ = run(capsys, "integrators", "--json")
    rows = {r["name"]: r for r in json.loads(out) if r["kind"] == "rotation"}
    assert list(rows) == list(ROTATIONS)
    assert rows["dlm"]["order"] == 2 and rows["dlm"]["composes_with"] == ["velocity-verlet"]
    assert rows["dlm"]["source"] == "steplab" and "Dullweber" in rows["dlm"]["reference"]
    _, out, _ = run(capsys, "integrators")
    lines = out.splitlines()
    main_rows = [line for line in lines if line.split()[:2] == ["rk4", "rotation"]]
    assert len(main_rows) == 1 and main_rows[0].split()[2] == "4"
    header = next(line for line in lines if "composes with" in line)
    start = header.index("composes with")
    table_rows = lines[lines.index(header) + 1:]
    assert len(table_rows) == len(ROTATIONS)
    for line in table_rows:  # aligned: each row's partner starts under the header
        name = line.split()[0]
        assert line[start:].startswith(", ".join(ROTATIONS[name].composes_with))
