"""Rigid bodies that rotate: principal inertia from a shape, the rotational state, torques.

A rotating body is a point mass of the translational state (:mod:`.state`: its centre of
mass moves as before, bit for bit) plus an orientation and an angular velocity, kept here in
a structure of their own beside it. :class:`RigidBodies` holds them for the R rotating
bodies of a scene (``index`` says which of the N bodies they are): the principal moments
(R, 3) in the body frame, the orientations (R, 4) as unit quaternions [w, x, y, z] (body to
world, :mod:`.quaternion`) and the angular velocities (R, 3) in the world frame, as the
scene file and ``steplab run --json`` give them. The rotation methods
(:mod:`steplab.integrators.rotation`) work in the body frame, where the inertia is diagonal.

A contact solver (issue 26) reads the same arrays: ``index`` gathers the rotating bodies'
rows of the translational state; a sphere that does not rotate has no row here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import quaternion as quat
from .rules import SMALLEST_INVERTIBLE, invertible

SHAPES = ("sphere", "box", "capsule", "cylinder")
#: relative slack on the triangle inequality I1 + I2 >= I3: a thin plate has I1 + I2 = I3
#: exactly, which the moments computed from its size meet only to round-off
TRIANGLE_SLACK = 1e-12


class InertiaError(ValueError):
    """Principal moments that are not those of a body; the message is one line."""


def principal_inertia(shape: str, mass: float, radius: float, size=None, length: float | None = None) -> np.ndarray:
    """Principal moments [I1, I2, I3] (kg m^2) of a uniform solid about its centre of mass.

    Parameters
    ----------
    shape : {"sphere", "box", "capsule", "cylinder"}
    mass : float
        kg.
    radius : float
        m; the sphere's, or the capsule's and cylinder's (about the body z axis).
    size : array, shape (3,)
        The box's full edges (a, b, c), m.
    length : float
        The cylinder's length, or the capsule's cylindrical part (the distance between
        the centres of its two hemispherical caps, as Box2D and Box3D define a capsule), m,
        along the body z axis.

    Notes
    -----
    sphere 2/5 m r^2; box m/12 (b^2 + c^2, a^2 + c^2, a^2 + b^2); cylinder
    m/12 (3 r^2 + l^2) about x and y, m r^2 / 2 about z. The capsule is the cylinder (mass
    m_c in proportion to its volume pi r^2 l) and the two caps (m_s, volume 4/3 pi r^3):
    I3 = m_c r^2 / 2 + 2/5 m_s r^2 and I1 = m_c (l^2/12 + r^2/4) + m_s (2/5 r^2 + l^2/4 + 3 l r / 8),
    each cap's centre of mass lying 3r/8 beyond the end of the cylinder.
    """
    if shape not in SHAPES:
        raise InertiaError(f"unknown shape {shape!r}; valid: {', '.join(SHAPES)}")
    if shape == "sphere":
        return np.full(3, 0.4 * mass * radius * radius)
    if shape == "box":
        a2, b2, c2 = np.asarray(size, float) ** 2
        return mass / 12 * np.array([b2 + c2, a2 + c2, a2 + b2])
    r2, l2 = radius * radius, length * length
    if shape == "cylinder":
        across = mass / 12 * (3 * r2 + l2)
        return np.array([across, across, 0.5 * mass * r2])
    else:  # the capsule
        cylinder, caps = math.pi * r2 * length, 4 / 3 * math.pi * r2 * radius
        m_c, m_s = mass * cylinder / (cylinder + caps), mass * caps / (cylinder + caps)
        across = m_c * (l2 / 12 + r2 / 4) + m_s * (0.4 * r2 + l2 / 4 + 3 * length * radius / 8)
        return np.array([across, across, 0.5 * m_c * r2 + 0.4 * m_s * r2])


def _first_bad(values, bad) -> str:
    """The first offending row of ``values`` for a one-line message: ``[I1, I2, I3]``, and for many
    bodies which one and how many (a scene of 10^5 bodies must not print them all)."""
    values, bad = np.asarray(values), np.asarray(bad)
    if values.ndim <= 1:
        return str(values.tolist())
    rows = np.flatnonzero(bad.reshape(-1))
    first = values.reshape(-1, values.shape[-1])[rows[0]].tolist()
    return f"{first} (row {rows[0]}, the first of {rows.size} such among {bad.size} bodies)"


def check_inertia(inertia) -> np.ndarray:
    """``inertia`` as float64 (..., 3) principal moments, or one line saying why it is no body's.

    The moments must be finite and positive and obey the triangle inequality (each at most
    the sum of the other two: I3 = sum m (x^2 + y^2) <= I1 + I2 = sum m (x^2 + y^2 + 2 z^2)).
    For many bodies the line names the first offending one and how many there are.
    """
    inertia = np.asarray(inertia, dtype=float)
    if inertia.shape[-1:] != (3,):
        raise InertiaError(f"inertia must be three principal moments [I1, I2, I3] kg m^2, got shape {inertia.shape}")
    finite = np.all(np.isfinite(inertia), axis=-1)
    if not np.all(finite):
        raise InertiaError(f"inertia must be finite, got {_first_bad(inertia, ~finite)}")
    positive = np.all(inertia > 0, axis=-1)
    if not np.all(positive):
        raise InertiaError(f"inertia must be > 0 kg m^2 in every moment, got {_first_bad(inertia, ~positive)}")
    inverse = np.all(invertible(inertia), axis=-1)
    if not np.all(inverse):  # a subnormal moment: I^-1 L overflows on the first step
        raise InertiaError(f"inertia must be at least {SMALLEST_INVERTIBLE:.3g} kg m^2 in every moment (a smaller one "
                           f"has no finite inverse), got {_first_bad(inertia, ~inverse)}")
    ordered = np.sort(inertia, axis=-1)
    broken = ordered[..., 0] + ordered[..., 1] < ordered[..., 2] * (1 - TRIANGLE_SLACK)
    if np.any(broken):
        raise InertiaError(f"inertia {_first_bad(inertia, broken)} breaks the triangle inequality (the two smaller "
                           "moments must sum to at least the largest): no body has these moments")
    return inertia


def shape_inertia_problem(shape: str, inertia) -> str | None:
    """Why the principal moments a shape's formula gave (:func:`principal_inertia`) are no body's: they
    overflowed, or underflowed to 0 or below the smallest moment with a finite inverse; None when fine."""
    inertia = np.asarray(inertia, dtype=float)
    if np.all(np.isfinite(inertia) & (inertia > 0) & invertible(inertia)):
        return None
    return (f"the {shape}'s principal moments {inertia.tolist()} kg m^2 are not each finite and at least "
            f"{SMALLEST_INVERTIBLE:.3g} kg m^2 (a smaller one has no finite inverse): the numbers overflow or "
            "underflow")


def check_orientation(orientation) -> np.ndarray:
    """``orientation`` [w, x, y, z] normalised, or one line: a zero or non-finite quaternion."""
    q = np.asarray(orientation, dtype=float)
    if q.shape[-1:] != (4,):
        raise InertiaError(f"orientation must be a finite quaternion [w, x, y, z], got shape {q.shape}")
    finite = np.all(np.isfinite(q), axis=-1)
    if not np.all(finite):
        raise InertiaError(f"orientation must be a finite quaternion [w, x, y, z], got {_first_bad(q, ~finite)}")
    scale = np.max(np.abs(q), axis=-1, keepdims=True)  # scaled first: no overflow or underflow
    if not np.all(scale > 0):
        raise InertiaError("orientation must be a non-zero quaternion [w, x, y, z], got "
                           f"{_first_bad(q, scale[..., 0] == 0)}")
    q = q / scale
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class RigidBodies:
    """The rotating bodies of a scene and their state.

    Attributes
    ----------
    index : int ndarray, shape (R,)
        Which of the scene's N bodies rotate.
    inertia : ndarray, shape (R, 3)
        Principal moments in the body frame, kg m^2.
    orientations : ndarray, shape (R, 4)
        Unit quaternions [w, x, y, z], body to world.
    angular_velocities : ndarray, shape (R, 3)
        World frame, rad/s.
    shapes : tuple of str
    """

    index: np.ndarray
    inertia: np.ndarray
    orientations: np.ndarray
    angular_velocities: np.ndarray
    shapes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return len(self.index)

    def body_angular_velocities(self) -> np.ndarray:
        """omega in the body frame, (R, 3): what the rotation methods integrate."""
        return quat.rotate_inverse(np, self.orientations, self.angular_velocities)

    def of_all(self, n_bodies: int) -> tuple[np.ndarray, np.ndarray]:
        """The orientations (N, 4) and world angular velocities (N, 3) of all ``n_bodies`` of the scene, new
        arrays: these bodies' own at their ``index``, the identity and zero for a point mass."""
        orientations = np.tile(quat.IDENTITY, (n_bodies, 1)).astype(float)
        angular_velocities = np.zeros((n_bodies, 3))
        orientations[self.index], angular_velocities[self.index] = self.orientations, self.angular_velocities
        return orientations, angular_velocities

    def kinetic_energy(self) -> float:
        """Rotational kinetic energy sum 1/2 omega . I omega (body frame), J."""
        return rotational_energy(np, self.inertia, self.body_angular_velocities()).sum()

    def angular_momenta(self) -> np.ndarray:
        """Each body's spin angular momentum R I omega_body about its centre of mass, world frame, (R, 3)."""
        return quat.rotate(np, self.orientations, self.inertia * self.body_angular_velocities())


