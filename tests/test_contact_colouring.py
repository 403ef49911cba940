"""The contact solver's coloured sweep order (issue 26): a proper colouring, and the same bytes on any threads.

The colouring is checked against its definition (no two manifolds of a colour share a dynamic
body; every point once; a manifold's points together and in their order), and the parallel
sweep against itself on one thread: the coloured order is the one order, so a pile of boxes
stepped on 1, 2 or 3 parts of each colour must give the same bytes.
"""

from __future__ import annotations

import importlib

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import get_integrator
from steplab.physics import Gravity, Model
from steplab.physics import quaternion as quat
from steplab.physics.collision import CollisionWorld, PairProperties, Plane, rigid_solver_step
from steplab.physics.collision.contact_colouring import (
    COLOURS,
    Colours,
    bodies_of,
    colour_contacts,
    next_groups,
    piece,
    rows_of,
    sides,
)
from steplab.physics.collision.rigid_solver_step import RigidScene, RigidSolverStep
from steplab.physics.collision.solver_settings import ContactSolver
from steplab.physics.rigid_body import RigidBodies, principal_inertia
from steplab.physics.scene import SceneError, parse_scene

from steplab.bench.stacking import box_pit_toml
from steplab.cli import main

#: the rigid narrow phase's module (the package's name ``manifolds`` is its function)
manifolds = importlib.import_module("steplab.physics.collision.manifolds")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 11), st.integers(-3, 11), st.integers(1, 4)), min_size=0, max_size=60),
       st.lists(st.integers(0, 1), min_size=12, max_size=12), st.integers(1, 4))
