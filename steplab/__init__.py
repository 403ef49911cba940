"""steplab: how wrong, how unstable and how slow a game-physics step is.

The public API in one place::

    from steplab import load_scene, simulate
    scene = load_scene("projectile")
    trajectory = simulate(scene.model, "euler", scene.y0, scene.t_start, 5.2, 0.2)
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from integrators import INTEGRATORS as INTEGRATORS
from integrators import DivergenceError as DivergenceError
from integrators import GameLoop as GameLoop
from integrators import Trajectory as Trajectory
from integrators import get_integrator as get_integrator
from integrators import simulate as simulate
from physics import Model as Model
from physics import projectile as projectile
from physics.scene import Scene as Scene
from physics.scene import SceneError as SceneError
from physics.scene import builtin_scenes as builtin_scenes
from physics.scene import load_scene as load_scene
from physics.scene import parse_scene as parse_scene

try:
    __version__ = version("steplab")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
