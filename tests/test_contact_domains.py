"""The contact solver's sweep order (issue 26): domains by nested dissection, and the same bytes on any threads.

The layout is checked against its definition written plainly (each domain's manifolds, then those
crossing each level's cuts grouped under the piece it halved, deepest first, each group in the
sorted order; the groups of a phase share no dynamic body), the cut against its planes, and the
parallel sweep against itself on one thread: the order depends on the scene alone, so a pile of
boxes stepped on 1 or 2 threads must give the same bytes.
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
from steplab.physics.collision import CollisionWorld, PairProperties, Plane, contact_domains, rigid_solver_step
from steplab.physics.collision.contact_domains import (
    bodies_of,
    cut_into_domains,
    domain_count,
    groups_in,
    halves,
    lay_out,
    phases,
    rows_of,
)
from steplab.physics.collision.rigid_solver_step import RigidScene, RigidSolverStep
from steplab.physics.collision.solver_settings import ContactSolver
from steplab.physics.rigid_body import RigidBodies, principal_inertia
from steplab.physics.scene import SceneError, parse_scene

from steplab.bench.stacking import box_pit_toml
from steplab.cli import main

#: the rigid narrow phase's module (the package's name ``manifolds`` is its function)
manifolds = importlib.import_module("steplab.physics.collision.manifolds")


def expected_group(i, j, domain, count):
    """The group of a manifold between bodies i and j (j < 0: static) among ``count`` domains, plainly:
    (phase, piece) with phase 0 the domain's own, else the level of the first bit the domains differ in."""
    if j < 0 or domain[i] == domain[j]:
        return 0, domain[i]
    phase = max(p for p in range(1, count.bit_length()) if (domain[i] >> (p - 1)) != (domain[j] >> (p - 1)))
    return phase, domain[i] >> phase


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 11), st.integers(-3, 11), st.integers(1, 4)), min_size=0, max_size=60),
       st.sampled_from([1, 2, 4, 8]), st.integers(0, 2**32 - 1))
def test_the_layout_is_nested_dissection_each_group_sorted(manifolds_, count, seed):
    """Random manifolds (a, b, points) among 12 bodies in random domains and 3 static shapes: the rows
    listed group by group, phase by phase, each group's in the sorted order (a manifold's points together,
    in their order); every row once; the groups of one phase share no dynamic body; each domain's bodies
    listed in turn, ascending."""
    pairs = sorted({(a, b): p for a, b, p in manifolds_ if a != b}.items())
    a = np.array([x for (i, _), p in pairs for x in [i] * p], np.int64)
    b = np.array([x for (_, j), p in pairs for x in [j] * p], np.int64)
    domain = np.random.default_rng(seed).integers(0, count, 12).astype(np.int64)
    order, layout = lay_out(a, b, domain, count)
    keyed = sorted(range(len(a)), key=lambda k: (expected_group(a[k], b[k], domain, count), k))
    assert order.tolist() == keyed
    assert layout.phase_start.tolist() == [0] + list(np.cumsum([count >> p for p in range(count.bit_length())]))
    assert phases(layout) == count.bit_length()
    for phase in range(phases(layout)):
        touched = []
        assert groups_in(layout, phase) == count >> phase
        for g in range(groups_in(layout, phase)):
            rows = order[slice(*rows_of(layout, phase, g))]
            assert all(expected_group(a[k], b[k], domain, count) == (phase, g) for k in rows)
            touched.append({int(x) for k in rows for x in (a[k], b[k]) if x >= 0})
        assert all(not (s & t) for m, s in enumerate(touched) for t in touched[m + 1:])
    assert layout.group_rows[-1] == len(a)
    listed = [layout.bodies[slice(*bodies_of(layout, d))].tolist() for d in range(count)]
    assert listed == [[body for body in range(12) if domain[body] == d] for d in range(count)]


def test_the_domain_count_is_a_power_of_two_of_the_bodies_alone():
    """One domain below CUT_BODIES bodies, two from there, then halved again while each domain keeps
    DOMAIN_BODIES bodies, at most MOST_DOMAINS."""
    cut, per = contact_domains.CUT_BODIES, contact_domains.DOMAIN_BODIES
    sizes = (0, 1, cut - 1, cut, 10**4, 4 * per - 1, 4 * per, 8 * per, 16 * per - 1)
    assert [domain_count(n) for n in sizes] == [1, 1, 1, 2, 2, 2, 4, 8, 8]
    assert domain_count(10**9) == contact_domains.MOST_DOMAINS


