"""steplab: how wrong, how unstable and how slow a game-physics step is.

The public API in one place::

    from steplab import load_scene, simulate
    scene = load_scene("projectile")
    trajectory = simulate(scene.model, "euler", scene.y0, scene.t_start, 5.2, 0.2)
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from steplab.integrators import INTEGRATORS as INTEGRATORS
from steplab.integrators import DivergenceError as DivergenceError
from steplab.integrators import GameLoop as GameLoop
from steplab.integrators import Trajectory as Trajectory
from steplab.integrators import get_integrator as get_integrator
from steplab.integrators import simulate as simulate
from steplab.physics import Model as Model
from steplab.physics import projectile as projectile
from steplab.physics.scene import Scene as Scene
from steplab.physics.scene import SceneError as SceneError
from steplab.physics.scene import builtin_scenes as builtin_scenes
from steplab.physics.scene import load_scene as load_scene
from steplab.physics.scene import parse_scene as parse_scene

try:
    __version__ = version("steplab")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
