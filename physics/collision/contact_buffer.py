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
from typing import NamedTuple

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed, approach_speeds
from .pairs import SweptSpheres, near_shapes
from .shapes import DEFAULT_MATERIAL
from .sphere_contacts import plane_height, row3, sphere_plane, sphere_sphere, sub3

#: the speculative margin added to every swept bound, as a fraction of the median radius: a
#: body sped up by a contact during the step can still reach this much further than its forces take it
MARGIN_OF_RADIUS = 0.25


class Materials(NamedTuple):
    """Restitution and friction per contact, looked up by material numbers (vectorised, and in the kernel)."""

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


class BodyState(NamedTuple):
    """The bodies at the start of the step, (N, 3) or (N,)."""

    q: np.ndarray  # positions, m
    v: np.ndarray  # velocities, m/s
    a: np.ndarray  # the forces' accelerations, m/s^2
    radii: np.ndarray  # m
    inverse_masses: np.ndarray  # 1/kg, 0: pinned


class PlaneColumns(NamedTuple):
    """The world's planes n . x <= offset: their numbers among the static shapes, (P,), (P, 3), (P,)."""

    index: np.ndarray
    normal: np.ndarray
    offset: np.ndarray

    @classmethod
    def of(cls, shapes) -> PlaneColumns:
        planes = [k for k, shape in enumerate(shapes) if shape.kind == "plane"]
        return cls(np.array(planes, dtype=np.int64),
                   np.array([shapes[k].normal for k in planes], dtype=float).reshape(-1, 3),
                   np.array([shapes[k].offset for k in planes], dtype=float))


def speculative_margin(radii) -> float:
    """The margin of every swept bound: :data:`MARGIN_OF_RADIUS` of the median radius, m."""
    return MARGIN_OF_RADIUS * float(np.median(radii)) if len(radii) else 0.0


def find_contacts(world, materials: Materials, bodies: BodyState, reached, removed=(),
                  margin: float | None = None) -> Contacts:
    """Every contact the ``bodies`` may make during the step that takes them, under their forces
    alone, to the positions ``reached`` (N, 3) (the scene's integrator's step).

    ``margin``: :func:`speculative_margin` of the radii unless given. Body pairs and planes,
    the contacts of piles and boxes of planes, go through one compiled pass that writes them
    in key order; other static shapes through their narrow phase, the whole then sorted by key.
    """
    n, n_shapes = len(bodies.radii), len(world.shapes)
    margin = speculative_margin(bodies.radii) if margin is None else margin
    swept = SweptSpheres.of(bodies.q, reached, bodies.radii, bodies.inverse_masses, removed, margin)
    pairs = swept.body_pairs(world.broadphase)
    columns = _pair_and_plane_contacts(pairs.i, pairs.j, bodies, swept, PlaneColumns.of(world.shapes), materials,
                                       n + n_shapes)
    others = [k for k, shape in enumerate(world.shapes) if shape.kind != "plane"]
    parts = [columns] + [_shape_contacts(group, materials, bodies, n + n_shapes)
                         for group in near_shapes([world.shapes[k] for k in others], swept, others) if len(group)]
    if len(parts) == 1:  # in key order already
        return Contacts(*columns)
    contacts = Contacts(*[np.concatenate(column) for column in zip(*parts)])
    return contacts.subset(np.argsort(contacts.key, kind="stable"))


def _shape_contacts(group, materials: Materials, bodies: BodyState, stride: int) -> tuple:
    """The columns of :class:`Contacts` for the bodies of a :class:`.pairs.ShapePairs` (its narrow phase)."""
    i, v, a = group.i, bodies.v, bodies.a
    contact = group.contact(bodies.radii, bodies.q)
    e = materials.restitution[materials.body[i], materials.shape[group.index]]
    mu = materials.friction[materials.body[i], materials.shape[group.index]]
    normal = np.atleast_2d(contact.normal)  # the shape is static: no velocity, no acceleration, no mass
    # the approach as the planes' compiled pass writes it, (0 - v_i) . n = -((v_i - 0) . n)
    speed, pressing = -approach_speeds(v[i], AT_REST, normal), approach_speeds(a[i], AT_REST, normal)
    return (i, np.full(len(i), -1), np.full(len(i), group.index), i * stride + len(bodies.radii) + group.index,
            normal, -contact.penetration_depth, speed, pressing, 1.0 / bodies.inverse_masses[i],
            np.broadcast_to(e, i.shape), np.broadcast_to(mu, i.shape))


@njit(cache=True, inline="always")
def _reaches_plane(centers, reach, b, plane_normal, plane_offset, k):
    """Body b's swept sphere reaches plane k, n . x <= offset: n . c - offset <= reach."""
    return plane_height(row3(centers, b), row3(plane_normal, k), plane_offset[k]) <= reach[b]


