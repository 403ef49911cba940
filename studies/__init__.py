"""Studies: functions from parameters to a result record; plotting only reads records.

Each study is registered in :data:`STUDIES` under its name. The error, stability,
work-precision, collision and broadphase studies arrive in later issues; for now the
registry holds the tour of the built-in scenes that ``steplab reproduce`` runs.
"""

from __future__ import annotations

from .scene_tour import scene_tour as scene_tour

#: name -> study function ``f(quick: bool, progress) -> record``
STUDIES = {"scenes": scene_tour}
