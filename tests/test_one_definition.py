"""Each formula of the collisions and of the pair forces is defined once, and every path calls that definition.

The sphere's contacts and times of impact (:mod:`steplab.physics.collision.sphere_contacts`),
the rest speed (:func:`steplab.physics.collision.resting.rest_speed`), the approach speed
(:mod:`steplab.physics.collision.approach`) and the impulse
(:mod:`steplab.physics.collision.compiled_response`) are compiled kernels; the NumPy
narrow phase, the contact solver's buffer, the event loop's re-test and its response all
call them. The spring and damper laws (:mod:`steplab.physics.pair_laws`) are evaluated by the
NumPy/JAX forces and compiled into the sparse Newton kernel. These tests fail when a path gets
its own copy again: by the names each module calls, by the numbers (against the lecture's
formulas, written out here), and, for the solver's reached position, by who computes it.
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
from steplab.physics import Dampers, Gravity, Model, Springs, dampers, pair_laws, sparse_kernels, springs
from steplab.physics.collision import CollisionWorld, Plane
from steplab.physics.collision.shapes import Sphere

# the modules by their full names: the package re-exports some functions under the same names
(approach, chords, compiled_loop, compiled_response, contact_buffer, detectors, narrow_phase, resting, response,
 retest, rigid_columns, sequential_impulses, solver_step, sphere_contacts, step, time_of_impact) = (
    importlib.import_module(f"steplab.physics.collision.{name}") for name in (
        "approach", "chords", "compiled_loop", "compiled_response", "contact_buffer", "detectors", "narrow_phase",
        "resting", "response", "retest", "rigid_columns", "sequential_impulses", "solver_step",
        "sphere_contacts", "step", "time_of_impact"))

#: (module, the definitions it must call and may not write again)
CALLERS = [
    (narrow_phase, ["sphere_sphere_rows", "sphere_plane_rows"]),
    (contact_buffer, ["sphere_sphere", "sphere_plane", "plane_height"]),
    (retest, ["sphere_sphere", "sphere_plane", "plane_height", "sphere_sphere_entry", "sphere_plane_entry_of",
              "rest_speed", "state_at"]),
    (compiled_response, ["sphere_sphere", "sphere_plane", "approach_speed"]),
    (contact_buffer, ["approach_speed", "approach_speeds"]),
    (retest, ["approach_speed"]),
    (compiled_loop, ["approach_speed"]),
    (resting, ["approach_speed", "approach_speeds"]),
    (sequential_impulses, ["approach_speed"]),
    (step, ["approach_speeds"]),
    (detectors, ["approach_speeds"]),
    (rigid_columns, ["approach_speed"]),  # the rigid contacts' pressing acceleration
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
    "rest_speed": resting, "impulse_rows": compiled_response, "resolve_rows": compiled_response, "state_at": chords,
    "approach_speed": approach, "approach_speeds": approach}


@pytest.mark.parametrize("module, names", CALLERS,
                         ids=[f"{m.__name__.rsplit('.', 1)[1]}-{names[-1]}" for m, names in CALLERS])
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


#: each law's pattern, as its copies wrote it (these patterns find every copy the code had at 1a4c08d:
#: springs.py, dampers.py and sparse_kernels.py); the laws' module is the only one to write them
LAW_PATTERNS = {"spring_tension": r"\(length - [\w.]*rest_length", "spring_transverse": r"1(\.0)? - [^#\n]*rest_length",
                "damper_tension": r"damping[\w.\[\]]* \* (dot\(|du\b|approach\b)"}


def test_no_module_but_the_pair_laws_writes_a_spring_or_damper_law():
    folder = pathlib.Path(pair_laws.__file__).parent
    for path in sorted(folder.rglob("*.py")):
        text = path.read_text()
        found = [name for name, pattern in LAW_PATTERNS.items() if re.search(pattern, text)]
        if path.name == "pair_laws.py":
            assert len(found) == len(LAW_PATTERNS)  # the patterns do find the definitions
        else:
            assert not found, f"{path.relative_to(folder)} writes {found} again"


@pytest.mark.parametrize("module, names", [
    (springs, ["spring_tension", "spring_potential", "spring_transverse", "spring_block"]),
    (dampers, ["damper_tension", "damper_velocity_block", "damper_position_block"]),
    (sparse_kernels, ["spring_tension", "spring_transverse", "spring_block", "damper_tension",
                      "damper_velocity_block", "damper_position_block"]),
], ids=["springs", "dampers", "sparse_kernels"])
def test_the_forces_and_the_kernel_evaluate_the_pair_laws(module, names):
    used = {node.attr if isinstance(node, ast.Attribute) else node.id
            for node in ast.walk(ast.parse(inspect.getsource(module))) if isinstance(node, ast.Name | ast.Attribute)}
    for name in names:
        assert name in used, f"{module.__name__} no longer evaluates pair_laws.{name}"
        if hasattr(module, name):
            assert getattr(module, name) is getattr(pair_laws, name), f"{module.__name__}.{name} is a copy"


def test_the_kernel_and_the_numpy_forces_are_hookes_and_the_dashpots_law(rng):
    # written out here as the lecture does: F = [k (l - L) + c (d . u)] d on the first body
    n, p = 12, 30
    i, j = rng.integers(0, n, p), rng.integers(0, n, p)
    i, j = i[i != j], j[i != j]
    k, rest, c = rng.uniform(1, 100, i.size), rng.uniform(0.1, 2, i.size), rng.uniform(0, 3, i.size)
    q, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    delta = q[j] - q[i]
    length = np.linalg.norm(delta, axis=1)
    d = delta / length[:, None]
    f = (k * (length - rest) + c * np.sum((v[j] - v[i]) * d, axis=1))[:, None] * d
    expected = np.zeros((n, 3))
    np.add.at(expected, i, f)
    np.add.at(expected, j, -f)
    springs_and_dampers = [Springs(i, j, k, rest), Dampers(i, j, c)]
    numpy_force = sum(force.force(np, q, v, np.ones(n)) for force in springs_and_dampers)
    kernel_force = np.zeros((n, 3))
    sparse_kernels.PairGroup(*springs_and_dampers).add_forces(kernel_force, q, v)
    np.testing.assert_allclose(numpy_force, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(kernel_force, expected, rtol=1e-12, atol=1e-12)


def test_the_approach_speed_is_the_relative_velocity_along_the_normal(rng):
    for _ in range(10):
        v_a, v_b, n = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        speed = approach.approach_speed(tuple(v_a), tuple(v_b), tuple(n))
        assert speed == (v_a[0] - v_b[0]) * n[0] + (v_a[1] - v_b[1]) * n[1] + (v_a[2] - v_b[2]) * n[2]
        assert np.isclose(speed, (v_a - v_b) @ n, rtol=1e-14, atol=1e-15)


#: the approach speed as its copies wrote it (these patterns find every copy the code had at 976350a:
#: retest.py, compiled_loop.py, resting.py, compiled_response.py, sequential_impulses.py, response.py,
#: contact_buffer.py, rigid_solver_step.py): a velocity or acceleration difference dotted with the normal
APPROACH_COPIES = {
    "dot3 of a difference": r"dot3\(sub3\(",  # the definition's own expression
    "dot3 of a relative velocity": r"dot3\(v_rel\b",
    "components by hand": r"\br0 \* (n0|normal\[k, 0\])",
    "NumPy sum along the normal": r"\* \w*normal\w*\)?, axis=-?1\)|_dot\(np\.asarray\(v_a\)",
    # two projections subtracted (the rigid columns' pressing acceleration at 18acd81)
    "a difference of projections": r"-= dot3\(|\) - dot3\(",
}


def test_no_collision_module_but_its_definition_writes_the_approach_speed():
    # the boxes' and capsules' narrow phases (manifold_*.py) project points on axes with the same
    # products: geometry, not an approach speed, and not searched
    folder = pathlib.Path(approach.__file__).parent
    for path in sorted(folder.glob("*.py")):
        if path.name.startswith("manifold_"):
            continue
        text = path.read_text()
        found = [name for name, pattern in APPROACH_COPIES.items() if re.search(pattern, text)]
        if path.name == "approach.py":
            assert found == ["dot3 of a difference"]  # the pattern does find the definition
        else:
            assert not found, f"{path.name} writes the approach speed again ({found})"


def test_the_numpy_approach_speeds_are_the_kernels_bit_for_bit(rng):
    v_a, v_b, n = rng.normal(size=(40, 3)), rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    rows = approach.approach_speeds(v_a, v_b, n)
    assert rows.shape == (40,)
    assert [approach.approach_speed(tuple(x), tuple(y), tuple(z)) for x, y, z in zip(v_a, v_b, n)] == rows.tolist()
    # broadcast like NumPy: one vector against rows, a static shape at rest, and single vectors
    assert np.array_equal(approach.approach_speeds(v_a, approach.AT_REST, n), np.sum(v_a * n, axis=1))
    assert approach.approach_speeds(v_a[0], v_b[0], n[0]) == rows[0]
    assert approach.approach_speeds(np.zeros((0, 3)), v_b[0], n[0]).shape == (0,)
