"""The registries: forces by scene key (each class parsing its own table), the one list of
detectors, every collision method, and the constant forces that ``exact`` solves in closed form."""

from __future__ import annotations

import argparse
import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import TWO_BODY_SCENE
from numpy.testing import assert_allclose, assert_array_equal
from steplab.integrators import simulate
from steplab.physics import ConstantForce, Force, Gravity, Model
from steplab.physics.collision import CollisionWorld
from steplab.physics.collision.detectors import DETECTOR_NAMES, DETECTORS
from steplab.physics.collision.methods import COLLISION_METHODS
from steplab.physics.forces import FORCES, register_force
from steplab.physics.scene import SceneError, parse_scene

from steplab.cli import build_parser
from steplab.core.registry import PluginError

G = np.array([0.0, 0.0, -9.81])
WIND = np.array([0.5, 0.0, 0.0])  # N


def projectile(t, p0, v0, a):
    """p0 + v0 t + a t^2 / 2 and v0 + a t, shape (K, N, 3), for a constant acceleration a."""
    t = np.asarray(t)[:, None, None]
    return p0 + v0 * t + 0.5 * a * t**2, v0 + a * t


# --- a constant force other than gravity ------------------------------------------------------


def test_constant_wind_exact_is_the_projectile_and_rk4_agrees():
    # the case: a 0.5 N wind on a 1 kg body gave x = 0 with exact, 0.25 m with rk4 after 1 s
    model = Model([1.0], [0.1], [Gravity(G), ConstantForce(WIND[None, :])])
    y0 = np.array([[[0.0, 0.0, 2.0]], [[1.0, 0.0, 3.0]]])
    exact = simulate(model, "exact", y0, 0.0, 1.0, 0.1)
    rk4 = simulate(model, "rk4", y0, 0.0, 1.0, 0.1)
    p, v = projectile(exact.t, y0[0], y0[1], WIND / 1.0 + G)
    assert_allclose(exact.positions, p, rtol=1e-15, atol=1e-15)
    assert_allclose(exact.velocities, v, rtol=1e-15, atol=1e-15)
    assert exact.positions[-1, 0, 0] == pytest.approx(1.0 + 0.25, rel=1e-15)
    # RK4 integrates a quadratic in t exactly: the two agree to round-off
    assert_allclose(rk4.positions, exact.positions, rtol=0, atol=1e-13)
    assert_allclose(rk4.velocities, exact.velocities, rtol=0, atol=1e-13)
    # conservative: U = -F . q - m g . q, so the mechanical energy is constant along the truth
    energy = [float(model.energy(np.stack([q, w]))) for q, w in zip(p, v)]
    assert_allclose(energy, energy[0], rtol=1e-14)


def test_constant_force_is_one_field_on_numpy_and_jax():
    # two bodies, a wind on both and a push on the second; the pinned third never moves
    f = np.array([WIND, WIND + [0.0, 1.0, 0.0], WIND])
    masses = np.array([1.0, 2.0, 3.0])
    model = Model(masses, [0.1] * 3, [Gravity(G), ConstantForce(f)], pinned=[False, False, True])
    expected = np.where([[False], [False], [True]], 0.0, f / masses[:, None] + G)
    assert_allclose(model.constant_acceleration, expected, rtol=1e-15)
    q, v = np.ones((3, 3)), np.ones((3, 3))
    assert_allclose(model.acceleration(0.0, q, v), expected, rtol=1e-15)
    dq, dv = model.jacobian(0.0, q, v)
    assert_array_equal(dq, 0.0)
    assert_array_equal(dv, 0.0)
    jmodel = model.cast(jnp)
    assert_allclose(np.asarray(jax.jit(jmodel.acceleration)(0.0, jnp.asarray(q), jnp.asarray(v))), expected,
                    rtol=1e-15)
    # F = -grad U, also through autodiff of the potential
    grad = jax.grad(jmodel.potential_energy)(jnp.asarray(q))
    assert_allclose(-np.asarray(grad), masses[:, None] * G + f, rtol=1e-15)