def test_the_domains_halve_each_piece_again():
    """A 16 x 16 lattice, 4 domains: 64 bodies each; domains 0, 1 (the first cut's one half) on one side of
    the first plane, 2, 3 on the other, and each pair split by a plane of its own."""
    k = np.arange(256)
    q = np.column_stack([k % 16, k // 16, np.zeros(256)]).astype(float)
    domain = cut_into_domains(q, np.ones(256, bool), 4)
    assert np.bincount(domain).tolist() == [64] * 4
    assert np.all((domain >= 2) == (q[:, 1] >= 8))  # the first cut: across y, one run along the numbering
    for half in (0, 1):  # each half 16 x 8: cut across x, its one wide extent
        assert q[domain == 2 * half, 0].max() < q[domain == 2 * half + 1, 0].min()
    assert not cut_into_domains(q, np.ones(256, bool), 1).any()


def test_a_half_is_across_the_widest_extent_at_the_moving_bodies_median():
    """Centres spread 10 m along y and 1 m along x: the cut is across y at the moving bodies' median;
    a pinned body far out does not move it."""
    rng = np.random.default_rng(4)
    q = np.column_stack([rng.uniform(0, 1, 101), rng.uniform(0, 10, 101), rng.uniform(0, 1, 101)])
    q[-1] = [0.0, 100.0, 0.0]
    movable = np.ones(101, bool)
    movable[-1] = False
    half = halves(q, movable, np.arange(101))
    assert np.sum(half[:-1] == 0) == 50 and half[-1] == 1
    assert np.all((half[:-1] == 1) == (q[:-1, 1] >= np.median(q[:-1, 1])))
    assert not halves(q, np.zeros(101, bool), np.arange(101)).any()


def test_of_two_wide_extents_the_halves_cut_the_numbering_into_fewer_runs():
    """A 20 x 20 lattice numbered along x, then y (as the box pit's): cut across x, each row of 20 is two
    runs (40 changes along the numbering); cut across y, the numbering changes half once. Both extents
    are wide, so the cut is across y; a lattice 3 times longer along x is cut across x."""
    k = np.arange(400)
    q = np.column_stack([k % 20, k // 20, np.zeros(400)]).astype(float)
    half = halves(q, np.ones(400, bool), np.arange(400))
    assert np.all(half == (q[:, 1] >= 10)) and np.count_nonzero(np.diff(half)) == 1
    q[:, 0] *= 3.0
    assert np.all(halves(q, np.ones(400, bool), np.arange(400)) == (q[:, 0] >= 30))


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


def several_domains(monkeypatch):
    """Every stage parallel however small the scene: the narrow phase's pairs in parts, and 40 boxes in
    4 domains (one per 10 bodies); returns the layouts the steps make, as they make them."""
    monkeypatch.setattr(contact_domains, "CUT_BODIES", 10)
    monkeypatch.setattr(contact_domains, "DOMAIN_BODIES", 10)
    monkeypatch.setattr(manifolds, "PARALLEL_PAIRS", 0)
    layouts, lay = [], rigid_solver_step.lay_out

    def spy(*args):
        order, layout = lay(*args)
        layouts.append((numba.get_num_threads(), layout))
        return order, layout

    monkeypatch.setattr(rigid_solver_step, "lay_out", spy)
    return layouts


def test_the_domains_on_two_threads_give_the_bytes_of_one(monkeypatch):
    """A pile of 40 boxes in 4 domains, 40 steps: the same bytes on 2 threads as on 1, with manifolds in
    every domain and some crossing the cuts (waiting for their phases)."""
    layouts = several_domains(monkeypatch)
    runs = [pile_run(threads) for threads in (1, 2)]
    assert runs[0][3] > 40 and runs[0] == runs[1]
    sizes = np.diff(layouts[-1][1].group_rows)  # the 4 domains, the 2 pieces of the second cuts, the first cut
    assert len(sizes) == 7 and (sizes[:4] > 0).all() and sizes[4:].sum() > 0


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="Numba has one thread here (NUMBA_NUM_THREADS)")
def test_the_threads_setting_runs_the_step_on_that_many_threads_with_the_same_bytes(monkeypatch):
    """``[collisions.solver] threads``: the step's parallel parts run on that many of Numba's threads
    (set for the step, restored after it), and threads = 1 and 2 give the same bytes."""
    layouts = several_domains(monkeypatch)
    before = numba.get_num_threads()
    runs = []
    for threads in (1, 2):
        layouts.clear()
        runs.append(pile_run(threads, steps=20))
        assert {t for t, _ in layouts} == {threads} and numba.get_num_threads() == before
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
