"""vbd: the colouring is proper, the converged sweep is implicit Euler's step, no energy is gained."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import spring_net
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import VBD, XPBD, simulate
from steplab.integrators.block_descent import descend
from steplab.integrators.colouring import adjacency, greedy_colouring
from steplab.integrators.constraint_projection import bodies, coordinates, project
from steplab.physics import Dampers, Gravity, Model, Springs
from steplab.physics.scene import load_scene

CLOTH = load_scene("cloth")


def test_the_cloths_colouring_is_proper_and_small():
    c = CLOTH.model.distance_constraints()
    colour = greedy_colouring(adjacency(CLOTH.model.n_bodies, c.i, c.j))
    assert not np.any(colour[c.i] == colour[c.j])
    # greedy uses at most max degree + 1 colours; the grid with its diagonals needs 4 (a 2x2 block is a K4)
    assert colour.max() + 1 == 4


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 30).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)).filter(lambda e: e[0] != e[1]),
                         max_size=4 * n))))
def test_the_greedy_colouring_of_any_graph_is_proper(graph):
    n, edges = graph
    i, j = (np.array(e, np.int64).reshape(-1) for e in zip(*edges)) if edges else (np.zeros(0, np.int64),) * 2
    colour = greedy_colouring(adjacency(n, i, j))
    degree = np.bincount(np.concatenate([i, j]), minlength=n)
    assert colour.min() >= 0 and not np.any(colour[i] == colour[j])
    assert colour.max() <= degree.max()  # Welsh and Powell's bound: at most max degree + 1 colours
    # brute force, independently of the graph structure built for the sweep: no two colour-mates share an edge
    for a, b in edges:
        assert colour[a] != colour[b]


def test_a_spring_from_a_body_to_itself_is_one_line():
    with pytest.raises(ValueError, match="spring 1 joins body 2 to itself: no colouring separates its ends"):
        adjacency(3, np.array([0, 2]), np.array([1, 2]))


def damped_net(seed):
    """:func:`spring_net` with dampers on half its springs, gravity and one pinned body."""
    model, y0 = spring_net(seed)
    springs = model.forces[0]
    half = slice(0, len(springs.i), 2)
    dampers = Dampers(springs.i[half], springs.j[half], np.full(len(springs.i[half]), 0.5))
    pinned = np.arange(model.n_bodies) == 0
    y0[1, 0] = 0.0
    return Model(model.masses, model.radii, [springs, dampers, Gravity()], pinned=pinned), y0


@pytest.mark.parametrize("dt", [1e-3, 1e-2, 5e-2])
@pytest.mark.parametrize("seed", [0, 1])
def test_converged_vbd_is_implicit_eulers_step(seed, dt):
    # implicit-euler's Newton iteration (dense, to its tolerance) and vbd's block descent find the
    # same stationary point of the incremental potential, from different starts and by different
    # linearisations: they agree to the Newton tolerance, a few steps in a row
    model, y0 = damped_net(seed)
    a = simulate(model, VBD(iterations=400), y0, 0.0, n_steps=3, dt=dt).y
    b = simulate(model, "implicit-euler", y0, 0.0, n_steps=3, dt=dt).y
    scale = np.abs(b[:, 1]).max()
    np.testing.assert_allclose(a[:, 0], b[:, 0], rtol=0, atol=1e-10)
    np.testing.assert_allclose(a[:, 1], b[:, 1], rtol=0, atol=1e-8 * scale)
    # and unconverged it is not (the comparison can fail)
    c = simulate(model, VBD(iterations=1), y0, 0.0, n_steps=3, dt=dt).y
    assert np.abs(c[:, 0] - b[:, 0]).max() > 1e-9


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("method", [VBD(1, 1), VBD(4, 2)])
def test_undamped_vbd_never_gains_energy(seed, method):
    # converged, the step is implicit Euler's, which only dissipates; unconverged, each local step
    # still lowers the incremental potential G, which this checks on the energy, step after step
    model, y0 = spring_net(seed)
    traj = simulate(model, method, y0, 0.0, n_steps=2000, dt=1e-2)
    energy = np.array([model.energy(y) for y in traj.y])
    assert energy.max() <= energy[0] * (1 + 1e-12)
    assert energy[-1] < 0.9 * energy[0]


def test_vbd_refuses_inextensible_springs_in_one_line():
    model = Model(np.ones(2), np.full(2, 0.1), [Springs(np.array([0]), np.array([1]), np.array([np.inf]),
                                                        np.array([1.0]))], pinned=[True, False])
    y0 = np.zeros((2, 2, 3))
    y0[0, 1, 0] = 1.0
    with pytest.raises(ValueError, match="stiffness = inf, an inextensible constraint.*pbd and xpbd take it"):
        simulate(model, "vbd", y0, 0.0, n_steps=1, dt=1e-3)


def test_the_python_and_compiled_sweeps_agree(monkeypatch):
    # Numba's compiled kernels against the same functions run by the Python interpreter on NumPy
    # scalars: the same operations in the same order, so the same bytes (for xpbd, the sweep's
    # eight-lane vector block against its plain-Python twin in integrators/projection_block.py)
    from steplab.integrators import constraint_projection

    model, y0 = damped_net(3)
    h = 1e-2
    for method in (VBD(), XPBD()):
        carry = method.init(model, 0.0, y0)
        q, v = y0
        external = carry.external
        if method.name == "xpbd":  # its carry holds the bodies in the sweep's rows (integrators/arrangement.py)
            carry = carry.for_substep(h)
            (q, v), external = carry.in_rows(y0)
        dy = h * (v + h * external)
        runs = []
        for kernel in ((descend, descend.py_func) if method.name == "vbd" else (project, project.py_func)):
            if method.name == "vbd":
                dx = dy.copy()
                kernel(dx, q, dy, carry.graph, h, 5)
            else:
                dx = coordinates(dy)  # the sweep's rows, a coordinate each
                with monkeypatch.context() as patch:
                    if kernel is project.py_func:  # its inlined segment, interpreted too
                        patch.setattr(constraint_projection, "_segment", constraint_projection._segment.py_func)
                    kernel(dx, coordinates(q), carry.inverse_mass, carry.sweep, 5, True, carry.work)
                dx = np.ascontiguousarray(bodies(dx, len(q)))
            runs.append(dx)
        assert runs[0].tobytes() == runs[1].tobytes()
        assert np.abs(runs[0] - dy).max() > 1e-6  # the sweep moved something


def test_vbd_holds_the_cloth_at_a_large_step_and_is_softer_unconverged():
    # implicit in the springs: the cloth at 25x its scene dt, far past semi-implicit Euler's limit;
    # stopped early, block descent has not taken up all the springs' force: the cloth sags more
    c = CLOTH.model.distance_constraints()
    lowest, most_stretched = [], []
    for iterations in (10, 100):
        traj = simulate(CLOTH.model, VBD(iterations=iterations), CLOTH.y0, 0.0, 1.0, 0.05)
        q = traj.positions[-1]
        assert np.all(np.isfinite(traj.y))
        lowest.append(q[:, 2].min())
        most_stretched.append(np.max(np.linalg.norm(q[c.j] - q[c.i], axis=1) / c.rest_length - 1))
    assert most_stretched[1] < 0.2 < most_stretched[0]
    assert lowest[0] < lowest[1] < CLOTH.y0[0, :, 2].min() - 0.1  # both fell, the unconverged one further
