"""Frame-rate independence: fixed physics steps consuming variable frame times."""

from __future__ import annotations

import math
from fractions import Fraction


class GameLoop:
    """The accumulator ("physics lag") loop of the lecture, with exact time bookkeeping.

    Each rendered frame hands over its frame time; the loop runs as many fixed physics
    steps of ``dt`` as fit into the time owed, and carries the remainder to the next
    frame. ``alpha = remainder / dt`` in [0, 1) is the render interpolation factor
    between the last two physics states.

    Two departures from the lecture's pseudo-code, on purpose:

    - it steps while ``lag >= dt`` (the lecture's ``lag > dt`` skips a step whenever the
      lag is exactly dt, so the physics falls a frame behind on exact frame times);
    - the lag is kept as an exact rational sum of the (binary) frame times, so whether a
      step runs never depends on floating-point round-off in the accumulator. The
      physics state therefore depends only on the number of steps, and any two frame
      sequences with the same total give bit-identical states.

    Parameters
    ----------
    step : callable
        ``step()`` advances the physics by one fixed ``dt``.
    dt : float
        Physics step, s.
    max_steps_per_frame : int
        Cap on steps per frame (the "spiral of death" guard); excess lag is dropped.
    """

    def __init__(self, step, dt: float, max_steps_per_frame: int = 1000):
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be finite and > 0, got {dt}")
        if isinstance(max_steps_per_frame, bool) or not isinstance(max_steps_per_frame, int) \
                or max_steps_per_frame < 1:  # the cap is what bounds a frame's work: it must exist
            raise ValueError(f"max_steps_per_frame must be an integer >= 1, got {max_steps_per_frame!r}")
        self._step = step
        self.dt = dt
        self._dt = Fraction(dt)
        self.max_steps_per_frame = max_steps_per_frame
        self._lag = Fraction(0)
        self.steps = 0
        self.dropped = Fraction(0)

    def advance(self, frame_time: float) -> float:
        """Consume one frame's time; return the interpolation factor alpha."""
        if not (frame_time >= 0 and math.isfinite(frame_time)):
            raise ValueError(f"frame time must be finite and >= 0, got {frame_time}")
        self._lag += Fraction(frame_time)
        taken = 0
        while self._lag >= self._dt:
            if taken == self.max_steps_per_frame:
                excess = self._lag - self._lag % self._dt
                self.dropped += excess
                self._lag -= excess
                break
            self._step()
            self._lag -= self._dt
            self.steps += 1
            taken += 1
        return self.alpha

    @property
    def alpha(self) -> float:
        """Fraction of a step owed: render at (1 - alpha) previous + alpha current."""
        return float(self._lag / self._dt)


def interpolate(previous, current, alpha: float):
    """Render state between the last two physics states."""
    return (1 - alpha) * previous + alpha * current
