"""Hostile input: the scene loader and the command line against thousands of malformed scenes.

Every input ends one of three ways, and only these:

- the scene loads (the command runs, status 0) and its state is finite;
- a :class:`SceneError` / status 2 with one line naming the problem;
- for a scene that loads but blows up, status 1 with one line naming the step.

Never a traceback, a warning on stderr, a hang (sizes are bounded, ``--max-steps`` caps
the runs here) or a partial output file. The scenes are generated with hypothesis: a valid
scene, then up to four mutations (a hostile value, a deleted key, an unknown key, a
duplicate, nesting); plus raw byte mutations of valid files and random command lines.
The ``ci`` profile (tests/conftest.py) makes them the same on every run.

Run more with ``STEPLAB_FUZZ_SCALE=10`` (ten times the examples) and fresh random ones
with ``HYPOTHESIS_PROFILE=explore``.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import re
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import ONE_BODY_SCENE, TWO_BODY_SCENE
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.physics.scene import MAX_BODIES, MAX_PAIRS, MAX_SCENE_BYTES, SceneError, parse_scene

from steplab.cli import main

SCALE = int(os.environ.get("STEPLAB_FUZZ_SCALE", "1"))


def budget(n: int) -> settings:
    """Hypothesis settings for ``n`` examples (times STEPLAB_FUZZ_SCALE)."""
    return settings(max_examples=n * SCALE)


FIXED_STEP = ["euler", "semi-implicit-euler", "velocity-verlet", "position-verlet", "heun", "midpoint", "rk4",
              "implicit-euler"]

# --- writing TOML (tomllib only reads) ------------------------------------------------------


class Raw(str):
    """A TOML token written as is (dates and times, which Python values would not round-trip)."""


def toml_string(text: str) -> str:
    out = ['"']
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return "".join(out) + '"'


def toml_key(key) -> str:
    key = str(key)
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else toml_string(key)


def toml_value(value) -> str:
    if isinstance(value, Raw):
        return str(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_document(doc: dict) -> str:
    """One line per top-level key; tables as inline tables (the same data as [headers])."""
    return "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in doc.items())


# --- valid scenes ---------------------------------------------------------------------------

finite = st.floats(-10, 10, allow_nan=False)
positive = st.floats(0.01, 10, allow_nan=False)
vector = st.lists(finite, min_size=3, max_size=3)
body_name = st.from_regex(r"[a-z]{1,6}", fullmatch=True)


@st.composite
def valid_scenes(draw) -> dict:
    """A small scene using every part of the schema that a draw picks (always loadable)."""
    dt = draw(st.floats(1e-3, 0.05))
    t_start = draw(st.sampled_from([0.0, 0.0, 5.0, -2.0]))
    sim = {"dt": dt, "t_end": t_start + dt * draw(st.integers(1, 20)), "integrator": draw(st.sampled_from(FIXED_STEP))}
    if t_start:
        sim["t_start"] = t_start
    doc = {"simulation": sim}
    if draw(st.booleans()):
        doc["name"] = draw(st.text(min_size=1, max_size=10).filter(str.isprintable))  # a name prints on one line
    names = draw(st.lists(body_name, min_size=1, max_size=4, unique=True))
    bodies = []
    for name in names:
        body = {"name": name, "mass": draw(positive), "radius": draw(positive), "position": draw(vector)}
        if draw(st.booleans()):
            body["pinned"] = True
        elif draw(st.booleans()):
            body["velocity"] = draw(vector)
        bodies.append(body)
    doc["bodies"] = bodies
    if draw(st.booleans()):
        shape = draw(st.sampled_from(["box", "grid", "mesh"]))
        soft = {"name": "S", "shape": shape, "mass": draw(positive), "stiffness": draw(positive)}
        if shape == "box":
            soft["size"] = draw(st.lists(positive, min_size=3, max_size=3))
        elif shape == "grid":
            soft.update(rows=draw(st.integers(1, 3)), cols=draw(st.integers(2, 3)), spacing=draw(positive))
        else:
            soft["vertices"] = draw(st.lists(vector, min_size=2, max_size=5))
            soft["edges"] = [[0, 1]]
        if draw(st.booleans()):
            soft["damping"] = draw(positive)
        doc["soft_bodies"] = [soft]
    if draw(st.booleans()):
        doc["particles"] = [{"name": "P", "count": draw(st.integers(1, 8)), "seed": draw(st.integers(0, 9)),
                             "mass": draw(positive), "radius": draw(positive), "box_min": [-1.0, -1.0, 0.0],
                             "box_max": [1.0, 1.0, 2.0], "speed": draw(positive)}]
    forces = {}
    if draw(st.booleans()):
        forces["gravity"] = {} if draw(st.booleans()) else {"g": draw(vector)}
    if len(names) >= 2 and draw(st.booleans()):
        forces["springs"] = [{"bodies": names[:2], "stiffness": draw(positive)}]
        forces["dampers"] = [{"bodies": names[:2], "damping": draw(positive)}]
    if draw(st.booleans()):
        forces["drag"] = {"density": 1.2}
    if draw(st.booleans()):
        forces["friction"] = {"mu_static": 0.5, "mu_dynamic": 0.3}
    if forces:
        doc["forces"] = forces
    if draw(st.integers(0, 4)) == 0:
        doc["collisions"] = {"detector": draw(st.sampled_from(["swept", "overlap", "none"])),
                             "restitution": draw(st.floats(0, 1)),
                             "planes": [{"normal": [0.0, 0.0, 1.0], "offset": -20.0}]}
    return doc


# --- hostile mutations ----------------------------------------------------------------------

NAN, INF = float("nan"), float("inf")
HOSTILE_CONSTANTS = [
    0, -1, 1, 0.0, -0.0, -1.5, NAN, INF, -INF, 5e-324, 1e-310, 1e308, -1e308, 2**63 - 1, -(2**63), 10**30, -(10**400),
    True, False, "", "1.0", "nan", "all-pairs", "edges", "box", "grid", "mesh", "rk4", "swept", "overlap",
    "verlet", [], {}, [0, 0], [0, 0, 0, 0], [NAN, 0, 0], [INF, 0, 0], [1e308, 1e308, 1e308], [1e-320, 0, 0],
    ["a", "b"], ["a", "a"], [[0, 0, 0]], [True, 0, 0], [[0, 1]], [[0, 0]], [[0, 99]], [-1], [0, 1], {"x": 1},
    Raw("1979-05-27T07:32:00Z"), Raw("07:32:00"), Raw("1979-05-27"),
]
scalars = st.one_of(
    st.sampled_from(HOSTILE_CONSTANTS),
    st.floats(),
    st.integers(-100, 100),
    st.text(max_size=12),
)
junk = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                        max_size=4), max_leaves=12)


def nested(depth: int, inner):
    for _ in range(depth):
        inner = [inner]
    return inner


hostile_values = st.one_of(
    scalars, scalars, junk,
    st.integers(1, 40).map(lambda d: nested(d, 0.0)),  # nested arrays
    st.integers(1, 3000).map(lambda d: Raw("[" * d + "]" * d)),  # nested deeper than tomllib's recursion
    st.integers(1, 3000).map(lambda d: Raw("{a = " * d + "1" + "}" * d)),
    st.lists(st.floats(-1, 1), min_size=4, max_size=2000),  # long arrays where 3 numbers belong
)


def all_paths(node, prefix=()):
    yield prefix
    if len(prefix) >= 12:  # not into deeply nested junk
        return
    if isinstance(node, dict):
        for key, value in node.items():
            yield from all_paths(value, prefix + (key,))
    elif isinstance(node, list):
        for k, value in enumerate(node):
            yield from all_paths(value, prefix + (k,))


def locate(doc, path):
    node = doc
    for key in path:
        node = node[key]
    return node


@st.composite
def hostile_scenes(draw) -> dict:
    """A valid scene with one to four hostile mutations."""
    doc = copy.deepcopy(draw(valid_scenes()))
    for _ in range(draw(st.integers(1, 4))):
        paths = [p for p in all_paths(doc) if p]
        if not paths:  # every key deleted
            break
        path = draw(st.sampled_from(paths))
        parent, key = locate(doc, path[:-1]), path[-1]
        kind = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown-key", "duplicate",
                                     "wrap"]))
        # copies: sampled_from hands out the same list and dict objects every time
        if kind == "replace":
            parent[key] = copy.deepcopy(draw(hostile_values))
        elif kind == "delete":
            del parent[key]
        elif kind == "unknown-key" and isinstance(parent[key], dict):
            parent[key][draw(st.text(min_size=1, max_size=8))] = copy.deepcopy(draw(hostile_values))
        elif kind == "duplicate" and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[key]))
        elif kind == "wrap":
            parent[key] = draw(st.sampled_from([[parent[key]], {"x": parent[key]}]))
    return doc


# --- checks ---------------------------------------------------------------------------------


def load_or_refuse(text, label="fuzz.toml"):
    """parse_scene's contract: a finite scene, or a SceneError of one line; no warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (overflow, 0/0) fails the test
        try:
            scene = parse_scene(text, label)
        except SceneError as err:
            message = str(err)
            assert message.startswith(f"{label}: ") and "\n" not in message and "\r" not in message
            return None
    assert np.all(np.isfinite(scene.y0))
    masses = np.asarray(scene.model.masses)
    assert np.all(masses > 0) and np.all(np.isfinite(1 / masses))
    assert np.all(np.asarray(scene.model.radii) > 0)
    assert 0 < scene.dt < math.inf and math.isfinite(scene.t_start) and scene.t_end > scene.t_start
    assert 1 <= scene.model.n_bodies <= MAX_BODIES
    return scene