def rotational_energy(xp, inertia, omega_body):
    """1/2 omega . I omega per body, J: shape (...)."""
    return 0.5 * (inertia[..., 0] * omega_body[..., 0] ** 2 + inertia[..., 1] * omega_body[..., 1] ** 2
                  + inertia[..., 2] * omega_body[..., 2] ** 2)


def total_angular_momentum(positions, velocities, masses, bodies: RigidBodies | None = None) -> np.ndarray:
    """The scene's angular momentum about the origin, kg m^2/s: sum m x x v plus each rotating body's spin."""
    total = np.sum(np.asarray(masses)[:, None] * np.cross(positions, velocities), axis=0)
    if bodies is not None and bodies.n:
        total = total + bodies.angular_momenta().sum(axis=0)
    return total


def torque_of_forces(xp, orientations, body_points, forces):
    """Torque about the centre of mass of forces applied at body-frame points, world frame.

    Parameters
    ----------
    orientations : array, shape (..., 4)
    body_points : array, shape (..., 3)
        Where each force acts, in the body frame relative to the centre of mass, m.
    forces : array, shape (..., 3)
        World frame, N.

    Returns
    -------
    array, shape (..., 3)
        (R r) x F, N m. Summing these over the points of one body (and the forces
        themselves for its net force) gives the body's wrench.
    """
    return quat.cross(xp, quat.rotate(xp, orientations, body_points), forces)


