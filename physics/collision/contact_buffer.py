"""The contact solver's contacts of one step: broadphase once, narrow phase every candidate.

The broadphase runs once per step over each body's swept bound: its bounding sphere from
where it is to where its forces alone would take it in the step, q + dt (v + dt a), padded
by a margin (:func:`.pairs.candidates`). Every candidate pair, body-body or body-shape, is
tested by the narrow phase (:mod:`.narrow_phase`) at the start of the step, and becomes a
contact: its normal, its separation (negative: penetration) and its approach speed there.
A contact still apart is *speculative*: the solver lets the pair close the gap and no more,
which is what keeps a fast body from tunnelling through a thin wall (Catto, "Speculative
Contacts", 2013). The normal is the one at the start of the step; two bodies that would
pass each other sideways can therefore touch "speculatively" (a ghost collision), the
approximation engines accept for it.

Contacts are sorted by a key, one integer per pair (body i against body j or static shape
k), so that the Gauss-Seidel order, and with it every result, is the same for the same
input, and so that last step's impulses can be found again for the warm start.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from .pairs import BodyPairs, candidates
from .shapes import DEFAULT_MATERIAL

#: the speculative margin added to every swept bound, as a fraction of the median radius: a
#: body sped up by a contact during the step can still reach this much further than its forces take it
MARGIN_OF_RADIUS = 0.25


@dataclasses.dataclass(frozen=True)
class Materials:
    """Restitution and friction per contact, looked up by material numbers (vectorised)."""

    body: np.ndarray  # (N,) material number of each body
    shape: np.ndarray  # (S,) material number of each static shape
    restitution: np.ndarray  # (M, M)
    friction: np.ndarray  # (M, M)

    @classmethod
    def of(cls, world, n_bodies: int) -> Materials:
        names = sorted({world.material(b) for b in range(n_bodies)} | {s.material for s in world.shapes}
                       | {DEFAULT_MATERIAL})
        number = {name: k for k, name in enumerate(names)}
        table = [[world.pair_properties.lookup(a, b) for b in names] for a in names]
        return cls(np.array([number[world.material(b)] for b in range(n_bodies)], dtype=np.int64),
                   np.array([number[s.material] for s in world.shapes], dtype=np.int64),
                   np.array([[e for e, _ in row] for row in table], dtype=float).reshape(len(names), -1),
                   np.array([[mu for _, mu in row] for row in table], dtype=float).reshape(len(names), -1))


@dataclasses.dataclass
class Contacts:
    """The contacts of one step, sorted by ``key``; ``j`` is -1 and ``shape`` >= 0 against a static shape."""

    i: np.ndarray
    j: np.ndarray
    shape: np.ndarray
    key: np.ndarray
    normal: np.ndarray  # (C, 3), from body i towards j (or the shape)
    separation: np.ndarray  # s0, m
    normal_speed: np.ndarray  # v_n- = (v_j - v_i) . n at the start of the step, m/s (< 0: approaching)
    pressing: np.ndarray  # (a_i - a_j) . n, m/s^2: the forces pushing the pair together
    mass: np.ndarray  # 1 / (1/m_i + 1/m_j), kg
    restitution: np.ndarray
    friction: np.ndarray

    @classmethod
    def empty(cls) -> Contacts:
        index, value = np.zeros(0, np.int64), np.zeros(0)
        return cls(index, index, index, index, np.zeros((0, 3)), value, value, value, value, value, value)

    def __len__(self) -> int:
        return len(self.key)

    def subset(self, keep) -> Contacts:
        return Contacts(**{f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self)})


def find_contacts(world, materials: Materials, q, v, a, radii, inverse_masses, dt: float, removed=()) -> Contacts:
    """Every contact the bodies (q, v) under accelerations ``a`` may make during a step of ``dt``."""
    n, n_shapes = len(radii), len(world.shapes)
    margin = MARGIN_OF_RADIUS * float(np.median(radii)) if n else 0.0
    groups = candidates(world.shapes, q, q + dt * (v + dt * a), radii, inverse_masses, world.broadphase,
                        removed, margin)
    parts = []
    for group in groups:
        i = group.i
        if isinstance(group, BodyPairs):  # most contacts of a pile: one compiled pass
            parts.append(_body_contacts(i, group.j, q, v, a, radii, inverse_masses, materials.body,
                                        materials.restitution, materials.friction, n + n_shapes))
            continue
        contact = group.contact(radii, q)
        j, shape = np.full(len(i), -1), np.full(len(i), group.index)
        other = n + group.index
        e = materials.restitution[materials.body[i], materials.shape[group.index]]
        mu = materials.friction[materials.body[i], materials.shape[group.index]]
        v_other, a_other, w_other = 0.0, 0.0, 0.0
        normal = np.atleast_2d(contact.normal)
        parts.append((i, j, shape, i * (n + n_shapes) + other, normal, -contact.penetration_depth,
                      np.sum((v_other - v[i]) * normal, axis=1), np.sum((a[i] - a_other) * normal, axis=1),
                      1.0 / (inverse_masses[i] + w_other), np.broadcast_to(e, i.shape), np.broadcast_to(mu, i.shape)))
    if not parts:
        return Contacts.empty()
    columns = [np.concatenate(column) for column in zip(*parts)]
    contacts = Contacts(*columns)
    order = np.argsort(contacts.key, kind="stable")
    return contacts.subset(order)


@njit(cache=True)
def _body_contacts(i, j, q, v, a, radii, inverse_masses, material, restitution, friction, stride):
    """The columns of :class:`Contacts` for body pairs (i, j): the sphere-sphere narrow phase
    (:func:`.narrow_phase.collide_sphere_sphere`, the same numbers) and each pair's properties."""
    k = len(i)
    normal = np.empty((k, 3))
    separation, normal_speed, pressing = np.empty(k), np.empty(k), np.empty(k)
    mass, e, mu = np.empty(k), np.empty(k), np.empty(k)
    for p in range(k):
        b, c = i[p], j[p]
        d0, d1, d2 = q[c, 0] - q[b, 0], q[c, 1] - q[b, 1], q[c, 2] - q[b, 2]
        dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dist > 0:
            n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
        else:  # concentric: +x by convention
            n0, n1, n2 = 1.0, 0.0, 0.0
        normal[p, 0], normal[p, 1], normal[p, 2] = n0, n1, n2
        separation[p] = -(radii[b] + radii[c] - dist)
        normal_speed[p] = (v[c, 0] - v[b, 0]) * n0 + (v[c, 1] - v[b, 1]) * n1 + (v[c, 2] - v[b, 2]) * n2
        pressing[p] = (a[b, 0] - a[c, 0]) * n0 + (a[b, 1] - a[c, 1]) * n1 + (a[b, 2] - a[c, 2]) * n2
        mass[p] = 1.0 / (inverse_masses[b] + inverse_masses[c])
        e[p] = restitution[material[b], material[c]]
        mu[p] = friction[material[b], material[c]]
    return (i, j, np.full(k, -1), i * stride + j, normal, separation, normal_speed, pressing, mass, e, mu)
