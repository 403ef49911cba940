"""The command line: outputs as a user sees them, and one-line errors with status 2."""

import json
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
    assert err.count("\n") == 1
    assert "'euler' diverged with dt = 0.5 s" in err and "step" in err and "t = " in err


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
    # scenes with collisions run them: the dropped ball bounces instead of falling through the floor
    drop = [r for r in rows if r["scene"] == "drop"]
    assert [r["backend"] for r in drop] == ["numpy"] and drop[0]["detector"] != "none"
    status, out, _ = run(capsys, "study", "scenes", "--quick", "--out", str(tmp_path))
    assert status == 0 and "scenes (cached)" in out
    status, out, _ = run(capsys, "study", "--list")
    assert {"truncation", "stability", "work_precision", "frame_rate", "scenes"} <= set(out.split())


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
    (["study", "nope"], "unknown study 'nope'"),
])
def test_more_bad_input_status_2(capsys, argv, message):
    with pytest.raises(SystemExit) as exit_:
        sys.exit(main(argv))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
