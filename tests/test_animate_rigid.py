"""``steplab animate`` on scenes with rotating bodies (boxes, a rolling sphere, a free box): each drawn as
it is at each frame's orientation, and the energy panel the mechanical energy ``steplab run`` reports,
the spin 1/2 omega . I omega included."""

import json
import math

import numpy as np
import pytest
from helpers import run_main

from steplab.animate import box_faces, box_outline, half_extents, rigid_outlines, rigid_polygons


def turn(axis, angle) -> np.ndarray:
    """The unit quaternion [w, x, y, z] of a turn by ``angle`` about ``axis`` (written out, not steplab's)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def same_polygon(a, b, atol=1e-12) -> bool:
    """Whether the polygons (M, 2) have the same vertices, in any order."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and all(np.min(np.linalg.norm(b - p, axis=1)) < atol for p in a)


def area(polygon) -> float:
    """The shoelace area of a polygon (M, 2), positive counter-clockwise."""
    x, y = np.asarray(polygon, float).T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# --- the outline of a turned box ---------------------------------------------------------------------------


def test_a_unit_cube_turned_45_degrees_about_z_is_a_diamond_seen_from_above():
    c = math.sqrt(2) / 2  # the half diagonal of a unit square
    outline = box_outline([0.0, 0.0, 0.0], turn([0, 0, 1], math.pi / 4), [0.5, 0.5, 0.5], axes=(0, 1))
    assert same_polygon(outline, [[c, 0], [0, c], [-c, 0], [0, -c]])
    assert area(outline) == pytest.approx(1.0, rel=1e-12)  # counter-clockwise, the unit square's area


def test_seen_from_the_side_the_turned_cube_is_a_rectangle_a_diagonal_wide():
    c = math.sqrt(2) / 2
    outline = box_outline([1.0, 2.0, 3.0], turn([0, 0, 1], math.pi / 4), [0.5, 0.5, 0.5], axes=(0, 2))
    assert same_polygon(outline, [[1 + c, 3.5], [1 - c, 3.5], [1 - c, 2.5], [1 + c, 2.5]])


def test_a_cube_seen_along_its_diagonal_is_a_regular_hexagon():
    # the body diagonal (1, 1, 1) turned onto z, about (1, -1, 0) by acos(1 / sqrt(3))
    outline = box_outline([0.0, 0.0, 0.0], turn([1, -1, 0], math.acos(1 / math.sqrt(3))), [0.5, 0.5, 0.5],
                          axes=(0, 1))
    assert outline.shape == (6, 2)
    np.testing.assert_allclose(np.linalg.norm(outline, axis=1), math.sqrt(2 / 3), rtol=1e-12)
    assert area(outline) == pytest.approx(math.sqrt(3), rel=1e-12)  # the cube's shadow along its diagonal


def test_a_box_shows_the_faces_toward_the_viewer():
    c = math.sqrt(2) / 2
    half = np.array([[0.5, 0.5, 0.5]])
    # unturned, seen in x-z (from -y): the one face whose normal is -y
    corners, facing, _ = box_faces(np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), half, (0, 2))
    [face] = np.flatnonzero(facing[0])
    assert same_polygon(corners[0, face], [[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    # turned 45 degrees about z: two faces, each half a diagonal wide, side by side
    corners, facing, _ = box_faces(np.zeros((1, 3)), turn([0, 0, 1], math.pi / 4)[None], half, (0, 2))
    faces = corners[0, facing[0]]
    assert len(faces) == 2
    assert sorted(abs(area(f)) for f in faces) == pytest.approx([c, c], rel=1e-12)
    spans = sorted((f[:, 0].min(), f[:, 0].max()) for f in faces)
    np.testing.assert_allclose(spans, [(-c, 0.0), (0.0, c)], atol=1e-12)


def test_a_frame_draws_each_box_far_to_near_with_its_outline():
    shapes = ("box", "sphere", "box")
    half = np.array([[0.15, 0.1, 0.05], [0.0, 0.0, 0.0], [0.5, 0.5, 0.5]])
    centers = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [2.0, -1.0, 0.0]])  # seen from -y: box 2 is nearer
    orientations = np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], turn([0, 0, 1], math.pi / 4)])
    points = rigid_outlines(shapes, half, [0.05, 0.1, 0.5], centers, orientations, (0, 2))
    verts, faces, edges, widths = rigid_polygons(shapes, half, centers, orientations, points, (0, 2),
                                                 np.array([True, True, False]))
    assert [b for _, b in verts] == [0, 0, 2, 2, 2]  # the sphere is a disc, drawn apart
    assert same_polygon(verts[1][0], [[0.15, 0.05], [-0.15, 0.05], [-0.15, -0.05], [0.15, -0.05]])
    assert same_polygon(verts[4][0], box_outline(centers[2], orientations[2], half[2], (0, 2)))
    assert faces[1][3] == faces[4][3] == 0.0 and widths[1] > widths[0]  # the outlines: edges only
    assert faces[2][0] > faces[2][2] and faces[0][2] > faces[0][0]  # the box outside the window is red


