"""The [[stacks]] scene table and the stacking scenes: counts, boxes touching, bad input."""

import itertools

import numpy as np
import pytest
from steplab.physics.collision.shapes import Plane
from steplab.physics.scene import SceneError, load_scene, parse_scene

STACKING_SCENES = ("box-column", "box-pyramid", "mass-ratio-stack", "rolling-sphere", "box-incline", "tumbling-boxes")


def stack_scene(stack: str) -> str:
    return f"""
[simulation]
dt = 0.01
t_end = 1.0

[[stacks]]
name = "box"
{stack}
"""


def boxes(scene):
    """(lower corner, upper corner) of each box of an unrotated stack, (n, 3) each."""
    bodies = scene.rigid_bodies
    assert np.all(bodies.orientations == [1, 0, 0, 0]) and set(bodies.shapes) == {"box"}
    # the edges back from the principal moments m/12 (b^2 + c^2, ...): an independent read of size
    m = scene.model.masses[bodies.index][:, None]
    s = 12 * bodies.inertia / m
    size = np.sqrt(0.5 * (s.sum(axis=1, keepdims=True) - 2 * s))
    q = scene.y0[0][bodies.index]
    return q - 0.5 * size, q + 0.5 * size


def supports(lo, hi, gap):
    """Brute force over all pairs: (upper, lower) where the upper box's bottom face lies ``gap``
    above the lower's top face with their footprints overlapping in an area > 0, and the
    overlapping volume of every pair (which must be 0)."""
    found, overlap = [], 0.0
    for i, j in itertools.permutations(range(len(lo)), 2):
        width = np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j])
        if np.all(width > 1e-9):  # touching faces meet to round-off
            overlap += np.prod(width)
        if abs(lo[i, 2] - hi[j, 2] - gap) < 1e-12 and width[0] > 1e-12 and width[1] > 1e-12:
            found.append((i, j, width[0]))
    return found, overlap


@pytest.mark.parametrize("rows", [1, 2, 7, 20])
@pytest.mark.parametrize("gap", [0.0, 0.05])
def test_column_boxes_stand_on_each_other(rows, gap):
    scene = parse_scene(stack_scene(f'kind = "column"\nrows = {rows}\nsize = [0.5, 0.3, 0.2]\nmass = 2.0\n'
                                    f'gap = {gap}\nbase = [1.0, 2.0, 3.0]'))
    assert scene.model.n_bodies == scene.rigid_bodies.n == rows
    lo, hi = boxes(scene)
    np.testing.assert_allclose(hi - lo, np.broadcast_to([0.5, 0.3, 0.2], (rows, 3)), rtol=1e-12)
    found, overlap = supports(lo, hi, gap)
    # box k stands on box k - 1 over its whole footprint, the bottom one `gap` above the base
    assert sorted((i, j) for i, j, _ in found) == [(k, k - 1) for k in range(1, rows)]
    assert overlap == 0.0
    assert lo[0, 2] == pytest.approx(3.0 + gap)
    np.testing.assert_allclose(scene.y0[0][:, :2], np.broadcast_to([1.0, 2.0], (rows, 2)))
    assert np.all(scene.y0[1] == 0) and np.all(scene.rigid_bodies.angular_velocities == 0)
    assert scene.model.names[0] == "box[0]" and np.all(scene.model.masses == 2.0)
    # the radius is the bounding sphere's: the half diagonal
    np.testing.assert_allclose(scene.model.radii, 0.5 * np.linalg.norm([0.5, 0.3, 0.2]))


@pytest.mark.parametrize("rows", [1, 2, 5, 20])
@pytest.mark.parametrize("gap", [0.0, 0.1])
def test_pyramid_boxes_rest_half_on_each_of_two(rows, gap):
    a = 0.8
    scene = parse_scene(stack_scene(f'kind = "pyramid"\nrows = {rows}\nsize = [{a}, 1.0, 0.5]\nmass = 1.0\n'
                                    f'gap = {gap}'))
    n = rows * (rows + 1) // 2
    assert scene.model.n_bodies == n
    lo, hi = boxes(scene)
    found, overlap = supports(lo, hi, gap)
    assert overlap == 0.0
    bottom = np.isclose(lo[:, 2], gap)
    assert bottom.sum() == rows
    upper = [i for i, _, _ in found]
    # every box above the bottom row rests on exactly two, over half its width minus half the gap each
    assert sorted(upper) == sorted(2 * [i for i in range(n) if not bottom[i]])
    np.testing.assert_allclose([w for *_, w in found], 0.5 * (a - gap) * np.ones(len(found)), rtol=1e-12)
    # side by side in a row: neighbours `gap` apart, the row centred on x = 0
    for z in np.unique(lo[:, 2]):
        row = np.sort(lo[np.isclose(lo[:, 2], z), 0])
        np.testing.assert_allclose(np.diff(row), a + gap)
        assert row.mean() + 0.5 * a == pytest.approx(0.0, abs=1e-12)


