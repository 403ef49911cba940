"""The force registry: every force a scene file can declare, by its key under ``[forces]``.

Each force class owns its entry: its ``name`` is the scene key (``[forces.gravity]``,
``[[forces.springs]]``), ``array_of_tables`` says which of the two forms it takes and
``from_scene`` reads its table. The scene builder looks the keys of a ``[forces]`` table
up here and knows nothing of any one force, so a new force (a test's, a plugin's) is
declarable in scene files the moment it is registered::

    @register_force
    @dataclasses.dataclass(frozen=True)
    class Buoyancy(Force):
        name: ClassVar[str] = "buoyancy"
        ...
        @classmethod
        def from_scene(cls, table, bodies): ...

Other distributions add theirs through the ``steplab.forces`` entry points
(``buoyancy = "my_forces:Buoyancy"``, see :mod:`.plugins`), loaded on first use.
"""

from __future__ import annotations

import re

from steplab.core.registry import PluginError, Registry

from .central_gravity import CentralGravity
from .constant_force import ConstantForce
from .dampers import Dampers
from .drag import Drag
from .force import Force
from .friction import Friction
from .gravity import Gravity
from .springs import Springs

#: a scene key must be a bare TOML key, so that ``[forces.<name>]`` needs no quotes
SCENE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _as_force(obj) -> tuple[str, type[Force]]:
    """A registry entry from what a plugin names: a Force subclass that reads its scene table."""
    if not (isinstance(obj, type) and issubclass(obj, Force)):
        raise PluginError(f"{obj!r} is not a subclass of steplab.physics.Force")
    name = obj.name
    if not isinstance(name, str) or not SCENE_KEY.fullmatch(name) or name == Force.name:  # "force": none given
        raise PluginError(f"force class {obj.__qualname__} needs a class attribute name = \"...\" (its scene "
                          f"key: letters, digits, _ and -), got {name!r}")
    if getattr(obj.from_scene, "__func__", None) is Force.from_scene.__func__:
        raise PluginError(f"force class {obj.__qualname__} needs a classmethod from_scene(table, bodies) "
                          "that reads its scene table")
    return name, obj


#: every force a scene file can declare, by scene key: steplab's own, then those of installed
#: plugins (the "steplab.forces" entry points, loaded on first use; see steplab.core.registry)
FORCES: Registry = Registry("steplab.forces", "force", [(cls.name, cls) for cls in (
    Gravity, CentralGravity, Springs, Dampers, Drag, Friction, ConstantForce,
)], _as_force)


def register_force(cls: type[Force]) -> type[Force]:
    """Make ``cls`` declarable in scene files as ``[forces.<cls.name>]``; returns ``cls``, so it
    also serves as a class decorator.

    Raises
    ------
    steplab.core.registry.PluginError
        Not a Force subclass with a scene key and a ``from_scene``, or the key is taken by
        another class ("force name 'gravity' is taken (by steplab); choose another name").
    """
    return FORCES.register(cls, origin="register_force")
