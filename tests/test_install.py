"""The installed distribution claims only the ``steplab`` name (the repository keeps its
top-level folders physics/, integrators/, studies/; they install as steplab.physics, ...)."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_wheel_holds_only_the_steplab_package(tmp_path):
    """A wheel built from this checkout: every file lies under ``steplab/`` or its dist-info,
    the model, integrators and studies among them, the built-in scenes included."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--wheel-dir", str(tmp_path),
                    str(ROOT)], check=True, capture_output=True)
    (wheel,) = tmp_path.glob("steplab-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"steplab"}
    for module in ("steplab/physics/model.py", "steplab/integrators/simulate.py", "steplab/studies/runner.py",
                   "steplab/physics/collision/step.py", "steplab/physics/broadphase/bvh.py",
                   "steplab/physics/scenes/drop.toml", "steplab/cli/__init__.py"):
        assert module in names
    assert not any(name.startswith(("physics/", "integrators/", "studies/", "tests/")) for name in names)


def test_the_installed_distribution_declares_one_top_level_name():
    assert metadata.distribution("steplab").read_text("top_level.txt").split() == ["steplab"]


def test_generic_names_are_not_importable_outside_the_checkout(tmp_path):
    """From another folder, ``physics`` and friends are not steplab's: only ``steplab.physics`` is."""
    code = ("import importlib.util as u, steplab.physics, steplab.integrators, steplab.studies;"
            "print([u.find_spec(n) is None for n in ('physics', 'integrators', 'studies')])")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[True, True, True]"


def test_the_command_is_not_shadowed_by_a_steplab_folder_in_the_working_directory(tmp_path):
    """``steplab --version`` run where a ``steplab/`` folder (say, a results folder) exists."""
    (tmp_path / "steplab").mkdir()
    script = Path(sys.executable).parent / "steplab"
    out = subprocess.run([str(script), "--version"], cwd=tmp_path, capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.startswith("steplab"), out.stderr


def test_the_folders_refuse_a_foreign_name_so_no_kernel_is_cached_under_it(tmp_path):
    """Issue 24's reproduction: from the repository root ``from physics.broadphase import
    find_pairs`` used to compile and cache a Numba kernel under the name ``physics``, which then
    failed to load from every other folder. Now the import fails, naming the right one, and the
    installed name works from anywhere afterwards."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    for folder in ("physics", "integrators", "studies"):
        wrong = subprocess.run([sys.executable, "-c", f"import {folder}"], cwd=ROOT, env=env,
                               capture_output=True, text=True)
        assert wrong.returncode != 0
        assert wrong.stderr.strip().splitlines()[-1] == (
            f"ImportError: {folder} is steplab's {folder}/ folder imported under the wrong name: "
            f"import steplab.{folder} instead")
    code = ("import numpy as np; from {0} import find_pairs;"
            "print(len(find_pairs(np.random.default_rng(1).random((200, 3)), 0.05)))")
    first = subprocess.run([sys.executable, "-c", code.format("physics.broadphase")], cwd=ROOT, env=env,
                           capture_output=True, text=True)
    assert first.returncode != 0 and "import steplab.physics instead" in first.stderr
    second = subprocess.run([sys.executable, "-c", code.format("steplab.physics")], cwd=tmp_path, env=env,
                            capture_output=True, text=True)
    assert second.returncode == 0, second.stderr
    assert int(second.stdout) > 0
