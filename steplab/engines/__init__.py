"""Game-physics engines as systems under test: MuJoCo, Bullet, Box2D and Chipmunk on steplab's scenes,
NVIDIA Newton on its spring-mass scenes.

Each adapter (one module per engine) builds the engine's bodies, forces and shapes from a
steplab scene and steps it at the scene's dt; ``advance(y0, dt, n_steps)`` returns a
steplab :class:`~steplab.integrators.Trajectory` with the engine's contacts as a collision
log, so the studies measure an engine by the same code as steplab's own integrators. An
adapter declares its engine's facts (display name, colour, planar or 3-D, precision, its
package, and the settings the engines study measures with the steplab method each is
expected to step and why its bounce deviates): see :class:`.base.EngineRun`. The registry
:data:`ENGINES` holds the adapters by key; another engine is its adapter module plus
``ENGINES.register(MyRun)`` (or a ``steplab.engines`` entry point). None of the engines is
a dependency of steplab: they are the optional extra ``pip install -e ".[engines]"`` (Newton,
which is large, its own: ``pip install -e ".[newton]"``) and are imported only when an adapter
is built.

>>> from steplab.engines import SETTINGS
>>> SETTINGS["mujoco-euler"].engine
'mujoco'
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from steplab.core.registry import PluginError, Registry

from .base import EngineNotInstalledError as EngineNotInstalledError
from .base import EngineRun as EngineRun
from .base import Setting as Setting
from .base import UnsupportedFeatureError as UnsupportedFeatureError
from .base import build_adapter
from .box2d_engine import Box2DRun
from .bullet_engine import BulletRun
from .chipmunk_engine import ChipmunkRun
from .mujoco_engine import MujocoRun
from .newton_engine import NewtonRun

INSTALL_HINT = 'pip install -e ".[engines]"'


def _as_engine(obj) -> tuple[str, type[EngineRun]]:
    """A registry entry from what a plugin names: an EngineRun subclass that declares its facts."""
    if not (isinstance(obj, type) and issubclass(obj, EngineRun)):
        raise PluginError(f"{obj!r} is not a subclass of steplab.engines.EngineRun")
    if obj.engine == EngineRun.engine or not obj.display_name or not obj.study_settings:
        raise PluginError(f"engine adapter {obj.__qualname__} needs class attributes engine (its key), "
                          "display_name and study_settings (a tuple of steplab.engines.Setting)")
    return obj.engine, obj


#: every engine adapter, by key: steplab's four game engines, Newton (spring-mass scenes, no
#: contacts: the extra ``steplab[newton]``), then registered ones and those of the
#: "steplab.engines" entry points (loaded on first use)
ENGINES: Registry = Registry("steplab.engines", "engine", [(cls.engine, cls) for cls in (
    MujocoRun, BulletRun, Box2DRun, ChipmunkRun, NewtonRun)], _as_engine)


class _Settings(Mapping):
    """Setting key -> :class:`Setting`, read from the registered adapters that express contacts
    each time (in their order)."""

    def __init__(self, kind: str = "study_settings"):
        self.kind = kind

    def _all(self) -> dict[str, Setting]:
        # the engines study measures contacts: only the adapters that express them
        return {s.key: s for cls in ENGINES.values() if cls.contacts or self.kind != "study_settings"
                for s in getattr(cls, self.kind)}

    def __getitem__(self, key: str) -> Setting:
        return self._all()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


#: the settings of the engines study, in its order: the ``study_settings`` of each adapter with contacts
SETTINGS: Mapping[str, Setting] = _Settings()
#: the settings of the rotation study's engines (a free rigid body): each adapter's ``rotation_settings``
ROTATION_SETTINGS: Mapping[str, Setting] = _Settings("rotation_settings")


def available(engine: str) -> bool:
    """Whether ``engine``'s Python package is installed (without importing it)."""
    return ENGINES.lookup(engine).available()


def missing() -> list[str]:
    """The distributions of the engines the engines study measures (those with contacts) that are not installed."""
    return [cls.distribution for cls in ENGINES.values() if cls.contacts and not cls.available()]


def build(engine: str, model, collisions=None, dt: float = 0.01, y0=None, bodies=None, **options) -> EngineRun:
    """The adapter of ``engine`` (a key of :data:`ENGINES`) built on a model, its collisions and
    its rotating ``bodies`` (a :class:`steplab.physics.rigid_body.RigidBodies`, or None).

    Raises
    ------
    UnsupportedFeatureError
        A feature of the scene the engine cannot express (one line).
    EngineNotInstalledError
        The engine's package is not installed.
    ValueError
        An unknown engine (:class:`steplab.core.registry.UnknownNameError`) or option.
    """
    return build_adapter(ENGINES.lookup(engine), model, collisions, dt, y0, bodies, **options)


def build_scene(engine: str, scene, **options) -> EngineRun:
    """The adapter of ``engine`` on a loaded :class:`steplab.physics.scene.Scene` (its dt, start and
    rotating bodies)."""
    return build(engine, scene.model, scene.collisions, scene.dt, scene.y0, scene.rigid_bodies, **options)


def run_scene(engine: str, scene, n_steps: int | None = None, save_every: int = 1, **options):
    """Run ``scene`` in ``engine`` for ``n_steps`` (default: to the scene's t_end); a Trajectory."""
    from steplab.integrators.simulate import step_count

    run = build_scene(engine, scene, **options)
    n = n_steps if n_steps is not None else step_count(scene.t_start, scene.t_end, scene.dt)
    return run.advance(scene.y0, scene.dt, n, t_start=scene.t_start, save_every=save_every)