def test_masses_bottom_up():
    scene = parse_scene(stack_scene('kind = "pyramid"\nrows = 3\nsize = [1, 1, 1]\nmasses = [3.0, 2.0, 1.0]'))
    np.testing.assert_array_equal(scene.model.masses, [3, 3, 3, 2, 2, 1])
    # a box's moments m (b^2 + c^2) / 12
    np.testing.assert_allclose(scene.rigid_bodies.inertia[:, 0], scene.model.masses / 6)


@pytest.mark.parametrize("stack,message", [
    ('kind = "tower"\nrows = 2\nsize = [1, 1, 1]\nmass = 1', "stacks[0].kind: must be one of column, pyramid"),
    ('kind = "column"\nrows = 0\nsize = [1, 1, 1]\nmass = 1', "stacks[0].rows: must be between 1 and 1000, got 0"),
    ('kind = "column"\nrows = 2\nsize = [1, 0, 1]\nmass = 1', "stacks[0].size: must be > 0 in every component"),
    ('kind = "column"\nrows = 2\nsize = [1, 1]\nmass = 1', "stacks[0].size: must be a list of 3 numbers"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]', "missing required key mass (every box) or masses"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmass = 1\nmasses = [1, 1]', "either mass (every box) or masses"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmass = -1', "stacks[0].mass: must be > 0, got -1"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmasses = [1]', "stacks[0].masses: must be a list of 2 masses"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmasses = [1, 0]', "stacks[0].masses[1]: must be > 0, got 0"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmass = 1\ngap = -0.1', "stacks[0].gap: must be >= 0"),
    ('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmass = 1\nspin = 1', "stacks[0]: unknown key 'spin'"),
    ('kind = "column"\nrows = 2\nsize = [1.7e308, 1.7e308, 1.7e308]\nmass = 1', "stacks[0].size: a box of edges"),
])
def test_bad_stack_is_one_line(stack, message):
    with pytest.raises(SceneError) as err:
        parse_scene(stack_scene(stack), "s.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_stack_names_must_not_clash():
    text = stack_scene('kind = "column"\nrows = 2\nsize = [1, 1, 1]\nmass = 1') + """
[[bodies]]
name = "box[1]"
mass = 1.0
radius = 0.1
position = [5.0, 0.0, 0.0]
"""
    with pytest.raises(SceneError, match="duplicate body name 'box\\[1\\]'"):
        parse_scene(text, "s.toml")


@pytest.mark.parametrize("name", STACKING_SCENES)
def test_stacking_scenes_stand_on_a_floor_in_the_solver_at_60_hz(name):
    scene = load_scene(name)
    assert scene.dt == pytest.approx(1 / 60) and scene.collisions.method == "solver"
    assert any(isinstance(s, Plane) for s in scene.collisions.shapes)
    assert scene.rigid_bodies is not None and scene.rigid_bodies.n == scene.model.n_bodies
    assert scene.description


def test_stacking_scene_sizes():
    counts = {name: load_scene(name).model.n_bodies for name in STACKING_SCENES}
    assert counts == {"box-column": 10, "box-pyramid": 210, "mass-ratio-stack": 4, "rolling-sphere": 1,
                      "box-incline": 2, "tumbling-boxes": 8}
    np.testing.assert_array_equal(load_scene("mass-ratio-stack").model.masses, [1, 1, 1, 100])


def test_incline_boxes_lie_on_the_incline():
    """Each box's bottom face on the plane: its centre half its height along the plane's normal,
    and its body z axis turned onto that normal."""
    from steplab.physics import quaternion as quat

    scene = load_scene("box-incline")
    plane = next(s for s in scene.collisions.shapes if isinstance(s, Plane))
    assert np.degrees(np.arccos(plane.normal[2])) == pytest.approx(20.0)
    np.testing.assert_allclose(scene.y0[0] @ plane.normal - plane.offset, 0.1, rtol=1e-12)
    np.testing.assert_allclose(quat.rotate(np, scene.rigid_bodies.orientations, np.array([0.0, 0.0, 1.0])),
                               np.broadcast_to(plane.normal, (2, 3)), atol=1e-15)
