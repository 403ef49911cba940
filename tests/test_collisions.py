"""Collisions: pair tests, bounding volumes, time of impact, response, detectors, events.

Every expected value is computed by hand (in the comments) or from a closed form written
out here, never from the code under test.
"""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import INTEGRATORS, Stepper, simulate
from steplab.integrators.semi_implicit_euler import SemiImplicitEuler
from steplab.physics import Drag, Gravity, Model
from steplab.physics.collision import (
    AABB,
    EVENT_LOOPS,
    OBB,
    PAIR_TESTS,
    BoundingSphere,
    Box,
    CollisionWorld,
    Hierarchy,
    ImpactCapError,
    OrientedBox,
    PairProperties,
    Plane,
    Sphere,
    collide,
    hierarchy_overlaps,
    impulse,
    overlaps,
    remove_on_impact,
    rotation_matrix,
    time_of_impact,
)
from steplab.physics.collision.time_of_impact import lecture_sphere_sphere, sphere_sphere

FIXED_STEP = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]
FLOOR = Plane(np.array([0.0, 0.0, 1.0]), 0.0, name="floor")
X = np.array([1.0, 0.0, 0.0])


def sphere(center, radius):
    return Sphere(np.asarray(center, dtype=float), np.asarray(radius, dtype=float))


def assert_contact(c, depth, normal, point_a, point_b):
    assert float(c.penetration_depth) == pytest.approx(depth, abs=1e-15)
    assert bool(c.touching) == (depth >= 0)
    np.testing.assert_allclose(c.normal, normal, atol=1e-15)
    np.testing.assert_allclose(c.point_a, point_a, atol=1e-15)
    np.testing.assert_allclose(c.point_b, point_b, atol=1e-15)


# --- narrow phase --------------------------------------------------------------------------


def test_sphere_sphere_by_hand():
    # centres 1.5 apart, radii 1 + 1: 0.5 deep; A's surface point at x = 1, B's at x = 0.5
    assert_contact(collide(sphere([0, 0, 0], 1), sphere([1.5, 0, 0], 1)), 0.5, X, [1, 0, 0], [0.5, 0, 0])
    # 3 apart: a gap of 1
    assert_contact(collide(sphere([0, 0, 0], 1), sphere([0, 3, 0], 1)), -1.0, [0, 1, 0], [0, 1, 0], [0, 2, 0])


def test_sphere_plane_by_hand():
    # floor z <= 0, centre 0.05 above it, r = 0.1: 0.05 deep, normal into the floor
    assert_contact(collide(sphere([1, 2, 0.05], 0.1), FLOOR), 0.05, [0, 0, -1], [1, 2, -0.05], [1, 2, 0])
    # tilted plane n = (0.6, 0.8, 0), offset 1: centre (2, 2, 0) is 1.2 + 1.6 - 1 = 1.8 above it
    tilted = Plane(np.array([0.6, 0.8, 0.0]), 1.0)
    c = collide(sphere([2, 2, 0], 2.0), tilted)
    assert float(c.penetration_depth) == pytest.approx(0.2, abs=1e-15)
    np.testing.assert_allclose(c.point_b, np.array([2, 2, 0]) - 1.8 * np.array([0.6, 0.8, 0]), atol=1e-15)


BOX = Box(np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]))


@pytest.mark.parametrize("center,radius,depth,normal,point_b", [
    ([1.5, 0, 0], 1.0, 0.5, [-1, 0, 0], [1, 0, 0]),  # face region
    ([2, 2, 0], 1.5, 1.5 - math.sqrt(2), [-1 / math.sqrt(2), -1 / math.sqrt(2), 0], [1, 1, 0]),  # edge
    ([2, 2, 2], 1.0, 1.0 - math.sqrt(3), -np.ones(3) / math.sqrt(3), [1, 1, 1]),  # corner, apart
    ([0.8, 0, 0], 0.5, 0.7, [-1, 0, 0], [1, 0, 0]),  # centre inside: leaves through +x, 0.2 + 0.5 deep
])
def test_sphere_box_by_hand(center, radius, depth, normal, point_b):
    c = collide(sphere(center, radius), BOX)
    normal = np.asarray(normal, float)
    assert_contact(c, depth, normal, np.asarray(center) + radius * normal, point_b)


