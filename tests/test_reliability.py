"""Reliability: invariants as property tests, determinism, crash-safe results, soak, edge cases.

Each section backs one guarantee of docs/guarantees.md, "What steplab guarantees". The property
tests draw random spring-mass systems with hypothesis (derandomised in the ``ci``
profile, tests/conftest.py); the crash tests kill real processes with SIGINT and SIGKILL
at seeded random moments. Nothing here asserts on wall-clock time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from steplab.integrators import INTEGRATORS, Stepper, simulate
from steplab.integrators.simulate import check_time_advances
from steplab.physics import Dampers, Drag, Friction, Gravity, Model, Springs
from steplab.physics.friction import CONTACT_DISTANCE, REST_SPEED
from steplab.physics.scene import parse_scene
from steplab.physics.soft_body import all_pairs
from steplab.studies import runner
from steplab.studies.plotting import plt, save_figure
from test_fuzz import toml_document, valid_scenes

FIXED_STEP = [name for name, method in INTEGRATORS.items() if isinstance(method, Stepper)]
EPS = np.finfo(float).eps
ROOT = Path(__file__).resolve().parent.parent


def examples(n: int) -> settings:
    return settings(max_examples=n * int(os.environ.get("STEPLAB_FUZZ_SCALE", "1")))


# --- random systems ---------------------------------------------------------------------------


@dataclasses.dataclass
class System:
    model: Model
    y0: np.ndarray
    masses: np.ndarray


@st.composite
def spring_systems(draw, damping=True, gravity=False, drag=False, coincident=True) -> System:
    """2-6 free bodies joined by random springs (and dampers), stretched, compressed and moving.

    With ``coincident``, one draw in two makes bodies 0 and 1 coincident: a zero-length
    spring with no direction, which exerts no force.
    """
    n = draw(st.integers(2, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    q = rng.uniform(-1, 1, (n, 3))
    if coincident and draw(st.booleans()):
        q[1] = q[0]
    v = rng.normal(size=(n, 3)) * draw(st.sampled_from([0.0, 0.1, 1.0, 5.0]))
    pairs = all_pairs(n)
    keep = rng.random(len(pairs)) < 0.7
    keep[0] = True
    i, j = pairs[keep].T
    rest = np.linalg.norm(q[j] - q[i], axis=1) * rng.uniform(0.5, 1.5, len(i)) + rng.uniform(0, 0.2, len(i))
    forces = [Springs(i, j, rng.uniform(1, 100, len(i)), rest)]
    if damping:
        forces.append(Dampers(i, j, rng.uniform(0, 5, len(i))))
    if gravity:
        forces.append(Gravity())
    masses = rng.uniform(0.2, 5, n)
    radii = np.full(n, 0.1)
    if drag:
        forces.append(Drag.from_coefficients(radii, density=50.0))
    return System(Model(masses, radii, forces), np.stack([q, v]), masses)


def run_steps(model, name, y, dt, n, t=0.0):
    """``n`` steps of a fixed-step method, every state returned (K + 1, 2, N, 3)."""
    method = INTEGRATORS[name]
    carry = method.init(model, t, y)
    states = [y]
    for k in range(n):
        y, carry = method.step(model, t + k * dt, y, dt, carry)
        states.append(y)
    return np.array(states)


# --- 1. momentum: internal forces and every fixed-step integrator conserve it -----------------


@examples(150)
@given(spring_systems(), st.floats(-3, 3))
def test_internal_forces_sum_to_zero_force_and_torque(system, scale):
    """Springs and dampers are pair forces: the net force and torque vanish to round-off."""
    q, v = system.y0
    v = v * scale
    f = system.model.net_force(0.0, q, v)
    magnitude = np.abs(f).sum() + 1.0
    assert np.all(np.abs(f.sum(axis=0)) <= 16 * EPS * magnitude)
    torque = np.cross(q, f).sum(axis=0)
    assert np.all(np.abs(torque) <= 16 * EPS * magnitude * (1 + np.abs(q).max()))


@pytest.mark.parametrize("name", FIXED_STEP)
@examples(25)
@given(system=spring_systems(), dt=st.sampled_from([0.001, 0.004, 0.01]))
def test_every_integrator_conserves_linear_momentum(name, system, dt):
    states = run_steps(system.model, name, system.y0, dt, 20)
    momentum = np.einsum("n,knc->kc", system.masses, states[:, 1])
    scale = np.einsum("n,knc->k", system.masses, np.abs(states[:, 1])).max() + 1.0
    assert np.all(np.isfinite(states))
    assert np.abs(momentum - momentum[0]).max() <= 8 * EPS * 20 * scale


# --- 2. energy: dissipative forces never add energy --------------------------------------------


@examples(150)
@given(spring_systems(drag=True), st.floats(-3, 3))
def test_dampers_and_drag_never_do_positive_work(system, scale):
    """The power F . V of dampers and of drag is <= 0 in every state (exactly: c (u.d)^2 >= 0)."""
    q, v = system.y0
    v = v * scale
    m = system.model.masses
    for force in system.model.forces:
        if isinstance(force, (Dampers, Drag)):
            f = force.force(np, q, v, m)
            assert np.sum(f * v) <= 16 * EPS * np.sum(np.abs(f * v))


@examples(150)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 8), mu=st.floats(0, 2), push=st.floats(-50, 50))
def test_sliding_ground_friction_never_does_positive_work(seed, n, mu, push):
    """Coulomb friction opposes sliding: the tangential part's power is <= 0 for sliding bodies
    (a body at rest, |V_t| <= REST_SPEED, may be nudged by up to mu_s |F_n| REST_SPEED)."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    radii = rng.uniform(0.05, 0.5, n)
    q = rng.normal(size=(n, 3))
    q += (0.0 + radii - q @ normal)[:, None] * normal  # every body touches the plane
    v = rng.normal(size=(n, 3)) + rng.normal(size=(n, 3)) * (rng.random((n, 1)) < 0.3) * 1e-7
    applied = rng.normal(size=(n, 3)) * 10 + push * normal
    friction = Friction(mu, 0.8 * mu, normal, 0.0, radii)
    f = friction.force(np, q, v, np.ones(n), applied)
    tangential = f - (f @ normal)[:, None] * normal
    v_t = v - (v @ normal)[:, None] * normal
    power = np.sum(tangential * v_t, axis=1)
    load = np.maximum(-(applied @ normal), 0)
    at_rest = np.linalg.norm(v_t, axis=1) <= REST_SPEED
    bound = np.where(at_rest, mu * load * REST_SPEED, 0) + 16 * EPS * np.abs(f).sum(axis=1) * (
        np.abs(v).sum(axis=1) + 1)  # round-off of projecting the support force out
    assert np.all(power <= bound)


