"""Intersection (swept) testing: when, within a step, does a moving sphere first touch a shape?

Inside one step a body moves along the straight chord from P1 (start of the step) to P2
(end of the step). Every test returns the fraction ``s`` in [0, 1] of the step at which
the sphere first touches the shape, or ``inf`` when it does not touch it during the step.
Already touching or overlapping at the start counts as an impact at ``s = 0`` when the
chord moves deeper and as none when it moves out. All tests are vectorised over a batch
of K spheres (``p1``, ``p2`` of shape (K, 3), ``radius`` of shape (K,)).

Sphere-sphere (the lecture's quadratic)
---------------------------------------
With A = P1 - Q1 (the centres' offset at the start) and B = (P2 - P1) - (Q2 - Q1) (the
relative displacement over the step), the centres are r_P + r_Q apart when
|A + t B|^2 = (r_P + r_Q)^2, i.e. B^2 t^2 + 2 (A . B) t + A^2 - (r_P + r_Q)^2 = 0, whose
first root is the lecture's

    t = (-(A . B) - sqrt((A . B)^2 - B^2 (A^2 - (r_P + r_Q)^2))) / B^2.

It is evaluated here in the equivalent rationalised form

    t = (A^2 - (r_P + r_Q)^2) / (-(A . B) + sqrt((A . B)^2 - B^2 (A^2 - (r_P + r_Q)^2))),

(the product of the two roots is c / a), which never divides by B^2 and does not lose
digits to cancellation when the impact is early in the step. The cases:

- B = 0 (no relative motion): the distance never changes, so no impact (if the spheres
  already overlap they are not approaching either).
- already overlapping (A^2 < (r_P + r_Q)^2): impact at t = 0 if approaching (A . B < 0).
- moving apart (A . B >= 0) while separated: no impact.
- discriminant < 0: the closest approach ``d^2 = A^2 - (A . B)^2 / B^2`` (the lecture's
  "simpler" test) exceeds (r_P + r_Q)^2: the spheres miss.
- discriminant = 0: grazing, touching at one instant with no approach speed.
- the second root, (-(A . B) + sqrt(...)) / B^2, is when they would separate again,
  had they passed through each other; only the first root is an impact.
- t > 1: the impact belongs to a later step.

Sphere-box (the Minkowski sum)
------------------------------
A sphere of radius r touches a box exactly when its centre enters the Minkowski sum of
the box and the sphere: the box grown by r, with rounded edges and corners. That solid
is the union of three slabs (the box grown by r along one axis only), twelve cylinders
of radius r around the edges and eight spheres of radius r around the corners, so the
centre's first entry is the earliest entry into any of the 23 pieces: exact, not
conservative. Oriented boxes are tested in their own frame.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from .narrow_phase import collide
from .shapes import Box, OrientedBox, Plane, Shape, Sphere
from .sphere_contacts import first_entry_rows, sphere_plane_entry_rows, sphere_sphere_entry_rows

NO_IMPACT = np.inf


def _dot(x, y):
    return (x * y).sum(axis=-1)


def _elementwise(rows, *args):
    """``rows`` (a compiled kernel on (K,) arrays) on the broadcast ``args``, in their shape."""
    args = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in args))
    return rows(*(np.ascontiguousarray(x.reshape(-1)) for x in args)).reshape(args[0].shape)


def _first_entry(a, b, c):
    """First root in [0, 1] of a t^2 + 2 b t + c = 0 for a point starting outside (c > 0), else inf
    (:func:`.sphere_contacts.first_entry_of`, elementwise)."""
    return _elementwise(first_entry_rows, a, b, c)


def sphere_sphere(p1, p2, q1, q2, r_p, r_q):
    """Fraction of the step at which sphere P (P1 -> P2) first touches sphere Q (Q1 -> Q2)
    (:func:`.sphere_contacts.sphere_sphere_entry`, row by row)."""
    a_vec = np.asarray(p1, dtype=float) - q1
    b_vec = (np.asarray(p2, dtype=float) - p1) - (np.asarray(q2) - q1)
    shape = np.broadcast_shapes(a_vec.shape, b_vec.shape, np.shape(np.asarray(r_p) + r_q) + (3,))
    def rows(x, tail):
        return np.ascontiguousarray(np.broadcast_to(x, shape[:-1] + tail).reshape((-1,) + tail))

    return sphere_sphere_entry_rows(rows(a_vec, (3,)), rows(b_vec, (3,)),
                                    rows(np.asarray(r_p, dtype=float) + r_q, ())).reshape(shape[:-1])


def lecture_sphere_sphere(p1, p2, q1, q2, r_p, r_q) -> float:
    """The lecture's formula as printed (scalar; divides by B^2). For comparison only."""
    a_vec, b_vec = np.subtract(p1, q1), np.subtract(p2, p1) - np.subtract(q2, q1)
    ab, bb, aa = a_vec @ b_vec, b_vec @ b_vec, a_vec @ a_vec
    return (-ab - np.sqrt(ab * ab - bb * (aa - (r_p + r_q) ** 2))) / bb


def sphere_plane(p1, p2, radius, plane: Plane):
    """The centre's height above the plane, less r, is linear along the chord: h0 + s (h1 - h0)."""
    h0 = _dot(p1, plane.normal) - plane.offset - radius
    h1 = _dot(p2, plane.normal) - plane.offset - radius
    return _elementwise(sphere_plane_entry_rows, h0, h1)  # :func:`.sphere_contacts.sphere_plane_entry_of`


