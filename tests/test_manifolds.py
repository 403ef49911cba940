"""The rigid narrow phase (steplab.physics.collision.manifolds) against brute force and exact answers.

Every reference here is computed another way: closest points by scipy's bounded minimisation,
box distances as a convex quadratic program, penetration depths by a search over directions,
signed distances by the box's own inequalities.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize
from steplab.physics import quaternion as quat
from steplab.physics.collision import Box, OrientedBox, Plane
from steplab.physics.collision.manifold_box import AXIS_TOLERANCE, CLIP_TOLERANCE, LINEAR_SLOP
from steplab.physics.collision.manifold_capsule_box import segment_box_closest
from steplab.physics.collision.manifolds import BOX, CAPSULE, SPHERE, Poses, RigidShapes, bounding_radius, manifolds
from steplab.physics.collision.shapes import rotation_matrix

SETTINGS = settings(max_examples=100, deadline=None)
#: the tests that call scipy's minimisers a few times an example: fewer examples, the same coverage of kinds
BRUTE_FORCE = settings(max_examples=40, deadline=None)
UP = np.array([0.0, 0.0, 1.0])

coordinate = st.floats(-1.0, 1.0)
size = st.floats(0.1, 1.0)
quaternion = st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1).map(
    lambda q: np.asarray(q) / np.linalg.norm(q))
vector = st.tuples(coordinate, coordinate, coordinate).map(np.asarray)


def scene(kinds, radii, halves, positions, orientations):
    return (RigidShapes(np.asarray(kinds, np.int8), np.asarray(radii, float), np.asarray(halves, float)),
            Poses(np.asarray(positions, float), np.asarray(orientations, float)))


def box_signed_distance(p, centre, rotation, half):
    """Signed distance of p to a box (negative inside), from the box's inequalities |x_k| <= h_k."""
    excess = np.abs((p - centre) @ rotation) - half
    return np.linalg.norm(np.maximum(excess, 0)) + min(excess.max(), 0.0)


# --- box and static shapes -----------------------------------------------------------------


@SETTINGS
@given(half=st.tuples(size, size, size), yaw=st.floats(-180, 180), x=coordinate, gap=st.floats(-0.01, 0.01),
       floor=st.sampled_from(["plane", "box", "oriented-box"]))
def test_a_box_resting_flat_on_the_floor_touches_it_at_its_four_bottom_corners(half, yaw, x, gap, floor):
    half = np.asarray(half)
    q = quat.from_axis_angle(np, UP, np.radians(yaw))
    floors = {"plane": Plane(UP), "box": Box(np.array([-5.0, -5, -1]), np.array([5.0, 5, 0])),
              "oriented-box": OrientedBox(np.array([0.0, 0, -1]), np.array([5.0, 5, 1]),
                                          rotation_matrix(UP, 30.0))}
    shapes, poses = scene([BOX], [0.0], [half], [[x, 0.0, half[2] + gap]], [q])
    m = manifolds(shapes, poses, np.empty((0, 2)), [floors[floor]], margin=0.02)
    assert len(m.a) == 4 and np.all(m.b == -1)
    np.testing.assert_allclose(m.separation, gap, atol=1e-12)
    np.testing.assert_allclose(m.normal, np.tile(-UP, (4, 1)), atol=1e-12)
    corners = np.array([[sx, sy, -1.0] for sx in (-1, 1) for sy in (-1, 1)]) * half @ quat.to_matrix(np, q).T
    corners += [x, 0.0, half[2] + gap]
    expected = corners - 0.5 * gap * UP  # halfway between the corner and the floor
    for p in m.point:
        assert np.min(np.linalg.norm(expected - p, axis=1)) < 1e-9
    assert len(np.unique(m.feature)) == 4
    # equal pushes at the four corners have no moment about the box's centre: it does not tip
    torque = np.cross(m.point - poses.position[0], -m.normal).sum(axis=0)
    np.testing.assert_allclose(torque, 0.0, atol=1e-12)


