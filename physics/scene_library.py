"""The named scenes: steplab's own TOML files, then those of installed plugins.

``steplab run cloth`` finds ``cloth`` here. steplab's scenes ship in ``physics/scenes/``;
a distribution adds its own through the ``steplab.scenes`` entry points, each naming
either a package whose folder holds ``*.toml`` files (read with :mod:`importlib.resources`,
so it works from a wheel or a zip) or a callable returning the paths of TOML files::

    [project.entry-points."steplab.scenes"]
    my-scenes = "my_package.scenes"             # a package folder of *.toml files
    generated = "my_package.make:scene_paths"   # a callable -> [path, ...]

A scene's name is its file name without ``.toml``; a name steplab's own scenes (or an
earlier plugin) already use is skipped with one warning line.
"""

from __future__ import annotations

import types
from importlib import resources
from pathlib import Path

from steplab.core.registry import PluginError, Registry

SUFFIX = ".toml"


def _toml_files(folder) -> list[tuple[str, object]]:
    """(name, file) for each ``*.toml`` in a folder (a Path or an importlib.resources Traversable)."""
    return sorted((f.name.removesuffix(SUFFIX), f) for f in folder.iterdir() if f.name.endswith(SUFFIX))


def _as_scenes(obj) -> list[tuple[str, object]]:
    """The scenes a "steplab.scenes" entry point brings: a package's folder of TOML files, or
    the paths a callable returns."""
    if isinstance(obj, types.ModuleType):
        if not hasattr(obj, "__path__"):
            raise PluginError(f"module {obj.__name__} is not a package (a folder of .toml files)")
        return _toml_files(resources.files(obj))
    if callable(obj):
        paths = [Path(p) for p in obj()]
        wrong = [str(p) for p in paths if p.suffix != SUFFIX or not p.is_file()]
        if wrong:
            raise PluginError(f"not a .toml file: {', '.join(wrong)}")
        return [(p.name.removesuffix(SUFFIX), p) for p in paths]
    raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a package of .toml files or a callable "
                      "returning their paths")


#: every named scene, name -> its TOML file: steplab's own, then those of installed plugins
#: (the "steplab.scenes" entry points, loaded on first use; see steplab.core.registry)
SCENES: Registry = Registry("steplab.scenes", "scene", _toml_files(resources.files("steplab.physics") / "scenes"),
                            _as_scenes)
