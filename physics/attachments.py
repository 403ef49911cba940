"""Springs and dampers attached at body-frame points of rotating bodies: lever arms and torques.

A pair force may act, at either end, at a point r fixed in a rotating body (in its body frame,
relative to the centre of mass) instead of at its centre. That point is at x + R(q) r in the
world and moves with v + omega x R(q) r. The force F there moves the centre as if it acted at
the centre, and it turns the body with the torque (R r) x F (:func:`.rigid_body.torque_of_forces`).
A spring's length, and so its potential 1/2 k (l - L)^2, is measured between the two points: the
energy of a run is the kinetic energy of both kinds plus that potential.

In a scene file, ``offsets = [[x, y, z], [x, y, z]]`` in a ``[[forces.springs]]`` or
``[[forces.dampers]]`` element gives one body-frame point per end, m (default: the centres). A
non-zero offset on a body that does not rotate is refused. A spring to a fixed world point is a
spring to a pinned point mass there (``pinned = true``), with a zero offset at that end.

A force carries its points as an :class:`Attachment`, with their lever arms R(q) r at the
orientations it is evaluated at; :func:`model_at` gives the model at other orientations, a new
one each time, and :class:`LeverArms` one model whose arms it turns in place, for a step that
takes them at every substep (the contact solver's). Both rotate all the attached forces' points
at once (:class:`AttachedPoints`): a scene's springs and dampers are few, so a step's cost is
NumPy's per-call overhead on arrays of a few rows, which grows with the number of calls, not of
rows. The rotation and the translation are then coupled: :mod:`steplab.integrators.attached`
steps them together. A force without offsets has no attachment and does exactly what it did
before. Every function here takes the model's array namespace (NumPy, or jax.numpy inside the
compiled loop), so both backends evaluate the same formulas.
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import NamedTuple

import numpy as np

from . import quaternion as quat
from . import rules

#: what a scene is told when it attaches off-centre to a point mass
NEEDS_ROTATION = ("a point attachment needs a rotating body: give it a shape, inertia, orientation or "
                  "angular_velocity")


class Attachment(NamedTuple):
    """Where a pair force acts on its two ends, and the lever arms there now.

    offsets : ndarray, shape (P, 2, 3)
        Body-frame points of the first and second end, relative to the centres of mass, m.
    arms : ndarray, shape (P, 2, 3)
        The same points relative to the centres in the world frame, R(q) r, m.
    velocities : ndarray, shape (P, 2, 3)
        Their velocities relative to the centres, omega x R(q) r, m/s.
    """

    offsets: np.ndarray
    arms: np.ndarray
    velocities: np.ndarray


def attachment_at(xp, offsets, i, j, orientations, angular_velocities) -> Attachment:
    """The :class:`Attachment` of pairs (i, j) at body-frame ``offsets`` (P, 2, 3) for the bodies'
    ``orientations`` (N, 4) and world ``angular_velocities`` (N, 3) (identity and zero for a point mass).

    Each end rotated on its own and the two stacked: the 2P points in one column would take half
    the NumPy calls, but XLA compiles that column into other roundings (an ulp here and there), and
    the compiled loop keeps the numbers it had."""
    offsets = xp.asarray(offsets, dtype=orientations.dtype)
    arms = xp.stack([quat.rotate(xp, orientations[i], offsets[:, 0]), quat.rotate(xp, orientations[j], offsets[:, 1])],
                    axis=1)
    velocities = xp.stack([quat.cross(xp, angular_velocities[i], arms[:, 0]),
                           quat.cross(xp, angular_velocities[j], arms[:, 1])], axis=1)
    return Attachment(offsets, arms, velocities)


def read_offsets(tables, bodies, pairs) -> np.ndarray | None:
    """The ``offsets`` of each element of ``[[forces.springs]]`` or ``[[forces.dampers]]``, (P, 2, 3);
    None when no element gives any (every force acts at the centres, as before).

    ``pairs`` are the elements' (i, j). A non-zero offset on a body that does not rotate is one
    line naming the body (:data:`NEEDS_ROTATION`).
    """
    if not any("offsets" in t.data for t in tables):
        return None
    offsets = np.zeros((len(tables), 2, 3))
    rotating = bodies.rotating if bodies.rotating is not None else np.zeros(bodies.n, bool)
    for k, (t, pair) in enumerate(zip(tables, pairs)):
        if "offsets" not in t.data:
            continue
        points = t.vectors("offsets", maximum=2)
        if len(points) != 2:
            t.fail(f"must be two body-frame points [[x, y, z], [x, y, z]], one per end, got {len(points)}", "offsets")
        for end, body in enumerate(pair):
            if np.any(points[end] != 0) and not rotating[body]:
                t.fail(f"puts an end off the centre of {bodies.names[body]!r}, which does not rotate: "
                       f"{NEEDS_ROTATION}", "offsets")
        offsets[k] = points
    return offsets


def initial_attachment(offsets, i, j, bodies) -> Attachment | None:
    """The attachment at the scene's initial orientations (None without offsets)."""
    if offsets is None:
        return None
    return attachment_at(np, offsets, i, j, bodies.orientations, bodies.angular_velocities)