def test_a_box_above_the_margin_has_no_contact_and_one_tilted_onto_an_edge_has_two():
    shapes, poses = scene([BOX], [0.0], [[0.5, 0.5, 0.5]], [[0.0, 0.0, 0.52]], [quat.IDENTITY])
    assert len(manifolds(shapes, poses, [], [Plane(UP)], margin=0.01).a) == 0
    tilted = quat.from_axis_angle(np, np.array([1.0, 0, 0]), np.pi / 4)
    shapes, poses = scene([BOX], [0.0], [[0.5, 0.5, 0.5]], [[0.0, 0.0, 0.5 * np.sqrt(2)]], [tilted])
    m = manifolds(shapes, poses, [], [Plane(UP)], margin=0.01)
    assert len(m.a) == 2
    np.testing.assert_allclose(m.separation, 0.0, atol=1e-12)
    np.testing.assert_allclose(m.point[:, 1:], 0.0, atol=1e-12)  # the edge along x at y = z = 0


def test_a_margin_as_a_number_and_as_an_array_share_one_compiled_kernel():
    """A margin given as one number and as an array per body are the same Numba type: the manifold kernel
    (about half a minute to compile) is compiled once, not once more for a read-only view of the array."""
    from steplab.physics.collision.manifolds import _slots_of_chunk

    shapes, poses = scene([BOX, SPHERE], [0.0, 0.3], [[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]],
                          [[0.0, 0.0, 0.5], [0.0, 0.0, 1.25]], [quat.IDENTITY, quat.IDENTITY])
    one, each = (manifolds(shapes, poses, [[0, 1]], [Plane(UP)], margin=m) for m in (0.1, np.full(2, 0.1)))
    assert len(one.a) == 5  # four corners on the floor, the sphere on the box's top face
    for field in one._fields:
        np.testing.assert_array_equal(getattr(one, field), getattr(each, field))
    assert len(_slots_of_chunk.signatures) == 1, _slots_of_chunk.signatures


@BRUTE_FORCE
@given(half=st.tuples(size, size, size), q=quaternion, centre=vector, radius=size,
       static=st.booleans())
def test_sphere_box_against_the_closest_point_of_the_box_surface(half, q, centre, radius, static):
    half, rotation = np.asarray(half), quat.to_matrix(np, q)
    box_centre = np.array([0.2, -0.1, 0.3])
    if static:  # the same box as a static oriented box
        shapes, poses = scene([SPHERE], [radius], [np.zeros(3)], [centre], [quat.IDENTITY])
        m = manifolds(shapes, poses, [], [OrientedBox(box_centre, half, rotation)], margin=10.0)
    else:
        shapes, poses = scene([BOX, SPHERE], [0.0, radius], [half, np.zeros(3)], [box_centre, centre],
                              [q, quat.IDENTITY])
        m = manifolds(shapes, poses, [[1, 0]], [], margin=10.0)
        m = m._replace(normal=-m.normal)  # from the sphere (body 1) to the box
    assert len(m.a) == 1
    # the box's surface point nearest the centre: each face as a bounded least-squares problem
    local = (centre - box_centre) @ rotation
    best = np.inf
    for k in range(3):
        for side in (-1.0, 1.0):
            others = [i for i in range(3) if i != k]

            def gap2(uv, k=k, side=side, others=others):
                y = np.empty(3)
                y[k], y[others] = side * half[k], uv
                return np.sum((y - local) ** 2)

            result = minimize(gap2, np.zeros(2), method="L-BFGS-B", bounds=[(-half[i], half[i]) for i in others])
            best = min(best, np.sqrt(result.fun))
    inside = np.all(np.abs(local) <= half)
    expected = (-best if inside else best) - radius
    assert m.separation[0] == pytest.approx(expected, abs=1e-6)
    np.testing.assert_allclose(np.linalg.norm(m.normal[0]), 1.0, atol=1e-12)
    # the two surfaces lie half the separation either side of the point, along the normal from a to b
    sphere_surface, box_surface = (m.point[0] - 0.5 * m.separation[0] * m.normal[0],
                                   m.point[0] + 0.5 * m.separation[0] * m.normal[0])
    assert box_signed_distance(box_surface, box_centre, rotation, half) == pytest.approx(0.0, abs=1e-6)
    assert np.linalg.norm(sphere_surface - centre) == pytest.approx(radius, abs=1e-9)
    if static:
        assert m.b[0] == -1
    else:  # pair (1, 0) is tested as (0, 1): a is the box, and the normal points from it to the sphere
        assert (m.a[0], m.b[0]) == (0, 1)