def test_the_colours_are_a_proper_colouring_of_the_manifolds(manifolds_, side, threads):
    """Random manifolds (a, b, points) among 12 bodies on random sides and 3 static shapes: each colour's
    manifolds share no body (statics excepted), those of side 0 (their body a's) before side 1's, each
    side in the sorted order; every row is listed once, each manifold's rows together and in order; the
    bodies listed side by side, each side ascending, and each thread's share of them on its side."""
    pairs = sorted({(a, b): p for a, b, p in manifolds_ if a != b}.items())
    a = np.array([x for (i, _), p in pairs for x in [i] * p], np.int64)
    b = np.array([x for (_, j), p in pairs for x in [j] * p], np.int64)
    side = np.array(side, np.int64)
    order, colours = colour_contacts(a, b, side, threads)
    assert sorted(order.tolist()) == list(range(len(a)))
    assert colours.threads == threads and colours.rows[-1] == len(a)
    groups = len(colours.colour_start) - 1
    assert colours.parallel == groups  # 12 bodies: never the overflow
    for g in range(groups):
        bodies, keys = [], []
        for m in range(colours.colour_start[g], colours.colour_start[g + 1]):
            rows = order[colours.rows[m]:colours.rows[m + 1]]
            assert len(set(zip(a[rows].tolist(), b[rows].tolist()))) == 1  # one manifold
            assert np.all(np.diff(rows) == 1)  # its points in their order
            assert side[a[rows[0]]] == (m >= colours.side_start[g])
            keys.append((side[a[rows[0]]], rows[0]))
            bodies += [a[rows[0]]] + ([b[rows[0]]] if b[rows[0]] >= 0 else [])
        assert len(bodies) == len(set(bodies))  # a colour's manifolds share no body
        assert keys == sorted(keys)
    expected = [body for s in (0, 1) for body in range(12) if side[body] == s]
    assert colours.bodies.tolist() == expected and colours.body_cut == np.sum(side == 0)
    # the velocity and position stages: every body once, and on an even thread count each side's bodies
    # on the threads that sweep that side
    taken = [colours.bodies[slice(*bodies_of(colours, part))].tolist() for part in range(threads)]
    assert sorted(sum(taken, [])) == list(range(12))
    if threads % 2 == 0:
        assert all(side[body] == (part >= threads // 2) for part, bodies in enumerate(taken) for body in bodies)
    for parts in range(1, 5):  # the passes by the sweep's parts (gather, masses) take every row once
        rows = [k for g in range(groups) for part in range(parts) for k in range(*rows_of(colours, g, part, parts))]
        assert sorted(rows) == list(range(len(a)))


@pytest.mark.parametrize("parts, expected", [
    (1, [(0, 10)]), (2, [(0, 4), (4, 10)]), (3, [(0, 3), (3, 6), (6, 10)]), (4, [(0, 2), (2, 4), (4, 7), (7, 10)])])
def test_an_even_number_of_parts_takes_half_of_them_from_each_side(parts, expected):
    """Manifolds 0 to 9, side 1's from 4: 2 parts are the two sides, 4 parts two of each, and an odd number
    of parts nearly equal spans whatever the sides."""
    assert [tuple(piece((0, 4, 10), part, parts)) for part in range(parts)] == expected


def test_the_sides_halve_the_moving_bodies_across_their_widest_extent():
    """Centres spread 10 m along y and 1 m along x: the cut is across y at the moving bodies' median;
    a pinned body far out does not move it."""
    rng = np.random.default_rng(4)
    q = np.column_stack([rng.uniform(0, 1, 101), rng.uniform(0, 10, 101), rng.uniform(0, 1, 101)])
    q[-1] = [0.0, 100.0, 0.0]
    movable = np.ones(101, bool)
    movable[-1] = False
    side = sides(q, movable)
    assert np.sum(side[:-1] == 0) == 50 and side[-1] == 1
    assert np.all((side[:-1] == 1) == (q[:-1, 1] >= np.median(q[:-1, 1])))
    assert not sides(q, np.zeros(101, bool)).any()


def test_of_two_wide_extents_the_sides_cut_the_numbering_into_fewer_runs():
    """A 20 x 20 lattice numbered along x, then y (as the box pit's): cut across x, each row of 20 is two
    runs (40 side changes along the numbering); cut across y, the numbering changes side once. Both
    extents are wide, so the cut is across y; a lattice 3 times longer along x is cut across x."""
    k = np.arange(400)
    q = np.column_stack([k % 20, k // 20, np.zeros(400)]).astype(float)
    side = sides(q, np.ones(400, bool))
    assert np.all(side == (q[:, 1] >= 10)) and np.count_nonzero(np.diff(side)) == 1
    q[:, 0] *= 3.0
    assert np.all(sides(q, np.ones(400, bool)) == (q[:, 0] >= 30))


def test_a_body_in_more_manifolds_than_colours_goes_to_the_overflow():
    """Body 0 touching COLOURS + 2 others: the last two manifolds find every colour taken."""
    a = np.zeros(COLOURS + 2, np.int64)
    b = np.arange(1, COLOURS + 3, dtype=np.int64)
    order, colours = colour_contacts(a, b, np.zeros(COLOURS + 3, np.int64), 2)
    assert colours.parallel == COLOURS and len(colours.colour_start) - 1 == COLOURS + 1
    assert colours.colour_start[-1] - colours.colour_start[-2] == 2
    assert order[-2:].tolist() == [COLOURS, COLOURS + 1]


def box_pile(n, seed, threads=1):
    """n boxes (0.1-0.2 m) in a seeded jumble above a floor, turned and spinning, the solver on
    ``threads`` threads: (step, y0)."""
    rng = np.random.default_rng(seed)
    half, masses = rng.uniform(0.05, 0.1, (n, 3)), rng.uniform(0.5, 2.0, n)
    inertia = np.array([principal_inertia("box", m, 0.0, 2 * h) for m, h in zip(masses, half)])
    bodies = RigidBodies(np.arange(n), inertia, quat.normalize(np, rng.normal(size=(n, 4))),
                         2 * rng.normal(size=(n, 3)), ("box",) * n)
    world = CollisionWorld(shapes=(Plane(np.array([0.0, 0.0, 1.0])),), method="solver",
                           pair_properties=PairProperties(0.2, 0.5), solver=ContactSolver(threads=threads),
                           rigid=RigidScene(np.full(n, manifolds.BOX, np.int8), np.zeros(n), half, bodies))
    k = np.arange(n)
    side = int(np.ceil(np.sqrt(n / 3)))
    position = np.stack([k % side * 0.3, k // side % side * 0.3, 0.2 + k // side**2 * 0.3], axis=1)
    step = RigidSolverStep(world, Model(masses, np.full(n, 0.1), [Gravity()]), get_integrator("semi-implicit-euler"))
    return step, np.stack([position + rng.uniform(-0.03, 0.03, (n, 3)), rng.normal(size=(n, 3))])


def pile_run(threads, steps=40):
    """The bytes of :func:`box_pile`'s 40 boxes after ``steps`` steps on ``threads`` threads, and its
    last step's contact points."""
    step, y = box_pile(40, seed=3, threads=threads)
    for k in range(steps):
        y, _ = step(k / 60, y, 1 / 60, None)
    return y.tobytes(), step.orientation.tobytes(), step.omega.tobytes(), len(step._previous.pn)


def every_colour_parallel(monkeypatch):
    """The step's colours cut into parts however few manifolds they hold (``serial_below`` 0)."""
    colour = rigid_solver_step.colour_contacts

    def parallel(*args):
        order, colours = colour(*args)
        return order, colours._replace(serial_below=0)

    monkeypatch.setattr(rigid_solver_step, "colour_contacts", parallel)


@pytest.mark.parametrize("threads", [1, 2])
def test_small_colours_and_the_overflow_are_swept_in_runs_on_one_thread(threads):
    """Groups of 600, 500, 20, 700 and 3 manifolds (the last the overflow), serial below 512: the
    sweep visits them in order, every manifold once; on 2 threads the colours of 600 and 700 alone
    in 2 parts and the others in runs on one thread, on 1 thread all of them in one run."""
    sizes = [600, 500, 20, 700, 3]
    start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    colours = Colours(np.arange(start[-1] + 1, dtype=np.int64), start, start[1:], 4, threads, 512, np.arange(4), 4)
    runs, group = [], 0
    while group < len(sizes):
        span_, parts, group = next_groups(colours, group)
        runs.append((int(span_[0]), int(span_[2]), parts))
    if threads == 2:
        assert runs == [(0, 600, 2), (600, 1120, 1), (1120, 1820, 2), (1820, 1823, 1)]
    else:
        assert runs == [(0, 1823, 1)]


@pytest.mark.parametrize("parts", [2, 3])
def test_the_parallel_sweep_gives_the_bytes_of_one_thread(monkeypatch, parts):
    """A pile of 40 boxes, 40 steps, every stage parallel (the size thresholds set to 0, every colour
    cut into parts): the same bytes with each colour cut into ``parts`` parts (the solver's threads)
    as on one thread. Numba runs the parts on the threads it has, so 3 parts are tested on a 2-core
    machine too."""
    monkeypatch.setattr(rigid_solver_step, "COLOURED_BODIES", 0)
    monkeypatch.setattr(manifolds, "PARALLEL_PAIRS", 0)
    every_colour_parallel(monkeypatch)
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", max(parts, numba.config.NUMBA_NUM_THREADS))
    monkeypatch.setattr(numba, "set_num_threads", lambda threads: None)
    runs = [pile_run(threads) for threads in (1, parts)]
    assert runs[0][3] > 40  # the boxes came to touch: many manifolds, several colours
    assert runs[0] == runs[1]


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="Numba has one thread here (NUMBA_NUM_THREADS)")
def test_the_threads_setting_runs_the_step_on_that_many_threads_with_the_same_bytes(monkeypatch):
    """``[collisions.solver] threads``: the step's parallel parts run on that many of Numba's threads
    (set for the step, restored after it), and threads = 1 and 2 give the same bytes."""
    monkeypatch.setattr(rigid_solver_step, "COLOURED_BODIES", 0)
    monkeypatch.setattr(manifolds, "PARALLEL_PAIRS", 0)
    every_colour_parallel(monkeypatch)
    seen = []
    colour = rigid_solver_step.colour_contacts

    def spy(*args):
        seen.append(numba.get_num_threads())
        return colour(*args)

    monkeypatch.setattr(rigid_solver_step, "colour_contacts", spy)
    before = numba.get_num_threads()
    runs = []
    for threads in (1, 2):
        seen.clear()
        runs.append(pile_run(threads, steps=20))
        assert set(seen) == {threads} and numba.get_num_threads() == before
    assert runs[0][3] > 40 and runs[0] == runs[1]


@pytest.mark.parametrize("threads", [0, -1, True, 1.0, "2", 10**6])
def test_the_threads_setting_is_refused_in_one_line_unless_numba_can_run_it(threads):
    """threads must be an integer from 1 to NUMBA_NUM_THREADS: the settings, the scene file (its key
    named) and the command line (status 2) say so in one line."""
    allowed = f"an integer from 1 to {numba.config.NUMBA_NUM_THREADS}"
    with pytest.raises(ValueError, match=f"contact solver: threads must be {allowed}"):
        ContactSolver(threads=threads)
    with pytest.raises(SceneError) as err:
        parse_scene(with_threads(box_pit_toml(3), toml(threads)), "pit.toml")
    line = str(err.value)
    assert line.startswith(f"pit.toml: collisions.solver.threads: must be {allowed}") and "\n" not in line


def toml(value) -> str:
    """A TOML value: true for True, "2" for a string."""
    return "true" if value is True else f'"{value}"' if isinstance(value, str) else repr(value)


def with_threads(text: str, value: str) -> str:
    """The box pit's scene file with ``[collisions.solver] threads = value``."""
    return text.replace("friction = 0.6\n", f"friction = 0.6\n\n[collisions.solver]\nthreads = {value}\n")


def test_the_command_line_refuses_a_bad_thread_count_with_status_2(tmp_path, capsys):
    path = tmp_path / "pit.toml"
    path.write_text(with_threads(box_pit_toml(3, t_end=0.05), str(numba.config.NUMBA_NUM_THREADS + 1)))
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert "collisions.solver.threads: must be an integer from 1 to" in err and err.count("\n") == 1


def test_a_scene_states_its_threads_and_defaults_to_one():
    """The default is one thread (Box2D's one worker); the bench's 2-core scene says 2, and so does its
    description."""
    assert parse_scene(box_pit_toml(3), "pit.toml").collisions.solver.threads == 1
    if numba.config.NUMBA_NUM_THREADS >= 2:
        solver = parse_scene(box_pit_toml(3, threads=2), "pit.toml").collisions.solver
        assert solver.threads == 2 and solver.describe().endswith(", 2 threads")