def _slab_entry(origin, d, lo, hi):
    """Entry fraction of the segment origin + s d (s in [0, 1]) into the box [lo, hi], or inf."""
    parallel = d == 0
    inside = (origin >= lo) & (origin <= hi)
    safe = np.where(parallel, 1.0, d)
    with np.errstate(over="ignore"):  # a subnormal d: the slab's bounds are +-inf, which the division gives
        t1, t2 = (lo - origin) / safe, (hi - origin) / safe
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    t_in, t_out = near.max(axis=-1), far.min(axis=-1)
    return np.where((t_in <= t_out) & (t_in >= 0) & (t_in <= 1), t_in, NO_IMPACT)


def _box_corners_and_edges(lo, hi):
    """The 8 corners (8, 3), and the 12 edges as (start corner (12, 3), axis (12,), length (12,))."""
    corners = np.array([np.where(np.array(bits, bool), hi, lo) for bits in itertools.product((0, 1), repeat=3)])
    starts, axes, lengths = [], [], []
    for k in range(3):
        for bits in itertools.product((0, 1), repeat=2):
            corner = lo.copy()
            others = [i for i in range(3) if i != k]
            corner[others[0]] = hi[others[0]] if bits[0] else lo[others[0]]
            corner[others[1]] = hi[others[1]] if bits[1] else lo[others[1]]
            starts.append(corner)
            axes.append(k)
            lengths.append(hi[k] - lo[k])
    return corners, np.array(starts), np.array(axes), np.array(lengths)


def _aabb_entry(p1, p2, radius, lo, hi):
    """First touch of moving spheres with the box [lo, hi]: entry into the rounded box."""
    p1, p2 = np.atleast_2d(p1), np.atleast_2d(p2)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), p1.shape[:1])
    d = p2 - p1
    r = radius[:, None]
    # three slabs: the box grown by r along one axis
    times = [_slab_entry(p1, d, lo - r * e, hi + r * e) for e in np.eye(3)]
    corners, starts, axes, lengths = _box_corners_and_edges(lo, hi)
    # twelve edge cylinders: the motion across the edge's axis enters a circle of radius r
    for start, k, length in zip(starts, axes, lengths):
        rel = p1 - start
        rel_across, d_across = rel.copy(), d.copy()
        rel_across[:, k], d_across[:, k] = 0.0, 0.0
        s = _first_entry(_dot(d_across, d_across), _dot(rel_across, d_across),
                         _dot(rel_across, rel_across) - radius**2)
        along = rel[:, k] + np.where(np.isfinite(s), s, 0.0) * d[:, k]
        times.append(np.where((along >= 0) & (along <= length), s, NO_IMPACT))
    # eight corner spheres
    for corner in corners:
        rel = p1 - corner
        times.append(_first_entry(_dot(d, d), _dot(rel, d), _dot(rel, rel) - radius**2))
    return np.min(np.stack(times), axis=0)


def _start_overlap(p1, p2, radius, shape):
    """For spheres already touching ``shape`` at the start: 0 if moving deeper, else inf."""
    contact = collide(Sphere.unchecked(np.atleast_2d(p1), np.broadcast_to(radius, np.shape(np.atleast_2d(p1))[:1])),
                      shape)
    deeper = _dot(np.atleast_2d(p2) - np.atleast_2d(p1), contact.normal) > 0
    return contact.touching, np.where(deeper, 0.0, NO_IMPACT)


def sphere_box(p1, p2, radius, box: Box):
    """Moving spheres against an axis-aligned box, through its Minkowski sum with the sphere."""
    touching, at_start = _start_overlap(p1, p2, radius, box)
    return np.where(touching, at_start, _aabb_entry(p1, p2, radius, box.lo, box.hi))


def sphere_oriented_box(p1, p2, radius, box: OrientedBox):
    """Moving spheres against an oriented box: the axis-aligned test in the box's frame."""
    touching, at_start = _start_overlap(p1, p2, radius, box)
    local = _aabb_entry(box.to_local(np.atleast_2d(p1)), box.to_local(np.atleast_2d(p2)), radius,
                        -box.half_extents, box.half_extents)
    return np.where(touching, at_start, local)


def sphere_static_sphere(p1, p2, radius, sphere: Sphere):
    """Moving spheres against a fixed sphere."""
    return sphere_sphere(p1, p2, sphere.center, sphere.center, radius, sphere.radius)


#: kind of the static shape -> swept test(p1, p2, radius, shape) -> s
SWEPT_TESTS: dict[str, Callable] = {
    "plane": sphere_plane,
    "box": sphere_box,
    "oriented-box": sphere_oriented_box,
    "sphere": sphere_static_sphere,
}


def time_of_impact(p1, p2, radius, shape: Shape):
    """Fraction of the step at which spheres moving P1 -> P2 first touch the static ``shape``.

    Parameters
    ----------
    p1, p2 : array, shape (K, 3) or (3,)
        Sphere centres at the start and at the end of the step.
    radius : array, shape (K,) or ()
    shape : Plane, Box, OrientedBox or Sphere

    Returns
    -------
    s : array, shape (K,) or ()
        In [0, 1], or ``inf`` for no impact during the step.
    """
    try:
        test = SWEPT_TESTS[shape.kind]
    except KeyError:
        raise NotImplementedError(f"no swept test for a sphere against {shape.kind}") from None
    s = test(p1, p2, radius, shape)
    return s if np.ndim(p1) > 1 else np.asarray(s).reshape(-1)[0]