def point_distance(offsets, k: int, pair, bodies) -> float:
    """The initial distance between the two points of element ``k`` (``offsets`` None: the centres), m:
    its default rest length."""
    a, b = pair
    delta = bodies.positions[b] - bodies.positions[a]
    if offsets is not None:
        delta = delta + (quat.rotate(np, bodies.orientations[b], offsets[k, 1])
                         - quat.rotate(np, bodies.orientations[a], offsets[k, 0]))
    return float(np.linalg.norm(delta))


def attached_forces(model) -> tuple:
    """The forces of ``model`` that act at body-frame points (those with an attachment)."""
    return tuple(f for f in model.forces if getattr(f, "attachment", None) is not None)


class AttachedPoints(NamedTuple):
    """The points of all of a model's attached forces as one block: their lever arms at new
    orientations are then one :func:`attachment_at`, whatever the number of springs and dampers
    (``hung-box`` has a spring and a damper on the same corner).

    places : tuple of int
        Where the attached forces are in ``model.forces``.
    rows : tuple of slice
        Each one's pairs in the block.
    offsets : ndarray, shape (P, 2, 3)
        Their body-frame points, one force's after the other's, m.
    i, j : int ndarray, shape (P,)
        The bodies of the pairs' first and second ends.
    """

    places: tuple
    rows: tuple
    offsets: np.ndarray
    i: np.ndarray
    j: np.ndarray

    @classmethod
    def of(cls, model) -> AttachedPoints:
        """The attached forces' points of ``model`` (none: an empty block)."""
        places = tuple(k for k, f in enumerate(model.forces) if getattr(f, "attachment", None) is not None)
        if not places:
            return cls((), (), np.zeros((0, 2, 3)), np.zeros(0, int), np.zeros(0, int))
        forces = [model.forces[k] for k in places]
        ends = np.cumsum([0] + [len(f.attachment.offsets) for f in forces])
        return cls(places, tuple(slice(a, b) for a, b in zip(ends[:-1], ends[1:])),
                   np.concatenate([np.asarray(f.attachment.offsets, float) for f in forces]),
                   np.concatenate([np.asarray(f.i) for f in forces]), np.concatenate([np.asarray(f.j) for f in forces]))

    def at(self, xp, orientations, angular_velocities) -> Attachment:
        """The block's :class:`Attachment` at ``orientations`` (N, 4) and world ``angular_velocities`` (N, 3)."""
        return attachment_at(xp, self.offsets, self.i, self.j, orientations, angular_velocities)

    def model(self, model, block: Attachment, xp=np, dtype=np.float64):
        """``model`` on ``xp`` in ``dtype``, each attached force acting with its rows of ``block`` (on
        NumPy, views of its arrays); the other forces are the same objects.

        ``model`` is a NumPy model (its arrays are read as constants, also when a compiled step traces
        this with jax.numpy). The result is a model of the same class: the model imports the forces,
        which import this module, so it is not imported here.
        """
        forces = list(model.forces)
        with rules.trusted():  # the parts of a checked model, every step: not checked again
            for place, rows in zip(self.places, self.rows):
                forces[place] = dataclasses.replace(forces[place], attachment=Attachment(*(a[rows] for a in block)))
            with contextlib.nullcontext() if xp is np else _constants_folded():
                return type(model)(np.asarray(model.masses), np.asarray(model.radii), forces, model.pinned,
                                   model.names, xp, dtype)


