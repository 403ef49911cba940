"""An integrator with the settings a scene gives it in ``[simulation.<integrator>]``.

The settings of a method are its dataclass fields (``xpbd``'s ``substeps`` and
``iterations``, ``implicit-euler``'s ``rtol``): a scene's table sets them by name, and the
method's own ``__post_init__`` checks their values.
"""

from __future__ import annotations

import dataclasses

from .base import Integrator
from .registry import get_integrator


def configured(integrator: str | Integrator, settings: dict, where: str = "") -> Integrator:
    """``integrator`` with ``settings`` (field name -> value) replacing its defaults.

    Raises
    ------
    ValueError
        One line, prefixed with ``where``: a key that is not a setting of the method (with the
        ones it has), or a value its checks refuse.
    """
    integrator = get_integrator(integrator)
    if not settings:
        return integrator
    prefix = f"{where}: " if where else ""
    fields = sorted(f.name for f in dataclasses.fields(integrator) if f.init)
    unknown = sorted(set(settings) - set(fields))
    if unknown:
        allowed = ", ".join(fields) if fields else "none"
        raise ValueError(f"{prefix}{unknown[0]!r} is not a setting of {integrator.name} (its settings: {allowed})")
    try:
        return dataclasses.replace(integrator, **settings)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{prefix}{err}") from None


def scene_integrator(scene, name: str | None = None) -> Integrator:
    """The integrator a run of ``scene`` uses: ``name`` (``--integrator``) or the scene's own,
    with the scene's settings when it is the scene's integrator."""
    name = name or scene.integrator
    settings = scene.integrator_settings if name == scene.integrator else {}
    return configured(name, settings, f"scene {scene.name}: [simulation.{name}]")
