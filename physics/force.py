"""The interface every force model implements.

A force is small immutable data (its parameters as arrays) and pure functions of the
state. It never knows which integrator calls it. Forces are evaluated with an explicit
array namespace ``xp`` so the same formula serves the NumPy and the JAX paths.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np


@dataclasses.dataclass(frozen=True)
class Force:
    """Base class: a force on N bodies, vectorised over bodies or over pairs."""

    #: name used in scene files and reports
    name: ClassVar[str] = "force"
    #: True when the force is independent of state and time (the ``exact`` integrator needs it)
    constant: ClassVar[bool] = False
    #: True when the force reacts to the sum of the other forces (ground contact)
    reactive: ClassVar[bool] = False

    def force(self, xp, q, v, m):
        """Force on each body, shape (N, 3), for positions ``q`` and velocities ``v`` (N, 3)."""
        raise NotImplementedError

    def jacobian(self, xp, q, v, m):
        """``(dF/dq, dF/dv)``, each (N, 3, N, 3) or ``None`` when identically zero.

        Implicit integrators use it; a force whose Jacobian is not provided is treated
        as frozen over the Newton iteration (still converges, just more slowly).
        """
        return None, None

    def potential(self, xp, q, m):
        """Potential energy (a scalar) or ``None`` for a non-conservative force."""
        return None

    def cast(self, xp, dtype) -> Force:
        """This force with its float arrays in namespace ``xp`` and precision ``dtype``."""
        changes = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if hasattr(value, "dtype"):  # a NumPy or JAX array
                value = np.asarray(value)
                kind = dtype if np.issubdtype(value.dtype, np.floating) else value.dtype
                changes[field.name] = xp.asarray(value, dtype=kind)
        return dataclasses.replace(self, **changes)
