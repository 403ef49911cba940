"""Studies: functions from parameters to a result record; plotting only reads records.

Each study module defines ``STUDY`` (a :class:`studies.runner.Study`) and is listed in
:data:`STUDIES`, which ``steplab study`` and ``steplab reproduce`` run.
"""

from __future__ import annotations

# Only the installed name: run from the repository root, ``import studies`` would find this
# folder too, and a Numba kernel cached under that foreign name fails to load elsewhere.
if __name__ != "steplab.studies":
    raise ImportError(f"{__name__} is steplab's studies/ folder imported under the wrong name: "
                      "import steplab.studies instead")

from steplab.core.registry import BUILTIN, PluginError, Registry

from . import (
    broadphase,
    contacts,
    engines,
    frame_rate,
    restitution,
    rotation,
    scene_tour,
    stability,
    truncation,
    tunnelling,
    work_precision,
)
from .runner import Study as Study
from .runner import run_study as run_study


def _as_study(obj) -> tuple[str, Study]:
    """A registry entry from what a "steplab.studies" entry point names: a Study."""
    if not isinstance(obj, Study):
        raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a steplab.studies.Study")
    return obj.name, obj


#: every study, by name: steplab's own, in the order ``steplab reproduce`` runs them, then
#: those of installed plugins ("steplab.studies" entry points), which ``steplab study NAME``
#: runs and ``reproduce`` leaves out (it reproduces the paper's records)
STUDIES: Registry = Registry("steplab.studies", "study", [(s.name, s) for s in (
    truncation.STUDY, stability.STUDY, work_precision.STUDY, frame_rate.STUDY, scene_tour.STUDY,
    restitution.STUDY, tunnelling.STUDY, broadphase.STUDY, contacts.STUDY, engines.STUDY, rotation.STUDY,
)], _as_study)


def builtin_studies() -> list[Study]:
    """steplab's own studies, in the order ``steplab reproduce`` runs them."""
    return [study for name, study in STUDIES.items() if STUDIES.origin(name) == BUILTIN]