def test_a_box_without_collisions_has_the_size_its_moments_give():
    from steplab.physics.scene import load_scene

    scene = load_scene("dzhanibekov")  # 0.3 x 0.2 x 0.1 m, no [collisions] to keep the size
    np.testing.assert_allclose(half_extents(scene.model, scene.rigid_bodies), [[0.15, 0.1, 0.05]], rtol=1e-12)
    scene = load_scene("tumbling-boxes")  # the contact solver's half edges
    np.testing.assert_array_equal(half_extents(scene.model, scene.rigid_bodies, scene.collisions.rigid.half),
                                  np.tile([0.2, 0.15, 0.1], (8, 1)))


# --- the energy drawn is the one run reports ----------------------------------------------------------------


def animated(capsys, tmp_path, scene, t_end, *argv):
    status, text, err = run_main(capsys, ["animate", scene, "--t-end", t_end, "--fps", "5", *argv,
                                          "--out", str(tmp_path / "a.gif")])
    assert status == 0, err
    return text


def run_json(capsys, *argv) -> dict:
    status, out, err = run_main(capsys, ["run", *argv, "--json"])
    assert status == 0, err
    return json.loads(out)


@pytest.mark.parametrize(("scene", "t_end"), [
    ("rolling-sphere", "0.5"),  # sliding into rolling: the spin it gains is some 30 % of its kinetic energy
    ("tumbling-boxes", "0.7"),  # eight spinning boxes, landing on the floor from 0.4 s on
])
def test_the_energy_drawn_is_the_energy_run_reports(capsys, tmp_path, drawn, scene, t_end):
    text = animated(capsys, tmp_path, scene, t_end)
    [[energies]] = drawn["energies"]
    summary = run_json(capsys, scene, "--t-end", t_end)
    assert energies[0] == pytest.approx(summary["energy_start"], rel=1e-12)
    assert energies[-1] == pytest.approx(summary["energy_end"], rel=1e-12)
    # the bodies drawn at the end are those run ends with, as its contact solver turned them
    [([(_, traj)], [rotation])] = drawn["calls"]
    np.testing.assert_array_equal(rotation.orientations[-1], np.asarray(summary["final_orientations"]))
    np.testing.assert_array_equal(rotation.angular_velocities[-1], np.asarray(summary["final_angular_velocities"]))
    assert "rotation: exponential-map" in text  # the solver's, named under the panel's title


def test_the_free_box_starts_with_its_spin_energy(capsys, tmp_path, drawn):
    animated(capsys, tmp_path, "dzhanibekov", "0.1")
    [[energies]] = drawn["energies"]
    # from the scene file: 0.2 kg, 0.3 x 0.2 x 0.1 m, omega = (0.05, 2 pi, 0.05) rad/s, unturned; at rest
    m, (a, b, c) = 0.2, (0.3, 0.2, 0.1)
    moments = m / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    omega = np.array([0.05, 2 * math.pi, 0.05])
    assert energies[0] == pytest.approx(0.5 * moments @ omega**2, rel=1e-12)
    assert energies[-1] == pytest.approx(energies[0], rel=1e-3)  # dlm keeps it, to its step's error
