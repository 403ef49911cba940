"""The model: bodies plus the forces a scene declares, as the right-hand side of
Newton's second law that every integrator sees.

``a(t, q, v) = F_net(t, q, v) / m``. Only declared forces are evaluated: a gravity-only
model's acceleration is the constant g, with no spring arrays and no branches for
absent forces (the force sum is assembled once, when the model is built). All constant
forces (gravity, a steady wind) are one acceleration field, added once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from . import constraints
from .force import Force
from .rules import mass_problem, number_problem, numeric, require, short, skip_checks

#: the largest (3N)^2 float64 matrix :meth:`Model.jacobian` builds (it holds about six: the Jacobians,
#: their scatter, a method's Newton matrix): 1 GiB is N = 3,862 bodies
DENSE_MAX_MATRIX_BYTES = 2**30


def dense_problem(n_bodies: int) -> str | None:
    """Why the dense (3N)^2 Jacobians of ``n_bodies`` cannot be built (over :data:`DENSE_MAX_MATRIX_BYTES`: a
    MemoryError, 671 GiB at 10^5 bodies, or swapping), or None."""
    size = 8 * (3 * n_bodies) ** 2
    if size <= DENSE_MAX_MATRIX_BYTES:
        return None
    return (f"the dense Jacobian of {n_bodies:,} bodies needs (3N)^2 matrices of {size / 2**30:.3g} GiB each (at "
            f"most {DENSE_MAX_MATRIX_BYTES / 2**30:g} GiB, steplab.physics.model.DENSE_MAX_MATRIX_BYTES); on the "
            "NumPy backend implicit-euler solves such a model by conjugate gradients on the sparse Jacobian "
            "(linear_solver 'auto' or 'cg')")


class Model:
    """Bodies and forces on one array backend and precision.

    Parameters
    ----------
    masses : array, shape (N,)
        kg, positive.
    radii : array, shape (N,)
        m, positive (bounding spheres; drag and collisions use them).
    forces : sequence of Force
    pinned : bool array, shape (N,), optional
        Pinned bodies never move (infinite inertia): cloth corners, anchors.
    names : sequence of str, optional
    xp : module
        ``numpy`` or ``jax.numpy``.
    dtype : numpy dtype
        ``float64`` (default) or ``float32``.
    """

    def __init__(self, masses, radii, forces: Sequence[Force] = (), pinned=None, names=None,
                 xp=np, dtype=np.float64):
        forces = tuple(forces)
        masses, pinned, names = self._checked(masses, radii, forces, pinned, names)
        n = masses.shape[0]
        self.xp = xp
        self.dtype = np.dtype(dtype)
        self.names = tuple(names) if names is not None else tuple(f"body{i}" for i in range(n))
        self.pinned = pinned
        self.masses = xp.asarray(masses, dtype=self.dtype)
        self.radii = xp.asarray(np.asarray(radii, dtype=float), dtype=self.dtype)
        self.inverse_masses = xp.asarray(np.where(pinned, 0.0, 1.0 / masses), dtype=self.dtype)
        self._source_forces = tuple(forces)  # float64 NumPy originals, for cast()
        self.forces = tuple(f.cast(xp, self.dtype) for f in forces)

        self._applied = tuple(f for f in self.forces if not f.reactive)
        self._reactive = tuple(f for f in self.forces if f.reactive)
        constant = [f for f in self._applied if f.constant]
        self._varying = tuple(f for f in self._applied if not f.constant)
        # The constant forces are one acceleration field, summed once: gravity's is g itself
        # (not m g / m), another's F / m. Pinned bodies must not move, so there the field is
        # masked per body.
        field = sum((f.constant_acceleration(masses) for f in constant), np.zeros(3))
        if pinned.any():
            field = np.where(pinned[:, None], 0.0, np.broadcast_to(field, (n, 3)))
        self._field = xp.asarray(field, dtype=self.dtype) if constant else None
        self.acceleration = self._assemble_acceleration()
        # stiffness = inf springs are constraints: a force evaluation would be inf * 0, so every
        # method that asks for the acceleration or its Jacobian is refused, and the energy counts
        # them as 0 (an enforced constraint's potential); position-based methods read
        # distance_constraints()
        self._energy_forces = self.forces
        self.inextensible = constraints.has_inextensible(self.forces)
        if self.inextensible:
            self._energy_forces = constraints.without_inextensible(self.forces)
            self.acceleration = self._refuse_inextensible

    @staticmethod
    def _checked(masses, radii, forces, pinned, names):
        """The bodies as a scene file's rules allow them (ValueError or TypeError, one line, else):
        at least one body; masses > 0 with a finite inverse, radii > 0, finite, one of each per
        body; ``pinned`` booleans and ``names`` strings, one per body; forces that fit them
        (unchecked inside :func:`.rules.trusted`: the parts of a model already checked)."""
        if skip_checks():
            masses = np.asarray(masses, dtype=float)
            pinned = np.zeros(masses.shape[0], bool) if pinned is None else np.asarray(pinned, bool)
            return masses, pinned, names
        arr = numeric(masses)
        if arr is None or arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"Model: masses must be one mass per body, numbers of shape (N,) with N >= 1, got "
                             f"{short(masses)}")
        require("Model: masses", mass_problem(arr))
        masses = np.asarray(masses, dtype=float)
        n = masses.shape[0]
        require("Model: radii", number_problem(radii, positive=True))
        if np.shape(radii) != (n,):
            raise ValueError(f"Model: radii must be one radius per body, shape ({n},) as masses, got shape "
                             f"{np.shape(radii)}")
        if pinned is None:
            pinned = np.zeros(n, bool)
        else:
            pinned = np.asarray(pinned)
            if pinned.dtype != bool or pinned.shape != (n,):
                raise ValueError(f"Model: pinned must be one boolean per body, shape ({n},), got {short(pinned)}")
        if names is not None:
            if isinstance(names, str) or not all(isinstance(name, str) for name in names):
                raise TypeError(f"Model: names must be a sequence of strings, one per body, got {short(names)}")
            names = tuple(names)
            if len(names) != n:
                raise ValueError(f"Model: names must name each of the {n} bodies, got {len(names)} names")
        for f in forces:
            check = getattr(f, "check_bodies", None)
            if check is not None:
                check(n)
        return masses, pinned, names

    @property
    def n_bodies(self) -> int:
        return self.masses.shape[0]

    @property
    def reactive_forces(self) -> tuple:
        """The forces that need the sum of all the others (ground contact)."""
        return self._reactive

    @property
    def varying_forces(self) -> tuple:
        """The applied forces that depend on the time or the state (not summed into the field)."""
        return self._varying

    @property
    def constant_field(self):
        """The constant forces' acceleration field, summed once ((3,), or (N, 3) with pinned
        bodies); None without constant forces."""
        return self._field

    def cast(self, xp=None, dtype=None) -> Model:
        """The same model on another backend and/or precision."""
        return Model(np.asarray(self.masses, dtype=float), np.asarray(self.radii, dtype=float),
                     self._source_forces, self.pinned, self.names,
                     xp or self.xp, dtype or self.dtype)

    @staticmethod
    def _refuse_inextensible(t, q, v):
        raise constraints.inextensible_error()

    def require_forces(self) -> None:
        """Refuse, in one line (:class:`.constraints.InextensibleSpringError`), to evaluate forces
        where a spring is inextensible (stiffness = inf): its force would be inf * 0. Every path
        that computes the forces or their Jacobian without ``acceleration`` calls this first."""
        if self.inextensible:
            raise constraints.inextensible_error()

    def distance_constraints(self) -> constraints.DistanceConstraints:
        """The springs as distance constraints, float64 NumPy (:mod:`.constraints`), for position-based methods.

        Raises :class:`.constraints.NotConstraintsError` (one line) for a model with forces
        that are neither springs, dampers on springs nor constant.
        """
        return constraints.distance_constraints(self._source_forces)

    # --- forces --------------------------------------------------------------------------

    def net_force(self, t, q, v):
        """Net force on each body, shape (N, 3), N."""
        xp, m = self.xp, self.masses
        f = xp.zeros_like(q)
        for term in self._applied:
            f = f + term.force(xp, q, v, m)
        for term in self._reactive:
            f = f + term.force(xp, q, v, m, f)
        return f

    def _assemble_acceleration(self):
        xp, m, inv_m, field = self.xp, self.masses, self.inverse_masses, self._field
        terms = self._varying
        if self._reactive:
            # Ground contact needs the sum of all other forces, gravity included.
            return lambda t, q, v: self.net_force(t, q, v) * inv_m[:, None]
        if not terms:
            if field is None:
                return lambda t, q, v: xp.zeros_like(q)
            return lambda t, q, v: xp.broadcast_to(field, q.shape)

        def acceleration(t, q, v):
            f = terms[0].force(xp, q, v, m)
            for term in terms[1:]:
                f = f + term.force(xp, q, v, m)
            a = f * inv_m[:, None]
            return a if field is None else a + field

        return acceleration

    def vector_field(self, t, y):
        """The first-order system y' = f(t, y) with y = (q, v), shape (2, N, 3)."""
        return self.xp.stack([y[1], self.acceleration(t, y[0], y[1])])

    @property
    def constant_acceleration(self):
        """The acceleration (N, 3) when the total force is constant, else ``None``.

        The sum of every constant force's acceleration (gravity's field g, another's F / m),
        zero on pinned bodies: what the ``exact`` integrator and ``recommend`` solve in closed form.
        """
        if any(not f.constant for f in self.forces):
            return None
        if self._field is None:
            return self.xp.zeros((self.n_bodies, 3), dtype=self.dtype)
        return self.xp.broadcast_to(self._field, (self.n_bodies, 3))

    def jacobian(self, t, q, v):
        """``(da/dq, da/dv)``, each of shape (3N, 3N).

        Built from the forces' analytic Jacobians; reactive forces (ground contact) are
        held fixed, which implicit integrators tolerate as a quasi-Newton iteration.
        """
        self.require_forces()
        xp, n = self.xp, self.n_bodies
        if problem := dense_problem(n):
            raise ValueError(problem)
        dq = xp.zeros((n, 3, n, 3), dtype=self.dtype)
        dv = xp.zeros((n, 3, n, 3), dtype=self.dtype)
        for term in self._applied:
            jq, jv = term.jacobian(xp, q, v, self.masses)
            if jq is not None:
                dq = dq + jq
            if jv is not None:
                dv = dv + jv
        scale = self.inverse_masses[:, None, None, None]
        return (dq * scale).reshape(3 * n, 3 * n), (dv * scale).reshape(3 * n, 3 * n)

    def jacobian_blocks(self, t, q, v, definite: bool = False) -> list:
        """The applied forces' Jacobians as 3x3 blocks (:meth:`Force.jacobian_blocks`), of those that have one.

        With ``definite``, each force's semidefinite part, which implicit Euler's conjugate
        gradients fall back to; :mod:`.sparse_jacobian` assembles them.
        """
        self.require_forces()
        blocks = (term.jacobian_blocks(self.xp, q, v, self.masses, definite) for term in self._applied)
        return [b for b in blocks if b is not None]

    def sparse_jacobian(self, t, q, v):
        """``(da/dq, da/dv)`` as (3N, 3N) scipy sparse (BSR) arrays: :func:`.sparse_jacobian.sparse_jacobian`."""
        from .sparse_jacobian import sparse_jacobian

        return sparse_jacobian(self, t, q, v)

    # --- energy --------------------------------------------------------------------------

    def kinetic_energy(self, v):
        return 0.5 * self.xp.sum(self.masses[:, None] * v * v)

    def potential_energy(self, q):
        """Sum of the potentials of the conservative forces (gravity, springs, constant forces), J."""
        total = 0.0
        for term in self._energy_forces:
            u = term.potential(self.xp, q, self.masses)
            if u is not None:
                total = total + u
        return total

    def energy(self, y, rigid_bodies=None):
        """Mechanical energy, kinetic plus potential, J; with ``rigid_bodies`` (a
        physics.rigid_body.RigidBodies at the same instant) their rotational kinetic energy too."""
        energy = self.kinetic_energy(y[1]) + self.potential_energy(y[0])
        return energy if rigid_bodies is None else energy + rigid_bodies.kinetic_energy()
