"""Bad input at the command line: one line naming what, where and what is allowed, status 2; never a
traceback, a hang, a temporary file's name or a silent non-finite number. Each case is the command
line's ``main`` in this process (the console script's own path is tests/test_cli.py's)."""

import json
from pathlib import Path

import pytest
from helpers import OSCILLATOR_SCENE, oscillator_scene, run_main

#: scenes whose integrator's [simulation.<integrator>] table run refuses
BAD_TABLES = {
    "substeps0.toml": oscillator_scene("xpbd", "\n[simulation.xpbd]\nsubsteps = 0\n"),
    # a damper whose xpbd gamma = c / (k h) overflows: it ran and reported "diverged at step 1"
    "heavy-damper.toml": oscillator_scene("xpbd", '\n[[forces.dampers]]\nbodies = ["anchor", "mass"]\n'
                                                  'damping = 1e308\n'),
    "heavy-damper-vbd.toml": oscillator_scene("vbd", '\n[[forces.dampers]]\nbodies = ["anchor", "mass"]\n'
                                                      'damping = 1e104\n'),
    "foo.toml": oscillator_scene(table="\n[simulation.semi-implicit-euler]\nfoo = 1\n"),
}

#: scenes whose every number is finite but too large or too small for what a command computes from them
EXTREME_SCENES = {
    # 1/2 rho C_D pi r^2 of a 1e300 m ball overflows: was "Drag: beta must be finite, got inf", naming no file or key
    "drag-huge-radius.toml": OSCILLATOR_SCENE.read_text().replace("radius = 0.05\nposition = [1.5",
                                                                  "radius = 1e300\nposition = [1.5")
    + "\n[forces.drag]\n",
    # a 1e308 m ball: the plot window overflowed inside matplotlib ("arange: cannot compute length")
    "huge-ball.toml": OSCILLATOR_SCENE.read_text().replace("radius = 0.05\nposition = [1.5",
                                                           "radius = 1e308\nposition = [1.5"),
    # a static box near the float range: matplotlib's OverflowError, a traceback
    "huge-box.toml": '[simulation]\ndt = 0.01\nt_end = 0.1\n[[bodies]]\nname = "b"\nmass = 1.0\nradius = 0.1\n'
                     'position = [0, 0, 5]\n[collisions]\n[[collisions.boxes]]\ncenter = [0.0, 0.0, -1e308]\n'
                     'size = [1e308, 1e308, 1e308]\n',
    # a ball of 1e-154 m: 2/5 m r^2 = 4e-309 kg m^2 has no finite inverse (the contact solver's state went non-finite)
    "subnormal-inertia.toml": (OSCILLATOR_SCENE.parent / "rolling-sphere.toml").read_text()
    .replace("radius = 0.1", "radius = 1e-154"),
    # the input audit's fuzz (each of these was a traceback, a library's words, inf in the JSON or a silent 0):
    # a spring of 1.7e308 N/m on the hung box: its stiffness matrix is finite, K + K^T overflowed in check
    "stiff-hung-box.toml": (OSCILLATOR_SCENE.parent / "hung-box.toml").read_text()
    .replace("stiffness = 200.0", "stiffness = 1.7e308"),
    # the same spring on the spring pendulum's cube: LAPACK's "The algorithm failed to compute an eigenvalue ..."
    "stiff-pendulum.toml": (OSCILLATOR_SCENE.parent / "spring-pendulum.toml").read_text()
    .replace("stiffness = 1e5", "stiffness = 1.7e308"),
    # a damper of 1.7e308 N s/m: check printed "damping_ratio": Infinity (hung box), or 0, undamped (cloth)
    "heavy-damper-hung-box.toml": (OSCILLATOR_SCENE.parent / "hung-box.toml").read_text()
    .replace("damping = 2.0", "damping = 1.7e308"),
    "heavy-damper-cloth.toml": (OSCILLATOR_SCENE.parent / "cloth.toml").read_text()
    .replace("damping = 0.05", "damping = 1.7e308"),
    # a cloth 1e300 m out: check blamed "a spring with its ends at one point and a rest length > 0"
    "far-cloth.toml": (OSCILLATOR_SCENE.parent / "cloth.toml").read_text()
    .replace("origin = [0.0, 0.0, 2.0]", "origin = [1e300, 1e300, 1e300]"),
    # particles drawn 1e300 m out in a collision scene: the refusal named particles[0].position, no such key
    "far-particles.toml": (OSCILLATOR_SCENE.parent / "n-balls.toml").read_text()
    .replace("box_max = [1.0, 1.0, 2.0]", "box_max = [1e300, 1e300, 1e300]"),
    # a 1e-300 kg body on a spring in vbd: its 3x3 block's determinant underflowed to 0, a ZeroDivisionError
    "light-mass.toml": OSCILLATOR_SCENE.read_text().replace("mass = 1.0\nradius = 0.05\nposition = [1.5",
                                                            "mass = 1e-300\nradius = 0.05\nposition = [1.5"),
    # a damper of 1e300 N s/m between two balls: the implicit methods' linear solve is singular in float64, NumPy's
    # "Singular matrix" (status 2, naming nothing)
    "heavy-damper-cradle.toml": (OSCILLATOR_SCENE.parent / "newtons-cradle.toml").read_text()
    + '\n[[forces.dampers]]\nbodies = ["ball1", "ball2"]\ndamping = 1e300\n',
    # a rolling ball of inertia 1e-300 kg m^2: implicit-gyroscopic's 3 x 3 solve of a spin that overflowed
    # was a traceback (Numba's LinAlgError)
    "tiny-inertia-ball.toml": (OSCILLATOR_SCENE.parent / "rolling-sphere.toml").read_text()
    .replace('shape = "sphere"', 'shape = "sphere"\ninertia = [1e-300, 1e-300, 1e-300]'),
}

