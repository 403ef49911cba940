"""Plugins: an installed distribution's entry points reach the registries and the command line;
and CONTRIBUTING.md's one-file contributions, each registered, are picked up where it says.

Each plugin test installs a fake distribution in ``tmp_path`` (a ``.dist-info`` folder with
METADATA and entry_points.txt beside its module) on sys.path, exactly what ``pip
install`` leaves in site-packages, and resets the registries' lazy load.
"""

from __future__ import annotations

import json
import re
import sys
import textwrap
import types
from pathlib import Path

import numpy as np
import pytest
from helpers import TWO_BODY_SCENE
from steplab.integrators import INTEGRATORS, UnknownIntegratorError, get_integrator
from steplab.physics.broadphase import METHODS as BROADPHASE_METHODS
from steplab.physics.collision.methods import COLLISION_METHODS
from steplab.physics.forces import FORCES
from steplab.physics.scene import parse_scene
from steplab.physics.scene_library import SCENES
from steplab.studies import STUDIES

from steplab.cli import main
from steplab.core.registry import PluginError
from steplab.engines import ENGINES

#: the broken entry point below warns wherever a registry is first read outside the command line
pytestmark = pytest.mark.filterwarnings("ignore::steplab.core.registry.PluginWarning")

#: the plugin module: Ralston's 2nd order method (a_21 = 2/3, b = (1/4, 3/4)) and a study
PLUGIN_MODULE = '''
import dataclasses
from typing import ClassVar

from steplab.integrators import ButcherTableau, ExplicitRungeKutta
from steplab.physics import Force
from steplab.physics.scene_toml import REQUIRED
from steplab.studies import Study


@dataclasses.dataclass(frozen=True)
class Ralston(ExplicitRungeKutta):
    """2nd order Ralston method. Uses 2 stages."""

    name = "ralston"
    order = 2
    evaluations = 2
    tableau = ButcherTableau(a_lower=((2 / 3,),), b=(1 / 4, 3 / 4), c=(2 / 3,))


@dataclasses.dataclass(frozen=True)
class Tether(Force):
    """A spring from each body to the origin: F = -k q."""

    stiffness: float
    name: ClassVar[str] = "tether"

    @classmethod
    def from_scene(cls, table, bodies):
        table.allow("stiffness")
        return cls(table.number("stiffness", REQUIRED, positive=True))

    def force(self, xp, q, v, m):
        return -self.stiffness * q


STUDY = Study("fake-study", "a study from a plugin", lambda quick: {}, lambda p, progress=None: {},
              lambda record, out: [])
'''

ENTRY_POINTS = """
[steplab.integrators]
ralston = fake_steplab_plugin:Ralston
broken = fake_steplab_missing:Method

[steplab.studies]
fake-study = fake_steplab_plugin:STUDY

[steplab.forces]
tether = fake_steplab_plugin:Tether

[steplab.scenes]
fake-scenes = fake_steplab_scenes
"""