def run_cli(argv):
    """``steplab`` in-process: (status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            status = main(argv)
        except SystemExit as exit_:  # argparse: --help, --version, bad options
            status = exit_.code
    return status, out.getvalue(), err.getvalue()


#: the one line ``steplab run`` prints before a run whose dt exceeds the predicted stable limit
DT_WARNING = re.compile(r"\Asteplab run: warning: dt = \S+ s exceeds the largest stable dt of [^\n]*\n")


def without_dt_warning(err: str) -> str:
    """stderr without the stability warning: a hostile dt may earn it, and nothing else."""
    return DT_WARNING.sub("", err, count=1)


def assert_one_line_error(status, err, command="run"):
    err = without_dt_warning(err)
    assert "Traceback" not in err and "Warning" not in err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"steplab {command}: error: ") or err.startswith("steplab: error: "), err
    return status


# --- the loader -----------------------------------------------------------------------------


@budget(200)
@given(valid_scenes())
def test_generated_valid_scenes_load(doc):
    """The generator's starting points are valid, so the mutations below start from real scenes."""
    assert load_or_refuse(toml_document(doc)) is not None


@budget(2500)
@given(hostile_scenes())
def test_loader_refuses_hostile_scenes_with_one_line(doc):
    load_or_refuse(toml_document(doc))