@examples(100)
@given(stiffness=st.floats(1, 500), mass=st.floats(0.1, 10), zeta=st.floats(0, 3), dt=st.floats(1e-3, 2),
       amplitude=st.floats(-0.3, 0.3), speed=st.floats(-1, 1))
def test_implicit_euler_energy_never_increases_on_a_damped_spring(stiffness, mass, zeta, dt, amplitude, speed):
    """Backward Euler is dissipative on a linear (here: 1-D) spring-damper, at every dt:
    E_{n+1} = E_n - dt c v_{n+1}^2 - (m |dv|^2 + k |dx|^2) / 2 <= E_n. Checked step by step.

    The spring must stay linear: if the predictor q + dt v carries the mass through the
    anchor, Newton can find the mirror-image root (the spring flipped through zero length),
    whose energy is higher; so |v| dt and the amplitude are kept below the rest length."""
    import helpers

    damping = 2 * zeta * math.sqrt(stiffness * mass)
    omega = math.sqrt(stiffness / mass)
    velocity = speed * min(0.3 * omega, 0.3 / dt)  # |x - rest| < 0.6 and |v| dt < 0.3: length > 0.4
    problem = helpers.oscillator(stiffness=stiffness, mass=mass, damping=damping, amplitude=amplitude,
                                 velocity=velocity, direction=(1.0, 2.0, -2.0), with_exact=False)
    states = run_steps(problem.model, "implicit-euler", problem.y0, dt, 40)
    energy = np.array([problem.model.energy(y) for y in states])
    # the potential is computed from a length of 1 m, so it carries a round-off of about k |s| 4 eps (1 m):
    # the floor where the motion is tiny (|s| <= sqrt(2 E0 / k) while the energy falls; a 1e-15 m
    # amplitude's energy, 6e-31 J, moves by 1e-31 J either way)
    eps = np.finfo(float).eps
    floor = 4 * eps * stiffness * (math.sqrt(2 * energy[0] / stiffness) + eps)
    assert np.all(np.diff(energy) <= 1e-12 * energy[0] + floor)


# --- 3. time reversibility and symmetry --------------------------------------------------------


@pytest.mark.parametrize("name", ["velocity-verlet", "position-verlet"])
@examples(40)
@given(system=spring_systems(damping=False, gravity=True, coincident=False),
       dt=st.sampled_from([0.001, 0.003, 0.006]), n=st.integers(1, 80))
def test_verlet_is_time_reversible_on_random_spring_systems(name, system, dt, n):
    """Forward n steps, then n steps of -dt: back to the start to round-off (position forces).

    Not through coincident bodies: a spring of rest length > 0 has no force at zero length
    but a full one a round-off away, a discontinuity that no method can retrace."""
    forward = run_steps(system.model, name, system.y0, dt, n)
    back = run_steps(system.model, name, forward[-1], -dt, n, t=n * dt)
    scale = max(1.0, np.abs(forward).max())
    assert np.abs(back[-1] - system.y0).max() <= 1e-10 * scale


MIRROR = np.array([-1.0, 1.0, 1.0])  # reflection in the plane x = 0