def test_sphere_oriented_box_by_hand():
    # a cube of half-size 1 turned 45 degrees about z has a vertical edge at (sqrt 2, 0):
    # a sphere of radius 1 centred at (2, 0, 0) reaches it, sqrt(2) - 1 deep
    box = OrientedBox(np.zeros(3), np.ones(3), rotation_matrix([0, 0, 1], 45.0))
    c = collide(sphere([2, 0, 0], 1.0), box)
    assert_contact(c, math.sqrt(2) - 1, [-1, 0, 0], [1, 0, 0], [math.sqrt(2), 0, 0])
    # unturned, it is the axis-aligned test
    same = collide(sphere([1.5, 0.3, -0.2], 1.0), OrientedBox(np.zeros(3), np.ones(3), np.eye(3)))
    ref = collide(sphere([1.5, 0.3, -0.2], 1.0), BOX)
    np.testing.assert_allclose(same.normal, ref.normal, atol=1e-15)
    assert float(same.penetration_depth) == pytest.approx(float(ref.penetration_depth), abs=1e-15)


def test_box_box_by_hand():
    a = Box(np.zeros(3), np.array([2.0, 2.0, 2.0]))
    assert_contact(collide(a, Box(np.array([1.5, 0, 0.5]), np.array([3.0, 2, 2]))), 0.5, X,
                   [2, 1, 1.25], [1.5, 1, 1.25])
    far = collide(a, Box(np.array([3.0, 4.0, 0]), np.array([4.0, 5.0, 2])))  # gap (1, 2, 0)
    assert float(far.penetration_depth) == pytest.approx(-math.sqrt(5), abs=1e-15)


def test_every_pair_is_registered_both_ways():
    kinds = {k for pair in PAIR_TESTS for k in pair}
    assert {"sphere", "plane", "box", "oriented-box"} <= kinds
    for a, b in PAIR_TESTS:
        assert (b, a) in PAIR_TESTS
    s, box = sphere([1.6, 0.4, 0.1], 1.0), BOX
    forward, backward = collide(s, box), collide(box, s)
    np.testing.assert_array_equal(backward.normal, -forward.normal)
    np.testing.assert_array_equal(backward.point_a, forward.point_b)
    assert float(backward.penetration_depth) == float(forward.penetration_depth)


def test_batched_sphere_tests_match_one_at_a_time(rng):
    centers, radii = rng.uniform(-2, 2, (50, 3)), rng.uniform(0.1, 1.0, 50)
    box = OrientedBox(np.array([0.2, 0, 0]), np.array([1.0, 0.5, 0.3]), rotation_matrix([1, 2, 3], 33.0))
    for shape in (BOX, FLOOR, box):
        batch = collide(Sphere(centers, radii), shape)
        for k in range(0, 50, 7):
            one = collide(sphere(centers[k], radii[k]), shape)
            np.testing.assert_allclose(batch.normal[k], one.normal, atol=1e-15)
            assert batch.penetration_depth[k] == pytest.approx(float(one.penetration_depth), abs=1e-15)


# --- bounding volumes ----------------------------------------------------------------------


def test_bounding_spheres_overlap_when_centres_are_closer_than_the_radii():
    # the lecture's slide has this backwards ("less than sum of radii then no collision")
    a = BoundingSphere(np.zeros(3), 1.0)
    assert overlaps(a, BoundingSphere(np.array([1.5, 0, 0]), 1.0))
    assert overlaps(a, BoundingSphere(np.array([2.0, 0, 0]), 1.0))  # touching counts
    assert not overlaps(a, BoundingSphere(np.array([2.5, 0, 0]), 1.0))


def test_obb_separating_axis_beats_the_aabb():
    cube = OBB(np.zeros(3), np.ones(3), np.eye(3))
    turned = OBB(np.array([2.2, 2.2, 0.0]), np.ones(3), rotation_matrix([0, 0, 1], 45.0))
    # along the diagonal the centres are 2.2 sqrt 2 = 3.11 apart, the reaches sqrt 2 + 1 = 2.41
    assert not overlaps(cube, turned)
    reach = np.abs(turned.axes) @ turned.half_extents  # its axis-aligned box overlaps the cube
    assert overlaps(AABB(-np.ones(3), np.ones(3)), AABB(turned.center - reach, turned.center + reach))
    assert overlaps(cube, OBB(np.array([2.3, 0, 0]), np.ones(3), rotation_matrix([0, 0, 1], 45.0)))  # corner at 0.886
    assert not overlaps(cube, OBB(np.array([2.5, 0, 0]), np.ones(3), rotation_matrix([0, 0, 1], 45.0)))
    assert overlaps(AABB(-np.ones(3), np.ones(3)), turned.__class__(np.array([0.5, 0, 0]), np.ones(3), np.eye(3)))