#: name -> (argv, what the one line of error says); the files are made in the fixture's folder
REFUSALS = {
    # 1: a --dt-max whose step count overflows (collision-free and with collisions)
    "recommend-dt-max-overflow": (["recommend", "projectile", "--tol", "0.01", "--dt-max", "1e-320"],
                                  "is below the smallest recommend measures"),
    "recommend-collisions-dt-max-overflow": (["recommend", "rolling-sphere", "--tol", "0.01", "--dt-max", "1e-320"],
                                             "is below the smallest recommend measures"),
    # 2: animate's step count: too small a dt, an uncountable span, a span beyond its step limit
    "animate-tiny-dt": (["animate", "projectile", "--dt", "1e-320", "--out", "o/a.gif"], "time would not advance"),
    "animate-huge-t-end": (["animate", "projectile", "--t-end", "1e308", "--out", "o/a.gif"], "--t-end|dt = "),
    "animate-long-run": (["animate", "projectile", "--t-end", "1e6", "--out", "o/a.gif"],
                         "exceed steplab animate's limit of 100000 steps"),
    "animate-fps-too-high": (["animate", "projectile", "--fps", "1000", "--out", "o/a.gif"],
                             "--fps must be an integer from 1 to 100"),
    # 3: check refuses the dts run refuses
    "check-dt-longer-than-run": (["check", "oscillator", "--dt", "1e308"], "is longer than the run"),
    "check-dt-too-small": (["check", "oscillator", "--dt", "1e-320"], "time would not advance"),
    # 4: the scene's integrator table, as run refuses it
    "check-bad-table": (["check", "substeps0.toml"], "[simulation.xpbd]"),
    "run-heavy-damper": (["run", "heavy-damper.toml"], "xpbd: the spring between bodies 0 and 1: its damping "
                         "1e+308 N s/m with compliance 0.0253303 m/N gives gamma = alpha c / h = inf at the substep "
                         "h = 0.01 s"),
    # vbd's 3x3 solve overflows long before gamma would: its Hessian block cubed (was "diverged at step 1")
    "run-heavy-damper-vbd": (["run", "heavy-damper-vbd.toml"], "vbd: body 1: its Hessian block (m / h^2 plus "
                             "2 k + c / h of each of its springs) reaches 1e+106 at the substep h = 0.01 s, past the "
                             "3.11e+102"),
    "run-heavy-damper-jax": (["run", "heavy-damper.toml", "--backend", "jax"],  # traced dt: checked before the run
                             "gives gamma = alpha c / h = inf at the substep h = 0.01 s"),
    "recommend-bad-table": (["recommend", "foo.toml", "--tol", "0.01"], "'foo' is not a setting"),
    "export-bad-table": (["export", "foo.toml", "--to", "mjcf"], "'foo' is not a setting"),
    "animate-bad-table": (["animate", "substeps0.toml", "--out", "o/a.gif"], "[simulation.xpbd]"),
    # 5: the contact solver steps with semi-implicit Euler: another candidate is refused in words that say so
    "recommend-solver-rk4": (["recommend", "rolling-sphere", "--tol", "0.01", "--integrators", "rk4"],
                             "steps with semi-implicit-euler only"),
    # 6: the path the user gave, never the temporary file's
    "export-out-folder": (["export", "projectile", "--to", "mjcf", "--out", "folder"], "folder: "),
    "run-out-unwritable": (["run", "projectile", "--out", "/proc/x.csv"], "/proc/x.csv: "),
    # 7: extreme but finite numbers in a scene: one line naming what overflows, never a library's words
    "run-drag-huge-radius": (["run", "drag-huge-radius.toml"], "drag-huge-radius.toml: forces.drag: the drag factor "
                             "1/2 rho C_D pi r^2 of body 'mass' (radius 1e+300 m"),
    "animate-huge-ball": (["animate", "huge-ball.toml", "--t-end", "0.05", "--out", "o/a.gif"],
                          "the picture's width would overflow float64"),
    "animate-huge-box": (["animate", "huge-box.toml", "--out", "o/a.gif"], "the picture's width would be 1.57e+308 m "
                         "across (the bodies with their radii, the static boxes and the attracting masses): animate "
                         "draws at most 1e+300 m"),
    "run-subnormal-inertia": (["run", "subnormal-inertia.toml"], "subnormal-inertia.toml: bodies[0]: the sphere's "
                              "principal moments [4e-309, 4e-309, 4e-309] kg m^2 are not each finite and at least "
                              "5.56e-309 kg m^2 (a smaller one has no finite inverse)"),
    # 8: the input audit: a run's end past float64 (it said "smaller than the float64 spacing nan s at t = inf s",
    # after a warning)
    "run-steps-end-overflow": (["run", "kepler", "--dt", "1.7e308", "--steps", "3"],
                               "3 steps of dt = 1.7e+308 s from t = 0 s end beyond the largest float64 time"),
    "run-steps-end-float32": (["run", "oscillator", "--precision", "float32", "--dt", "1e38", "--steps", "5"],
                              "t = 5e+38 s is beyond the largest float32 number, 3.40282e+38"),
    "check-stiff-hung-box": (["check", "stiff-hung-box.toml"], "the model's stiffest mode at its initial state "
                             "has no finite omega_max (inf: it overflows float64): a stiffness or damping too large"),
    "check-stiff-pendulum": (["check", "stiff-pendulum.toml"], "the model's stiffness, with its bodies turned, has "
                             "no eigenvalues LAPACK can compute in float64"),
    "check-heavy-damper-hung-box": (["check", "heavy-damper-hung-box.toml", "--json"],
                                    "has no finite damping ratio (inf: it overflows float64)"),
    "check-heavy-damper-cloth": (["check", "heavy-damper-cloth.toml"], "has no finite damping ratio"),
    "check-far-cloth": (["check", "far-cloth.toml"], "the initial state is non-finite or too large to integrate in "
                        "float64: body 'cloth[0]' has position [1e+300, 1e+300, 1e+300]"),
    "run-far-cloth": (["run", "far-cloth.toml"], "body 'cloth[0]' has position [1e+300, 1e+300, 1e+300]"),
    "run-far-particles": (["run", "far-particles.toml"], "far-particles.toml: particles[0]: body 'ball[0]': a "
                          "position of"),
    # position-based substeps: h = dt / substeps underflowing to 0 (a ZeroDivisionError traceback), alpha / h^2
    # overflowing (blamed on "its damping 0 N s/m"), a block whose determinant underflows (a ZeroDivisionError)
    "run-xpbd-substep-underflow": (["run", "oscillator", "--integrator", "xpbd", "--substeps", "2", "--dt", "5e-324",
                                    "--steps", "3"], "xpbd: dt = 4.94066e-324 s in 2 substeps gives the substep h = "
                                   "dt / substeps = 0 s (it underflows)"),
    "run-vbd-substep-underflow": (["run", "oscillator", "--integrator", "vbd", "--substeps", "2", "--dt", "5e-324",
                                   "--steps", "3"], "vbd: dt = 4.94066e-324 s in 2 substeps gives the substep h"),
    "run-xpbd-compliance-overflow": (["run", "oscillator", "--integrator", "xpbd", "--dt", "1e-300", "--steps", "3"],
                                     "xpbd: the spring between bodies 0 and 1: its compliance 0.0253303 m/N gives "
                                     "alpha / h^2 = inf at the substep h = 1e-300 s"),
    "run-vbd-light-body": (["run", "light-mass.toml", "--integrator", "vbd", "--steps", "3"],
                           "vbd: body 1: its inertia term m / h^2 = 1e-296 at the substep h = 0.01 s is below "
                           "2.81e-103"),
    "run-vbd-huge-dt": (["run", "oscillator", "--integrator", "vbd", "--dt", "1e300", "--steps", "3"],
                        "vbd: body 1: its inertia term m / h^2 = 0 at the substep h = 1e+300 s"),
    # the contact solver's substep h = dt / substeps underflowing to 0: Baumgarte's beta / h, a ZeroDivisionError
    "run-solver-substep-underflow": (["run", "box-column", "--dt", "5e-324", "--steps", "3"],
                                     "contact solver: the substep h = dt / substeps is 0 s (it underflows)"),
    # 9: a bench record whose ratio is not a finite number
    "bench-ratio-string": (["bench", "--from", "x.json"], "x.json: ratios."),
    "bench-ratio-nan": (["bench", "--from", "nan.json"], "nan.json: ratios."),
}

