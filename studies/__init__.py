"""Studies: functions from parameters to a result record; plotting only reads records.

Each study module defines ``STUDY`` (a :class:`studies.runner.Study`) and is listed in
:data:`STUDIES`, which ``steplab study`` and ``steplab reproduce`` run.
"""

from __future__ import annotations

import functools
import importlib

# Only the installed name: run from the repository root, ``import studies`` would find this
# folder too, and a Numba kernel cached under that foreign name fails to load elsewhere.
if __name__ != "steplab.studies":
    raise ImportError(f"{__name__} is steplab's studies/ folder imported under the wrong name: "
                      "import steplab.studies instead")

from steplab.core.lazy_exports import lazy_exports  # noqa: E402

#: the study modules, in the order ``steplab reproduce`` runs them; each defines ``STUDY``
BUILTIN_MODULES = ("truncation", "stability", "work_precision", "frame_rate", "scene_tour", "restitution",
                   "tunnelling", "broadphase", "contacts", "engines", "rotation", "soft_bodies")

# ``Study``, ``run_study`` and the submodules are imported on first use (steplab/core/lazy_exports.py),
# and so is ``STUDIES``, below: importing one module of this package (records, timing) does
# not import every study, nor matplotlib
_getattr, __dir__ = lazy_exports(__name__, {"Study": ".runner", "run_study": ".runner"})


def __getattr__(name: str):
    if name == "STUDIES":
        return _registry()
    return _getattr(name)


@functools.cache
def _registry():
    """:data:`STUDIES`, built on first use: steplab's own studies, in the order ``steplab reproduce``
    runs them, then those of installed plugins ("steplab.studies" entry points), which
    ``steplab study NAME`` runs and ``reproduce`` leaves out (it reproduces the paper's records)."""
    from steplab.core.registry import PluginError, Registry

    from .runner import Study

    def as_study(obj) -> tuple[str, Study]:
        """A registry entry from what a "steplab.studies" entry point names: a Study."""
        if not isinstance(obj, Study):
            raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a steplab.studies.Study")
        return obj.name, obj

    studies = [importlib.import_module(f".{name}", __name__).STUDY for name in BUILTIN_MODULES]
    registry = Registry("steplab.studies", "study", [(s.name, s) for s in studies], as_study)
    globals()["STUDIES"] = registry
    return registry


def builtin_studies() -> list:
    """steplab's own studies, in the order ``steplab reproduce`` runs them."""
    from steplab.core.registry import BUILTIN

    registry = _registry()
    return [study for name, study in registry.items() if registry.origin(name) == BUILTIN]