def test_fitted_volumes_hold_their_points_and_the_hierarchy_refines(rng):
    points = rng.normal(size=(200, 3)) * [3.0, 1.0, 0.2] @ rotation_matrix([1, 1, 0], 30.0).T
    for volume in (BoundingSphere.around(points), AABB.around(points), OBB.around(points)):
        assert np.all(volume.contains(points))
    assert np.prod(OBB.around(points).half_extents) < np.prod(0.5 * np.ptp(points, axis=0))  # tighter fit
    torso = rng.uniform(-0.3, 0.3, (50, 3)) + [0, 0, 1.2]
    head = rng.uniform(-0.1, 0.1, (20, 3)) + [0, 0, 1.8]
    avatar = Hierarchy.around([AABB.around(torso), BoundingSphere.around(head)], [torso, head])
    far = Hierarchy.around([BoundingSphere.around(head + [5, 0, 0])], [head + [5, 0, 0]])
    assert hierarchy_overlaps(avatar, far) == ([], 1)  # one coarse test, nothing refined
    near = Hierarchy.around([BoundingSphere.around(head + [0.1, 0, 0])], [head + [0.1, 0, 0]])
    pairs, tests = hierarchy_overlaps(avatar, near)
    assert pairs == [(1, 0)] and tests == 3


# --- time of impact ------------------------------------------------------------------------


def test_sphere_sphere_time_of_impact_by_hand():
    # P from x = -5 to 5 past a fixed Q, reach 2: touch at x = -2, 3/10 of the way
    p1, p2, q = np.array([-5.0, 0, 0]), np.array([5.0, 0, 0]), np.zeros(3)
    assert sphere_sphere(p1, p2, q, q, 1.0, 1.0) == pytest.approx(0.3, abs=1e-15)
    assert lecture_sphere_sphere(p1, p2, q, q, 1.0, 1.0) == pytest.approx(0.3, abs=1e-15)
    # both moving, head on, closing 4 m per step from 3 apart with reach 1: s = 0.5
    assert sphere_sphere(np.zeros(3), 2 * X, 3 * X, X, 0.5, 0.5) == pytest.approx(0.5, abs=1e-15)
    # the first root, not the second (they would part again at s = 0.7)
    assert sphere_sphere(p1, p2, q, q, 1.0, 1.0) < 0.5


@pytest.mark.parametrize("case,p1,p2,q1,q2,expected", [
    ("no relative motion (B = 0)", [0, 0, 0], [1, 0, 0], [3, 0, 0], [4, 0, 0], np.inf),
    ("overlapping, approaching", [0, 0, 0], [1, 0, 0], [1.5, 0, 0], [1.5, 0, 0], 0.0),
    ("overlapping, separating", [0, 0, 0], [-1, 0, 0], [1.5, 0, 0], [1.5, 0, 0], np.inf),
    ("grazing: touches once at x = 0", [-5, 2, 0], [5, 2, 0], [0, 0, 0], [0, 0, 0], 0.5),
    ("missing by 0.1", [-5, 2.1, 0], [5, 2.1, 0], [0, 0, 0], [0, 0, 0], np.inf),
    ("moving apart", [0, 0, 0], [-1, 0, 0], [3, 0, 0], [4, 0, 0], np.inf),
    ("impact after the step", [-5, 0, 0], [-4, 0, 0], [0, 0, 0], [0, 0, 0], np.inf),
    ("impact at the very end", [-5, 0, 0], [-2, 0, 0], [0, 0, 0], [0, 0, 0], 1.0),
])
def test_sphere_sphere_time_of_impact_edge_cases(case, p1, p2, q1, q2, expected):
    s = sphere_sphere(*(np.array(x, float) for x in (p1, p2, q1, q2)), 1.0, 1.0)
    assert s == pytest.approx(expected, abs=1e-12), case


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=12, max_size=12), st.floats(0.05, 1.5), st.floats(0.05, 1.5))
def test_sphere_sphere_time_of_impact_is_the_first_touch(xs, r_p, r_q):
    p1, p2, q1, q2 = (np.array(xs[3 * k:3 * k + 3]) for k in range(4))
    s = float(sphere_sphere(p1, p2, q1, q2, r_p, r_q))
    a, b, reach = p1 - q1, (p2 - p1) - (q2 - q1), r_p + r_q
    # closest approach of the relative motion over [0, 1], in closed form
    t_star = 0.0 if b @ b == 0 else min(max(-(a @ b) / (b @ b), 0.0), 1.0)
    closest = np.linalg.norm(a + t_star * b)
    if np.linalg.norm(a) <= reach:  # touching at the start: impact now iff approaching
        assert s == (0.0 if a @ b < 0 else np.inf)
    elif closest > reach * (1 + 1e-9):
        assert s == np.inf
    elif closest < reach * (1 - 1e-9):
        assert 0 < s <= 1
        assert np.linalg.norm(a + s * b) == pytest.approx(reach, rel=1e-9)
        assert (a + s * b) @ b <= 1e-12  # closing in at the touch: the first root
        assert s == pytest.approx(lecture_sphere_sphere(p1, p2, q1, q2, r_p, r_q), rel=1e-6, abs=1e-9)


