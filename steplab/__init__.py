"""steplab: how wrong, how unstable and how slow a game-physics step is.

The public API in one place::

    from steplab import load_scene, simulate
    scene = load_scene("projectile")
    trajectory = simulate(scene.model, "euler", scene.y0, scene.t_start, 5.2, 0.2)

Importing steplab turns on 64-bit floats in JAX (``jax_enable_x64``) without importing
JAX: float64 is the default everywhere JAX is used, float32 is asked for explicitly. The
names below are imported on first use (steplab/core/lazy_exports.py), so a command that needs
neither JAX nor Numba starts without them.
"""

from __future__ import annotations

import os
import sys
from importlib.metadata import PackageNotFoundError, version

# JAX reads JAX_ENABLE_X64 when it is first imported, whoever imports it (a study, diffrax,
# a Dask worker started from this process); one imported before steplab is switched here.
os.environ["JAX_ENABLE_X64"] = "1"
if "jax" in sys.modules:
    sys.modules["jax"].config.update("jax_enable_x64", True)

from steplab.core.lazy_exports import lazy_exports  # noqa: E402

__getattr__, __dir__ = lazy_exports(__name__, {
    "INTEGRATORS": "steplab.integrators", "DivergenceError": "steplab.integrators",
    "GameLoop": "steplab.integrators", "Trajectory": "steplab.integrators",
    "get_integrator": "steplab.integrators", "simulate": "steplab.integrators",
    "Model": "steplab.physics", "projectile": "steplab.physics", "Scene": "steplab.physics.scene",
    "SceneError": "steplab.physics.scene", "builtin_scenes": "steplab.physics.scene",
    "load_scene": "steplab.physics.scene", "parse_scene": "steplab.physics.scene",
})

try:
    __version__ = version("steplab")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