#: 5: valid requests on scenes with the contact solver, which a default rk4 reference refused
SOLVER_REQUESTS = {
    "recommend-solver-rolling-sphere": ["recommend", "rolling-sphere", "--tol", "0.01", "--integrators",
                                        "semi-implicit-euler"],
    "recommend-solver-box-column": ["recommend", "box-column", "--tol", "0.05", "--t-end", "1", "--integrators",
                                    "semi-implicit-euler"],
}


def _files(folder: Path) -> None:
    for name, text in {**BAD_TABLES, **EXTREME_SCENES}.items():
        (folder / name).write_text(text)
    (folder / "folder").mkdir()
    # a bench record's fields (read_record checks every ratio before anything is printed)
    record = {"order": ["vs_numba_semi_implicit_euler"], "seconds": {}, "targets": {},
              "ratios": {"vs_numba_semi_implicit_euler": "x"}}
    (folder / "x.json").write_text(json.dumps(record))
    record["ratios"] = {"vs_numba_semi_implicit_euler": float("nan")}
    (folder / "nan.json").write_text(json.dumps(record))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("refusals")
    _files(folder)
    return folder


def steplab(argv, folder, capsys, monkeypatch) -> tuple[int, str, str]:
    """``steplab *argv`` in this process, in ``folder``: (status, stdout, stderr)."""
    monkeypatch.chdir(folder)
    return run_main(capsys, argv)


