"""`recommend` on collision scenes: measured with the collisions, checked against the bouncing ball's closed form."""

import json
import math

import numpy as np
import pytest

from steplab.cli import main


def bouncing_height(t, h, g, eps):
    """Height of a ball dropped from rest at height h onto z = 0, bouncing with restitution eps.

    Typed from the textbook: the first fall takes sqrt(2 h / g); each impact multiplies the
    speed by eps, and a flight at launch speed u lasts 2 u / g. Returns the heights at the
    times ``t`` and the impact times before max(t).
    """
    t = np.asarray(t, dtype=float)
    t_hit, u = math.sqrt(2 * h / g), math.sqrt(2 * g * h)
    impacts = []
    z = h - 0.5 * g * t**2
    while t_hit <= t.max():
        impacts.append(t_hit)
        u *= eps
        after = t >= t_hit
        s = t[after] - t_hit
        z[after] = u * s - 0.5 * g * s**2
        t_hit += 2 * u / g
    return z, impacts


def test_recommend_drop_bounces_as_the_ball_does():
    """The answer's run bounces as often as the reference and the closed form, and stays within tol of it."""
    from steplab.integrators import simulate
    from steplab.physics.scene import load_scene
    from steplab.studies.recommend_collisions import CollisionProblem, recommend_with_collisions

    scene = load_scene("drop")
    t_end, tol = 1.3, 1e-3  # two bounces (at 0.433 s and 1.176 s)
    problem = CollisionProblem(scene.model, scene.y0, scene.t_start, t_end, scene.collisions)
    r = recommend_with_collisions(problem, tol, scene_dt=scene.dt,
                                  integrators=["semi-implicit-euler", "velocity-verlet"])
    run = simulate(scene.model, r["integrator"], scene.y0, scene.t_start, dt=r["dt"], n_steps=r["steps"],
                   collisions=scene.collisions)
    floor = [e for e in run.collisions.events if e.kind == "impact" and e.other_name == "floor"]
    g = -float(np.ravel(scene.model.constant_acceleration)[2])
    height0 = float(scene.y0[0, 0, 2])  # the ball's centre is on z = 0 when it touches the floor
    z, impacts = bouncing_height(run.t, height0, g, 0.858)
    assert len(impacts) == 2 and len(floor) == r["impacts"] == r["reference"]["impacts"] == 2
    assert r["regime"] == "trajectories" and r["reference"]["converged"]
    assert np.max(np.abs(run.positions[:, 0, 2] - z)) <= 1.1 * tol  # the reference's own error: < tol / 10
    assert r["dt"] >= 1e-3  # an answer, not the reference: a millisecond bounces right already


def test_recommend_times_every_answer_in_the_same_interleaved_rounds(monkeypatch):
    # timed one after another, a burst of load on one answer made a slower method the cheapest
    from steplab.physics.scene import load_scene
    from steplab.studies import recommend_collisions as rc

    rounds = []

    def interleaved(calls, repeats):
        rounds.append(len(calls))
        return {k: 2.0 - k for k in calls}  # the last answer the cheapest in these rounds

    monkeypatch.setattr(rc, "interleaved_medians", interleaved)
    scene = load_scene("drop")
    problem = rc.CollisionProblem(scene.model, scene.y0, scene.t_start, 1.3, scene.collisions)
    r = rc.recommend_with_collisions(problem, 1e-2, scene_dt=scene.dt,
                                     integrators=["semi-implicit-euler", "velocity-verlet", "rk4"])
    assert rounds == [3] and r["integrator"] == "rk4" and r["seconds"] == 0.0  # every one passes at 1 cm


def test_recommend_refuses_with_evidence(capsys):
    """Explicit Euler cannot follow the ball to a micrometre: status 1, one line naming the best run."""
    status = main(["recommend", "drop", "--tol", "1e-6", "--t-end", "0.6", "--integrators", "euler"])
    err = capsys.readouterr().err
    assert status == 1 and err.count("\n") == 1
    assert "no fixed-step method reaches 1e-06 m" in err and "best: euler" in err and "1 impacts" in err


def test_collision_free_recommendation_keeps_the_closed_form(capsys):
    """A scene without collisions is measured as before, against the projectile's closed form.

    Velocity Verlet is exact under a constant force, so the answer is the first dt tried:
    the largest whole division of the run not above --dt-max.
    """
    assert main(["recommend", "projectile", "--tol", "1e-6", "--integrators", "velocity-verlet",
                 "--dt-max", "0.1", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    span = 5.4  # the scene's run: t = 5 -> 10.4 s
    assert r["integrator"] == "velocity-verlet" and "reference" not in r
    assert r["steps"] == math.ceil(span / 0.1) and r["dt"] == pytest.approx(span / r["steps"], rel=1e-12)
    assert r["error"] <= 1e-12


def test_largest_penetration_matches_all_pairs():
    """The one-call broadphase over all states finds the deepest overlap that an all-pairs loop finds."""
    from steplab.physics.collision import CollisionWorld, Plane
    from steplab.studies.recommend_collisions import largest_penetration

    rng = np.random.default_rng(3)
    q = rng.uniform(-1.0, 1.0, (30, 12, 3))
    radii = rng.uniform(0.05, 0.3, 12)
    floor = Plane(np.array([0.0, 0.0, 1.0]), -0.9)
    deepest = 0.0
    for p in q:  # r_i + r_j - |p_i - p_j| over every pair, r - (n . p - offset) against the floor
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.diag(np.full(12, np.inf))
        deepest = max(deepest, np.max(radii[:, None] + radii[None] - d), np.max(radii - (p[:, 2] + 0.9)))
    assert largest_penetration(CollisionWorld(shapes=(floor,)), radii, q) == pytest.approx(deepest, abs=1e-12)


def test_the_energy_compared_counts_the_spin_the_contact_solver_gives(capsys):
    """A sphere launched sliding on a floor with friction rolls at 5/7 of its speed: its energy then
    is 1/2 m v^2 + 1/2 I omega^2. recommend's energy over time is the one steplab run reports (the
    translation alone read 2/7 of the kinetic energy lower once it rolls)."""
    from steplab.physics.scene import load_scene
    from steplab.studies.recommend_collisions import CollisionProblem, _measured_run

    scene = load_scene("rolling-sphere")
    steps = 30
    t_end = scene.t_start + steps * scene.dt
    problem = CollisionProblem(scene.model, scene.y0, scene.t_start, t_end, scene.collisions, scene.rigid_bodies)
    run, energies = _measured_run(problem, "semi-implicit-euler", steps)
    assert main(["run", "rolling-sphere", "--steps", str(steps), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert len(energies) == steps + 1
    for value, key in ((energies[0], "energy_start"), (energies[-1], "energy_end")):
        assert value == pytest.approx(summary[key], rel=1e-12, abs=0)
    # rolling (omega r = v) a solid sphere's spin, 1/2 (2/5 m r^2) omega^2, is 2/5 of 1/2 m v^2
    translation = float(scene.model.energy(run.y[-1]))
    kinetic = 0.5 * scene.model.masses[0] * float(np.sum(run.y[-1, 1, 0] ** 2))
    assert energies[-1] - translation == pytest.approx(0.4 * kinetic, rel=0.02)
