"""The bound on impacts per step: large enough never to limit a real scene, and never silent.

The event loop resolves a step's impacts one after the other, earliest first; a step
that keeps producing impacts (an inelastic collapse: a ball squeezed between two others
bouncing ever faster, Zeno's series without the rest speed to end it) would never end.
The cap stops it. It scales with the bodies, :data:`IMPACTS_PER_BODY` per body (a
crowded box of 2,000 balls dropped at eps = 0.8 peaks at under one impact per body and
step), plus :data:`MIN_IMPACTS_PER_STEP` for a few collapsing clusters (three balls
meeting at eps = 0 in a corner of a room at 100 m/s take 439 impacts to come to rest
within one step, and do). A step that reaches it raises :class:`ImpactCapError`: the
remaining impacts are never dropped silently.
"""

from __future__ import annotations

#: impacts per body and step before a step is taken to be stuck (about 20 times the densest
#: scene measured, 2,000 balls crowded into a 6 m box)
IMPACTS_PER_BODY = 16
#: the cap's floor: a few inelastic collapses of a handful of bodies (measured: up to 441 impacts
#: in one step for 3 balls at eps = 0, tests/test_reliability.py's rooms)
MIN_IMPACTS_PER_STEP = 1000


def default_cap(n_bodies: int) -> int:
    """Impacts resolved per step at most when a scene sets no ``max_impacts_per_step``."""
    return MIN_IMPACTS_PER_STEP + IMPACTS_PER_BODY * int(n_bodies)


class ImpactCapError(ArithmeticError):
    """A step holds more impacts than the cap allows; the run stops instead of dropping them.

    Attributes
    ----------
    t : float
        Start time of the step, s.
    impacts : int
        Impacts resolved in the step before the cap stopped it.
    cap : int
        The cap, ``max_impacts_per_step``.
    """

    def __init__(self, t: float, impacts: int, cap: int):
        self.t, self.impacts, self.cap = t, impacts, cap
        super().__init__(f"the step at t = {t:g} s holds more than {cap} impacts ({impacts} resolved); "
                         f"raise the cap with max_impacts_per_step under [collisions] in the scene")