@pytest.mark.parametrize("name", REFUSALS)
def test_bad_input_is_one_line_and_status_2(folder, capsys, monkeypatch, name):
    if name == "run-out-unwritable" and not Path("/proc").is_dir():
        pytest.skip("no /proc here")
    argv, message = REFUSALS[name]
    status, out, err = steplab(argv, folder, capsys, monkeypatch)
    assert status == 2, (status, out[-500:], err[-2000:])
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith(f"steplab {argv[0]}: error: "), err
    assert any(m in err for m in message.split("|")), err
    assert ".tmp" not in err and "nan" not in out.lower()


#: name -> (argv, what the one line says) of runs that blow up on legal but extreme input: status 1 (a failed run),
#: one line naming the step or the body (the input audit's fuzz: each was a traceback, or status 2 with the
#: broadphase's "centers must be finite", naming neither the run nor its step)
FAILED_RUNS = {
    "run-solver-dt-overflow": (["run", "box-column", "--dt", "1e300", "--steps", "3"],
                               "body 0 moved to [0.0, 0.0, -inf] m in the step, beyond the 1e+150 m the broadphase "
                               "squares without overflow: the run diverged"),
    "run-event-dt-overflow": (["run", "billiards", "--dt", "1e300", "--steps", "3"], "the run diverged"),
    "run-stiff-hung-box": (["run", "stiff-hung-box.toml", "--steps", "3"], "the contact solver's state became "
                           "non-finite"),
    "run-stiff-pendulum": (["run", "stiff-pendulum.toml", "--steps", "3"], "diverged with dt = 0.001 s"),
    "run-implicit-euler-singular": (["run", "heavy-damper-cradle.toml", "--integrator", "implicit-euler",
                                     "--detector", "none", "--steps", "3"], "integrator 'implicit-euler' diverged"),
    "run-implicit-damping-singular": (["run", "heavy-damper-cradle.toml", "--integrator", "implicit-damping-euler",
                                       "--detector", "none", "--steps", "3"],
                                      "integrator 'implicit-damping-euler' diverged"),
    "run-tiny-inertia-gyroscopic": (["run", "tiny-inertia-ball.toml", "--steps", "3", "--rotation",
                                     "implicit-gyroscopic"], "the contact solver's state became non-finite at "
                                    "body 'ball'"),
}


