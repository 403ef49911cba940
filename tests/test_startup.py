"""Start-up: the light commands import none of the heavy layers, and float64 stays JAX's default.

Checked in fresh processes through ``sys.modules`` at exit, never by a clock (the times
are measured by benchmarks/benchmarks/startup.py).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: what a NumPy-only command must not load: JAX (and diffrax), matplotlib, Dask, the study
#: modules, the Numba-compiled collision and broadphase kernels, and Numba itself
HEAVY = ("jax", "diffrax", "matplotlib", "dask", "distributed", "numba", "steplab.physics.collision",
         "steplab.physics.broadphase", "steplab.studies.truncation", "steplab.studies.stability",
         "steplab.studies.work_precision", "steplab.studies.contacts", "steplab.studies.engines",
         "steplab.studies.plotting", "steplab.engines")


def loaded_after(code: str) -> list[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)), file=sys.stderr)\n"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return json.loads(done.stderr.strip().splitlines()[-1])


def heavy(modules: list[str]) -> list[str]:
    return [m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY)]


@pytest.mark.parametrize("argv", [["run", "projectile"], ["integrators"], ["scenes"], ["--help"]])
def test_light_commands_import_nothing_heavy(argv):
    code = f"from steplab.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass"
    modules = loaded_after(code)
    assert "steplab.cli.main" in modules  # it ran
    assert heavy(modules) == []


def test_the_check_sees_a_heavy_import():
    assert heavy(loaded_after("import steplab.physics.collision")) != []


@pytest.mark.parametrize("order", ["import steplab.physics\nimport jax.numpy as jnp",
                                   "import jax.numpy as jnp\nimport steplab"])
def test_float64_is_jax_default_whichever_is_imported_first(order):
    """x64 without importing JAX: JAX_ENABLE_X64 before JAX loads, the config where it already has."""
    code = f"{order}\nprint(jnp.zeros(1).dtype, jnp.asarray(1.5).dtype, file=sys.stderr)"
    done = subprocess.run([sys.executable, "-c", f"import sys\n{code}"], capture_output=True, text=True, check=True)
    assert done.stderr.split() == ["float64", "float64"]


def test_the_public_names_are_there_on_first_use():
    import steplab.physics as physics
    from steplab.integrators import simulate
    from steplab.physics import Model, Springs, find_pairs, projectile

    import steplab

    assert callable(find_pairs) and callable(projectile) and callable(simulate)
    assert physics.Model is Model and "Springs" in dir(physics) and Springs.__name__ == "Springs"
    assert steplab.load_scene("projectile").name == "projectile"
    with pytest.raises(AttributeError, match="has no attribute 'nope'"):
        physics.nope  # noqa: B018


def test_a_listing_piped_into_head_ends_quietly(tmp_path):
    """``steplab scenes | head -1``: the closed pipe ends the command with status 0 and no error line."""
    script = Path(sys.executable).parent / "steplab"
    done = subprocess.run(f"'{script}' scenes | head -1; exit ${{PIPESTATUS[0]}}", shell=True, executable="/bin/bash",
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0 and done.stderr == "" and done.stdout.startswith("name")
