"""Game-physics engines as systems under test: MuJoCo, Bullet, Box2D and Chipmunk on steplab's scenes.

Each adapter (one module per engine) builds the engine's bodies, forces and shapes from a
steplab scene and steps it at the scene's dt; ``advance(y0, dt, n_steps)`` returns a
steplab :class:`~steplab.integrators.Trajectory` with the engine's contacts as a collision
log, so the studies measure an engine by the same code as steplab's own integrators. None
of the engines is a dependency of steplab: they are the optional extra
``pip install -e ".[engines]"`` and are imported only when an adapter is built.

>>> from steplab.engines import SETTINGS
>>> SETTINGS["mujoco-euler"].engine
'mujoco'
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util

from .base import EngineNotInstalledError as EngineNotInstalledError
from .base import EngineRun as EngineRun
from .base import UnsupportedFeatureError as UnsupportedFeatureError

#: engine -> (adapter class "module:Class", the Python package it needs, its distribution on PyPI)
ENGINES = {
    "mujoco": ("mujoco_engine:MujocoRun", "mujoco", "mujoco"),
    "bullet": ("bullet_engine:BulletRun", "pybullet", "pybullet"),
    "box2d": ("box2d_engine:Box2DRun", "Box2D", "Box2D"),
    "chipmunk": ("chipmunk_engine:ChipmunkRun", "pymunk", "pymunk"),
}
INSTALL_HINT = 'pip install -e ".[engines]"'


@dataclasses.dataclass(frozen=True)
class Setting:
    """One engine in one configuration, as the engines study measures it.

    ``continuous`` says whether the setting detects collisions continuously (None: the
    engine has no such switch); ``options`` are the adapter's keyword arguments.
    """

    key: str
    engine: str
    label: str
    options: dict = dataclasses.field(default_factory=dict)
    continuous: bool | None = None

    def build(self, model, collisions=None, dt: float = 0.01, y0=None) -> EngineRun:
        return build(self.engine, model, collisions, dt, y0, **self.options)

    @property
    def available(self) -> bool:
        return available(self.engine)


#: the settings of the engines study, in its order
SETTINGS = {s.key: s for s in (
    Setting("mujoco-euler", "mujoco", "MuJoCo Euler", {"integrator": "Euler"}, False),
    Setting("mujoco-rk4", "mujoco", "MuJoCo RK4", {"integrator": "RK4"}, False),
    Setting("mujoco-implicit", "mujoco", "MuJoCo implicit", {"integrator": "implicit"}, False),
    Setting("mujoco-implicitfast", "mujoco", "MuJoCo implicitfast", {"integrator": "implicitfast"}, False),
    Setting("mujoco-discrete", "mujoco", "MuJoCo discrete", {"integrator": "discrete"}, False),
    Setting("bullet-default", "bullet", "Bullet default", {}, False),
    Setting("bullet-no-position-correction", "bullet", "Bullet, position correction off",
            {"position_correction": False}, False),
    Setting("bullet-ccd", "bullet", "Bullet, CCD on", {"ccd": True}, True),
    Setting("box2d-continuous-off", "box2d", "Box2D, continuous off", {"continuous": False}, False),
    Setting("box2d-default", "box2d", "Box2D default", {}, True),
    Setting("box2d-bullet", "box2d", "Box2D, bullets", {"bullet": True}, True),
    Setting("chipmunk", "chipmunk", "Chipmunk", {}, False),
)}


def available(engine: str) -> bool:
    """Whether ``engine``'s Python package is installed (without importing it)."""
    return importlib.util.find_spec(_entry(engine)[1]) is not None


def missing() -> list[str]:
    """The distributions of the engines that are not installed."""
    return [ENGINES[name][2] for name in ENGINES if not available(name)]


def build(engine: str, model, collisions=None, dt: float = 0.01, y0=None, **options) -> EngineRun:
    """The adapter of ``engine`` (a key of :data:`ENGINES`) built on a model and its collisions.

    Raises
    ------
    UnsupportedFeatureError
        A feature of the scene the engine cannot express (one line).
    EngineNotInstalledError
        The engine's package is not installed.
    ValueError
        An unknown engine or option.
    """
    path = _entry(engine)[0]
    module, name = path.split(":")
    cls = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    try:
        run = cls(model, collisions, dt, y0=y0, **options)
    except TypeError as err:
        if "unexpected keyword" in str(err):
            raise ValueError(f"{engine}: {err}") from None
        raise
    # after a divergence the run sets itself up again this way: NaN can stay in an engine's caches
    run.rebuild = lambda self: cls.__init__(self, model, collisions, dt, y0=y0, **options)
    return run


def build_scene(engine: str, scene, **options) -> EngineRun:
    """The adapter of ``engine`` on a loaded :class:`steplab.physics.scene.Scene` (its dt and start)."""
    return build(engine, scene.model, scene.collisions, scene.dt, scene.y0, **options)


def run_scene(engine: str, scene, n_steps: int | None = None, save_every: int = 1, **options):
    """Run ``scene`` in ``engine`` for ``n_steps`` (default: to the scene's t_end); a Trajectory."""
    from steplab.integrators.simulate import step_count

    run = build_scene(engine, scene, **options)
    n = n_steps if n_steps is not None else step_count(scene.t_start, scene.t_end, scene.dt)
    return run.advance(scene.y0, scene.dt, n, t_start=scene.t_start, save_every=save_every)


def _entry(engine: str):
    try:
        return ENGINES[engine]
    except KeyError:
        raise ValueError(f"unknown engine {engine!r}; valid: {', '.join(ENGINES)}") from None