@st.composite
def mirror_symmetric_soft_bodies(draw):
    """A soft body symmetric under x -> -x: pairs of mirrored vertices plus vertices on the
    plane, all-pairs springs and dampers, gravity, drag and a ground plane with friction."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    h, c = draw(st.integers(1, 3)), draw(st.integers(0, 2))
    half = rng.uniform([0.1, -1.0, 0.2], [1.0, 1.0, 2.0], (h, 3))
    plane = rng.uniform([0.0, -1.0, 0.2], [0.0, 1.0, 2.0], (c, 3))
    q = np.concatenate([half, half * MIRROR, plane])
    v_half = rng.normal(size=(h, 3))
    v_plane = rng.normal(size=(c, 3)) * MIRROR * [0, 1, 1]
    v = np.concatenate([v_half, v_half * MIRROR, v_plane])
    m_half = rng.uniform(0.2, 2, h)
    masses = np.concatenate([m_half, m_half, rng.uniform(0.2, 2, c)])
    mirror = np.concatenate([np.arange(h) + h, np.arange(h), 2 * h + np.arange(c)])
    n = len(q)
    i, j = all_pairs(n).T
    rest = 0.9 * np.linalg.norm(q[j] - q[i], axis=1)
    radii = np.full(n, 0.05)
    forces = [Springs(i, j, np.full(len(i), 40.0), rest), Dampers(i, j, np.full(len(i), 0.3)), Gravity(),
              Drag.from_coefficients(radii)]
    ground = Friction(0.5, 0.3, np.array([0.0, 0.0, 1.0]), 0.0, radii)
    return masses, radii, forces, ground, np.stack([q, v]), mirror


@pytest.mark.parametrize("name", FIXED_STEP)
@examples(12)
@given(scene=mirror_symmetric_soft_bodies())
def test_a_mirror_symmetric_scene_stays_symmetric(name, scene):
    masses, radii, forces, ground, y0, mirror = scene
    # implicit Euler's Newton iteration does not converge once a body lands on the friction
    # ground (a non-smooth force with a frozen Jacobian): the run reports divergence
    model = Model(masses, radii, forces + ([ground] if name != "implicit-euler" else []))
    dt = 0.005
    states = run_steps(model, name, y0, dt, 60)
    if name != "implicit-euler":
        states = states[:before_sliding_stops(states, Model(masses, radii, forces), ground, dt)]
    scale = max(1.0, np.abs(states).max())
    asymmetry = np.abs(states[:, :, mirror] * MIRROR - states).max()
    assert asymmetry <= 1e-10 * scale


def before_sliding_stops(states, applied, ground, dt) -> int:
    """The number of states before a body pressed on the ground slides slower than two steps of sliding
    friction take away (mu_d a_n 2 dt). There sliding friction's direction, -v_t / |v_t|, turns
    within a step (or a stage) through v_t = 0, where the round-off in v_t picks it: a 1e-17 m/s
    difference between mirror images becomes one of mu_d a_n dt (the discontinuity of Coulomb
    friction, which no ordering of the arithmetic makes symmetric). ``applied``: the model without
    the ground, whose acceleration presses the bodies on it."""
    n = ground.normal
    for k, (q, v) in enumerate(states):
        pressing = -(np.asarray(applied.acceleration(0.0, q, v)) @ n)
        on = (q @ n - ground.height - ground.radii <= CONTACT_DISTANCE) & (pressing > 0)
        sliding = np.linalg.norm(v - (v @ n)[:, None] * n, axis=1)
        if np.any(on & (sliding <= ground.mu_dynamic * pressing * 2 * dt)):
            return k
    return len(states)


# --- 4. determinism ---------------------------------------------------------------------------


def trajectory_bytes(scene_text: str, suffix: str, tmp: Path, *argv):
    """(exit status, the trajectory file's bytes or None)."""
    from steplab.cli import main

    path, out = tmp / "scene.toml", tmp / f"t{suffix}"
    path.write_text(scene_text)
    with contextlib.redirect_stderr(io.StringIO()):
        status = main(["run", str(path), "--max-steps", "100", "--out", str(out), "--json", *argv])
    data = out.read_bytes() if out.exists() else None
    out.unlink(missing_ok=True)
    return status, data


@examples(40)
@given(doc=valid_scenes())
def test_same_scene_same_bytes_in_process(doc, tmp_path_factory):
    """Any valid scene, run twice: byte-identical NPZ and CSV (seeded particles included),
    or the same failure (a diverging run) both times."""
    tmp = tmp_path_factory.mktemp("det")
    text = toml_document(doc)
    with contextlib.redirect_stdout(io.StringIO()):
        for suffix in (".npz", ".csv"):
            first = trajectory_bytes(text, suffix, tmp)
            assert first == trajectory_bytes(text, suffix, tmp)
            assert (first[0] == 0) == (first[1] is not None)


def test_same_scene_same_bytes_across_processes(tmp_path):
    """Two fresh processes (different hash seeds, fresh JAX compilations) write the same bytes,
    and the same bytes as this process: CSV and NPZ, NumPy and JAX, seeded particles."""
    from steplab.cli import main

    runs = [("n-balls", ".csv", "numpy"), ("n-balls", ".npz", "numpy"), ("soft-cube", ".npz", "jax")]

    def argv(folder, scene, suffix, backend):
        return ["run", scene, "--t-end", "0.3", "--backend", backend, "--json", "--out",
                str(folder / f"{scene}-{backend}{suffix}")]

    code = ("import contextlib, io, sys\nfrom steplab.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    sys.exit(max(main(a) for a in %r))\n")
    for k in range(2):
        folder = tmp_path / f"process{k}"
        arguments = [argv(folder, *run) for run in runs]
        done = subprocess.run([sys.executable, "-c", code % (arguments,)], capture_output=True, cwd=ROOT,
                              env=dict(os.environ, PYTHONHASHSEED=str(k + 1)), timeout=600)
        assert done.returncode == 0, done.stderr
    here = tmp_path / "here"
    with contextlib.redirect_stdout(io.StringIO()):
        assert max(main(argv(here, *run)) for run in runs) == 0
    for scene, suffix, backend in runs:
        name = f"{scene}-{backend}{suffix}"
        files = [(tmp_path / folder / name).read_bytes() for folder in ("process0", "process1", "here")]
        assert files[0] == files[1] == files[2], name


#: NumPy and JAX runs of the same model agree to this, relative to the largest state component
#: (measured: at most 4 eps ~ 1e-15 after 20 steps; XLA reorders and fuses the arithmetic)
BACKEND_RTOL = 1e-12


@examples(8)
@given(system=spring_systems(gravity=True, drag=True), name=st.sampled_from(FIXED_STEP))
def test_numpy_and_jax_agree_to_the_documented_tolerance(system, name):
    a = simulate(system.model, name, system.y0, 0.0, 0.1, 0.005)
    b = simulate(system.model, name, system.y0, 0.0, 0.1, 0.005, backend="jax")
    assert_array_equal(a.t, b.t)
    assert np.abs(a.y - b.y).max() <= BACKEND_RTOL * np.abs(a.y).max()


# --- 5. crash-safe results --------------------------------------------------------------------

TOY_SCRIPT = textwrap.dedent("""
    import os
    import sys

    import numpy as np

    from steplab import studies
    from steplab.integrators import simulate
    from steplab import cli
    from steplab.studies import runner
    from steplab.studies.plotting import plt, save_figure
    from steplab.studies.problems import oscillator_problem


    def make(k):
        def parameters(quick):
            return {"k": k, "t_end": 2.0 if quick else 4.0}

        def compute(params, progress=None):
            p = oscillator_problem(t_end=params["t_end"])
            traj = simulate(p.model, "rk4", p.y0, 0.0, params["t_end"], 0.002 * (1 + k % 3))
            return {"x": traj.positions[::25, 1, 0].tolist()}

        def plot(record, out):
            fig, ax = plt.subplots()
            ax.plot(record["x"])
            return save_figure(fig, out, f"toy{k}")

        return runner.Study(f"toy{k}", f"toy study {k}", parameters, compute, plot)


    studies.STUDIES.clear()
    studies.STUDIES.update({s.name: s for s in map(make, range(int(sys.argv[2])))})
    print("ready", flush=True)
    status = cli.main(["reproduce", "--quick", "--out", sys.argv[1]])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # no interpreter tear-down, where a late SIGINT would kill silently
""")


def start(argv, script=None):
    """A process that prints "ready" just before ``steplab.cli.main`` runs and exits as soon as
    it returns, so a signal lands inside steplab, not in Python's start-up or tear-down (where
    Python itself handles it: a traceback, or a silent death by SIGINT)."""
    code = script or ("import os, sys\nfrom steplab.cli import main\nprint('ready', flush=True)\n"
                      f"status = main({argv!r})\nsys.stdout.flush()\nsys.stderr.flush()\nos._exit(status)\n")
    process = subprocess.Popen([sys.executable, "-c", code, *(argv if script else [])], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, cwd=ROOT)
    assert process.stdout.readline() == b"ready\n"
    return process


def assert_results_consistent(folder: Path):
    """Every JSON record parses, is complete, and names figures that exist and are whole."""
    for path in folder.glob("*.json"):
        record = json.loads(path.read_text())
        assert record["study"] == path.stem and record["cache_key"]
        for figure in record["figures"]:
            assert (folder / figure).is_file(), figure
    for png in folder.glob("*.png"):
        assert png.read_bytes().endswith(b"IEND\xaeB`\x82"), png  # the PNG end chunk
    for svg in folder.glob("*.svg"):
        assert svg.read_bytes().rstrip().endswith(b"</svg>"), svg


def comparable(record: dict) -> dict:
    """A record without what may differ between equal runs: provenance (dates), whether it
    came from the cache, and the cache key (it hashes the source, which may be edited meanwhile)."""
    return {k: v for k, v in record.items() if k not in ("provenance", "cached", "cache_key")}


def folder_contents(folder: Path) -> dict:
    out = {}
    for path in sorted(folder.iterdir()):
        data = path.read_bytes()
        if path.suffix == ".json":
            out[path.name] = comparable(json.loads(data))
        else:
            out[path.name] = hashlib.sha256(data).hexdigest()
    return out


TOYS = 6


@pytest.fixture(scope="module")
def toy_reference(tmp_path_factory):
    """An uninterrupted ``steplab reproduce`` of the toy studies, and the script."""
    tmp = tmp_path_factory.mktemp("toy")
    script = tmp / "toy.py"
    script.write_text(TOY_SCRIPT)
    process = start([str(tmp / "reference"), str(TOYS)], TOY_SCRIPT)
    started = time.perf_counter()
    assert process.wait(timeout=600) == 0, process.stderr.read()
    duration = time.perf_counter() - started  # only to place the kills inside the run
    return folder_contents(tmp / "reference"), duration


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_reproduce_killed_at_random_moments_leaves_whole_files_and_resumes(sig, toy_reference, tmp_path):
    reference, duration = toy_reference
    rng = np.random.default_rng(8 + int(sig))
    out = tmp_path / "results"
    interrupted = 0
    for delay in rng.uniform(0.02, 0.3, size=3) * duration:
        if out.exists() and len(list(out.glob("*.json"))) == TOYS:
            shutil.rmtree(out)  # a run that finished leaves nothing to interrupt: start afresh
        process = start([str(out), str(TOYS)], TOY_SCRIPT)
        time.sleep(delay)
        process.send_signal(sig)
        status = process.wait(timeout=600)
        err = process.stderr.read().decode()
        if sig == signal.SIGINT and status != 0:  # (0: it finished first)
            assert status == 130 and err == "steplab reproduce: error: interrupted\n", (status, err)
        elif sig == signal.SIGKILL:
            assert status in (-signal.SIGKILL, 0)
        interrupted += status != 0
        if out.exists():
            assert_results_consistent(out)
    # the delays are early fractions of a whole run, and every attempt has work left: at least
    # one lands inside a run (the machine's load only ever makes a run longer than "early")
    assert interrupted
    # the next run cleans up, resumes (what was complete is cached) and gives the same results
    process = start([str(out), str(TOYS)], TOY_SCRIPT)
    stdout = process.stdout.read().decode()
    assert process.wait(timeout=600) == 0
    assert not list(out.glob(".*.tmp"))
    assert folder_contents(out) == reference
    assert stdout.count("(computed)") + stdout.count("(cached)") == TOYS


def test_interrupted_run_prints_one_line_and_writes_no_file(tmp_path):
    """Ctrl-C in the middle of ``steplab run --out``: status 130, one line, no trajectory file."""
    out = tmp_path / "t.csv"
    process = start(["run", "projectile", "--dt", "1e-6", "--save-every", "1000", "--out", str(out)])
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    status, err = process.wait(timeout=600), process.stderr.read()
    assert status == 130, err.decode(errors="replace")[-3000:]
    assert err == b"steplab run: error: interrupted\n"
    assert not list(tmp_path.iterdir())


def test_a_ctrl_c_that_lands_in_a_garbage_collection_callback_is_not_lost(tmp_path):
    """Python drops a KeyboardInterrupt raised inside a gc callback ("Exception ignored"); JAX runs
    one at every collection, so a Ctrl-C landing there used to let the run go on to status 0.
    Here a callback holds the first collection for 2 s and the Ctrl-C lands in it, every time."""
    out = tmp_path / "t.csv"
    argv = ["run", "projectile", "--dt", "1e-6", "--save-every", "1000", "--out", str(out)]
    code = ("import gc, os, sys, time\nfrom steplab.cli import main\nheld = []\n"
            "def hold(phase, info):\n"
            "    if phase == 'start' and not held:\n"
            "        held.append(1)\n        print('ready', flush=True)\n        time.sleep(2.0)\n"
            "gc.callbacks.append(hold)\ngc.collect()\nheld.clear()\nsys.stdout.write('')\n"
            f"status = main({argv!r})\nsys.stderr.flush()\nos._exit(status)\n")
    process = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    assert process.stdout.readline() == b"ready\n"  # the collection before main: let it pass
    assert process.stdout.readline() == b"ready\n"  # a collection inside main, held
    process.send_signal(signal.SIGINT)
    status, err = process.wait(timeout=600), process.stderr.read()
    assert status == 130, err.decode(errors="replace")[-3000:]  # what went wrong, where it did (once, under load)
    assert err == b"steplab run: error: interrupted\n"  # the dropped one is not printed
    assert not out.exists()


def test_temporary_files_of_a_killed_run_are_removed_when_the_next_run_starts(tmp_path):
    def compute(params, progress=None):
        return {"value": 1}

    def plot(record, out):
        fig, ax = plt.subplots()
        ax.plot([0, 1])
        return save_figure(fig, out, "t")

    study = runner.Study("t", "t", lambda quick: {}, compute, plot)
    tmp_path.mkdir(exist_ok=True)
    stale = [tmp_path / ".t.json.k2j3h4g5.tmp", tmp_path / ".t.png.abc_1234.tmp", tmp_path / ".other.svg.x.tmp"]
    for path in stale:
        path.write_bytes(b"half a fi")
    keep = tmp_path / "notes.tmp"
    keep.write_text("not ours")
    runner.run_study(study, tmp_path)
    assert not any(path.exists() for path in stale) and keep.exists()
    assert runner.run_study(study, tmp_path)["cached"]


def test_corrupt_or_foreign_records_are_recomputed_not_trusted(tmp_path):
    calls = []

    def compute(params, progress=None):
        calls.append(1)
        return {"value": 2}

    study = runner.Study("s", "s", lambda quick: {"a": 1}, compute, lambda record, out: [])
    for text in ("", "{", "[]", "null", '{"cache_key": 5}', '{"figures": [1]}', "\xff"):
        (tmp_path / "s.json").write_bytes(text.encode("latin-1"))
        assert not runner.is_cached(study, tmp_path, quick=False)
    runner.run_study(study, tmp_path)
    record = json.loads((tmp_path / "s.json").read_text())
    record["figures"] = [{"not": "a name"}]
    (tmp_path / "s.json").write_text(json.dumps(record))
    assert not runner.run_study(study, tmp_path)["cached"] and len(calls) == 2


def test_cache_key_follows_the_source_code(tmp_path):
    """Editing any .py or .toml of physics, integrators or studies changes the key; caches do not."""
    for package in runner.SOURCE_PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    before = runner.source_hash(tmp_path)
    assert before == runner.source_hash(tmp_path) == runner.source_hash(ROOT)
    (tmp_path / "physics" / "__pycache__").mkdir(exist_ok=True)
    (tmp_path / "physics" / "__pycache__" / "x.pyc").write_bytes(b"\0")
    assert runner.source_hash(tmp_path) == before
    springs = tmp_path / "physics" / "springs.py"
    springs.write_text(springs.read_text() + "\n# a comment is a change\n")
    assert runner.source_hash(tmp_path) != before
    springs.write_text((ROOT / "physics" / "springs.py").read_text())
    assert runner.source_hash(tmp_path) == before
    scene = next((tmp_path / "physics" / "scenes").glob("*.toml"))
    scene.write_text(scene.read_text() + "\n")
    assert runner.source_hash(tmp_path) != before


def test_a_study_key_follows_only_the_study_modules_it_uses(tmp_path):
    """Editing one study's module re-runs that study, not the others; a shared module re-runs all users."""
    from steplab.studies import STUDIES

    for package in runner.SOURCE_PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    stability, frame_rate = (runner.study_modules(STUDIES[name]) for name in ("stability", "frame_rate"))
    assert {"steplab.studies.stability", "steplab.studies.stiffness", "steplab.studies.extremes",
            "steplab.studies.problems"} <= stability
    assert "steplab.studies.stiffness" not in frame_rate and "steplab.studies.problems" in frame_rate

    def keys():
        return runner.source_hash(tmp_path, stability), runner.source_hash(tmp_path, frame_rate)

    before = keys()
    assert before == (runner.source_hash(ROOT, stability), runner.source_hash(ROOT, frame_rate))
    for module, changes in (("stiffness", (True, False)), ("problems", (True, True))):
        path = tmp_path / "studies" / f"{module}.py"
        path.write_text(path.read_text() + "\n# an edit\n")
        assert tuple(a != b for a, b in zip(keys(), before)) == changes
        path.write_text((ROOT / "studies" / f"{module}.py").read_text())


def test_real_study_killed_then_resumed_matches_a_clean_computation(tmp_path):
    """``steplab study frame_rate --quick`` (a real study with figures): SIGKILL, SIGINT, resume."""
    from steplab.studies import frame_rate

    out = tmp_path / "results"
    argv = ["study", "frame_rate", "--quick", "--out", str(out)]
    rng = np.random.default_rng(4000)
    process = start(argv)
    time.sleep(rng.uniform(0.5, 3.0))
    process.kill()
    process.wait(timeout=600)
    if out.exists():
        assert_results_consistent(out)
    process = start(argv)
    time.sleep(rng.uniform(0.5, 3.0))
    process.send_signal(signal.SIGINT)
    status, err = process.wait(timeout=600), process.stderr.read().decode()
    assert (status, err) in ((130, "steplab study: error: interrupted\n"), (0, "")), (status, err)
    if out.exists():
        assert_results_consistent(out)
    done = subprocess.run([str(Path(sys.executable).parent / "steplab"), *argv], capture_output=True, timeout=600)
    assert done.returncode == 0 and not list(out.glob(".*.tmp"))
    record = json.loads((out / "frame_rate.json").read_text())
    clean = frame_rate.compute(frame_rate.parameters(True))
    assert {k: record[k] for k in clean} == json.loads(json.dumps(clean))
    clean_out = tmp_path / "clean"
    clean_out.mkdir()
    frame_rate.plot(record, clean_out)
    for figure in record["figures"]:
        assert (out / figure).read_bytes() == (clean_out / figure).read_bytes()
    # and the next run takes the resumed record from the cache (in this process: what it reads is on disk)
    from steplab.cli import main

    with contextlib.redirect_stdout(io.StringIO()) as again, contextlib.redirect_stderr(io.StringIO()):
        assert main(argv) == 0
    assert "frame_rate (cached)" in again.getvalue()


def test_svg_figures_are_byte_identical(tmp_path):
    for k in range(2):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [1, 0])
        save_figure(fig, tmp_path / str(k), "f")
    assert (tmp_path / "0" / "f.png").read_bytes() == (tmp_path / "1" / "f.png").read_bytes()
    assert (tmp_path / "0" / "f.svg").read_bytes() == (tmp_path / "1" / "f.svg").read_bytes()


