"""Each formula of the collision pipeline is defined once, and every path calls that definition.

The sphere's contacts and times of impact (:mod:`steplab.physics.collision.sphere_contacts`),
the rest speed (:func:`steplab.physics.collision.resting.rest_speed`) and the impulse
(:mod:`steplab.physics.collision.compiled_response`) are compiled kernels; the NumPy
narrow phase, the contact solver's buffer, the event loop's re-test and its response all
call them. These tests fail when a path gets its own copy again: by the names each module
calls, by the numbers (against the lecture's formulas, written out here), and, for the
solver's reached position, by who computes it.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pathlib
import re

import numpy as np
import pytest
from steplab.integrators.semi_implicit_euler import SemiImplicitEuler
from steplab.physics import Gravity, Model
from steplab.physics.collision import CollisionWorld, Plane
from steplab.physics.collision.shapes import Sphere

# the modules by their full names: the package re-exports some functions under the same names
(chords, compiled_response, contact_buffer, narrow_phase, resting, response, retest, solver_step, sphere_contacts, step,
 time_of_impact) = (importlib.import_module(f"steplab.physics.collision.{name}") for name in (
    "chords", "compiled_response", "contact_buffer", "narrow_phase", "resting", "response", "retest", "solver_step",
    "sphere_contacts", "step", "time_of_impact"))

#: (module, the definitions it must call and may not write again)
CALLERS = [
    (narrow_phase, ["sphere_sphere_rows", "sphere_plane_rows"]),
    (contact_buffer, ["sphere_sphere", "sphere_plane", "plane_height"]),
    (retest, ["sphere_sphere", "sphere_plane", "plane_height", "sphere_sphere_entry", "sphere_plane_entry_of",
              "rest_speed", "state_at"]),
    (compiled_response, ["sphere_sphere", "sphere_plane"]),
    (time_of_impact, ["first_entry_rows", "sphere_plane_entry_rows", "sphere_sphere_entry_rows"]),
    (response, ["impulse_rows", "resolve_rows"]),
    (step, ["rest_speed"]),
    (solver_step, ["rest_speed"]),
]


#: where each definition lives
DEFINITIONS = {
    **{name: sphere_contacts for name in (
        "sphere_sphere", "sphere_plane", "plane_height", "first_entry_rows", "sphere_sphere_entry",
        "sphere_plane_entry_rows", "sphere_plane_entry_of", "sphere_sphere_rows", "sphere_plane_rows",
        "sphere_sphere_entry_rows")},
    "rest_speed": resting, "impulse_rows": compiled_response, "resolve_rows": compiled_response, "state_at": chords}


@pytest.mark.parametrize("module, names", CALLERS, ids=[m.__name__.rsplit(".", 1)[1] for m, _ in CALLERS])
def test_every_path_calls_the_one_definition(module, names):
    source = ast.parse(inspect.getsource(module))
    used = {node.id for node in ast.walk(source) if isinstance(node, ast.Name)}  # called or passed on
    defined = {node.name for node in ast.walk(source) if isinstance(node, ast.FunctionDef)}
    for name in names:
        assert name in used, f"{module.__name__} no longer uses {name}"
        assert name not in defined, f"{module.__name__} defines its own {name}"
        assert getattr(module, name) is getattr(DEFINITIONS[name], name), f"{module.__name__}.{name} is a copy"


def test_no_collision_module_but_the_definitions_writes_a_sphere_formula():
    # the sphere-sphere depth (r_a + r_b) - |d|, the rationalised root c / (-b + sqrt(disc))
    # and the plane's normal 0 - n: written anywhere else in physics/collision/, they are a copy
    # (these patterns find every copy the code had at 3dbeb93)
    copies = [re.compile(pattern) for pattern in
              (r"(\+|radius_sum)[^\n=]*- dist\b", r"-b \+ np\.sqrt", r"0\.0 - \w*normal")]
    folder = pathlib.Path(sphere_contacts.__file__).parent
    for path in sorted(folder.glob("*.py")):
        found = [pattern.pattern for pattern in copies if pattern.search(path.read_text())]
        if path.name == "sphere_contacts.py":
            assert len(found) == len(copies)  # the patterns do find the definitions
        else:
            assert not found, f"{path.name} writes {found} again"


def test_the_narrow_phase_and_the_kernels_agree_with_the_lectures_case_b(rng):
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    r_a, r_b = rng.uniform(0.1, 1.0, 50), rng.uniform(0.1, 1.0, 50)
    contact = narrow_phase.collide_sphere_sphere(Sphere(a, r_a), Sphere(b, r_b))
    d = b - a
    dist = np.linalg.norm(d, axis=1)
    np.testing.assert_allclose(contact.normal, d / dist[:, None], rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(contact.penetration_depth, r_a + r_b - dist, rtol=1e-14, atol=1e-15)
    for k in range(5):  # the scalar kernel is the same numbers, row by row
        normal, depth = sphere_contacts.sphere_sphere(tuple(d[k]), r_a[k] + r_b[k])
        assert np.array_equal(normal, contact.normal[k]) and depth == contact.penetration_depth[k]
    # concentric: +x by convention, depth r_a + r_b
    normal, depth = sphere_contacts.sphere_sphere((0.0, 0.0, 0.0), 0.5)
    assert normal == (1.0, 0.0, 0.0) and depth == 0.5


def test_a_planes_normal_is_the_same_bits_in_the_solver_and_the_narrow_phase():
    # the one definition writes the normal as 0 - n, so a zero component is +0 on every path
    # (the solver's contact buffer used to write -n: -0.0 in its logs, the only change of bits)
    floor = Plane(np.array([0.0, 0.0, 1.0]))
    narrow = narrow_phase.collide_sphere_plane(Sphere(np.array([[0.3, 0.2, 0.05]]), np.array([0.1])), floor)
    world = CollisionWorld(shapes=(floor,), method="solver")
    q, v, a = np.array([[0.3, 0.2, 0.05]]), np.zeros((1, 3)), np.array([[0.0, 0.0, -9.81]])
    bodies = contact_buffer.BodyState(q, v, a, np.array([0.1]), np.ones(1))
    c = contact_buffer.find_contacts(world, contact_buffer.Materials.of(world, 1), bodies, q, margin=0.01)
    assert np.array_equal(c.normal, narrow.normal) and not np.signbit(c.normal[0, :2]).any()
    assert c.separation[0] == -narrow.penetration_depth[0] == 0.05 - 0.1


def test_rest_speed_is_one_function_on_numbers_and_arrays():
    pressing = np.array([-3.0, 0.0, 9.81])
    expected = 1e-3 + resting.RESTING_STEPS * np.maximum(pressing, 0.0) * 0.01
    assert np.array_equal(resting.rest_speed(1e-3, pressing, 0.01), expected)
    assert [resting.rest_speed(1e-3, p, 0.01) for p in pressing] == expected.tolist()


def test_the_impulse_is_equation_4_with_coulomb_friction(rng):
    # written out with masses as the lecture does, independently of the kernel
    for _ in range(20):
        m1, m2 = rng.uniform(0.5, 3.0, 2)
        v1, v2, n = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        n /= np.linalg.norm(n)
        eps, mu = rng.uniform(0, 1), rng.choice([0.0, 0.2, 5.0])
        vn = (v1 - v2) @ n
        lam_s = -(m1 * m2 * (1 + eps) * vn / (m1 + m2)) if vn > 0 else 0.0
        vt = (v1 - v2) - vn * n
        jt = min(np.linalg.norm(vt) * m1 * m2 / (m1 + m2), mu * abs(lam_s)) if vn > 0 else 0.0
        expected = lam_s * n - jt * vt / np.linalg.norm(vt)
        y = np.stack([np.zeros((2, 3)), np.stack([v1, v2])])
        lam = response.resolve(y, np.array([0]), np.array([1]), np.array([1 / m1, 1 / m2]), n[None],
                               np.array([0.0]), eps, mu)
        np.testing.assert_allclose(lam[0], expected, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(y[1], [v1 + expected / m1, v2 - expected / m2], rtol=1e-12, atol=1e-14)


@dataclasses.dataclass(frozen=True)
class _CountingEuler(SemiImplicitEuler):
    """Semi-implicit Euler that counts its steps (a class attribute: the instances are frozen)."""

    calls = []

    def step(self, model, t, y, dt, carry):
        self.calls.append(t)
        return super().step(model, t, y, dt, carry)


def test_the_solvers_reached_position_is_its_integrators_step():
    model = Model(np.ones(2), np.full(2, 0.1), [Gravity()])
    world = CollisionWorld(shapes=(Plane(np.array([0.0, 0.0, 1.0])),), method="solver")
    stepper = solver_step.SolverStep(world, model, _CountingEuler())
    y = np.array([[[0.0, 0.0, 0.1], [0.5, 0.0, 0.3]], [[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]])
    _CountingEuler.calls.clear()
    for k in range(3):
        y, _ = stepper(0.01 * k, y, 0.01, None)
    assert _CountingEuler.calls == [0.0, 0.01, 0.02]  # once per step, from its start