@dataclasses.dataclass(frozen=True)
class RotationModel:
    """What the rotation methods integrate: principal moments and the torque on each body.

    ``torque(xp, t, q, omega_body)`` returns the body-frame torque (R, 3); the torque-free
    body (``torques = ()``) is Euler's free rigid body. Each torque term is an object with
    ``torque(xp, t, q, omega_body) -> world torque (R, 3)``.
    """

    inertia: np.ndarray
    torques: tuple = ()
    #: the array namespace the methods compute with (:mod:`._array`)
    xp: object = dataclasses.field(default=np, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "inertia", check_inertia(self.inertia))

    def torque(self, xp, t, q, omega_body):
        """Net torque in the body frame, (R, 3), N m."""
        if not self.torques:
            return xp.zeros_like(omega_body)
        world = sum(term.torque(xp, t, q, omega_body) for term in self.torques)
        return quat.rotate_inverse(xp, q, world)


@dataclasses.dataclass(frozen=True)
class ForceAtPoint:
    """A constant world-frame force F applied at the body-frame point r: torque (R r) x F.

    With the pivot as the origin of the body frame and F = -M g e_z at the centre of mass
    r = d e3, it is the heavy top's gravity (the inertia then about the pivot).
    """

    body_point: np.ndarray
    force: np.ndarray

    def torque(self, xp, t, q, omega_body):
        return torque_of_forces(xp, q, xp.asarray(self.body_point), xp.asarray(self.force))


#: the [[bodies]] keys of a rotating body (beside mass, radius, position, velocity)
SCENE_KEYS = ("shape", "size", "length", "inertia", "orientation", "angular_velocity")


def from_scene_body(t, mass: float, radius: float):
    """(shape, inertia, orientation, angular velocity) of one [[bodies]] table, or None for a point mass.

    A body rotates when it has a non-sphere ``shape`` or any of ``inertia``, ``orientation``
    and ``angular_velocity``; a sphere that rotates gets 2/5 m r^2. ``t`` is the body's
    :class:`.scene_toml.Table`: every refusal is one line naming the file and key.
    """
    if not any(key in t.data for key in SCENE_KEYS):  # a point mass, as before: nothing more to read
        return None
    from .rules import short
    from .scene_toml import REQUIRED

    shape = t.string("shape", "sphere", choices=SHAPES)
    if "size" in t.data and shape != "box":
        t.fail(f'is the edges of a box; this body\'s shape is "{shape}"', "size")
    if "length" in t.data and shape not in ("capsule", "cylinder"):
        t.fail(f'is the length of a capsule or cylinder; this body\'s shape is "{shape}"', "length")
    if shape == "sphere" and not any(key in t.data for key in ("inertia", "orientation", "angular_velocity")):
        return None
    size = t.vector("size", REQUIRED, positive=True) if shape == "box" else None
    length = (t.number("length", REQUIRED, positive=shape == "cylinder", nonnegative=True)
              if shape in ("capsule", "cylinder") else None)
    if "inertia" in t.data:
        try:
            inertia = check_inertia(t.vector("inertia", REQUIRED))
        except InertiaError as err:
            t.fail(str(err), "inertia")
    else:
        inertia = principal_inertia(shape, mass, radius, size, length)
        problem = shape_inertia_problem(shape, inertia)
        if problem:
            t.fail(f"{problem}; give inertia = [I1, I2, I3]")
    orientation = t.raw("orientation", [1.0, 0.0, 0.0, 0.0])
    if (not isinstance(orientation, list) or len(orientation) != 4
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in orientation)):
        t.fail(f"must be a quaternion [w, x, y, z] of 4 numbers, got {short(orientation)}", "orientation")
    try:
        orientation = check_orientation([float(x) for x in orientation])
    except (InertiaError, OverflowError) as err:
        t.fail(str(err) if isinstance(err, InertiaError) else "must be finite", "orientation")
    return shape, inertia, orientation, t.vector("angular_velocity", [0.0, 0.0, 0.0])