# --- 6. soak ----------------------------------------------------------------------------------


def energy_error_envelope(n_steps: int, integrator: str = "velocity-verlet"):
    """Run the oscillator scene ``n_steps`` with one compiled loop that tracks the extreme
    relative energy errors (E - E0) / E0 at every step; returns (lowest, highest, final state)."""
    import jax
    import jax.numpy as jnp
    from jax import lax
    from steplab.physics.scene import load_scene

    scene = load_scene("oscillator")
    model = scene.model.cast(jnp, np.float64)
    method = INTEGRATORS[integrator]

    def run(y0, dt):
        e0 = model.energy(y0)

        def body(k, state):
            y, carry, low, high = state
            y, carry = method.step(model, k * dt, y, dt, carry)
            error = (model.energy(y) - e0) / e0
            return y, carry, jnp.minimum(low, error), jnp.maximum(high, error)

        zero = jnp.zeros((), y0.dtype)
        y, _, low, high = lax.fori_loop(0, n_steps, body, (y0, method.init(model, 0.0, y0), zero, zero))
        return low, high, y

    low, high, y = jax.jit(run)(jnp.asarray(scene.y0), scene.dt)
    omega = math.sqrt(float(scene.model.forces[0].stiffness[0]) / float(scene.model.masses[1]))
    return float(low), float(high), np.asarray(y), omega * scene.dt