@budget(1000)
@given(valid_scenes(), st.data())
def test_loader_survives_byte_mutations(doc, data):
    """Flip, insert, delete and truncate bytes of a valid file: malformed TOML and non-UTF-8 bytes."""
    raw = bytearray(toml_document(doc).encode())
    for _ in range(data.draw(st.integers(1, 6))):
        op = data.draw(st.sampled_from(["flip", "insert", "delete", "truncate"]))
        k = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if op == "flip" and raw:
            raw[k] = data.draw(st.integers(0, 255))
        elif op == "insert":
            raw[k:k] = data.draw(st.binary(min_size=1, max_size=8))
        elif op == "delete":
            del raw[k:k + data.draw(st.integers(1, 8))]
        else:
            del raw[k:]
    load_or_refuse(bytes(raw))


@budget(300)
@given(st.binary(max_size=300))
def test_loader_survives_random_bytes(raw):
    load_or_refuse(raw)


# --- the command line -----------------------------------------------------------------------


@budget(250)
@given(hostile_scenes())
def test_cli_run_on_hostile_scenes(doc):
    """``steplab run`` in-process: status 0, 1 or 2; one line on error; no file unless status 0."""
    with tempfile.TemporaryDirectory() as folder:
        scene, out = Path(folder, "fuzz.toml"), Path(folder, "out", "trajectory.npz")
        scene.write_text(toml_document(doc), encoding="utf-8")
        status, stdout, err = run_cli(["run", str(scene), "--max-steps", "50", "--out", str(out)])
        if status == 0:
            assert without_dt_warning(err) == "" and out.is_file()
            with np.load(out) as data:
                assert np.all(np.isfinite(data["positions"])) and np.all(np.isfinite(data["velocities"]))
        else:
            assert status in (1, 2), (status, err)
            assert_one_line_error(status, err)
            assert not out.exists()
        leftovers = [p.name for p in Path(folder).rglob(".*.tmp")]
        assert not leftovers