CONSTANT_SCENE = """
[simulation]
integrator = "exact"
dt = 0.25
t_end = 2.0
[[bodies]]
name = "a"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 5.0]
velocity = [1.0, 2.0, 3.0]
[[bodies]]
name = "b"
mass = 2.0
radius = 0.1
position = [1.0, 0.0, 5.0]
[forces.gravity]
[[forces.constant]]
force = [0.5, 0.0, 0.0]
[[forces.constant]]
force = [0.0, 1.0, 0.0]
bodies = ["b"]
"""


def test_constant_wind_from_a_scene_file_is_solved_exactly():
    scene = parse_scene(CONSTANT_SCENE, "wind.toml")
    a = np.array([WIND + G, (WIND + [0.0, 1.0, 0.0]) / 2.0 + G])
    assert_allclose(scene.model.constant_acceleration, a, rtol=1e-15)
    exact = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, scene.t_end, scene.dt)
    p, v = projectile(exact.t, scene.y0[0], scene.y0[1], a)
    assert_allclose(exact.positions, p, rtol=1e-15, atol=1e-14)
    rk4 = simulate(scene.model, "rk4", scene.y0, scene.t_start, scene.t_end, scene.dt)
    assert_allclose(rk4.positions, exact.positions, rtol=0, atol=1e-13)


def test_constant_force_table_errors_name_the_key():
    with pytest.raises(SceneError, match=r"^s.toml: forces.constant\[1\].bodies: names unknown body 'c'$"):
        parse_scene(CONSTANT_SCENE.replace('["b"]', '["c"]'), "s.toml")
    with pytest.raises(SceneError, match=r"^s.toml: forces.constant\[0\].force: missing required key$"):
        parse_scene(TWO_BODY_SCENE + "[[forces.constant]]\n", "s.toml")
    huge = TWO_BODY_SCENE + "[[forces.constant]]\nforce = [1e308, 0, 0]\n" * 2
    with pytest.raises(SceneError, match=r"forces.constant\[1\].force: .* more than the largest float"):
        parse_scene(huge, "s.toml")


# --- the force registry drives the scene parser -----------------------------------------------

#: the smallest table of each of steplab's own forces, on TWO_BODY_SCENE's bodies "a" and "b"
MINIMAL = {
    "gravity": "[forces.gravity]\n",
    "central_gravity": "[forces.central_gravity]\nmu = 1.0\n",
    "springs": '[[forces.springs]]\nbodies = ["a", "b"]\nstiffness = 1.0\n',
    "dampers": '[[forces.dampers]]\nbodies = ["a", "b"]\ndamping = 1.0\n',
    "drag": "[forces.drag]\n",
    "friction": "[forces.friction]\nmu_static = 0.5\nmu_dynamic = 0.3\n",
    "constant": "[[forces.constant]]\nforce = [1.0, 0.0, 0.0]\n",
}


@pytest.mark.parametrize("key", list(FORCES))
def test_every_registered_force_parses_from_its_minimal_table(key):
    if FORCES.origin(key) != "steplab":
        pytest.skip(f"{key} comes from a plugin ({FORCES.origin(key)})")
    assert key in MINIMAL, f"add a minimal scene table for the force {key!r} to MINIMAL"
    (force,) = parse_scene(TWO_BODY_SCENE + MINIMAL[key]).model.forces
    assert type(force) is FORCES[key] and force.name == key
    bracket = "[[" if FORCES[key].array_of_tables else "["
    assert MINIMAL[key].startswith(f"{bracket}forces.{key}]")


def test_unknown_force_key_lists_the_registered_keys():
    with pytest.raises(SceneError) as err:
        parse_scene(TWO_BODY_SCENE + "[forces.wind]\nforce = [1.0, 0.0, 0.0]\n", "s.toml")
    assert str(err.value) == f"s.toml: forces: unknown key 'wind'; allowed: {', '.join(sorted(FORCES))}"


@dataclasses.dataclass(frozen=True)
class LinearDrag(Force):
    """Stokes drag, F = -b V, defined here: the scene file reaches it through the registry alone."""

    b: np.ndarray

    name: ClassVar[str] = "linear_drag"

    @classmethod
    def from_scene(cls, table, bodies):
        table.allow("b")
        return cls(np.full(bodies.n, table.number("b", 0.1, nonnegative=True)))

    def force(self, xp, q, v, m):
        return -self.b[:, None] * v