def check_verlet_energy_bound(n_steps):
    low, high, y, omega_dt = energy_error_envelope(n_steps)
    # velocity Verlet on a harmonic oscillator: the energy error oscillates in
    # [-(omega dt)^2 / 4, 0] E0 (it conserves a modified energy exactly), plus round-off.
    bound = omega_dt**2 / 4
    assert -bound * (1 + 1e-6) - 1e-11 <= low <= -bound * (1 - 1e-3)
    assert 0 <= high <= 1e-11
    assert np.all(np.isfinite(y))
    return low, high


def test_verlet_energy_error_bounded_short():
    """10^5 steps (the soak test's machinery, in the default run)."""
    check_verlet_energy_bound(10**5)


@pytest.mark.slow
def test_soak_ten_million_verlet_steps_keep_the_energy_error_bounded():
    """10^7 steps of velocity Verlet on the oscillator (10^5 s, 10^5 periods): the relative
    energy error stays within [-(omega dt)^2/4 - 1e-11, 1e-11]; measured: [-9.8696044e-4, 5.1e-13]."""
    low, high = check_verlet_energy_bound(10**7)
    print(f"velocity Verlet, oscillator, 10^7 steps: relative energy error in [{low:.10g}, {high:.3g}]")


# --- 7. numerical edge cases ------------------------------------------------------------------