# --- box against box ----------------------------------------------------------------------


def corners(centre, rotation, half):
    return centre + (np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half) @ rotation.T


def fibonacci_directions(n):
    """n directions spread evenly over the upper half sphere (an axis and its opposite overlap alike)."""
    k = np.arange(n) + 0.5
    z, phi = k / n, np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


DIRECTIONS = fibonacci_directions(4000)


def brute_penetration(va, vb):
    """min over unit L of the overlap of the boxes' projections on L: sampled, then refined by Nelder–Mead."""

    def overlap(direction):
        pa, pb = va @ direction, vb @ direction
        return min(pa.max() - pb.min(), pb.max() - pa.min())

    def overlap_angles(angles):
        theta, phi = angles
        return overlap(np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]))

    pa, pb = va @ DIRECTIONS.T, vb @ DIRECTIONS.T
    sampled = np.minimum(pa.max(axis=0) - pb.min(axis=0), pb.max(axis=0) - pa.min(axis=0))
    best = sampled.min()
    for k in np.argsort(sampled)[:6]:
        x, y, z = DIRECTIONS[k]
        result = minimize(overlap_angles, [np.arccos(z), np.arctan2(y, x)], method="Nelder-Mead",
                          options={"xatol": 1e-10, "fatol": 1e-12})
        best = min(best, result.fun)
    return best, overlap


def brute_distance(box_a, box_b):
    """The boxes' distance: min |c_a + R_a u - c_b - R_b w| over |u| <= h_a, |w| <= h_b, a convex bounded QP."""
    (ca, ra, ha), (cb, rb, hb) = box_a, box_b

    def gap2(x):
        g = ca + ra @ x[:3] - cb - rb @ x[3:]
        return g @ g, 2 * np.concatenate([ra.T @ g, -rb.T @ g])

    bounds = [(-h, h) for h in np.concatenate([ha, hb])]
    result = minimize(gap2, np.zeros(6), jac=True, method="L-BFGS-B", bounds=bounds,
                      options={"ftol": 1e-15, "gtol": 1e-12})
    return np.sqrt(max(result.fun, 0.0))


box_pose = st.tuples(st.tuples(size, size, size).map(np.asarray), quaternion, vector.map(lambda v: 0.8 * v))


@BRUTE_FORCE
@given(a=box_pose, b=box_pose)
def test_box_box_manifold_against_brute_force(a, b):
    (ha, qa, ca), (hb, qb, cb) = a, b
    margin = 0.05
    shapes, poses = scene([BOX, BOX], [0.0, 0.0], [ha, hb], [ca, cb], [qa, qb])
    m = manifolds(shapes, poses, [[0, 1]], [], margin=0.5 * margin)
    ra, rb = quat.to_matrix(np, qa), quat.to_matrix(np, qb)
    distance = brute_distance((ca, ra, ha), (cb, rb, hb))
    assert len(m.a) <= 4 and np.all(m.separation < margin)
    if distance > margin + 1e-7:
        assert len(m.a) == 0  # apart beyond the margin: nothing
        return
    for point, normal, separation in zip(m.point, m.normal, m.separation):
        assert np.linalg.norm(normal) == pytest.approx(1.0, abs=1e-12)
        # on both surfaces: each lies half the separation either side of the point along the normal, the
        # reference face's to the clipping tolerance (a corner within it of the face's side is kept)
        assert abs(box_signed_distance(point - 0.5 * separation * normal, ca, ra, ha)) <= CLIP_TOLERANCE + 1e-9
        assert abs(box_signed_distance(point + 0.5 * separation * normal, cb, rb, hb)) <= CLIP_TOLERANCE + 1e-9
    if distance > 1e-7:  # apart: no point is closer than the boxes are
        assert np.all(m.separation >= distance - 1e-7)
        return
    va, vb = corners(ca, ra, ha), corners(cb, rb, hb)
    depth, overlap = brute_penetration(va, vb)
    assert len(m.a) >= 1
    normal = m.normal[np.argmin(m.separation)]
    # the normal is the axis of least penetration, to the tolerance that keeps faces before edges
    assert overlap(normal) <= depth + AXIS_TOLERANCE + 1e-7
    assert -m.separation.min() <= overlap(normal) + 1e-9
    # no corner of either box is deeper inside the other than the manifold's deepest point
    deepest = max(-min(box_signed_distance(v, cb, rb, hb) for v in va), -min(box_signed_distance(v, ca, ra, ha)
                                                                              for v in vb))
    assert deepest <= -m.separation.min() + AXIS_TOLERANCE + 1e-9