@njit(cache=True)
def _pair_and_plane_contacts(pi, pj, bodies, swept, planes, materials, stride):
    """The columns of :class:`Contacts` for the body pairs (``pi``, ``pj``; sorted) and the planes,
    in key order: body i's pairs (j ascending), then its planes (world number ascending).

    A moving body's swept sphere (``swept``, a :class:`.pairs.SweptSpheres`) reaches a plane
    n . x <= offset when n . c - offset <= reach. The contacts are
    :func:`.sphere_contacts.sphere_sphere` and :func:`.sphere_contacts.sphere_plane` (the
    narrow phase's), the separation minus their penetration depth.
    """
    q, v, a, radii, inverse_masses = bodies
    plane, plane_normal, plane_offset = planes
    material, restitution, friction = materials.body, materials.restitution, materials.friction
    n, n_planes, n_pairs = len(radii), len(plane), len(pi)
    near = np.zeros((n_planes, n), dtype=np.bool_)
    count = n_pairs
    for k in range(n_planes):  # plane by plane: one vectorisable loop over the bodies
        for b in range(n):
            near[k, b] = swept.active[b] and inverse_masses[b] > 0 and _reaches_plane(
                swept.centers, swept.reach, b, plane_normal, plane_offset, k)
            count += near[k, b]
    ci, cj, shape, key = (np.empty(count, np.int64), np.empty(count, np.int64), np.empty(count, np.int64),
                          np.empty(count, np.int64))
    normal = np.empty((count, 3))
    separation, normal_speed, pressing = np.empty(count), np.empty(count), np.empty(count)
    mass, e, mu = np.empty(count), np.empty(count), np.empty(count)
    row, p = 0, 0
    for b in range(n):
        while p < n_pairs and pi[p] == b:
            c = pj[p]
            (n0, n1, n2), depth = sphere_sphere(sub3(row3(q, c), row3(q, b)), radii[b] + radii[c])
            ci[row], cj[row], shape[row], key[row] = b, c, -1, b * stride + c
            normal[row, 0], normal[row, 1], normal[row, 2] = n0, n1, n2
            separation[row] = -depth
            normal_speed[row] = approach_speed(row3(v, c), row3(v, b), (n0, n1, n2))  # (v_j - v_i) . n
            pressing[row] = approach_speed(row3(a, b), row3(a, c), (n0, n1, n2))
            mass[row] = 1.0 / (inverse_masses[b] + inverse_masses[c])
            e[row] = restitution[material[b], material[c]]
            mu[row] = friction[material[b], material[c]]
            row += 1
            p += 1
        for k in range(n_planes):
            if not near[k, b]:
                continue
            (n0, n1, n2), depth, _ = sphere_plane(row3(q, b), radii[b], row3(plane_normal, k), plane_offset[k])
            ci[row], cj[row], shape[row], key[row] = b, -1, plane[k], b * stride + n + plane[k]
            normal[row, 0], normal[row, 1], normal[row, 2] = n0, n1, n2
            separation[row] = -depth
            # (0 - v_i) . n written as -((v_i - 0) . n): the same bits as before, -0.0 at rest included
            normal_speed[row] = -approach_speed(row3(v, b), AT_REST, (n0, n1, n2))
            pressing[row] = approach_speed(row3(a, b), AT_REST, (n0, n1, n2))
            mass[row] = 1.0 / inverse_masses[b]
            e[row] = restitution[material[b], materials.shape[plane[k]]]
            mu[row] = friction[material[b], materials.shape[plane[k]]]
            row += 1
    return ci, cj, shape, key, normal, separation, normal_speed, pressing, mass, e, mu


@njit(cache=True)
def previous_rows(old_key, key):
    """Each contact's row in the last step's contacts (same key), or -1: one merge of the sorted keys."""
    rows = np.full(len(key), -1, dtype=np.int64)
    p = 0
    for k in range(len(key)):
        while p < len(old_key) and old_key[p] < key[k]:
            p += 1
        if p < len(old_key) and old_key[p] == key[k]:
            rows[k] = p
    return rows


@njit(cache=True)
def warm_start(previous, old_pn, old_pt, normal):
    """The impulses each contact starts from: its last step's (0 if new), the tangential one kept
    in the new contact plane (its normal part removed)."""
    m = len(previous)
    pn, pt = np.zeros(m), np.zeros((m, 3))
    for k in range(m):
        p = previous[k]
        if p < 0:
            continue
        pn[k] = old_pn[p]
        along = old_pt[p, 0] * normal[k, 0] + old_pt[p, 1] * normal[k, 1] + old_pt[p, 2] * normal[k, 2]
        for a in range(3):
            pt[k, a] = old_pt[p, a] - along * normal[k, a]
    return pn, pt


@njit(cache=True)
def newly_hit(total, previous, old_total):
    """Contacts given an impulse in this step (``total`` > 0) and none in the last (not a contact
    then, or one of zero impulse): the step's impacts."""
    hit = np.empty(len(total), dtype=np.bool_)
    for k in range(len(total)):
        p = previous[k]
        hit[k] = total[k] > 0 and not (p >= 0 and old_total[p] > 0)
    return hit