def test_a_force_registered_in_a_test_parses_from_a_scene():
    with pytest.raises(SceneError, match="unknown key 'linear_drag'"):
        parse_scene(TWO_BODY_SCENE + "[forces.linear_drag]\nb = 0.5\n")
    assert register_force(LinearDrag) is LinearDrag
    try:
        assert register_force(LinearDrag) is LinearDrag  # the same class again: no error
        scene = parse_scene(TWO_BODY_SCENE.replace("mass = 1.0", "mass = 2.0", 1) + "[forces.linear_drag]\nb = 0.5\n")
        (force,) = scene.model.forces
        assert isinstance(force, LinearDrag)
        v = np.array([[1.0, 2.0, 3.0], [-4.0, 0.0, 1.0]])
        assert_allclose(scene.model.acceleration(0.0, scene.y0[0], v), -0.5 * v / [[2.0], [1.0]], rtol=1e-15)
        with pytest.raises(SceneError, match=r"forces.linear_drag.b: must be >= 0"):
            parse_scene(TWO_BODY_SCENE + "[forces.linear_drag]\nb = -1.0\n")
    finally:
        del FORCES[LinearDrag.name]
    assert "linear_drag" not in FORCES


def test_register_force_refuses_a_taken_key_and_a_class_without_a_table():
    taken = dataclasses.make_dataclass("OtherGravity", [], bases=(LinearDrag,), frozen=True,
                                       namespace={"name": "gravity"})
    with pytest.raises(PluginError, match="force name 'gravity' is taken"):
        register_force(taken)
    unparsed = dataclasses.make_dataclass("Unparsed", [], bases=(Force,), frozen=True, namespace={"name": "unparsed"})
    with pytest.raises(PluginError, match="needs a classmethod from_scene"):
        register_force(unparsed)
    with pytest.raises(PluginError, match="not a subclass"):
        register_force(Gravity())
    assert FORCES["gravity"] is Gravity and "unparsed" not in FORCES


# --- one list of detectors ----------------------------------------------------------------------


def _detector_choices() -> dict[str, tuple]:
    """The --detector choices of every steplab subcommand that has the option."""
    (commands,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return {name: tuple(action.choices) for name, sub in commands.choices.items() for action in sub._actions
            if "--detector" in action.option_strings}


def test_detector_names_are_one_list():
    assert DETECTOR_NAMES == tuple(DETECTORS) and "swept" in DETECTOR_NAMES
    choices = _detector_choices()
    assert set(choices) >= {"run", "animate"}
    assert all(c == DETECTOR_NAMES for c in choices.values())


@pytest.mark.parametrize("detector", [*DETECTOR_NAMES, "sweep"])
def test_world_and_scene_accept_exactly_the_detector_names(detector):
    scene = TWO_BODY_SCENE + f'[collisions]\ndetector = "{detector}"\n'
    if detector in DETECTOR_NAMES:
        assert CollisionWorld(detector).detector == detector
        assert parse_scene(scene).collisions.detector == detector
        return
    with pytest.raises(ValueError, match=f"valid: {', '.join(DETECTOR_NAMES)}$"):
        CollisionWorld(detector)
    with pytest.raises(SceneError, match=f"collisions.detector: must be one of {', '.join(DETECTOR_NAMES)}, got"):
        parse_scene(scene, "s.toml")


# --- every collision method, as registered --------------------------------------------------

#: a ball of radius 0.1 m dropped from rest 1 m above a floor (z = 0), restitution 0, for 1.5 s:
#: it lands at t = sqrt(2 * 0.9 / g) = 0.43 s and must then rest on the floor
DROP_ON_FLOOR = """
[simulation]
integrator = "semi-implicit-euler"
dt = 0.01
t_end = 1.5
[[bodies]]
name = "ball"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 1.0]
[forces.gravity]
[collisions]
method = "{method}"
restitution = 0.0
[[collisions.planes]]
normal = [0.0, 0.0, 1.0]
"""


@pytest.mark.parametrize("method", list(COLLISION_METHODS))
def test_every_collision_method_stops_a_ball_dropped_on_the_floor(method):
    """Free fall to the floor within a first-order method's error of the parabola, |z - (1 - g t^2 / 2)|
    <= g dt t / 2 (semi-implicit Euler's, in steps or substeps), then at rest on it: the centre
    one radius above the floor, within 1 mm at every step."""
    scene = parse_scene(DROP_ON_FLOOR.format(method=method))
    assert scene.collisions.method == method
    traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, scene.t_end, scene.dt,
                    collisions=scene.collisions)
    t, z, vz = traj.t, traj.positions[:, 0, 2], traj.velocities[:, 0, 2]
    before = t < 0.35  # well above the floor
    assert np.all(np.abs(z - (1.0 - 0.5 * 9.81 * t**2))[before] <= 0.5 * 9.81 * scene.dt * t[before] * (1 + 1e-9))
    assert np.all(z >= 0.1 - 1e-3)
    assert abs(z[-1] - 0.1) <= 1e-3 and abs(vz[-1]) <= 0.1