@pytest.mark.parametrize("name", FIXED_STEP)
def test_subnormal_states_stay_finite_with_no_division_by_zero(name):
    """Distances and speeds in the subnormal range: lengths underflow to zero, so springs,
    dampers and drag treat the bodies as coincident or at rest: finite, no 0/0."""
    tiny = 1e-310
    q = np.array([[0.0, 0.0, 0.0], [tiny, 0.0, 0.0], [0.0, 3 * tiny, -tiny]])
    v = np.array([[tiny, 0.0, 0.0], [0.0, 0.0, -2 * tiny], [0.0, 0.0, 0.0]])
    i, j = all_pairs(3).T
    radii = np.full(3, 0.1)
    model = Model([1.0, 2.0, 3.0], radii, [Springs(i, j, np.full(3, 10.0), np.array([0.0, tiny, 1.0])),
                                           Dampers(i, j, np.full(3, 1.0)), Drag.from_coefficients(radii)])
    with np.errstate(divide="raise", invalid="raise"):
        traj = simulate(model, name, np.stack([q, v]), 0.0, 0.1, 0.01)
    assert np.all(np.isfinite(traj.y))
    # the spring with rest length 1 between (near-)coincident bodies has no direction: no force
    assert_allclose(traj.y[-1], traj.y[0] + [traj.y[0, 1] * 0.1, np.zeros((3, 3))], rtol=0, atol=1e-320)


