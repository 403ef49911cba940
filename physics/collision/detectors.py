"""The collision detectors, chosen per scene: ``none``, ``overlap`` and ``swept``.

Both real detectors share what happens to pairs already in contact at the start of a
(sub-)step: touching and approaching faster than the rest speed is an impact right away
(s = 0); touching and slower is a resting contact (left to :mod:`.resting`). They differ in how they find
the collisions of pairs that were apart: overlap testing looks at the end of the step
and bisects (:mod:`.overlap`), intersection testing computes the time of impact
(:mod:`.swept`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from steplab.core.registry import Registry, function_entry

from . import overlap, swept
from .approach import approach_speeds

#: detector name -> collision_times(pairs, radii, q0, q1, iterations) -> (s, bracket start), None for
#: "none" (no collision handling); the one list of detectors: the world's validation and the scene
#: schema read it, then registered ones and those of the "steplab.detectors" entry points
_OWN = (("none", None), ("overlap", overlap.collision_times), ("swept", swept.collision_times))
DETECTORS: Registry = Registry("steplab.detectors", "collision detector", _OWN,
                               function_entry("collision_times(pairs, radii, q0, q1, iterations)"))
#: steplab's own detectors, by name (the command line's --detector choices; reading the registry
#: would load its plugins at import)
DETECTOR_NAMES = tuple(name for name, _ in _OWN)


@dataclasses.dataclass(frozen=True)
class Impact:
    """The earliest collision of a sub-step: pair ``k`` of candidate group ``pairs`` at fraction ``s``."""

    s: float
    lo: float
    pairs: object
    k: int


@dataclasses.dataclass
class StartState:
    """The pairs of a group at the start of a sub-step: touching (within the slop), approach speed.

    ``rest_speed`` (per pair, m/s): a touching pair approaching slower than this is a resting
    contact, not an impact (see :func:`physics.collision.step.rest_speeds`).
    """

    in_contact: np.ndarray
    speed: np.ndarray
    normal: np.ndarray
    rest_speed: np.ndarray | float = 0.0

    @property
    def impacting(self) -> np.ndarray:
        return self.in_contact & (self.speed > self.rest_speed)

    @property
    def resting(self) -> np.ndarray:
        return self.in_contact & ~(self.speed > self.rest_speed)


def start_state(pairs, radii, y, slop: float) -> StartState:
    contact = pairs.contact(radii, y[0])
    speed = approach_speeds(y[1][pairs.i], pairs.velocity_b(y[1]), contact.normal)
    return StartState(contact.penetration_depth >= -slop, speed, contact.normal)


def pair_times(detector: str, pairs, start: StartState, radii, y0, y1, iterations: int):
    """Each pair's collision time in the sub-step ``y0 -> y1``: (s, bracket start), ``inf`` for none.

    Touching and approaching faster than the rest speed is an impact at s = 0 (not for a
    trigger shape: a body already inside one has not entered it); touching and slower is
    a resting contact (``inf``); pairs apart get the detector's times.
    """
    s, lo = np.full(len(pairs), np.inf), np.zeros(len(pairs))
    if not pairs.trigger:
        s[start.impacting] = 0.0
    apart = np.flatnonzero(~start.in_contact)
    if apart.size:
        s[apart], lo[apart] = DETECTORS[detector](pairs.subset(apart), radii, y0[0], y1[0], iterations)
    return s, lo


def earliest_impact(detector: str, groups, starts, radii, y0, y1, iterations: int, ignored) -> Impact | None:
    """The first collision while bodies move from ``y0`` to ``y1``, or ``None``.

    ``starts`` holds the :class:`StartState` of each group at ``y0``. Trigger shapes report
    entries only: a body already inside one is not a collision. Pairs whose key is in
    ``ignored`` (cancelled earlier in the step) are skipped.
    """
    best = None
    for pairs, start in zip(groups, starts):
        s, lo = pair_times(detector, pairs, start, radii, y0, y1, iterations)
        if ignored:
            for k in np.flatnonzero(np.isfinite(s)):
                if pairs.key(k) in ignored:
                    s[k] = np.inf
        k = int(np.argmin(s))
        if s[k] < (best.s if best is not None else np.inf):
            best = Impact(float(s[k]), float(lo[k]), pairs, k)
    return best