OPTIONS = {  # option: (valid values, hostile values)
    "--integrator": (FIXED_STEP + ["exact"], ["nope", "", "RK4", "rk4 ", "diffrax"]),
    "--dt": (["0.01", "1e-3", "0.05"], ["0", "-1", "nan", "inf", "1e-320", "5e-324", "abc", "", "1e308"]),
    "--t-end": (["5.5", "6.0"], ["0.5", "-1", "nan", "1e308", "1e-300", "x"]),
    "--backend": (["numpy", "numpy", "jax"], ["cuda", ""]),
    "--precision": (["float64", "float32"], ["float16", "double"]),
    "--save-every": (["1", "3", "1000"], ["0", "-2", "1e3", str(2**64), "x"]),
    "--max-steps": (["1000", "600"], ["1", "0", "-5", "many", str(10**30)]),
    "--detector": (["none", "overlap", "swept"], ["broad"]),
}


@st.composite
def command_lines(draw) -> list[str]:
    """``steplab run`` with a few options, each valid or (one time in four) hostile."""
    if draw(st.integers(0, 3)) == 3:
        scene = draw(st.sampled_from(["no-such-scene", "", "-", "x.toml", "/dev/null", "/"]))
    else:
        scene = draw(st.sampled_from(["projectile", "oscillator", "drop", "soft-cube"]))
    argv = ["run", scene]
    chosen = draw(st.lists(st.sampled_from(sorted(OPTIONS)), max_size=4, unique=True))
    for option in sorted(set(chosen) | {"--t-end", "--max-steps"}):  # short runs unless hostile
        valid, hostile = OPTIONS[option]
        argv += [option, draw(st.sampled_from(hostile if draw(st.integers(0, 3)) == 3 else valid))]
    if draw(st.booleans()):
        argv.append("--json")
    if draw(st.integers(0, 9)) == 9:
        argv.insert(draw(st.integers(0, len(argv))), draw(st.sampled_from(["--frobnicate", "--dt", "extra"])))
    return argv


@budget(200)
@given(command_lines(), st.sampled_from([".npz", ".csv", ".txt", ""]))
def test_cli_command_line_fuzz(argv, suffix):
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder, "t" + suffix)
        status, stdout, err = run_cli(argv + ["--out", str(out)])
        if status == 0:
            assert out.is_file() and without_dt_warning(err) == ""
        else:
            assert status in (1, 2), (argv, status, err)
            assert_one_line_error(status, err)
            assert not out.exists()
        assert not list(Path(folder).glob(".*.tmp"))


# --- chosen hostile inputs, each with the line it must print ---------------------------------

SCENE, TWO = ONE_BODY_SCENE, TWO_BODY_SCENE

