"""The bodies' motion inside a step: each on a straight chord, from where it last changed to the end.

At the start of a step every body's chord runs from its state y to its integrated end
state y_end. A collision at time t_c gives its bodies a new chord, from their state
just after the collision to their new end state; every other body stays on its chord.
A body's state at time t is the point of its chord at fraction
(t - t_from) / (t_end - t_from), positions and velocities alike (:mod:`.step`).

Only the states of the bodies a collision involves are ever computed (O(1) per
collision, not O(N)); they are written into one state array, :attr:`Chords.now`, whose
other rows are stale. The swept bounds of every body's rest of the step are kept beside
the chords: the step's bounds (:func:`.pairs.candidates`) contain every later part of
an unchanged chord, and a changed body's bounds are replaced by its new chord's.
"""

from __future__ import annotations

import numpy as np


class Chords:
    """Every body's chord in one step, and the swept bounds of what is left of it.

    Parameters
    ----------
    y, y_end : ndarray, shape (2, N, 3)
        States at the start and at the end of the step (``y_end`` is shared and updated in place).
    t, t_end : float
        The step.
    radii : ndarray, shape (N,)
    margin : float
        Added to every reach (the contact slop).
    """

    def __init__(self, y, y_end, t, t_end, radii, margin):
        self.y_from = y.copy()
        self.now = y.copy()
        self.y_end = y_end
        self.t_from = np.full(len(radii), float(t))
        self.t_end = t_end
        self.radii = radii
        self.centers, self.reach = swept_bounds(y[0], y_end[0], radii, margin)

    def at(self, bodies, t, t_sub=None, s=None) -> np.ndarray:
        """Write the states of ``bodies`` at time ``t`` into :attr:`now` and return it.

        A body whose chord starts at ``t_sub`` is placed at the given fraction ``s`` (the
        detector's own number, so the point of impact is where the test found it).
        """
        t_from = self.t_from[bodies]
        length = self.t_end - t_from
        f = np.divide(t - t_from, length, out=np.zeros_like(length), where=length > 0)
        if t_sub is not None:
            f[t_from == t_sub] = s
        y0 = self.y_from[:, bodies]
        self.now[:, bodies] = y0 + f[None, :, None] * (self.y_end[:, bodies] - y0)
        return self.now

    def restart(self, bodies, t, y_rest, margin) -> None:
        """``bodies`` continue from their states in :attr:`now` at ``t`` to their new end states ``y_rest``."""
        self.y_from[:, bodies] = self.now[:, bodies]
        self.t_from[bodies] = t
        self.y_end[:, bodies] = y_rest
        self.centers[bodies], self.reach[bodies] = swept_bounds(self.y_from[0, bodies], y_rest[0],
                                                                self.radii[bodies], margin)


def swept_bounds(q0, q1, radii, margin):
    """Spheres holding the bodies along their chords ``q0 -> q1``: centre, reach (:func:`.pairs.candidates`)."""
    return 0.5 * (q0 + q1), radii + 0.5 * np.sqrt(np.sum((q1 - q0) ** 2, axis=1)) + margin