def test_a_box_resting_on_a_box_gets_four_points_of_the_top_boxs_bottom_face():
    shapes, poses = scene([BOX, BOX], [0.0, 0.0], [[1.0, 1.0, 0.5], [0.5, 0.5, 0.5]], [[0, 0, 0.5], [0.2, 0.1, 1.49]],
                          [quat.IDENTITY, quat.from_axis_angle(np, UP, 0.3)])
    m = manifolds(shapes, poses, [[0, 1]], [], margin=0.01)
    assert len(m.a) == 4
    np.testing.assert_allclose(m.separation, -0.01, atol=1e-12)
    np.testing.assert_allclose(m.normal, np.tile(UP, (4, 1)), atol=1e-12)
    np.testing.assert_allclose(m.point[:, 2], 0.995, atol=1e-12)


# --- capsules ------------------------------------------------------------------------------


@SETTINGS
@given(half=st.tuples(size, size, size), inside=st.tuples(*[st.floats(-0.99, 0.99)] * 3), direction=vector,
       length=st.floats(2.5, 4.0))
def test_a_segment_through_a_box_is_at_distance_zero(half, inside, direction, length):
    # through a point inside the box and out on both sides: every point of it between the two faces it
    # crosses is inside, so the distance is exactly 0, whatever p + t d rounds to on those faces' planes
    # (one in seven such segments came out a hair outside and took another face's contact)
    assume(np.linalg.norm(direction) > 0.1)
    d = length * np.max(half) * direction / np.linalg.norm(direction)
    p = np.asarray(inside) * np.asarray(half) - 0.5 * d
    t, distance2 = segment_box_closest(tuple(p), tuple(d), half)
    assert distance2 == 0.0
    assert np.all(np.abs(p + t * d) <= np.asarray(half) * (1 + 1e-12))


def segment(centre, q, half_length):
    axis = quat.rotate(np, q, UP)
    return centre - half_length * axis, 2 * half_length * axis


@BRUTE_FORCE
@given(ca=vector, cb=vector, qa=quaternion, qb=quaternion, la=st.floats(0.0, 1.0), lb=st.floats(0.0, 1.0),
       ra=size, rb=size)
def test_capsule_capsule_against_scipy_minimisation_of_the_segments_distance(ca, cb, qa, qb, la, lb, ra, rb):
    shapes, poses = scene([CAPSULE, CAPSULE], [ra, rb], [[0, 0, la], [0, 0, lb]], [ca, cb], [qa, qb])
    m = manifolds(shapes, poses, [[0, 1]], [], margin=10.0)
    (p, d), (r, e) = segment(ca, qa, la), segment(cb, qb, lb)

    def distance2(st_):
        return np.sum((p + st_[0] * d - r - st_[1] * e) ** 2)

    best = min(minimize(distance2, start, method="L-BFGS-B", bounds=[(0, 1), (0, 1)]).fun
               for start in ([0.5, 0.5], [0, 0], [0, 1], [1, 0], [1, 1]))
    expected = np.sqrt(best) - ra - rb
    assert 1 <= len(m.a) <= 2
    # two points stand for a side-by-side stretch: the pair's gap there is the distance to within the slop
    assert m.separation.min() == pytest.approx(expected, abs=1e-6 if len(m.a) == 1 else LINEAR_SLOP)
    assert m.separation.min() >= expected - 1e-6


def test_parallel_capsules_side_by_side_touch_at_both_ends_of_their_common_stretch():
    lying = quat.from_axis_angle(np, np.array([0.0, 1, 0]), np.pi / 2)  # segments along x
    shapes, poses = scene([CAPSULE, CAPSULE], [0.1, 0.1], [[0, 0, 0.5], [0, 0, 0.5]],
                          [[0.0, 0, 0], [0.3, 0.19, 0]], [lying, lying])
    m = manifolds(shapes, poses, [[0, 1]], [], margin=0.1)
    assert len(m.a) == 2 and sorted(m.feature) == [1, 2]
    np.testing.assert_allclose(m.separation, -0.01, atol=1e-12)
    # the common stretch of [-0.5, 0.5] and [-0.2, 0.8]
    np.testing.assert_allclose(np.sort(m.point[:, 0]), [-0.2, 0.5], atol=1e-12)
    np.testing.assert_allclose(m.normal, [[0, 1, 0], [0, 1, 0]], atol=1e-12)