HOSTILE = [
    # (scene text, extra argv, fragment of the one-line message)
    ("a = " + "[" * 3000 + "]" * 3000 + "\n" + SCENE, [], "nested too deeply"),
    ("a = " + "{b = " * 2000 + "1" + "}" * 2000 + "\n" + SCENE, [], "nested too deeply"),
    (SCENE.replace("mass = 1.0", "mass = " + "9" * 400), [], "bodies[0].mass: must be finite"),
    (SCENE.replace("[0.0, 0.0, 0.0]", "[-" + "9" * 400 + ", 0, 0]"), [], "bodies[0].position: must be finite"),
    (SCENE.replace("mass = 1.0", "mass = 1e-320"), [], "bodies[0].mass: a body of mass 1e-320 kg has no finite"),
    (SCENE.replace("[0.0, 0.0, 0.0]", "[" + ", ".join(["0.0"] * 100_000) + "]"), [],
     "bodies[0].position: must be a list of 3 numbers"),
    (SCENE + '[[particles]]\nname = "p"\ncount = 10000000\nmass = 1.0\nradius = 0.1\n'
     "box_min = [0.0, 0.0, 0.0]\nbox_max = [1.0, 1.0, 1.0]\n", [], f"count: must be between 1 and {MAX_BODIES}"),
    (SCENE + '[[particles]]\nname = "p"\ncount = 3\nmass = 1.0\nradius = 0.1\n'
     "box_min = [-1e308, 0.0, 0.0]\nbox_max = [1e308, 1.0, 1.0]\n", [],
     "particles[0].box_max: box_max - box_min overflows"),
    (SCENE + '[[soft_bodies]]\nname = "c"\nshape = "grid"\nrows = 100000\ncols = 2\nspacing = 1.0\n'
     "mass = 1.0\nstiffness = 1.0\n", [], "soft_bodies[0].rows: must be between 1 and 1000"),
    (SCENE + '[[soft_bodies]]\nname = "c"\nshape = "mesh"\nmass = 1.0\nstiffness = 1.0\nvertices = ['
     + ", ".join(f"[{k}.0, 0.0, 0.0]" for k in range(3200)) + "]\n", [], f"more than {MAX_PAIRS} all-pairs springs"),
    (SCENE + '[[soft_bodies]]\nname = "c"\nshape = "mesh"\nmass = 1.0\nstiffness = 1.0\n'
     "vertices = [[-1e308, 0.0, 0.0], [1e308, 0.0, 0.0]]\n", [], "a spring's rest length overflows"),
    (SCENE + '[[soft_bodies]]\nname = "c"\nshape = "mesh"\nmass = 1.0\nstiffness = 1.0\n'
     "vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]\nedges = [[" + "9" * 30 + ", 1]]\n", [],  # past int64
     f"soft_bodies[0].edges: vertex index {'9' * 30} out of range 0..1"),
    (TWO + '[[forces.springs]]\nbodies = ["a", "b"]\nstiffness = 1.0\nrest_length = inf\n', [],
     "forces.springs[0].rest_length: must be finite, got inf"),
    (TWO.replace("[1.0, 0.0, 0.0]", "[1e308, 0.0, 0.0]").replace("[0.0, 0.0, 0.0]", "[-1e308, 0.0, 0.0]")
     + '[[forces.springs]]\nbodies = ["a", "b"]\nstiffness = 1.0\n', [], "rest_length: must be finite, got inf"),
    (SCENE + '[[soft_bodies]]\nname = "c"\nshape = "box"\ncenter = [1.5e308, 0.0, 0.0]\nsize = [1e308, 1.0, 1.0]\n'
     "mass = 1.0\nstiffness = 1.0\n", [], "soft_bodies[0]: body 'c[4]' would be placed at a non-finite position"),
    (TWO.replace('name = "b"', 'name = "a"'), [], "bodies[1].name: duplicate body name 'a'"),
    (SCENE + '[[soft_bodies]]\nname = "a"\nshape = "box"\nmass = 1.0\nstiffness = 1.0\n'
     + '[[bodies]]\nname = "a[3]"\nmass = 1.0\nradius = 0.1\nposition = [5.0, 0.0, 0.0]\n', [],
     "soft_bodies[0].name: duplicate body name 'a[3]'"),
    (SCENE + "[simulation.extra]\nx = 1\n", [], "simulation: unknown key 'extra'"),
    (SCENE.replace("t_end = 1.0", "t_start = -1e308\nt_end = 1e308").replace("dt = 0.01", "dt = 1e300"), [],
     "more steps of dt = 1e+300 s than a float can count"),
    (SCENE.replace("t_end = 1.0", "t_end = 1e300").replace("dt = 0.01", "dt = 1e-300"), [],
     "time would not advance"),
    (SCENE.replace("dt = 0.01", "dt = 1e-9"), [], "exceed the limit of 10000000"),
    (SCENE.replace("t_end = 1.0", "t_start = 1e10\nt_end = 10000000001.0").replace("dt = 0.01", "dt = 1e-7"),
     ["--max-steps", "100000000"], "time would not advance"),
    (SCENE.replace("[0.0, 0.0, 0.0]", "[1e300, 0.0, 0.0]"), [], "the initial state is non-finite or too large"),
    (SCENE.replace("[0.0, 0.0, 0.0]", "[1e30, 0.0, 0.0]"), ["--precision", "float32"],
     "too large to integrate in float32"),
    (SCENE, ["--dt", "1e-50", "--t-end", "1e-45", "--precision", "float32"], "smaller than the float32 spacing"),
    (SCENE + '[[particles]]\nname = "p"\ncount = 1000\nmass = 1.0\nradius = 0.1\n'
     "box_min = [0.0, 0.0, 0.0]\nbox_max = [1.0, 1.0, 1.0]\n", ["--max-steps", "10000000", "--dt", "1e-6"],
     "GiB, more than the limit"),
    ("[simulation]\ndt = 0.1\nt_end = 1.0\n" + 'name = "\\u0007\\n"\n', [], "declares no bodies"),
]


