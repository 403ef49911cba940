"""The Python API refuses, in one line at construction, what a scene file refuses (physics/rules.py)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import refused
from steplab.physics import Dampers, Drag, Friction, Gravity, Model, Springs
from steplab.physics.central_gravity import CentralGravity
from steplab.physics.collision.narrow_phase import collide
from steplab.physics.collision.response import PairProperties
from steplab.physics.collision.shapes import Box, OrientedBox, Plane, Sphere, rotation_matrix
from steplab.physics.collision.world import CollisionWorld
from steplab.physics.constant_force import ConstantForce

NAN = float("nan")
UP = np.array([0.0, 0.0, 1.0])
FLOOR = Plane(UP, 0.0, "floor")
TURN = rotation_matrix([1.0, 2.0, 3.0], 40.0)


def tilted(center=None, half=None, rotation=TURN):
    return OrientedBox(np.zeros(3) if center is None else center, np.ones(3) if half is None else half, rotation)


def pair(k=10.0, rest=1.0, i=0, j=1):
    return Springs(np.array([i]), np.array([j]), np.array([k]), np.array([rest]))


REFUSALS = [
    # 1. gravity: 3 finite numbers
    (lambda: Gravity(-9.81), ValueError, "Gravity: g must be 3 numbers"),
    (lambda: Gravity(np.array([0, -9.81])), ValueError, "Gravity: g must be 3 numbers"),
    (lambda: Gravity(np.array([0, 0, NAN])), ValueError, "Gravity: g must be finite"),
    # 2. restitution in [0, 1], friction >= 0, finite
    (lambda: PairProperties(2.0), ValueError, "PairProperties: restitution must be between 0 and 1"),
    (lambda: PairProperties(-0.5), ValueError, "PairProperties: restitution must be between 0 and 1"),
    (lambda: PairProperties(NAN), ValueError, "PairProperties: restitution must be finite"),
    (lambda: PairProperties(0.5, -1.0), ValueError, "PairProperties: friction must be >= 0"),
    (lambda: PairProperties(0.5, NAN), ValueError, "PairProperties: friction must be finite"),
    (lambda: PairProperties(0.5, 0.0, {frozenset({"a"}): (1.5, 0.0)}), ValueError,
     "PairProperties: table[frozenset({'a'})] restitution must be between 0 and 1"),
    # 3. shapes
    (lambda: Plane(np.zeros(3)), ValueError, "Plane: normal must be a non-zero vector"),
    (lambda: Plane(np.array([0, NAN, 1.0])), ValueError, "Plane: normal must be finite"),
    (lambda: Plane(UP, NAN), ValueError, "Plane: offset must be finite"),
    (lambda: Box(np.array([1.0, 1, 1]), np.zeros(3)), ValueError, "Box: hi must exceed lo"),
    (lambda: Box(np.zeros(2), np.ones(3)), ValueError, "Box: lo must be 3 numbers"),
    (lambda: Sphere(np.zeros(2), 0.1), ValueError, "Sphere: center must be one point [x, y, z], shape (3,), or K"),
    (lambda: Sphere(np.zeros((2, 4)), np.full(2, 0.1)), ValueError, "Sphere: center must be one point"),
    (lambda: Sphere("here", 0.1), ValueError, "Sphere: center must be one point"),
    (lambda: Sphere(np.array([0.0, NAN, 0.0]), 0.1), ValueError, "Sphere: center must be finite, got nan (element 1)"),
    (lambda: Sphere(np.zeros(3), -0.1), ValueError, "Sphere: radius must be > 0, got -0.1"),
    (lambda: Sphere(np.zeros(3), 0.0), ValueError, "Sphere: radius must be > 0, got 0"),
    (lambda: Sphere(np.zeros((2, 3)), np.array([0.1, np.inf])), ValueError, "Sphere: radius must be finite"),
    (lambda: Sphere(np.zeros(3), np.array([0.1, 0.2])), ValueError,
     "Sphere: radius must be one radius, shape () for a center of shape (3,), got shape (2,)"),
    (lambda: Sphere(np.zeros((2, 3)), np.array(0.1)), ValueError,
     "Sphere: radius must be one radius per center, shape (2,) for a center of shape (2, 3), got shape ()"),
    (lambda: tilted(center=np.array([0.0, 0.0, NAN])), ValueError, "OrientedBox: center must be finite"),
    (lambda: tilted(center=np.zeros(2)), ValueError, "OrientedBox: center must be 3 numbers"),
    (lambda: tilted(half=np.array([1.0, 0.0, 1.0])), ValueError, "OrientedBox: half_extents must be > 0"),
    (lambda: tilted(half=np.array([1.0, -1.0, 1.0])), ValueError, "OrientedBox: half_extents must be > 0"),
    (lambda: tilted(half=np.array([1.0, np.inf, 1.0])), ValueError, "OrientedBox: half_extents must be finite"),
    (lambda: tilted(rotation=np.eye(2)), ValueError,
     "OrientedBox: rotation must be a 3 x 3 rotation matrix, got shape (2, 2)"),
    (lambda: tilted(rotation=np.full((3, 3), NAN)), ValueError, "OrientedBox: rotation must be finite"),
    (lambda: tilted(rotation=2 * np.eye(3)), ValueError,
     "OrientedBox: rotation must be orthonormal (max |R^T R - I| <= 1e-09), got 3"),
    (lambda: tilted(rotation=TURN + 1e-6), ValueError, "OrientedBox: rotation must be orthonormal"),
    (lambda: tilted(rotation=np.zeros((3, 3))), ValueError, "OrientedBox: rotation must be orthonormal"),
    (lambda: tilted(rotation=TURN.astype(np.float32) * np.float32(1.0001)), ValueError,
     "OrientedBox: rotation must be orthonormal (max |R^T R - I| <= 1e-05)"),
    (lambda: tilted(rotation=TURN @ np.diag([1.0, 1.0, -1.0])), ValueError,
     "OrientedBox: rotation must be a rotation (det +1), got a reflection (det -1)"),
    # 4. the collision world
    (lambda: CollisionWorld("overlap", (FLOOR,), bisection_iterations=10**7), ValueError,
     "CollisionWorld: bisection_iterations must be between 0 and 60"),
    (lambda: CollisionWorld("overlap", (FLOOR,), bisection_iterations=2.5), ValueError,
     "CollisionWorld: bisection_iterations must be an integer"),
    (lambda: CollisionWorld(shapes=FLOOR), TypeError, "CollisionWorld: shapes must be a tuple of static shapes"),
    (lambda: CollisionWorld(shapes=(FLOOR,), materials="golf"), TypeError,
     "CollisionWorld: materials must be a tuple of material names"),
    (lambda: CollisionWorld(max_impacts_per_step=0.5), ValueError,
     "CollisionWorld: max_impacts_per_step must be an integer"),
    (lambda: CollisionWorld(rest_speed=NAN), ValueError, "CollisionWorld: rest_speed must be finite"),
    (lambda: CollisionWorld(pair_properties=0.5), TypeError, "CollisionWorld: pair_properties must be"),
    # central gravity and constant forces, as a scene file's [forces.central_gravity] and [[forces.constant]]
    (lambda: CentralGravity(-1.0), ValueError, "CentralGravity: mu must be > 0, got -1"),
    (lambda: CentralGravity(1.0, np.zeros(2)), ValueError, "CentralGravity: center must be 3 numbers"),
    (lambda: ConstantForce(np.array([1.0, 0.0, 0.0])), ValueError, "ConstantForce: f must be one force [x, y, z] a"),
    (lambda: ConstantForce(np.array([[NAN, 0.0, 0.0]])), ValueError, "ConstantForce: f must be finite"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], [ConstantForce(np.zeros((3, 3)))]), ValueError,
     "ConstantForce: f must be one force a body, shape (2, 3)"),
    # 5. the model's bodies
    (lambda: Model([1.0, 1.0], [0.1]), ValueError, "Model: radii must be one radius per body"),
    (lambda: Model(1.0, [0.1]), ValueError, "Model: masses must be one mass per body"),
    (lambda: Model(None, [0.1]), ValueError, "Model: masses must be one mass per body"),
    (lambda: Model([], []), ValueError, "Model: masses must be one mass per body"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], pinned="no"), ValueError, "Model: pinned must be one boolean per body"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], pinned=[True]), ValueError, "Model: pinned must be one boolean per body"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], names=["a"]), ValueError, "Model: names must name each of the 2"),
    (lambda: Model([1.0, -1.0], [0.1, 0.1]), ValueError, "Model: masses must be > 0, got -1 (element 1)"),
    (lambda: Model([0.0], [0.1]), ValueError, "Model: masses must be > 0"),
    (lambda: Model([NAN], [0.1]), ValueError, "Model: masses must be finite"),
    (lambda: Model([np.inf], [0.1], pinned=[True]), ValueError, "Model: masses must be finite"),
    (lambda: Model([1e-320], [0.1]), ValueError, "Model: masses: a body of mass 1e-320 kg has no finite inverse mass"),
    (lambda: Model([1.0], [-0.1]), ValueError, "Model: radii must be > 0"),
    # 6. forces
    (lambda: Springs(0, 1, 10.0, 1.0), ValueError, "Springs: i must be a 1-D array of body indices"),
    (lambda: pair(i=-1), ValueError, "Springs: i must be body indices >= 0"),
    (lambda: pair(i=1, j=1), ValueError, "Springs: a pair must join two different bodies"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], [pair(j=5)]), ValueError, "Springs: body index 5 out of range"),
    (lambda: pair(k=-1.0), ValueError, "Springs: stiffness must be >= 0"),
    (lambda: pair(k=NAN), ValueError, "Springs: stiffness must be finite"),
    (lambda: pair(rest=-1.0), ValueError, "Springs: rest_length must be >= 0"),
    (lambda: Springs(np.array([0]), np.array([1]), np.array([1.0, 2.0]), np.array([1.0])), ValueError,
     "Springs: stiffness must have one value per pair"),
    (lambda: Dampers(np.array([0]), np.array([1]), np.array([-1.0])), ValueError, "Dampers: damping must be >= 0"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], [Dampers(np.array([0]), np.array([2]), np.array([1.0]))]), ValueError,
     "Dampers: body index 2 out of range"),
    (lambda: Drag.from_coefficients(np.array([0.1]), density=-1), ValueError, "Drag: density must be > 0"),
    (lambda: Drag.from_coefficients(np.array([0.1]), drag_coefficient=NAN), ValueError,
     "Drag: drag_coefficient must be finite"),
    (lambda: Drag.from_coefficients(np.array([0.1, 1e300])), ValueError,
     "Drag: the drag factor 1/2 rho C_D pi r^2 of body 1 (radius 1e+300 m, density 1.225 kg/m^3, drag_coefficient 0.4) "
     "is inf kg/m, beyond float64"),
    (lambda: Drag(np.array([-0.1])), ValueError, "Drag: beta must be >= 0"),
    (lambda: Model([1.0, 1.0], [0.1, 0.1], [Drag(np.array([0.1]))]), ValueError, "Drag: beta must be one value"),
    (lambda: Friction(-0.5, 0.3, UP, 0.0, np.array([0.1])), ValueError, "Friction: mu_static must be >= 0"),
    (lambda: Friction(0.5, NAN, UP, 0.0, np.array([0.1])), ValueError, "Friction: mu_dynamic must be finite"),
    (lambda: Friction(0.5, 0.3, np.zeros(3), 0.0, np.array([0.1])), ValueError,
     "Friction: normal must be a non-zero vector"),
    # Coulomb friction: sliding is resisted no harder than sticking holds
    (lambda: Friction(0.3, 0.5, UP, 0.0, np.array([0.1])), ValueError,
     "Friction: mu_dynamic must be <= mu_static (Coulomb friction: sliding cannot be resisted harder than "
     "sticking holds), got mu_dynamic = 0.5 > mu_static = 0.3"),
    (lambda: Friction(0.0, 1e-9, UP, 0.0, np.array([0.1])), ValueError, "got mu_dynamic = 1e-09 > mu_static = 0"),
]


@pytest.mark.parametrize("build, error, message", REFUSALS, ids=[m for _, _, m in REFUSALS])
def test_refused_in_one_line(build, error, message):
    with pytest.raises(error) as info:
        build()
    text = str(info.value)
    assert message in text and "\n" not in text


def test_materials_must_match_the_bodies_where_the_world_meets_the_model():
    from steplab.integrators import get_integrator

    model = Model([1.0, 1.0], [0.1, 0.1], [Gravity()])
    world = CollisionWorld("swept", (FLOOR,), materials=("golf",))
    with pytest.raises(ValueError, match="CollisionWorld: materials must name one material per body.*got 1 for 2"):
        world.stepper(model, get_integrator("semi-implicit-euler"))


def test_a_non_unit_normal_is_normalised_as_a_scene_file_does_and_a_unit_one_kept_to_the_byte():
    assert np.array_equal(Plane(np.array([0, 0, 5.0])).normal, UP)
    assert np.array_equal(Friction(0.5, 0.3, np.array([0.0, 3.0, 4.0]), 0.0, np.array([0.1])).normal, [0, 0.6, 0.8])
    tilted = np.array([0.6, 0.8, 0.0])
    assert Plane(tilted).normal is tilted


def test_valid_construction_still_works_on_numpy_and_jax():
    forces = [Gravity(), pair(k=np.inf), pair(k=0.0), Dampers(np.array([0]), np.array([1]), np.array([0.0])),
              Drag.from_coefficients(np.array([0.1, 0.2])),
              Friction(0.5, 0.3, UP, 0.0, np.array([0.1, 0.2]))]
    model = Model([1.0, 2.0], [0.1, 0.2], forces, pinned=[True, False], names=["a", "b"])
    world = CollisionWorld("overlap", [FLOOR, Box(np.zeros(3), np.ones(3))], materials=["a", "b"],
                           pair_properties=PairProperties(0.0, 0.0, {frozenset({"a", "b"}): (1.0, 2.0)}),
                           bisection_iterations=60)
    assert world.shapes[0] is FLOOR and world.materials == ("a", "b")
    jnp = pytest.importorskip("jax.numpy")
    jax_model = Model([1.0, 2.0], [0.1, 0.2], forces[:1] + forces[3:], xp=jnp).cast(jnp, np.float32)
    assert jax_model.xp is jnp and jax_model.n_bodies == 2
    assert model.cast(jnp).xp is jnp


def test_valid_spheres_and_oriented_boxes_are_kept_as_given():
    center, radius = np.array([0.0, 0.0, 0.05]), np.array(0.1)
    sphere = Sphere(center, radius)
    assert sphere.center is center and sphere.radius is radius
    assert Sphere(np.zeros((0, 3)), np.zeros(0)).center.shape == (0, 3)  # an empty batch
    assert Sphere(np.zeros((2, 3)), np.array([0.1, 0.2])).radius.shape == (2,)
    assert Sphere([0, 0, 1], 1).radius == 1  # lists and integers, as number_problem takes them
    # a rotation to round-off (1e-12 off orthonormal), a float32 one, an integer permutation
    for rotation in (TURN + 1e-12, TURN.astype(np.float32), np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]])):
        assert tilted(rotation=rotation).rotation is rotation
    jnp = pytest.importorskip("jax.numpy")
    assert Sphere(jnp.array([0.0, NAN, 0.0]), jnp.array(-1.0)).radius == -1  # JAX values pass unchecked


def test_the_collision_codes_own_spheres_are_not_checked():
    # bisection and the swept tests build a sphere of a run's positions at every iteration: unchecked
    # (the checks would nearly triple a contact test), and a diverged run's NaN is the run's to report
    sphere = Sphere.unchecked(np.array([[0.0, 0.0, NAN]]), np.array([0.1]))
    assert sphere.name == "sphere" and sphere.material == "default" and not sphere.trigger
    assert not collide(sphere, FLOOR).touching[0]
    assert repr(Sphere.unchecked(np.zeros(3), np.array(0.1))) == repr(Sphere(np.zeros(3), np.array(0.1)))


FRICTION_SCENE = """
[simulation]
dt = 0.01
t_end = 0.05
[[bodies]]
name = "crate"
mass = 10.0
radius = 0.1
position = [0, 0, 0.1]
[forces.gravity]
[forces.friction]
mu_static = {mu_s}
mu_dynamic = {mu_d}
"""


def test_a_scene_files_friction_is_refused_by_the_same_rule_in_one_line(capsys, tmp_path):
    from steplab.cli import main

    path = tmp_path / "crate.toml"
    path.write_text(FRICTION_SCENE.format(mu_s=0.4, mu_d=0.6))
    err = refused(capsys, ["run", str(path)])
    assert err.startswith(f"steplab run: error: {path}: forces.friction.mu_dynamic: must be <= mu_static"), err
    assert "got mu_dynamic = 0.6 > mu_static = 0.4" in err
    path.write_text(FRICTION_SCENE.format(mu_s=0.5, mu_d=0.5))  # equal coefficients: no stick-slip jump
    assert main(["run", str(path)]) == 0


@pytest.mark.parametrize("center, size, angle", [
    ("[0, 0, 0]", "[5e-324, 1, 1]", 30.0),   # size / 2 underflows to 0: OrientedBox's half_extents
    ("[0, 0, 0]", "[5e-324, 1, 1]", 0.0),    # lo = hi: Box
    ("[1.7e308, 0, 0]", "[1e308, 1, 1]", 0.0),  # hi overflows: Box
])
def test_a_scene_files_box_is_refused_at_its_key_before_the_constructor(capsys, tmp_path, center, size, angle):
    path = tmp_path / "wall.toml"
    path.write_text(FRICTION_SCENE.format(mu_s=0.5, mu_d=0.3) + f"[collisions]\n[[collisions.boxes]]\n"
                    f"center = {center}\nsize = {size}\nangle = {angle}\n")
    err = refused(capsys, ["run", str(path)])
    assert err.startswith(f"steplab run: error: {path}: collisions.boxes[0].size: gives a box float64 cannot"), err