def test_an_unknown_collision_method_is_one_line_naming_the_known_ones():
    with pytest.raises(SceneError, match=r"^s.toml: collisions.method: must be one of event, solver, got"):
        parse_scene(DROP_ON_FLOOR.format(method="magic"), "s.toml")
    with pytest.raises(ValueError, match=r"^unknown collision method 'magic'; valid: event, solver$"):
        CollisionWorld(method="magic")
    with pytest.raises(SceneError, match=r"collisions.solver: sets the collision method 'solver', but the method "
                                         r'is not "solver" \(add method = "solver"\)$'):
        parse_scene(DROP_ON_FLOOR.format(method="event") + "[collisions.solver]\nsubsteps = 2\n", "s.toml")


# --- one kind of registry ---------------------------------------------------------------------


def _registries():
    from steplab.integrators import INTEGRATORS
    from steplab.physics.broadphase import METHODS
    from steplab.physics.scene_library import SCENES
    from steplab.studies import STUDIES

    from steplab.engines import ENGINES

    return {"integrator": INTEGRATORS, "force": FORCES, "collision detector": DETECTORS,
            "collision method": COLLISION_METHODS, "broadphase method": METHODS, "engine": ENGINES,
            "scene": SCENES, "study": STUDIES}


@pytest.mark.parametrize("what", list(_registries()))
def test_every_registry_is_one_kind_with_its_group_and_one_lookup_error(what):
    from steplab.core.registry import GROUPS, Registry, UnknownNameError

    registry = _registries()[what]
    assert isinstance(registry, Registry) and registry.what == what and registry.group in GROUPS
    with pytest.raises(UnknownNameError) as err:
        registry.lookup("nope")
    assert str(err.value) == f"unknown {what} 'nope'; valid: {', '.join(registry)}"
    assert isinstance(err.value, KeyError) and isinstance(err.value, ValueError)


def test_a_function_registry_takes_a_name_and_serves_as_a_decorator():
    from steplab.physics.broadphase import METHODS, brute_force_pairs, find_pairs

    with pytest.raises(PluginError, match=r"has no name: register it with name="):
        METHODS.register(lambda c, r: brute_force_pairs(c, r))
    with pytest.raises(PluginError, match=r"^3 is not a function pairs\(centers, radii\)$"):
        METHODS.register(3, name="three")
    with pytest.raises(PluginError, match=r"broadphase method name 'grid' is taken \(by steplab\)"):
        METHODS.register(brute_force_pairs, name="grid")

    @METHODS.register(name="brute-again")
    def brute_again(c, r):
        return brute_force_pairs(c, r)

    try:
        assert METHODS["brute-again"] is brute_again
        c = np.random.default_rng(3).uniform(0, 2, (40, 3))
        assert_array_equal(find_pairs(c, 0.3, "brute-again"), find_pairs(c, 0.3, "brute"))
    finally:
        del METHODS["brute-again"]