@pytest.mark.parametrize("name", FIXED_STEP)
def test_coincident_particles_in_springs_stay_finite_and_together(name):
    scene = parse_scene("""
[simulation]
dt = 0.01
t_end = 0.3
[[soft_bodies]]
name = "c"
shape = "mesh"
vertices = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.5]]
mass = 4.0
stiffness = 50.0
damping = 0.5
velocity = [0.3, 0.0, 0.0]
[[bodies]]
name = "a"
mass = 1.0
radius = 0.1
position = [2.0, 0.0, 1.0]
[[bodies]]
name = "b"
mass = 1.0
radius = 0.1
position = [2.0, 0.0, 1.0]
[[forces.springs]]
bodies = ["a", "b"]
stiffness = 10.0
rest_length = 0.0
[[forces.dampers]]
bodies = ["a", "b"]
damping = 1.0
[forces.gravity]
""")
    with np.errstate(divide="raise", invalid="raise"):
        traj = simulate(scene.model, name, scene.y0, 0.0, 0.3, 0.01)
    assert np.all(np.isfinite(traj.y))
    a, b, c0, c1 = (scene.model.names.index(name) for name in ("a", "b", "c[0]", "c[1]"))
    # vertices c[0] and c[1] coincide and feel identical forces: they move together
    assert_allclose(traj.positions[:, c0], traj.positions[:, c1], rtol=0, atol=1e-14)
    # a and b coincide at their spring's rest length 0: no force, no 0/0 in its direction
    # (with a rest length > 0 the file is refused: the spring would push along no direction;
    # tests/test_cli_refusals_fringe.py)
    assert_array_equal(traj.positions[:, a], traj.positions[:, b])


@examples(200)
@given(t_start=st.floats(-1e12, 1e12), dtype=st.sampled_from([np.float64, np.float32]), k=st.integers(1, 20))
def test_smallest_dt_that_advances_time_is_accepted_and_a_smaller_one_refused(t_start, dtype, k):
    """dt below the float spacing at the run's largest |t| is refused (t + dt == t would stand
    still); the smallest accepted dt advances time at every step, in the run's precision."""
    t_start = float(dtype(t_start))
    dt = float(np.spacing(dtype(2 * abs(t_start) + 1e-30)))  # the spacing at every |t| of the run
    t_end = t_start + k * dt
    check_time_advances(t_start, t_end, dt, dtype)
    model = Model([1.0], [0.1], [], dtype=dtype)  # no forces: only time matters here
    traj = simulate(model, "semi-implicit-euler", np.zeros((2, 1, 3)), t_start, t_end, dt, dtype=dtype)
    assert traj.steps >= 1
    times = t_start + np.arange(traj.steps + 1) * dt
    assert np.all(np.diff(times.astype(dtype)) > 0)
    far = max(abs(t_start), abs(t_end))
    tiny = float(np.nextafter(dtype(np.spacing(dtype(far))), dtype(0)))  # just below the spacing
    if tiny > 0:
        with pytest.raises(ValueError, match="time would not advance"):
            simulate(model, "euler", np.zeros((2, 1, 3)), t_start, t_end, tiny, dtype=dtype, max_steps=10**30)


def test_time_resolution_in_examples():
    """The documented cases: at t = 0 even the smallest subnormal dt advances time."""
    model = Model([1.0], [0.1], [Gravity()])
    traj = simulate(model, "euler", np.zeros((2, 1, 3)), 0.0, 10 * 5e-324, 5e-324)
    assert traj.steps == 10 and np.all(np.diff(traj.t) > 0)
    with pytest.raises(ValueError, match=r"dt = 1e-07 s is smaller than the float64 spacing 1.9\d*e-06 s at t = 1e"):
        simulate(model, "euler", np.zeros((2, 1, 3)), 1e10, 1e10 + 1e-6, 1e-7)
    with pytest.raises(ValueError, match="float32 spacing"):
        simulate(model, "euler", np.zeros((2, 1, 3)), 1000.0, 1000.001, 1e-5, dtype=np.float32)
    simulate(model, "euler", np.zeros((2, 1, 3)), 1000.0, 1000.001, 1e-5)  # fine in float64


# --- 8. collisions and broadphase ---------------------------------------------------------------