def model_at(model, orientations, angular_velocities, xp=np, dtype=np.float64):
    """``model`` with every attached force's lever arms at these ``orientations`` (N, 4) and world
    ``angular_velocities`` (N, 3), on the array namespace ``xp`` in precision ``dtype``: a new model,
    which nothing changes later (:class:`LeverArms` is the one that does)."""
    points = AttachedPoints.of(model)
    return points.model(model, points.at(xp, orientations, angular_velocities), xp, dtype)


class LeverArms:
    """One NumPy model of ``model`` in precision ``dtype`` (its lever arms in the first orientations'
    precision, as :func:`model_at` builds them) whose attached forces' lever arms :meth:`turn` rewrites
    in place.

    Building a model (:func:`model_at`: a Model, a copy of each force, each cast again) is some 60
    of the 270 us that ``hung-box``'s forces and torques would cost the contact solver at each
    substep (its points rotated as one block; 390 us before that). A step that takes them at every
    substep or stage and lets no model out (:class:`.collision.rigid_solver_step.RigidSolverStep`,
    the NumPy :class:`steplab.integrators.attached.AttachedStep`) builds it once here: its attached
    forces' arms and velocities are views of one :class:`Attachment` (:meth:`AttachedPoints.model`),
    and :meth:`turn` copies those at the new orientations into it. The forces read them when they are
    evaluated, so :attr:`model` is the model at the last turn's orientations, bit for bit what
    :func:`model_at` builds there; a caller that keeps it past the next turn sees it turn too, so it
    takes what it needs from it (forces, torques) before that turn.
    """

    def __init__(self, model, orientations, angular_velocities, dtype=np.float64):
        self.points = AttachedPoints.of(model)
        self.block = self.points.at(np, orientations, angular_velocities)
        self.model = self.points.model(model, self.block, np, dtype)

    def turn(self, orientations, angular_velocities):
        """:attr:`model`, its lever arms now at ``orientations`` (N, 4) and world ``angular_velocities`` (N, 3)."""
        turned = self.points.at(np, orientations, angular_velocities)
        np.copyto(self.block.arms, turned.arms)
        np.copyto(self.block.velocities, turned.velocities)
        return self.model


def _constants_folded():
    """Inside a compiled step, the model's constant arrays (masses, gravity's field) stay concrete
    while it is built, as the model reads some of them back with NumPy; the lever arms are traced."""
    import jax

    return jax.ensure_compile_time_eval()


def torques(model, q, v):
    """The torque about each body's centre, world frame, (N, 3), N m, of ``model``'s attached forces
    at positions ``q`` and velocities ``v`` (N, 3).

    Each pair's force F on its first end (-F on its second) at the body-frame point r gives
    (R r) x F (:func:`.rigid_body.torque_of_forces`) with the lever arm R r its attachment holds:
    the one F was evaluated with, not rotated again. A point mass's entries are zero.
    """
    xp = model.xp
    total = xp.zeros_like(q)
    for f in attached_forces(model):
        force = f.pair_force(xp, q, v)
        arms = f.attachment.arms  # each end on its own, as attachment_at rotates them (XLA rounds alike)
        total = _add_rows(xp, total, f.i, quat.cross(xp, arms[:, 0], force))
        total = _add_rows(xp, total, f.j, quat.cross(xp, arms[:, 1], -force))
    return total


def _add_rows(xp, total, index, rows):
    """``total`` with ``rows`` added at ``index`` (repeated indices add up)."""
    if xp is np:
        np.add.at(total, index, rows)
        return total
    return total.at[index].add(rows)