@pytest.mark.parametrize("text,extra,message", HOSTILE, ids=range(len(HOSTILE)))
def test_hostile_scene_gets_one_line_and_status_2(tmp_path, text, extra, message):
    path = tmp_path / "hostile.toml"
    path.write_text(text)
    out = tmp_path / "out.npz"
    status, stdout, err = run_cli(["run", str(path), "--out", str(out), *extra])
    assert status == 2, err
    assert_one_line_error(status, err)
    assert err.startswith(f"steplab run: error: {path}: ") or "hostile.toml" not in err
    assert message in err, err
    assert not out.exists() and stdout == ""


def test_friction_normal_of_huge_or_tiny_components_is_a_unit_vector():
    """[1e200, 1e200, 0] overflowed the norm to inf and silently became a zero normal."""
    for normal in ("[1e200, 1e200, 0.0]", "[1e-320, 0.0, 1e-320]", "[0.0, 0.0, 3.0]"):
        scene = parse_scene(SCENE + f"[forces.friction]\nmu_static = 0.5\nmu_dynamic = 0.3\nnormal = {normal}\n")
        (friction,) = scene.model.forces
        assert np.linalg.norm(friction.normal) == pytest.approx(1.0, rel=1e-15)
    with pytest.raises(SceneError, match="forces.friction.normal: must be a non-zero vector"):
        parse_scene(SCENE + "[forces.friction]\nmu_static = 0.5\nmu_dynamic = 0.3\nnormal = [0.0, -0.0, 0.0]\n")


def test_scene_file_larger_than_the_limit_is_refused_before_parsing(tmp_path):
    path = tmp_path / "big.toml"
    path.write_bytes(SCENE.encode() + b"# " + b"x" * MAX_SCENE_BYTES + b"\n")
    status, _, err = run_cli(["run", str(path)])
    assert status == 2 and "larger than the limit" in err
    assert_one_line_error(status, err)


def test_output_path_problems_are_one_line_before_the_run(tmp_path):
    (tmp_path / "a-file").write_text("")
    (tmp_path / "folder.npz").mkdir()
    for out, message in ((tmp_path / "a-file" / "x.npz", "is a file, not a folder"),
                         (tmp_path / "folder.npz", "is a folder, not a file")):
        status, _, err = run_cli(["run", "projectile", "--out", str(out)])
        assert status == 2 and message in err
        assert_one_line_error(status, err)


def test_unwritable_output_is_one_line(tmp_path):
    """An OSError while writing (here: /proc refuses new files) is one line, not a traceback."""
    status, _, err = run_cli(["run", "projectile", "--out", "/proc/steplab-cannot-write-here/t.npz"])
    assert status == 2
    assert_one_line_error(status, err)


