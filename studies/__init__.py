"""Studies: functions from parameters to a result record; plotting only reads records.

Each study module defines ``STUDY`` (a :class:`studies.runner.Study`) and is listed in
:data:`STUDIES`, which ``steplab study`` and ``steplab reproduce`` run.
"""

from __future__ import annotations

from . import broadphase, frame_rate, restitution, scene_tour, stability, truncation, tunnelling, work_precision
from .runner import Study as Study
from .runner import run_study as run_study

#: every study, by name, in the order ``steplab reproduce`` runs them
STUDIES: dict[str, Study] = {s.name: s for s in (
    truncation.STUDY, stability.STUDY, work_precision.STUDY, frame_rate.STUDY, scene_tour.STUDY,
    restitution.STUDY, tunnelling.STUDY, broadphase.STUDY,
)}
