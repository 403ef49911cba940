"""The rotation methods' registry (kind ``rotation``), beside :data:`.registry.INTEGRATORS`:
their own, since their names ("rk4") are those of the translation methods they pair with. A
scene's ``[simulation] rotation = "NAME"`` and ``--rotation NAME`` look them up here;
``steplab.rotations`` entry points add more."""

from __future__ import annotations

from steplab.core.registry import PluginError, Registry, UnknownNameError

from .registry import UnknownIntegratorError, _as_integrator
from .rotation import DEFAULT_ROTATION as DEFAULT_ROTATION
from .rotation import METHODS as ROTATION_METHODS
from .rotation import RotationMethod


def _as_rotation(obj) -> tuple[str, RotationMethod]:
    """A registry entry from what a plugin names: a RotationMethod instance, or a class made with no arguments."""
    if isinstance(obj, type) and issubclass(obj, RotationMethod):
        obj = obj()
    if not isinstance(obj, RotationMethod):
        raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a steplab.integrators.RotationMethod")
    return _as_integrator(obj)


#: every rotation method by name: steplab's own, then the "steplab.rotations" entry points
ROTATIONS: Registry = Registry("steplab.rotations", "rotation method",
                               [(method.name, method) for method in ROTATION_METHODS], _as_rotation)


def get_rotation(method: str | RotationMethod) -> RotationMethod:
    """The rotation method ``method`` (a name in :data:`ROTATIONS`, or a RotationMethod).

    Raises
    ------
    UnknownIntegratorError
        One line naming the valid methods.
    """
    if isinstance(method, RotationMethod):
        return method
    try:
        return ROTATIONS.lookup(method)
    except UnknownNameError as err:
        raise UnknownIntegratorError(str(err)) from None