def test_diverging_run_leaves_no_output_file(tmp_path):
    out = tmp_path / "t.csv"
    status, _, err = run_cli(["run", "oscillator", "--integrator", "euler", "--dt", "0.5", "--t-end", "1000",
                              "--out", str(out)])
    assert status == 1 and "diverged" in err
    assert_one_line_error(status, err)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_line_breaks_in_a_message_are_escaped(tmp_path):
    """A body name with a line break in an error message cannot split the error line."""
    path = tmp_path / "s.toml"
    path.write_text(SCENE + '[[forces.springs]]\nbodies = ["a", "x\\ny"]\nstiffness = 1.0\n')
    status, _, err = run_cli(["run", str(path)])
    assert status == 2 and "names unknown body 'x\\ny'" in err
    assert_one_line_error(status, err)


# --- the real executable, in fresh processes -------------------------------------------------

STEPLAB = str(Path(sys.executable).parent / "steplab")


def run_process(*argv, cwd=None, timeout=120):
    return subprocess.run([STEPLAB, *argv], capture_output=True, timeout=timeout, cwd=cwd)


def test_subprocess_hostile_inputs(tmp_path):
    """What only a real process shows: stderr really is one line (no RuntimeWarning from NumPy,
    no traceback), reading /dev/zero ends, a non-UTF-8 file name prints."""
    spring = TWO.replace("[1.0, 0.0, 0.0]", "[1e200, 0.0, 0.0]") + '[[forces.springs]]\nbodies = ["a", "b"]\n' \
        "stiffness = 1.0\n"
    (tmp_path / "spring.toml").write_text(spring)
    (tmp_path / "deep.toml").write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    cases = [
        (["run", "spring.toml"], "rest_length: must be finite"),
        (["run", "deep.toml"], "nested too deeply"),
        (["run", "/dev/zero"], "larger than the limit"),
        (["run", "projectile", "--out", "spring.toml/x.csv"], "is a file, not a folder"),
    ]
    for argv, message in cases:
        done = run_process(*argv, cwd=tmp_path)
        err = done.stderr.decode()
        assert done.returncode == 2, (argv, err)
        assert err.count("\n") == 1 and "Traceback" not in err and "Warning" not in err, (argv, err)
        assert message in err, (argv, err)


def test_subprocess_non_utf8_file_name(tmp_path):
    name = os.fsdecode(b"sc\xffne.toml")
    Path(tmp_path, name).write_text(SCENE)
    done = run_process("run", name, "--t-end", "0.05", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert b"sc\\xffne: semi-implicit-euler" in done.stdout
    Path(tmp_path, name).write_text(SCENE.replace("mass = 1.0", "mass = 0.0"))
    done = run_process("run", name, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count(b"\n") == 1 and b"must be > 0" in done.stderr


def test_collision_plane_normal_and_box_axis_of_huge_or_tiny_components():
    """The same overflow for [collisions]: a plane normal [1e200, 1e200, 0] became [0, 0, 0]."""
    scene = parse_scene(SCENE + "[collisions]\n[[collisions.planes]]\nnormal = [1e200, 1e200, 0.0]\n"
                        "[[collisions.boxes]]\ncenter = [0.0, 0.0, -5.0]\nsize = [1.0, 1.0, 1.0]\n"
                        "axis = [1e-320, 0.0, 0.0]\nangle = 30.0\n")
    plane, box = scene.collisions.shapes
    np.testing.assert_allclose(plane.normal, [2**-0.5, 2**-0.5, 0.0], rtol=1e-15)
    np.testing.assert_allclose(box.rotation[:, 0], [1.0, 0.0, 0.0], atol=1e-15)  # turned about x
    with pytest.raises(SceneError, match=r"collisions.planes\[0\].normal: must be a non-zero vector"):
        parse_scene(SCENE + "[collisions]\n[[collisions.planes]]\nnormal = [0.0, 0.0, 0.0]\n")