def test_sphere_plane_time_of_impact():
    assert time_of_impact(np.array([0, 0, 1.0]), np.array([0, 0, -1.0]), 0.5, FLOOR) == pytest.approx(0.25)
    assert time_of_impact(np.array([0, 0, 0.5]), np.array([0, 0, 0.0]), 0.5, FLOOR) == 0.0  # touching, in
    assert time_of_impact(np.array([0, 0, 0.5]), np.array([0, 0, 1.0]), 0.5, FLOOR) == np.inf  # leaving
    assert time_of_impact(np.array([0, 0, 2.0]), np.array([3, 0, 1.0]), 0.5, FLOOR) == np.inf  # not there yet


@pytest.mark.parametrize("y,z,expected", [
    (0.0, 0.0, 1.5 / 6),                                 # face: centre reaches x = -1.5
    (1.3, 0.0, (2 - 0.4) / 6),                           # rounded edge: (x + 1)^2 + 0.3^2 = 0.5^2
    (1.3, 1.3, (2 - math.sqrt(0.25 - 0.18)) / 6),        # rounded corner: (x + 1)^2 + 2 0.3^2 = 0.5^2
    (1.4, 1.4, np.inf),                                  # passes the corner 0.566 away: a miss
    (1.6, 0.0, np.inf),                                  # passes beside the face
])
def test_sphere_box_time_of_impact_through_the_rounded_minkowski_sum(y, z, expected):
    s = time_of_impact(np.array([-3.0, y, z]), np.array([3.0, y, z]), 0.5, BOX)
    assert s == pytest.approx(expected, abs=1e-14)


def test_sphere_oriented_box_time_of_impact_is_frame_independent(rng):
    turn = rotation_matrix([1, -2, 0.5], 40.0)
    center = np.array([0.3, -0.2, 1.0])
    box = OrientedBox(center, np.ones(3), turn)
    for y, z, expected in [(0.0, 0.0, 0.25), (1.3, 0.0, 1.6 / 6), (1.4, 1.4, np.inf)]:
        p1 = center + turn @ np.array([-3.0, y, z])
        p2 = center + turn @ np.array([3.0, y, z])
        assert time_of_impact(p1, p2, 0.5, box) == pytest.approx(expected, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=6, max_size=6), st.floats(0.05, 1.0))
def test_sphere_box_time_of_impact_is_exact(xs, r):
    p1, p2 = np.array(xs[:3]), np.array(xs[3:])
    s = float(time_of_impact(p1, p2, r, BOX))
    def depth(t):  # penetration depth at fractions t of the chord, vectorised
        t = np.atleast_1d(t)
        return collide(Sphere(p1 + t[:, None] * (p2 - p1), np.full(len(t), r)), BOX).penetration_depth

    samples = np.linspace(0, 1, 401)
    if depth(0.0)[0] >= 0:
        return
    if s == np.inf:
        assert depth(samples).max() < 1e-9
    else:
        assert depth(s)[0] == pytest.approx(0.0, abs=1e-9)
        assert depth(samples[samples < s - 1e-9]).max(initial=-1) < 1e-9


