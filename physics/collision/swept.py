"""Intersection (swept) testing: predict the collision within the step, in closed form.

Each body's motion over the step is the chord from its start to its end position (the
sphere sweeps a capsule); :mod:`.time_of_impact` gives the fraction of the step at which
two swept shapes first touch. The simulation is advanced to the earliest one, the
collision is resolved there and the rest of the step is simulated, so no collision is
missed however fast the bodies move.
"""

from __future__ import annotations


def collision_times(pairs, radii, q0, q1, iterations: int):
    """For pairs apart at the start: (time of impact, the same as the bracket start), inf for none."""
    s = pairs.time_of_impact(radii, q0, q1)
    return s, s
