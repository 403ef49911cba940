"""The interface every force model implements.

A force is small immutable data (its parameters as arrays) and pure functions of the
state. It never knows which integrator calls it. Forces are evaluated with an explicit
array namespace ``xp`` so the same formula serves the NumPy and the JAX paths.

A force declarable in scene files also says how: its ``name`` is its key under
``[forces]`` and its ``from_scene`` reads its own table; the registry
(:data:`steplab.physics.forces.FORCES`) maps the key to the class.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .incidence import shared_indices


@dataclasses.dataclass(frozen=True)
class Force:
    """Base class: a force on N bodies, vectorised over bodies or over pairs."""

    #: name used in scene files (the key under [forces]) and reports
    name: ClassVar[str] = "force"
    #: True when a scene declares it as an array of tables ([[forces.springs]], one per element)
    array_of_tables: ClassVar[bool] = False
    #: True when the force is independent of state and time (the ``exact`` integrator needs it)
    constant: ClassVar[bool] = False
    #: True when the force reacts to the sum of the other forces (ground contact)
    reactive: ClassVar[bool] = False

    @classmethod
    def from_scene(cls, table, bodies) -> Force:
        """The force a scene file declares under ``[forces.<name>]``.

        Parameters
        ----------
        table : steplab.physics.scene_toml.Table, or a list of them
            The force's table, checked key by key (``table.allow(...)``, ``table.number(...)``);
            a list of the elements when ``array_of_tables`` (never empty).
        bodies : steplab.physics.scene.SceneBodies
            The scene's bodies: ``masses``, ``radii``, ``positions`` (N,), (N,), (N, 3) arrays,
            ``n``, and the lookups ``indices(table, key)``, ``pair(table)``, ``mask(table, key)``.
        """
        raise NotImplementedError(f"{cls.__qualname__} cannot be declared in a scene file")

    def check_bodies(self, n_bodies: int) -> None:
        """Refuse (ValueError, one line) what does not fit a model of ``n_bodies``: a body index out
        of range, an array of one value per body of another length. The model calls it once,
        when it is built; the default checks nothing."""

    def force(self, xp, q, v, m):
        """Force on each body, shape (N, 3), for positions ``q`` and velocities ``v`` (N, 3)."""
        raise NotImplementedError

    def constant_acceleration(self, m) -> np.ndarray:
        """For a ``constant`` force: the acceleration F / m it gives each body, float64 NumPy.

        Shape (N, 3), or (3,) when the same for every body. The model adds it once as a field
        instead of evaluating F and dividing by m on every evaluation.

        Parameters
        ----------
        m : ndarray, shape (N,)
            Masses, kg.
        """
        m = np.asarray(m, dtype=float)
        rest = np.zeros((m.shape[0], 3))  # a constant force does not depend on q or v
        return np.asarray(self.cast(np, np.float64).force(np, rest, rest, m), dtype=float) / m[:, None]

    def jacobian(self, xp, q, v, m):
        """``(dF/dq, dF/dv)``, each (N, 3, N, 3) or ``None`` when identically zero.

        Implicit integrators use it; a force whose Jacobian is not provided is treated
        as frozen over the Newton iteration (still converges, just more slowly).
        """
        return None, None

    def jacobian_blocks(self, xp, q, v, m, definite: bool = False):
        """The Jacobian as 3x3 blocks, for the sparse assembly; ``None`` when not provided.

        A :class:`~steplab.physics.sparse_jacobian.PairJacobian` (one block per pair) or
        :class:`~steplab.physics.sparse_jacobian.BodyJacobian` (one per body). With
        ``definite``: a part of it whose blocks are symmetric and keep ``-dF/dq`` and
        ``-dF/dv`` positive semidefinite (a damper's dependence on positions and a
        compressed spring's negative stiffness left out), which implicit Euler's conjugate
        gradients fall back to when the symmetric part of the Jacobian makes their
        system indefinite; the Newton iteration converges without what it leaves out,
        which stays in the forces. A force without blocks is frozen over the sparse
        Newton iteration, like ground contact.
        """
        return None

    def potential(self, xp, q, m):
        """Potential energy (a scalar) or ``None`` for a non-conservative force."""
        return None

    def cast(self, xp, dtype) -> Force:
        """This force with its float arrays in namespace ``xp`` and precision ``dtype``.

        Integer arrays (body indices) with equal contents become one array on JAX, so
        forces on the same pairs share their gathers in a compiled step
        (:func:`.incidence.shared_indices`).
        """
        changes = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if hasattr(value, "dtype"):  # a NumPy or JAX array
                value = np.asarray(value)
                if np.issubdtype(value.dtype, np.integer):
                    changes[field.name] = shared_indices(xp, value)
                else:
                    kind = dtype if np.issubdtype(value.dtype, np.floating) else value.dtype
                    changes[field.name] = xp.asarray(value, dtype=kind)
        return dataclasses.replace(self, **changes)