@st.composite
def ball_sets(draw, n_max=10):
    """2-10 free balls (no forces) with random masses, radii and speeds from 0.1 to 100 m/s;
    one draw in four puts two of them at the same centre."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(2, n_max))
    q = rng.uniform(-1, 1, (n, 3))
    if draw(st.integers(0, 3)) == 3:
        q[1] = q[0]
    v = rng.normal(size=(n, 3)) * draw(st.sampled_from([0.1, 1.0, 10.0, 100.0]))
    return Model(rng.uniform(0.1, 10, n), rng.uniform(0.02, 0.25, n)), np.stack([q, v])


def box_of_planes(half: float = 2.0):
    """Six walls, the room [-half, half]^3 (a plane is the solid half-space normal . x <= offset)."""
    from steplab.physics.collision import Plane

    return tuple(Plane(sign * np.eye(3)[k], -half, name=f"wall{k}{'+' if sign > 0 else '-'}")
                 for k in range(3) for sign in (1.0, -1.0))


@examples(40)
@given(balls=ball_sets(), detector=st.sampled_from(["swept", "overlap"]), eps=st.floats(0, 1),
       friction=st.sampled_from([0.0, 0.4]))
def test_collisions_between_bodies_conserve_momentum(balls, detector, eps, friction):
    from steplab.physics.collision import CollisionWorld, PairProperties

    model, y0 = balls
    world = CollisionWorld(detector, pair_properties=PairProperties(eps, friction))
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, 0.2, 0.005, collisions=world)
    m = np.asarray(model.masses)[:, None]
    momentum = (m * traj.velocities).sum(axis=1)
    assert np.all(np.isfinite(traj.y))
    assert np.abs(momentum - momentum[0]).max() <= 1e-13 * np.abs(m * y0[1]).sum()


@examples(40)
@given(balls=ball_sets(), detector=st.sampled_from(["swept", "overlap"]), eps=st.floats(0, 1),
       friction=st.sampled_from([0.0, 0.4]))
def test_collisions_with_eps_at_most_one_never_add_energy(balls, detector, eps, friction):
    """Balls bouncing off each other and the six walls of a room: with no forces the motion
    between collisions is exact, so the kinetic energy may only fall (eps < 1, friction)."""
    from steplab.physics.collision import CollisionWorld, PairProperties

    model, y0 = balls
    world = CollisionWorld(detector, box_of_planes(), pair_properties=PairProperties(eps, friction))
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, 0.2, 0.005, collisions=world)
    energy = np.array([float(model.kinetic_energy(v)) for v in traj.velocities])
    assert np.all(np.isfinite(energy))
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])


@examples(60)
@given(exponent=st.floats(-2, 7), angle=st.floats(0, 60), turn=st.floats(-90, 90), radius=st.floats(1e-3, 0.5),
       thickness=st.floats(1e-4, 0.1), dt=st.sampled_from([1e-3, 1e-2, 0.05]), phase=st.floats(0.01, 0.99),
       wall=st.sampled_from(["plane", "box", "oriented-box"]), eps=st.floats(0, 1))
def test_swept_detection_never_lets_a_sphere_through_a_wall(exponent, angle, turn, radius, thickness, dt, phase,
                                                            wall, eps):
    """At any speed (1 cm/s to 10^7 m/s), any angle, any wall thickness: the centre never
    gets past the wall's near face. (Overlap testing misses such walls: test_collisions.py.)"""
    from steplab.physics.collision import Box, CollisionWorld, OrientedBox, PairProperties, Plane, rotation_matrix

    speed = 10.0**exponent
    rotation = rotation_matrix([0.0, 0.0, 1.0], turn)
    normal = rotation[:, 0]  # the wall's outward normal on the ball's side is -normal
    half = 0.5 * thickness if wall != "plane" else 0.0
    if wall == "plane":
        shape = Plane(-normal, 0.0, name="wall")  # solid where -normal . x <= 0: the far side
    elif wall == "box":
        rotation, normal = np.eye(3), np.array([1.0, 0.0, 0.0])
        shape = Box.from_center([0.0, 0.0, 0.0], [thickness, 1e12, 1e12], name="wall")
    else:
        shape = OrientedBox(np.zeros(3), np.array([half, 5e11, 5e11]), rotation, name="wall")
    along = speed * math.cos(math.radians(angle))
    sideways = speed * math.sin(math.radians(angle)) * rotation[:, 1]
    start = -(half + radius + along * dt * (1 + phase)) * normal  # first touch after 1 + phase steps
    y0 = np.array([[start], [along * normal + sideways]])
    world = CollisionWorld("swept", (shape,), pair_properties=PairProperties(eps))
    traj = simulate(Model([1.0], [radius]), "semi-implicit-euler", y0, 0.0, 6 * dt, dt, collisions=world)
    depth = traj.positions[:, 0] @ normal  # signed distance of the centre along the normal
    assert np.all(depth <= -half), depth + half
    assert len(traj.collisions.events) >= 1


@pytest.mark.parametrize("detector", ["swept", "overlap"])
def test_every_broadphase_gives_the_same_trajectory_and_collisions(detector):
    """The whole pipeline with each broadphase method: bit-identical states and events
    (find_pairs itself is checked against brute force in test_broadphase.py)."""
    from steplab.physics.broadphase import METHODS
    from steplab.physics.collision import CollisionWorld, PairProperties

    rng = np.random.default_rng(11)
    n = 40
    q = rng.uniform(-1.5, 1.5, (n, 3))
    y0 = np.stack([q, -4 * q + rng.normal(size=(n, 3))])  # thrown together
    model = Model(rng.uniform(0.5, 2.0, n), rng.uniform(0.1, 0.25, n))
    runs = {}
    for method in METHODS:
        world = CollisionWorld(detector, box_of_planes(), pair_properties=PairProperties(0.8), broadphase=method)
        traj = simulate(model, "semi-implicit-euler", y0, 0.0, 0.3, 0.005, collisions=world)
        runs[method] = (traj.y.tobytes(), traj.collisions.to_csv())
    assert len(runs["brute"][1].splitlines()) > 20  # plenty of collisions
    for method, run in runs.items():
        assert run == runs["brute"], method


@pytest.mark.parametrize("detector", ["swept", "overlap"])
def test_coincident_spheres_collide_without_nan(detector):
    """Two balls with the same centre have no normal between them: +x by convention."""
    from steplab.physics.collision import CollisionWorld

    y0 = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], [[1.0, 0.5, 0.0], [-1.0, 0.0, 0.2]]])
    model = Model([1.0, 3.0], [0.1, 0.2])
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, 0.2, 0.01, collisions=CollisionWorld(detector))
    assert np.all(np.isfinite(traj.y))
    m = np.asarray(model.masses)[:, None]
    assert_allclose((m * traj.velocities).sum(axis=1), np.broadcast_to((m * y0[1]).sum(axis=0), (21, 3)),
                    rtol=0, atol=1e-14)


def test_game_loop_with_a_subnormal_dt_or_a_huge_frame_stays_bounded():
    """The accumulator loop is exact (rational lag), so t + dt == t cannot stall it, and the
    per-frame cap bounds a frame's work even when 10^321 steps are owed."""
    from steplab.integrators import GameLoop

    steps = []
    loop = GameLoop(lambda: steps.append(1), 5e-324, max_steps_per_frame=1000)
    loop.advance(1 / 60)
    assert loop.steps == len(steps) == 1000 and loop.dropped > 0 and 0 <= loop.alpha < 1
    loop = GameLoop(lambda: None, 0.01)
    loop.advance(1e300)
    assert loop.steps == 1000
    for bad in (0, -1, 2.5, None, float("inf"), True):
        with pytest.raises(ValueError, match="max_steps_per_frame"):
            GameLoop(lambda: None, 0.01, max_steps_per_frame=bad)