#: the plugin's scene: 1 kg tethered to the origin by the plugin's force, k = 4 pi^2 N/m
#: (omega = 2 pi rad/s), released 0.5 m out
TETHERED = """
description = "A mass on the plugin's tether."

[simulation]
integrator = "semi-implicit-euler"
dt = 0.01
t_end = 1.0

[[bodies]]
name = "mass"
mass = 1.0
radius = 0.05
position = [0.5, 0.0, 0.0]

[forces.tether]
stiffness = 39.47841760435743
"""


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The fake distribution ``fake-plugin 0.1`` installed on sys.path, registries reset."""
    (tmp_path / "fake_steplab_plugin.py").write_text(PLUGIN_MODULE)
    info = tmp_path / "fake_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    (tmp_path / "fake_steplab_scenes").mkdir()
    (tmp_path / "fake_steplab_scenes" / "__init__.py").write_text("")
    (tmp_path / "fake_steplab_scenes" / "tethered.toml").write_text(TETHERED)
    monkeypatch.syspath_prepend(str(tmp_path))
    registries = (INTEGRATORS, STUDIES, FORCES, SCENES)
    for registry in registries:
        registry.reset()
    yield tmp_path
    for registry in registries:
        registry.reset()
    for module in ("fake_steplab_plugin", "fake_steplab_scenes"):
        sys.modules.pop(module, None)


def ralston_oscillator(steps: int, dt: float, omega: float, u0: float) -> float:
    """Displacement after ``steps`` Ralston steps on u'' = -omega^2 u from (u0, 0), by matrix powers.

    On a linear system y' = A y every 2-stage method of order 2 multiplies by
    I + dt A + (dt A)^2 / 2 per step.
    """
    a = np.array([[0.0, 1.0], [-omega**2, 0.0]])
    step = np.eye(2) + dt * a + (dt * a) @ (dt * a) / 2
    return float((np.linalg.matrix_power(step, steps) @ [u0, 0.0])[0])


def test_an_entry_point_integrator_is_listed_run_and_importable(plugin, capsys):
    status = main(["integrators", "--json"])
    out, err = capsys.readouterr()
    rows = {r["name"]: r for r in json.loads(out)}
    assert status == 0 and rows["ralston"]["order"] == 2
    assert rows["ralston"]["source"] == "fake-plugin 0.1 (ralston = fake_steplab_plugin:Ralston)"
    assert rows["rk4"]["source"] == "steplab"
    # the broken entry point costs one line, naming it, and steplab's own methods stay
    (line,) = err.splitlines()
    assert "broken = fake_steplab_missing:Method" in line and "fake_steplab_missing" in line
    assert "semi-implicit-euler" in rows and "broken" not in rows

    # the oscillator scene: 1 kg on k = 4 pi^2 N/m, released 0.5 m from rest length (linear along x)
    for reference in ("ralston", "fake_steplab_plugin:Ralston"):
        status = main(["run", "oscillator", "--integrator", reference, "--dt", "0.01", "--t-end", "1", "--json"])
        out, _ = capsys.readouterr()
        summary = json.loads(out)
        assert status == 0 and summary["integrator"] == "ralston" and summary["steps"] == 100
        expected = 1.0 + ralston_oscillator(100, 0.01, 2 * np.pi, 0.5)
        assert summary["final_positions"][1][0] == pytest.approx(expected, rel=1e-12)

    method = get_integrator("fake_steplab_plugin:Ralston")  # a class: made into an instance
    assert method.name == "ralston" and method == INTEGRATORS["ralston"]


def test_a_plugin_stepper_joins_the_studies_and_a_plugin_study_runs_by_name(plugin, capsys):
    for study in ("truncation", "stability", "work_precision"):
        assert "ralston" in STUDIES[study].parameters(True)["integrators"]
    assert STUDIES.origin("fake-study").startswith("fake-plugin 0.1")
    status = main(["study", "--list"])
    assert status == 0 and "fake-study" in capsys.readouterr().out
    from steplab.studies import builtin_studies

    assert "fake-study" not in {s.name for s in builtin_studies()}  # reproduce: the paper's studies


def test_an_entry_point_force_and_scene_folder_reach_scenes_run_and_check(plugin, capsys):
    assert main(["scenes", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["tethered"]["forces"] == ["tether"] and "cloth" in rows
    assert FORCES.origin("tether").startswith("fake-plugin 0.1")
    omega = 2 * np.pi
    assert main(["check", "tethered", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["omega_max"] == pytest.approx(omega, rel=1e-9)
    rows = {r["integrator"]: r for r in report["integrators"]}
    assert rows["ralston"]["dt_max"] == 0  # like Heun: unstable on an undamped mode at every dt
    assert rows["semi-implicit-euler"]["dt_max"] == pytest.approx(2 / omega, rel=1e-9)
    assert main(["run", "tethered", "--integrator", "ralston", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    expected = ralston_oscillator(100, 0.01, omega, 0.5)
    assert summary["final_positions"][0][0] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("reference, message", [
    ("broken", "broken = fake_steplab_missing:Method"),
    ("fake_steplab_nowhere:Ralston", "no module named 'fake_steplab_nowhere'"),
    ("fake_steplab_plugin:Nope", "has no attribute 'Nope'"),
    ("fake_steplab_plugin:STUDY", "not a steplab.integrators.Integrator"),
    ("fake_steplab_plugin:", "not of the form package.module:Name"),
])
def test_a_bad_plugin_or_reference_is_one_line_and_status_2(plugin, capsys, reference, message):
    status = main(["run", "oscillator", "--integrator", reference, "--t-end", "0.1"])
    out, err = capsys.readouterr()
    (line,) = [line for line in err.splitlines() if not line.startswith("steplab: warning: integrator plugin")]
    assert status == 2 and out == "" and line.startswith("steplab run: error: ") and message in line, err


def test_register_integrator_refuses_a_taken_name(plugin):
    from steplab.integrators import RK4, register_integrator

    ralston = type(get_integrator("fake_steplab_plugin:Ralston"))
    assert register_integrator(ralston) is INTEGRATORS["ralston"]  # the same method again: a no-op

    class Impostor(RK4):
        """Not RK4."""

    with pytest.raises(PluginError, match="name 'rk4' is taken"):
        register_integrator(Impostor())
    with pytest.raises(UnknownIntegratorError, match="unknown integrator 'nope'.*package.module:Name"):
        get_integrator("nope")
    assert type(INTEGRATORS["rk4"]) is RK4


def test_a_module_in_the_working_directory_is_found_from_the_command_line(tmp_path, monkeypatch, capsys):
    (tmp_path / "my_steplab_method.py").write_text(textwrap.dedent(PLUGIN_MODULE))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))  # the CLI appends the working directory
    try:
        status = main(["run", "oscillator", "--integrator", "my_steplab_method:Ralston", "--t-end", "0.1"])
        assert status == 0 and "ralston" in capsys.readouterr().out
    finally:
        sys.modules.pop("my_steplab_method", None)


# --- CONTRIBUTING.md: each snippet is one file, registered, and steplab picks it up ------------

CONTRIBUTING = Path(__file__).resolve().parent.parent / "CONTRIBUTING.md"


def contributing_snippets() -> dict[str, str]:
    """The file each ```python block of CONTRIBUTING.md is (its first line, ``# path``) -> its code."""
    blocks = re.findall(r"```python\n(.*?)```", CONTRIBUTING.read_text(), flags=re.S)
    return {block.splitlines()[0].removeprefix("# "): block for block in blocks}


@pytest.fixture
def contributed(monkeypatch):
    """Each snippet run as a module of its own; every registry put back as it was afterwards."""
    registries = (INTEGRATORS, FORCES, COLLISION_METHODS, BROADPHASE_METHODS, ENGINES, STUDIES)
    before = [dict(registry) for registry in registries]
    modules = {}
    try:
        for path, code in contributing_snippets().items():
            module = types.ModuleType(f"contributing_{Path(path).stem}")
            monkeypatch.setitem(sys.modules, module.__name__, module)  # dataclasses read the module
            exec(compile(code, f"CONTRIBUTING.md ({path})", "exec"), module.__dict__)
            modules[path] = module
        yield modules
    finally:
        for registry, entries in zip(registries, before):
            registry.clear()
            registry.update(entries)  # in the same order


def test_contributing_walks_through_one_file_of_each_kind():
    assert list(contributing_snippets()) == [
        "integrators/kutta3.py", "physics/buoyancy.py", "physics/collision/projection.py",
        "physics/broadphase/x_sweep.py", "steplab/engines/toy_engine.py", "studies/euler_free_fall.py"]


def test_contributed_integrator_has_its_order_and_runs(contributed, capsys):
    from test_integrators import damped, oscillator, test_convergence_order_matches_declared_order

    assert get_integrator("kutta3").order == 3
    for problem in (oscillator, damped):  # the parametrised test, on the new method
        test_convergence_order_matches_declared_order("kutta3", problem)
    assert main(["run", "projectile", "--integrator", "kutta3"]) == 0
    assert "kutta3" in capsys.readouterr().out


def test_contributed_force_is_declared_in_a_scene(contributed):
    """Gravity and buoyancy in water are one constant acceleration: a = g (rho_w V / m - 1)."""
    scene = parse_scene(TWO_BODY_SCENE + "[forces.gravity]\n[forces.buoyancy]\ndensity = 1000.0\n")
    (_, buoyancy) = scene.model.forces
    assert buoyancy.name == "buoyancy"
    volume, g = 4 / 3 * np.pi * 0.1**3, 9.81
    q, v = scene.y0
    a = scene.model.acceleration(0.0, q, v)
    np.testing.assert_allclose(a[:, 2], g * (1000.0 * volume / np.array([1.0, 1.0]) - 1.0), rtol=1e-14)
    np.testing.assert_array_equal(a[:, :2], 0.0)


def test_contributed_collision_method_runs_from_the_command_line(contributed, tmp_path, capsys):
    """steplab run drop --method projection: the golf ball (eps = 0.858 under the event loop) ends
    at rest on the floor, its centre one radius above the plane at -r, so at z = 0, every step at
    or above it."""
    from test_registries import test_every_collision_method_stops_a_ball_dropped_on_the_floor

    test_every_collision_method_stops_a_ball_dropped_on_the_floor("projection")
    out = tmp_path / "drop.npz"
    assert main(["run", "drop", "--method", "projection", "--out", str(out)]) == 0
    saved = np.load(out)
    z, vz = saved["positions"][:, 0, 2], saved["velocities"][:, 0, 2]
    assert z.min() >= -1e-15 and abs(z[-1]) <= 1e-15 and vz[-1] == 0.0


def test_contributed_broadphase_method_agrees_and_joins_the_study(contributed):
    from steplab.studies.broadphase import parameters
    from test_broadphase import test_boundary_cases, test_every_method_equals_brute_force

    test_boundary_cases("x-sweep")
    test_every_method_equals_brute_force(method="x-sweep")  # hypothesis draws the scenes
    assert "x-sweep" in parameters(quick=True)["methods"]


def test_contributed_engine_appears_in_the_engines_study(contributed, tmp_path, capsys):
    """The study, on the toy engine alone: its row identifies it as the semi-implicit Euler it is,
    and what it cannot run (contacts) is one line in the record."""
    from test_engines import test_free_fall_is_the_parabola_plus_the_methods_known_lead

    test_free_fall_is_the_parabola_plus_the_methods_known_lead("toy")
    toy = ENGINES["toy"]
    ENGINES.clear()  # the fixture puts the others back
    ENGINES.register(toy)
    assert main(["study", "engines", "--quick", "--out", str(tmp_path)]) == 0
    record = json.loads((tmp_path / "engines.json").read_text())
    (row,) = record["rows"]
    assert (row["setting"], row["engine"], row["label"]) == ("toy", "toy", "Toy engine")
    assert row["identification"]["equals"] == ["semi-implicit-euler"]
    assert row["identification"]["difference"] <= 1e-12
    assert row["order"] == pytest.approx(1.0, abs=0.1)
    assert row["drops"] == {"error": "collisions: the toy engine has no contacts"}
    assert row["deviation"] == "no contacts: the ball falls through the floor"


def test_contributed_study_runs_by_name(contributed, tmp_path):
    """Explicit Euler's free fall lags the parabola by exactly g dt t / 2 (the sum of the kicks)."""
    assert main(["study", "euler-free-fall", "--quick", "--out", str(tmp_path)]) == 0
    record = json.loads((tmp_path / "euler-free-fall.json").read_text())
    dts = np.array(record["parameters"]["dts"])
    np.testing.assert_allclose(record["errors"], 0.5 * 9.81 * dts * 1.0, rtol=1e-12)
    assert (tmp_path / "euler_free_fall.png").exists()