@BRUTE_FORCE
@given(half=st.tuples(size, size, size), qb=quaternion, cc=vector, qc=quaternion, length=st.floats(0.0, 1.0),
       radius=size)
def test_box_capsule_against_the_segments_distance_to_the_box(half, qb, cc, qc, length, radius):
    half = np.asarray(half)
    shapes, poses = scene([BOX, CAPSULE], [0.0, radius], [half, [0, 0, length]], [np.zeros(3), cc], [qb, qc])
    m = manifolds(shapes, poses, [[0, 1]], [], margin=10.0)
    rotation = quat.to_matrix(np, qb)
    p, d = segment(cc, qc, length)

    def distance2(x):  # a point of the segment and a point of the box (its local coordinates)
        return np.sum((p + x[0] * d - rotation @ x[1:]) ** 2)

    bounds = [(0, 1)] + [(-h, h) for h in half]
    best = min(minimize(distance2, np.r_[s, np.zeros(3)], method="L-BFGS-B", bounds=bounds).fun for s in (0, 0.5, 1))
    assume(best > 1e-6)  # apart: the reported gap is the distance; overlapping cores are the SAT's
    assert 1 <= len(m.a) <= 2
    assert m.separation.min() == pytest.approx(np.sqrt(best) - radius, abs=1e-5)
    for point, separation in zip(m.point, m.separation):  # on or between both surfaces
        assert box_signed_distance(point, np.zeros(3), rotation, half) <= max(separation, 0) / 2 + radius + 1e-6


# --- feature ids and symmetry -------------------------------------------------------------

kind = st.sampled_from([SPHERE, BOX, CAPSULE])
body = st.tuples(kind, st.tuples(size, size, size).map(np.asarray), quaternion, vector.map(lambda v: 0.6 * v))


def bodies_scene(bodies):
    kinds = [b[0] for b in bodies]
    radii = [0.0 if k == BOX else 0.5 * b[1][0] for k, b in zip(kinds, bodies)]
    halves = [b[1] if k == BOX else [0, 0, b[1][2] if k == CAPSULE else 0] for k, b in zip(kinds, bodies)]
    return scene(kinds, radii, halves, [b[3] for b in bodies], [b[2] for b in bodies])


STATICS = [Plane(UP, -0.8), OrientedBox(np.array([1.2, 0, 0]), np.array([0.3, 2, 2]), rotation_matrix(UP, 20.0))]


@settings(max_examples=50, deadline=None)
@given(bodies=st.lists(body, min_size=2, max_size=6), seed=st.integers(0, 2**32 - 1))
def test_feature_ids_survive_a_reordering_of_the_pairs(bodies, seed):
    shapes, poses = bodies_scene(bodies)
    n = len(bodies)
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    reference = manifolds(shapes, poses, pairs, STATICS, margin=0.05)
    rng = np.random.default_rng(seed)
    shuffled = pairs[rng.permutation(len(pairs))]
    flip = rng.random(len(pairs)) < 0.5
    shuffled[flip] = shuffled[flip, ::-1]
    again = manifolds(shapes, poses, shuffled, STATICS, margin=0.05)
    for column, other in zip(reference, again):
        assert np.array_equal(column, other)  # the same bytes, row by row
    assert np.all(np.diff(reference.a) >= 0)