def test_a_chord_with_a_subnormal_component_enters_the_box_without_a_warning():
    """d = 5e-324 along x: its slab's bounds are +-inf (the division overflows, as it should, silently)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert float(time_of_impact(np.array([0.0, 0.0, 3.0]), np.array([5e-324, 0.0, -3.0]), 0.5, BOX)) == \
            pytest.approx((3.0 - 1.5) / 6.0)
        assert float(time_of_impact(np.array([3.0, 0.0, 3.0]), np.array([3.0 + 5e-324, 0.0, -3.0]), 0.5, BOX)) == np.inf


# --- response ------------------------------------------------------------------------------


def lecture_equation_4(m1, m2, eps, v1, v2, n):
    """Lambda = -(m1 m2 (1 + eps) ((V1- - V2-) . n) / (m1 + m2)) n, as printed."""
    return -(m1 * m2 * (1 + eps) * ((v1 - v2) @ n) / (m1 + m2)) * n


def test_impulse_is_the_lectures_equation_4_and_even_in_the_normal(rng):
    for _ in range(100):
        m1, m2, eps = rng.uniform(0.1, 10), rng.uniform(0.1, 10), rng.uniform(0, 1)
        v1, v2, n = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        n /= np.linalg.norm(n)
        if (v1 - v2) @ n <= 0:
            n = -n  # equation 4 applies to approaching bodies
        lam = impulse(v1, v2, 1 / m1, 1 / m2, n, eps)
        np.testing.assert_allclose(lam, lecture_equation_4(m1, m2, eps, v1, v2, n), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(lecture_equation_4(m1, m2, eps, v1, v2, -n), lam, rtol=1e-12, atol=1e-15)


def test_impulse_conserves_momentum_gives_the_restitution_and_never_adds_energy(rng):
    for _ in range(500):
        m1, m2 = 10 ** rng.uniform(-3, 3, 2)
        eps, mu = rng.uniform(0, 1), rng.choice([0.0, rng.uniform(0, 2)])
        v1, v2, n = rng.normal(size=3) * 5, rng.normal(size=3) * 5, rng.normal(size=3)
        n /= np.linalg.norm(n)
        if (v1 - v2) @ n <= 0:
            n = -n
        lam = impulse(v1, v2, 1 / m1, 1 / m2, n, eps, mu)
        w1, w2 = v1 + lam / m1, v2 - lam / m2
        p0 = m1 * v1 + m2 * v2
        np.testing.assert_allclose(m1 * w1 + m2 * w2, p0, rtol=1e-12, atol=1e-12 * np.abs(m1 * v1).max())
        ke0, ke1 = m1 * v1 @ v1 + m2 * v2 @ v2, m1 * w1 @ w1 + m2 * w2 @ w2
        assert ke1 <= ke0 * (1 + 1e-12)
        if mu == 0:
            assert (w1 - w2) @ n == pytest.approx(-eps * ((v1 - v2) @ n), rel=1e-9, abs=1e-9)
            if eps == 1:
                assert ke1 == pytest.approx(ke0, rel=1e-12)
        t_before, t_after = (v1 - v2) - ((v1 - v2) @ n) * n, (w1 - w2) - ((w1 - w2) @ n) * n
        assert np.linalg.norm(t_after) <= np.linalg.norm(t_before) * (1 + 1e-12)  # friction only slows sliding


@pytest.mark.parametrize("ratio", [1.0, 10.0, 1e3, 1e6])
@pytest.mark.parametrize("eps", [0.0, 0.6, 1.0])
def test_head_on_collision_matches_the_textbook(ratio, eps):
    m1, m2, u1, u2 = ratio, 1.0, 2.0, -3.0
    # 1-D: v1 = ((m1 - e m2) u1 + (1 + e) m2 u2) / (m1 + m2), and symmetrically for v2
    v1 = ((m1 - eps * m2) * u1 + (1 + eps) * m2 * u2) / (m1 + m2)
    v2 = ((m2 - eps * m1) * u2 + (1 + eps) * m1 * u1) / (m1 + m2)
    lam = impulse(u1 * X, u2 * X, 1 / m1, 1 / m2, X, eps)
    assert u1 + lam[0] / m1 == pytest.approx(v1, rel=1e-12, abs=1e-12)
    assert u2 - lam[0] / m2 == pytest.approx(v2, rel=1e-12, abs=1e-12)


def test_static_body_is_infinite_mass_and_friction_is_clamped():
    v = np.array([1.0, 0.0, -3.0])
    down = np.array([0.0, 0.0, -1.0])  # from the ball into the floor
    np.testing.assert_allclose(v + impulse(v, np.zeros(3), 1.0, 0.0, down, 0.5), [1.0, 0.0, 1.5], atol=1e-15)
    # normal impulse 1.5 * 3 = 4.5 for m = 1; mu = 0.1 takes 0.45 off the sliding speed
    np.testing.assert_allclose(v + impulse(v, np.zeros(3), 1.0, 0.0, down, 0.5, 0.1), [0.55, 0, 1.5], atol=1e-15)
    # mu large: the sliding stops, and no more
    np.testing.assert_allclose(v + impulse(v, np.zeros(3), 1.0, 0.0, down, 0.5, 10.0), [0, 0, 1.5], atol=1e-15)
    assert np.all(impulse(-v, np.zeros(3), 1.0, 0.0, down, 0.5) == 0)  # leaving: nothing


def test_material_pairs_are_unordered():
    props = PairProperties(0.9, 0.0, {frozenset(("golf", "floor")): (0.858, 0.1), frozenset(("steel",)): (0.5, 0)})
    assert props.lookup("golf", "floor") == props.lookup("floor", "golf") == (0.858, 0.1)
    assert props.lookup("steel", "steel") == (0.5, 0)
    assert props.lookup("golf", "golf") == (0.9, 0.0)


# --- detectors and the step ------------------------------------------------------------------


def wall_shot(speed, detector, dt=0.01, w=0.001, r=0.05, iterations=5, phase=0.37):
    """A ball at ``speed`` towards a wall w thick at x = 0, first touch after 1 + phase steps."""
    x0 = -(0.5 * w + r) - speed * dt * (1 + phase)
    world = CollisionWorld(detector, (Box.from_center([0, 0, 0], [w, 1, 1], name="wall"),),
                           pair_properties=PairProperties(1.0), bisection_iterations=iterations)
    y0 = np.array([[[x0, 0, 0]], [[speed, 0, 0]]])
    steps = math.ceil((w + 2 * r) / (speed * dt)) + 4
    traj = simulate(Model([1.0], [r]), "semi-implicit-euler", y0, 0.0, steps * dt, dt, collisions=world)
    return traj, (1 + phase) * dt


@pytest.mark.parametrize("speed", [0.1, 10.0, 1e3, 1e5, 1e7])
def test_swept_never_tunnels(speed):
    traj, t_true = wall_shot(speed, "swept")
    assert traj.velocities[-1, 0, 0] == pytest.approx(-speed, rel=1e-12)  # bounced straight back
    assert traj.positions[-1, 0, 0] < 0
    (event,) = traj.collisions.events
    assert event.t == pytest.approx(t_true, rel=1e-9) and event.other_name == "wall"


def test_overlap_misses_a_fast_ball_and_catches_a_slow_one():
    fast, _ = wall_shot(100.0, "overlap")  # v dt = 1 m >> w + 2r = 0.101 m
    assert fast.velocities[-1, 0, 0] == 100.0 and fast.positions[-1, 0, 0] > 0 and not fast.collisions.events
    slow, _ = wall_shot(5.0, "overlap")  # v dt = 0.05 m < w + 2r: always seen
    assert slow.velocities[-1, 0, 0] == pytest.approx(-5.0, rel=1e-12)


@pytest.mark.parametrize("iterations", [0, 1, 5, 12])
def test_overlap_bisection_brackets_the_collision_time(iterations):
    dt = 0.01
    traj, t_true = wall_shot(5.0, "overlap", dt=dt, iterations=iterations)
    (event,) = traj.collisions.events
    lo, hi = event.bracket
    assert hi - lo == pytest.approx(dt / 2**iterations, rel=1e-9)
    assert lo - 1e-15 <= t_true <= hi + 1e-15 and event.t == hi


@pytest.mark.parametrize("detector", ["swept", "overlap"])
def test_a_resting_ball_stays_put_for_ten_thousand_steps(detector):
    model = Model([1.0], [0.1], [Gravity()])
    y0 = np.array([[[0.0, 0.0, 0.1]], [[0.0, 0.0, 0.0]]])
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, 10.0, 0.001, collisions=CollisionWorld(detector, (FLOOR,)),
                    save_every=50)
    assert traj.steps == 10_000
    assert np.abs(traj.positions[:, 0, 2] - 0.1).max() <= 1e-15  # no sinking, no jitter
    assert np.abs(traj.velocities).max() == 0.0
    assert not traj.collisions.events


@pytest.mark.parametrize("integrator", FIXED_STEP)
def test_every_integrator_rests_and_settles(integrator):
    model = Model([1.0], [0.1], [Gravity()])
    world = CollisionWorld("swept", (FLOOR,), pair_properties=PairProperties(0.5, 0.2))
    rest = simulate(model, integrator, np.array([[[0, 0, 0.1]], [[0, 0, 0.0]]]), 0, 0.5, 0.001, collisions=world)
    assert np.abs(rest.positions[:, 0, 2] - 0.1).max() <= 1e-15 and np.abs(rest.velocities).max() == 0
    drop = simulate(model, integrator, np.array([[[0, 0, 0.3]], [[0.4, 0, 0.0]]]), 0, 2.0, 0.001, collisions=world)
    assert drop.positions[-1, 0, 2] == pytest.approx(0.1, abs=1e-15)  # came to rest on the floor ...
    np.testing.assert_array_equal(drop.velocities[-1], 0.0)  # ... and friction stopped the sliding


def test_energy_never_increases_while_bouncing_to_rest():
    # velocity Verlet is exact between collisions under constant gravity: any gain would be the collisions'
    model = Model([1.0], [0.1], [Gravity()])
    for eps in (0.3, 0.9, 1.0):
        world = CollisionWorld("swept", (FLOOR,), pair_properties=PairProperties(eps))
        traj = simulate(model, "velocity-verlet", np.array([[[0, 0, 1.0]], [[0.3, 0, 0]]]), 0, 3.0, 0.001,
                        collisions=world)
        energy = np.array([float(model.energy(y)) for y in traj.y])
        assert np.diff(energy).max() <= 1e-13 * energy[0]
        if eps == 1.0:
            assert energy[-1] == pytest.approx(energy[0], rel=1e-5)


@pytest.mark.parametrize("detector", ["swept", "overlap"])
def test_ball_collisions_conserve_momentum_and_elastic_energy(detector, rng):
    n = 27  # a 3 x 3 x 3 block of balls 0.4 m apart, thrown together
    q = np.stack(np.meshgrid(*[np.arange(3) * 0.4] * 3), -1).reshape(-1, 3)
    y0 = np.stack([q, -2.0 * (q - q.mean(axis=0)) + rng.normal(size=(n, 3))])
    model = Model(rng.uniform(0.5, 2.0, n), np.full(n, 0.15))
    traj = simulate(model, "semi-implicit-euler", y0, 0, 1.0, 0.005, collisions=CollisionWorld(detector))
    assert len(traj.collisions.events) > 20
    m = np.asarray(model.masses)[:, None]
    momentum = (m * traj.velocities).sum(axis=1)
    assert np.abs(momentum - momentum[0]).max() <= 1e-12 * np.abs(m * y0[1]).sum()
    energy = 0.5 * (m * traj.velocities**2).sum(axis=(1, 2))
    np.testing.assert_allclose(energy, energy[0], rtol=1e-12)


def test_newtons_cradle_passes_the_momentum_down_the_row():
    n, r = 5, 0.1
    q = np.array([[2 * r * k, 0, 0] for k in range(n)], float)
    q[0, 0] -= 0.5
    v = np.zeros((n, 3))
    v[0, 0] = 2.0
    traj = simulate(Model(np.ones(n), np.full(n, r)), "semi-implicit-euler", np.stack([q, v]), 0, 0.5, 0.01,
                    collisions=CollisionWorld("swept"))
    np.testing.assert_allclose(traj.velocities[-1, :, 0], [0, 0, 0, 0, 2.0], atol=1e-14)
    assert [(e.body, e.other) for e in traj.collisions.events] == [(0, 1), (1, 2), (2, 3), (3, 4)]


def test_verlet_carry_is_reinitialised_after_an_impulse():
    calls = []

    class Counting(SemiImplicitEuler):
        def init(self, model, t, y):
            calls.append(t)
            return None

    model = Model([1.0], [0.1], [Drag.from_coefficients(np.array([0.1]), 1.2, 0.5)])
    traj, _ = wall_shot(5.0, "swept")
    y0 = traj.y[0]
    simulate(model, Counting(), y0, 0, 0.05, 0.01,
             collisions=CollisionWorld("swept", (Box.from_center([0, 0, 0], [0.001, 1, 1]),)))
    assert len(calls) >= 2 and calls[0] == 0.0  # the start, and again after the collision


def test_collisions_refuse_jax_and_reference_solvers():
    model, y0 = Model([1.0], [0.1], [Gravity()]), np.array([[[0, 0, 1.0]], [[0, 0, 0.0]]])
    world = CollisionWorld("swept", (FLOOR,))
    with pytest.raises(ValueError, match="NumPy backend only"):
        simulate(model, "semi-implicit-euler", y0, 0, 1, 0.01, backend="jax", collisions=world)
    with pytest.raises(ValueError, match="fixed-step integrator"):
        simulate(model, "scipy-dop853", y0, 0, 1, 0.01, collisions=world)
    none = simulate(model, "euler", y0, 0, 1, 0.01, backend="jax", collisions=world.with_detector("none"))
    assert none.collisions is None


@pytest.mark.parametrize("event_loop", EVENT_LOOPS)
def test_bound_on_impacts_per_step_is_reported(event_loop):
    # a ball between two walls 2r + 1 um apart at 1 km/s bounces hundreds of times per step:
    # the step stops at the bound, naming it, instead of leaving the rest unresolved
    walls = (Plane(X, -0.1, "left"), Plane(-X, -0.100001, "right"))
    world = CollisionWorld("swept", walls, max_impacts_per_step=8, event_loop=event_loop)
    with pytest.raises(ImpactCapError, match=r"t = 0 s .* more than 8 impacts \(8 resolved\).*max_impacts_per_step "
                       r"under \[collisions\]") as err:
        simulate(Model([1.0], [0.1]), "semi-implicit-euler", np.array([[[0.0, 0, 0]], [[1000.0, 0, 0]]]),
                 0, 0.03, 0.01, collisions=world)
    assert (err.value.t, err.value.impacts, err.value.cap) == (0.0, 8, 8)
    assert isinstance(err.value, ArithmeticError)


# --- events ----------------------------------------------------------------------------------


def test_prologue_cancels_and_epilogue_fires():
    heard = []

    def ghost(event, log):  # the wall only records the ball
        return event.other_name != "ghost"

    def sound(event, log):
        heard.append((event.other_name, round(event.impact_speed, 12)))

    shapes = (Box.from_center([0, 0, 0], [0.01, 1, 1], name="ghost"),
              Box.from_center([1, 0, 0], [0.01, 1, 1], name="wall"))
    world = CollisionWorld("swept", shapes, prologues=(ghost,), epilogues=(sound,))
    traj = simulate(Model([1.0], [0.05]), "semi-implicit-euler", np.array([[[-0.5, 0, 0]], [[10.0, 0, 0]]]),
                    0, 0.3, 0.01, collisions=world)
    kinds = [(e.kind, e.other_name) for e in traj.collisions.events]
    # asked once per crossing: a cancelled pair is left alone until the ball has left the ghost
    assert kinds == [("cancelled", "ghost"), ("impact", "wall"), ("cancelled", "ghost")]
    assert heard == [("wall", 10.0)]  # the epilogue only hears resolved collisions
    assert traj.velocities[-1, 0, 0] == -10.0


def test_trigger_records_entry_only_and_epilogue_can_remove_a_body():
    shapes = (Box.from_center([0, 0, 0], [0.4, 1, 1], name="goal", trigger=True),
              Plane(-X, -1.0, name="far wall"))
    world = CollisionWorld("overlap", shapes, epilogues=(remove_on_impact("far wall"),))
    traj = simulate(Model([1.0], [0.05]), "semi-implicit-euler", np.array([[[-1.0, 0, 0]], [[5.0, 0, 0]]]),
                    0, 0.6, 0.01, collisions=world)
    kinds = [(e.kind, e.other_name) for e in traj.collisions.events]
    assert kinds == [("trigger", "goal"), ("impact", "far wall")]  # inside the goal for 10 steps: one entry
    assert traj.collisions.removed == {0}
    assert traj.velocities[-1, 0, 0] == -5.0  # removed after bouncing: the goal no longer sees it
    csv = traj.collisions.to_csv().splitlines()
    assert csv[0].startswith("t,kind,body,other") and len(csv) == 3


def test_same_run_same_bytes():
    from steplab.physics.scene import load_scene

    scene = load_scene("n-balls")
    a, b = (simulate(scene.model, scene.integrator, scene.y0, 0, 1.0, scene.dt, collisions=scene.collisions)
            for _ in range(2))
    assert a.y.tobytes() == b.y.tobytes() and a.collisions.to_csv() == b.collisions.to_csv()


def test_combinations_the_lecture_miscounts():
    # "5 different types of objects -> 10 (5 choose 2 = 10) different CORs": with self-pairs, 15
    assert len(list(itertools.combinations_with_replacement(range(5), 2))) == 15


def test_swept_spheres_refuse_a_blown_up_active_body_only():
    # MAX_COORDINATE is the broadphase's range: a chord from the origin to 3 x that point has its swept
    # sphere's centre at 1.5 x the range and its reach as far; a body removed from the run is not looked at
    from steplab.physics.broadphase.common import MAX_COORDINATE
    from steplab.physics.collision.pairs import SweptSpheres

    q0 = np.zeros((3, 3))
    q1 = np.array([[1.0, 0.0, 0.0], [3 * MAX_COORDINATE, 0.0, 0.0], [0.0, 1.0, 0.0]])
    radii, inverse_masses = np.full(3, 0.5), np.ones(3)
    swept = SweptSpheres.of(q0, q1, radii, inverse_masses, removed=(1,))
    np.testing.assert_array_equal(swept.active, [True, False, True])
    with pytest.raises(FloatingPointError, match="body 1 moved to"):
        SweptSpheres.of(q0, q1, radii, inverse_masses)
    q1[1] = [0.0, np.nan, 0.0]
    with pytest.raises(FloatingPointError, match="body 1 moved to"):
        SweptSpheres.of(q0, q1, radii, inverse_masses)
    SweptSpheres.of(q0, q1, radii, inverse_masses, removed=[1])