@pytest.mark.parametrize("name", FAILED_RUNS)
def test_a_run_that_blows_up_is_one_line_and_status_1(folder, capsys, monkeypatch, name):
    argv, message = FAILED_RUNS[name]
    status, out, err = steplab(argv, folder, capsys, monkeypatch)
    assert status == 1, (status, out[-500:], err[-2000:])
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert err.startswith("steplab run: error: ") and message in err, err


def test_a_scipy_reference_stops_at_its_step_budget(folder, capsys, monkeypatch):
    # 3 steps of dt = 1e300 s of the oscillator: solve_ivp, which has no step budget, never ended (diffrax stops at
    # its max_steps); the budget made small here so that the test takes a moment
    from steplab.integrators import references

    monkeypatch.setattr(references, "MAX_REFERENCE_STEPS", 1000)
    status, _, err = steplab(["run", "oscillator", "--integrator", "scipy-dop853", "--dt", "1e300", "--steps", "3"],
                             folder, capsys, monkeypatch)
    assert status == 1 and err.count("\n") == 1, err
    # its first 10,000 evaluations, the first look at its rate, reach some 30 s of the 3e300: hopeless, and said so
    assert "scipy-dop853 failed: it would need more than its budget of 1,000 steps" in err, err


def test_the_refusal_of_a_solver_candidate_names_what_is_allowed(folder, capsys, monkeypatch):
    _, _, err = steplab(REFUSALS["recommend-solver-rk4"][0], folder, capsys, monkeypatch)
    assert "not rk4" in err and "--integrators semi-implicit-euler" in err and "use integrator" not in err


@pytest.mark.parametrize("name", SOLVER_REQUESTS)
def test_recommend_takes_the_contact_solvers_integrator(folder, capsys, monkeypatch, name):
    status, out, err = steplab(SOLVER_REQUESTS[name], folder, capsys, monkeypatch)
    assert status == 0, err
    assert "semi-implicit-euler with dt = " in out and "contact solver" in out