@SETTINGS
@given(a=body, b=body, direction=vector, twist=vector)
def test_feature_ids_are_unchanged_by_a_tiny_change_of_the_poses(a, b, direction, twist):
    shapes, poses = bodies_scene([a, b])
    # in a generic pose: hypothesis's simple numbers (sizes of 1.0, the centres together) put two
    # shapes exactly on one of the kernel's decision boundaries (a capsule through a box's centre is
    # as deep behind two or four of its faces), where any nudge may flip the features; the same
    # small fixed shift and turn of every example leaves those boundaries
    rng = np.random.default_rng(20261204)
    turn_axes = rng.normal(size=(2, 3))
    generic = quat.from_axis_angle(np, turn_axes / np.linalg.norm(turn_axes, axis=1, keepdims=True),
                                   1e-3 * rng.uniform(0.5, 1.0, 2))
    poses = Poses(poses.position + rng.uniform(-1e-3, 1e-3, (2, 3)), quat.multiply(np, poses.orientation, generic))
    axis = twist / np.linalg.norm(twist) if np.linalg.norm(twist) > 0.1 else np.array([0.6, 0.0, 0.8])

    def nudged(size):  # the poses moved by size along direction and turned by size radians about axis
        turn = quat.from_axis_angle(np, axis, size)
        return manifolds(shapes, Poses(poses.position + size * direction, quat.multiply(np, poses.orientation, turn)),
                         [[0, 1]], STATICS, margin=0.05)

    before, after = nudged(0.0), nudged(1e-9)
    assume(np.all(np.abs(before.separation - 0.05) > 1e-6))  # no point on the edge of the margin
    assert np.array_equal(before.a, after.a) and np.array_equal(before.b, after.b)
    assert np.array_equal(before.feature, after.feature)
    # the separations move as little as the poses (the points may jump where the normal has no direction:
    # concentric cores take +x by convention)
    np.testing.assert_allclose(after.separation, before.separation, atol=1e-7)


@SETTINGS
@given(a=body, b=body)
def test_swapping_a_and_b_flips_the_normal(a, b):
    shapes, poses = bodies_scene([a, b])
    forward = manifolds(shapes, poses, [[0, 1]], margin=0.05)
    backward = manifolds(*bodies_scene([b, a]), [[0, 1]], margin=0.05)
    if BOX not in (a[0], b[0]) and len(forward.a):  # round cores that meet have no normal: +x by convention
        assume(forward.separation.min() > -shapes.radius.sum() + 1e-9)
    if a[0] != b[0] or a[0] == SPHERE:  # the one kernel, its normals negated
        assert np.array_equal(forward.normal, -backward.normal)
        assert np.array_equal(forward.point, backward.point)
        assert np.array_equal(forward.separation, backward.separation)
        assert np.array_equal(forward.feature, backward.feature)
    elif len(forward.a) and len(backward.a):  # two boxes or two capsules: the reference may change within tolerance
        tolerance = AXIS_TOLERANCE if a[0] == BOX else LINEAR_SLOP
        assert forward.separation.min() == pytest.approx(backward.separation.min(), abs=tolerance + 1e-9)
        if abs(forward.separation.min() - backward.separation.min()) < 1e-12 and a[0] == CAPSULE:
            deepest, other = np.argmin(forward.separation), np.argmin(backward.separation)
            np.testing.assert_allclose(forward.normal[deepest], -backward.normal[other], atol=1e-9)


# --- bad input -----------------------------------------------------------------------------


@pytest.mark.parametrize("kind, radius, half, message", [
    (BOX, 0.0, [0.5, 0.0, 0.5], "body 1: a box needs half edges > 0 m"),
    (SPHERE, 0.0, [0, 0, 0], "body 1: a sphere needs a radius > 0 m"),
    (CAPSULE, -0.1, [0, 0, 0.5], "body 1: a capsule needs a radius > 0 m"),
    (CAPSULE, 0.1, [0, 0, -0.5], "body 1: a capsule's length must be >= 0 m"),
    (7, 0.1, [0, 0, 0], "body 1: kind 7 is no shape"),
    (BOX, 0.0, [0.5, np.nan, 0.5], "body 1: radius and half edges must be finite"),
])
def test_a_shape_that_is_no_body_is_refused_in_one_line_naming_the_body(kind, radius, half, message):
    shapes, poses = scene([SPHERE, kind], [0.1, radius], [[0, 0, 0], half], np.zeros((2, 3)),
                          [quat.IDENTITY, quat.IDENTITY])
    with pytest.raises(ValueError, match=message) as error:
        manifolds(shapes, poses, [[0, 1]], [Plane(UP)])
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match=message):
        bounding_radius(shapes)


def test_bad_poses_pairs_margins_and_statics_are_refused_in_one_line():
    shapes, poses = scene([SPHERE, SPHERE], [0.1, 0.1], np.zeros((2, 3)), np.zeros((2, 3)),
                          [quat.IDENTITY, [1.0, 1.0, 0, 0]])
    with pytest.raises(ValueError, match="body 1: the pose needs a finite position and a unit quaternion"):
        manifolds(shapes, poses, [[0, 1]])
    shapes, poses = scene([SPHERE, SPHERE], [0.1, 0.1], np.zeros((2, 3)), np.zeros((2, 3)), [quat.IDENTITY] * 2)
    with pytest.raises(ValueError, match="pair 0 must join two different bodies 0 .. 1, got"):
        manifolds(shapes, poses, [[0, 2]])
    with pytest.raises(ValueError, match="margin must be finite and >= 0 m"):
        manifolds(shapes, poses, [[0, 1]], margin=-1.0)
    with pytest.raises(ValueError, match="static shape 0: a Sphere has no manifold; valid: Plane, Box, OrientedBox"):
        from steplab.physics.collision import Sphere

        manifolds(shapes, poses, [[0, 1]], [Sphere(np.zeros(3), np.array(1.0))])


def test_bounding_radius_holds_each_shape():
    shapes = RigidShapes(np.array([SPHERE, BOX, CAPSULE], np.int8), np.array([0.3, 0.0, 0.2]),
                         np.array([[0, 0, 0], [1.0, 2.0, 2.0], [0, 0, 0.5]]))
    np.testing.assert_allclose(bounding_radius(shapes), [0.3, 3.0, 0.7])


def test_many_pairs_on_threads_give_each_pairs_own_manifold_in_sorted_order(monkeypatch):
    """From PARALLEL_PAIRS pairs the narrow phase runs in chunks on Numba's threads, each chunk packing
    its points one after another, and lays them out sorted: the result must be every pair's manifold
    computed on its own (two bodies, or one body and the statics), in the order (a, b, feature), equal
    features in the order found. Two parts are asked for whatever the cores (Numba runs the parts on
    the threads it has)."""
    from steplab.physics.collision import manifolds as narrow

    rng = np.random.default_rng(11)
    n = 800
    kinds = rng.choice([SPHERE, BOX, CAPSULE], n)
    radii = np.where(kinds == BOX, 0.0, rng.uniform(0.05, 0.12, n))
    halves = np.where(kinds[:, None] == BOX, rng.uniform(0.05, 0.12, (n, 3)),
                      np.where(kinds[:, None] == CAPSULE, [0.0, 0.0, 0.08], 0.0))
    positions = np.column_stack([np.arange(n) * 0.09, rng.uniform(-0.05, 0.05, n), rng.uniform(0.0, 0.2, n)])
    turns = rng.normal(size=(n, 4))
    shapes, poses = scene(kinds, radii, halves, positions, turns / np.linalg.norm(turns, axis=1, keepdims=True))
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, min(i + 4, n))])
    statics = [Plane(UP), Box(np.array([10.0, -1, -1]), np.array([20.0, 1, 0.1]))]
    assert len(pairs) >= narrow.PARALLEL_PAIRS
    monkeypatch.setattr(narrow.numba, "get_num_threads", lambda: 2)
    got = manifolds(shapes, poses, pairs, statics, margin=0.02)
    monkeypatch.undo()

    def alone(bodies, pair_list, shape_list):  # the manifolds of a subset of the bodies, renumbered back
        sub = scene(kinds[bodies], radii[bodies], halves[bodies], positions[bodies], poses.orientation[bodies])
        m = manifolds(*sub, pair_list, shape_list, margin=0.02)
        return m._replace(a=np.asarray(bodies)[m.a], b=np.where(m.b >= 0, np.asarray(bodies)[np.maximum(m.b, 0)], m.b))

    parts = [alone([i, j], [[0, 1]], ()) for i, j in pairs] + [alone([i], [], statics) for i in range(n)]
    expected = type(got)(*(np.concatenate(column) for column in zip(*parts)))
    order = np.lexsort((expected.feature, expected.b, expected.a))  # stable: equal features as found
    assert len(got.a) > len(pairs)  # most pairs touch: the chunks' packing is exercised
    for name, column in zip(got._fields, got):
        np.testing.assert_array_equal(column, getattr(expected, name)[order], err_msg=name)
