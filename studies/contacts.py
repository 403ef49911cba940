"""Contacts study: what the engines' contact solver trades for speed, against the event loop.

The lecture resolves collisions one at a time, each at its time (the event loop,
:mod:`steplab.physics.collision.step`). Engines gather the step's contacts and solve them
together by sequential impulses, with substeps (``[collisions] method = "solver"``,
:mod:`steplab.physics.collision.solver_step`). Each part below measures one consequence,
against the event loop or an analytic answer:

- **restitution**: the lecture's nine balls dropped from 92 cm; the c.o.r. recovered from the
  first bounce, sqrt(h / H), against the one given, by iterations and substeps. The solver
  bounces a ball off the approach speed at the start of the step of impact, g dt slower than
  at the impact, and from the floor instead of from the height it reached the floor at;
- **Newton's cradle**: the event loop sends the last of five balls off at the first one's
  speed and stops the others; how many balls does the solver move, and with what energy,
  from 1 to 100 iterations and 1 to 16 substeps?
- **resting contact**: a column of 10 balls on the floor and a pile of balls in a box:
  penetration (against the soft contact's static deflection, n g / omega^2 for the floor
  contact of a column of n), jitter (rms speed at rest) and the energy gained over 10 s
  after settling, by iterations, substeps and dt;
- **small steps** (Macklin et al. 2019): at equal cost, n substeps of 1 iteration against
  1 step of n iterations, on the ball column (its penetration) and on a chain of balls hanging
  from stiff springs (its stretch, and the energy its swing loses);
- **tunnelling**: speculative contacts on the tunnelling study's wall, against the analytic
  miss rates of overlap testing;
- **cost**: wall time per step against the number of bodies, up to 10^5, for both methods
  on the bench's ball pits. This part times: it runs last, alone;
- **inelastic collapse** (McNamara and Young 1994): a crowded pit coming to rest, its impacts
  per simulated second and the event loop's cost per impact against the rest speed below
  which a touching pair stops bouncing. Timed too, after the cost.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from steplab.integrators import get_integrator, simulate
from steplab.integrators.simulate import DivergenceError
from steplab.physics import Gravity, Model, Springs
from steplab.physics.ball_pit import RESTITUTION as RESTITUTION_PIT
from steplab.physics.ball_pit import ball_pit
from steplab.physics.collision import Box, CollisionWorld, ImpactCapError, PairProperties, Plane
from steplab.physics.collision.solver_batch import run_batch
from steplab.physics.collision.solver_settings import ContactSolver

from . import plotting
from .restitution import H_CM, LECTURE_TABLE
from .runner import Study
from .tables import Table, markdown_table
from .tunnelling import analytic_miss_rate

SIE = get_integrator("semi-implicit-euler")
#: the solver's default settings (what the column's dt sweep, the pile and the cost rows run)
DEFAULTS = ContactSolver()
G = 9.81
FLOOR = Plane(np.array([0.0, 0.0, 1.0]), name="floor")
#: the balls of the cradle, the column and the chain, m and kg
RADIUS, MASS = 0.1, 1.0


def parameters(quick: bool) -> dict:
    return {
        "dt": 1 / 60,
        "iterations": [1, 2, 4, 10, 30, 100] if not quick else [1, 4, 30],
        "substeps": [1, 2, 4, 8, 16] if not quick else [1, 4, 16],
        "restitution_objects": [name for name, *_ in LECTURE_TABLE],
        "cradle_balls": 5,
        "column_balls": 10, "column_settle_s": 5.0, "rest_s": 10.0,
        "column_dts": [1 / 30, 1 / 60, 1 / 120, 1 / 240] if not quick else [1 / 30, 1 / 60, 1 / 120],
        "pile_side": 10 if not quick else 5, "pile_settle_s": 20.0 if not quick else 8.0,
        "small_steps": [1, 2, 4, 8, 16] if not quick else [1, 4, 16], "small_steps_s": 2.0,
        "chain_links": 10, "chain_stiffness": 2e3, "chain_s": 2.0,
        "tunnelling_ratios": np.round(np.geomspace(0.1, 50, 12 if not quick else 6), 4).tolist(),
        "tunnelling_shots": 50 if not quick else 12, "seed": 20240611,
        "cost_sizes": [1_000, 10_000, 100_000] if not quick else [500, 2_000], "cost_steps": 10 if not quick else 5,
        # the crowded pit (balls, box side in m, steps of 1/60 s) and the rest speeds it is run at, m/s
        "collapse_pit": [2_000, 6.0, 60] if not quick else [200, 1.2, 30],
        "collapse_rest_speeds": [0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4] if not quick else [0.1, 0.01, 1e-3],
    }


def solver_world(shapes, eps, mu=0.0, **settings) -> CollisionWorld:
    return CollisionWorld(shapes=tuple(shapes), pair_properties=PairProperties(eps, mu), method="solver",
                          solver=ContactSolver(**settings))


def grid(params) -> list[tuple[int, int]]:
    return [(i, s) for i in params["iterations"] for s in params["substeps"]]


# --- restitution ---------------------------------------------------------------------------


def restitution(params) -> dict:
    """First-bounce c.o.r. of the lecture's balls, event loop and solver at every setting."""
    H = H_CM / 100
    model = Model(np.array([0.0459]), np.array([0.0214]), [Gravity()])
    y0 = np.array([[[0.0, 0.0, H + 0.0214]], [[0.0, 0.0, 0.0]]])
    dt, steps = params["dt"], math.ceil(2.2 * math.sqrt(2 * H / G) / params["dt"]) + 1
    given = [float(cor) for name, _, _, cor in LECTURE_TABLE if name in params["restitution_objects"]]

    def bounce(ys):
        """sqrt(h+ / h-): the heights z + v^2 / 2g (above resting) just before and just after the first
        bounce; energy heights, so the free flight's own error (semi-implicit Euler's, O(g dt^2) a step)
        stays out of the c.o.r. measured."""
        z, vz = ys[:, 0, 0, 2] - 0.0214, ys[:, 1, 0, 2]
        up = int(np.argmax(vz > 0))  # the first state after the bounce
        height = z + vz**2 / (2 * G)
        return math.sqrt(max(float(height[up]), 0.0) / float(height[up - 1]))

    event = []
    for eps in given:
        world = CollisionWorld(shapes=(FLOOR,), pair_properties=PairProperties(eps))
        event.append(bounce(simulate(model, SIE, y0, 0.0, dt=dt, n_steps=steps, collisions=world).y))
    settings = grid(params)
    worlds = [solver_world([FLOOR], eps, iterations=i, substeps=s) for i, s in settings for eps in given]
    runs = run_batch([w.stepper(model, SIE) for w in worlds], [y0] * len(worlds), 0.0, dt, steps, save_every=1)
    measured = np.array([bounce(ys) for ys in runs]).reshape(len(settings), len(given))
    return {"given": given, "event_loop": event,
            "solver": [{"iterations": i, "substeps": s, "measured": m.tolist(),
                        "max_error": float(np.max(np.abs(m - given)))} for (i, s), m in zip(settings, measured)],
            "event_loop_max_error": float(np.max(np.abs(np.array(event) - given)))}


# --- Newton's cradle -------------------------------------------------------------------------


def cradle(params) -> dict:
    n, dt = params["cradle_balls"], params["dt"]
    q = np.zeros((n, 3))
    q[:, 0] = 2 * RADIUS * np.arange(n)
    q[0, 0] -= 0.05  # the first ball arrives at 1 m/s within the run
    v = np.zeros((n, 3))
    v[0, 0] = 1.0
    y0, model, steps = np.stack([q, v]), Model(np.full(n, MASS), np.full(n, RADIUS), []), 30

    def outcome(vx):
        return {"velocities": vx.tolist(), "moving": int(np.sum(np.abs(vx) > 1e-3)),
                "energy_kept": float(np.sum(vx**2) / 1.0), "last_ball_speed": float(vx[-1])}

    event = simulate(model, SIE, y0, 0.0, dt=dt, n_steps=steps, collisions=CollisionWorld(
        pair_properties=PairProperties(1.0)))
    settings = grid(params)
    worlds = [solver_world((), 1.0, iterations=i, substeps=s) for i, s in settings]
    runs = run_batch([w.stepper(model, SIE) for w in worlds], [y0] * len(worlds), 0.0, dt, steps)
    solver = [{"iterations": i, "substeps": s, **outcome(ys[-1][1][:, 0])} for (i, s), ys in zip(settings, runs)]
    return {"event_loop": outcome(event.y[-1][1][:, 0]), "solver": solver,
            "most_energy_kept": max(row["energy_kept"] for row in solver)}


# --- resting contact -------------------------------------------------------------------------


def column(n):
    q = np.zeros((n, 3))
    q[:, 2] = RADIUS + 2 * RADIUS * np.arange(n)
    return Model(np.full(n, MASS), np.full(n, RADIUS), [Gravity()]), np.stack([q, np.zeros_like(q)])


def at_rest(model, ys, radius_floor=RADIUS) -> dict:
    """Penetration of the floor, jitter and the energy change between saves 1 (settled) and 2 (10 s on)."""
    settled, end = ys[1], ys[2]
    pe = float(model.potential_energy(settled[0]) - model.potential_energy(np.zeros_like(settled[0])))
    return {"floor_penetration": float(radius_floor - end[0][:, 2].min()),
            "jitter": float(np.sqrt(np.mean(np.sum(end[1] ** 2, axis=1)))),
            "energy_gained": float(model.energy(end) - model.energy(settled)), "potential_energy": pe}


def resting(params) -> dict:
    n, dt = params["column_balls"], params["dt"]
    model, y0 = column(n)
    rows = []
    for step_dt in params["column_dts"]:
        settings = grid(params) if step_dt == dt else [(DEFAULTS.iterations, DEFAULTS.substeps)]
        worlds = [solver_world([FLOOR], 0.5, iterations=i, substeps=s) for i, s in settings]
        settle, rest = round(params["column_settle_s"] / step_dt), round(params["rest_s"] / step_dt)
        every = math.gcd(settle, rest)
        runs = run_batch([w.stepper(model, SIE) for w in worlds], [y0] * len(worlds), 0.0, step_dt,
                         settle + rest, save_every=every)
        for (i, s), world, ys in zip(settings, worlds, runs):
            picked = ys[[0, settle // every, (settle + rest) // every]]
            omega = 2 * math.pi * world.solver.contact_hertz
            rows.append({"dt": step_dt, "iterations": i, "substeps": s, **at_rest(model, picked),
                         "soft_deflection": n * G / omega**2})
    side = params["pile_side"]
    model, y0 = pile(side)
    half = side * 0.105
    world = solver_world(walls(half), 0.5, 0.5)
    settle, rest = round(params["pile_settle_s"] / dt), round(params["rest_s"] / dt)
    step, every = world.stepper(model, SIE), math.gcd(settle, rest)
    (ys,) = run_batch([step], [y0], 0.0, dt, settle + rest, save_every=every)
    pile_row = {"balls": side**3, "dt": dt, **at_rest(model, ys[[0, settle // every, (settle + rest) // every]]),
                "largest_residual": step.log.largest_residual}
    return {"column": rows, "pile": pile_row}


def pile(side: int):
    """side^3 balls on a loose lattice (jittered) in a box, to fall into a pile."""
    rng = np.random.default_rng(1)
    g = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3).astype(float)
    q = (g - (side - 1) / 2) * 0.21
    q[:, 2] = g[:, 2] * 0.21 + RADIUS + 0.01
    q[:, :2] += rng.uniform(-0.004, 0.004, (len(q), 2))
    return Model(np.full(len(q), MASS), np.full(len(q), RADIUS), [Gravity()]), np.stack([q, np.zeros_like(q)])


def walls(half):
    return (FLOOR,) + tuple(Plane(np.array(n, float), -half, name=f"wall {k}")
                            for k, n in enumerate(([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0])))


# --- small steps -----------------------------------------------------------------------------


def small_steps(params) -> dict:
    """n substeps x 1 iteration against 1 substep x n iterations, at equal cost (n sweeps per step)."""
    dt, rows = params["dt"], []
    model, y0 = column(params["column_balls"])
    ns = params["small_steps"]
    worlds = [solver_world([FLOOR], 0.5, iterations=1, substeps=n) for n in ns]
    worlds += [solver_world([FLOOR], 0.5, iterations=n, substeps=1) for n in ns]
    steps = round(params["small_steps_s"] / dt)
    runs = run_batch([w.stepper(model, SIE) for w in worlds], [y0] * len(worlds), 0.0, dt, steps)
    for world, ys in zip(worlds, runs):
        s = world.solver
        deflection = params["column_balls"] * G / (2 * math.pi * s.contact_hertz) ** 2
        penetration = float(RADIUS - ys[-1][0][:, 2].min())
        # how far from its resting state the column still is after the same time: the convergence
        rows.append({"system": "column", "substeps": s.substeps, "iterations": s.iterations,
                     "floor_penetration": penetration, "soft_deflection": deflection,
                     "error": abs(penetration - deflection) / deflection})
    model, y0 = chain(params["chain_links"], params["chain_stiffness"])
    e0 = float(model.energy(y0))
    for n in ns:
        for substeps, iterations in ((n, 1), (1, n)):
            world = solver_world((), 0.0, iterations=iterations, substeps=substeps)
            row = {"system": "chain", "substeps": substeps, "iterations": iterations, "stretch": None,
                   "energy_lost": None}  # None: the springs' step diverged (omega h > 2)
            try:
                traj = simulate(model, SIE, y0, 0.0, dt=dt, t_end=params["chain_s"], collisions=world)
            except (DivergenceError, FloatingPointError):
                rows.append(row)
                continue
            links = np.linalg.norm(np.diff(traj.y[:, 0], axis=1), axis=2)
            rest = 2 * RADIUS + 0.02
            stretch = float(np.max(np.abs(links - rest)) / rest)
            if stretch < 1:  # else it blew up below the divergence limit: diverged all the same
                row.update(stretch=stretch, energy_lost=(e0 - float(model.energy(traj.y[-1]))) / abs(e0))
            rows.append(row)
    return {"rows": rows}


def chain(links: int, stiffness: float):
    """A chain of balls joined by stiff springs, hanging from a pinned ball, released horizontal."""
    n = links + 1
    q = np.zeros((n, 3))
    q[:, 0] = (2 * RADIUS + 0.02) * np.arange(n)
    q[:, 2] = 3.0
    pinned = np.zeros(n, bool)
    pinned[0] = True
    springs = Springs(np.arange(links), np.arange(1, n), np.full(links, stiffness), np.full(links, 2 * RADIUS + 0.02))
    return Model(np.full(n, 0.1), np.full(n, RADIUS), [Gravity(), springs], pinned=pinned), np.stack(
        [q, np.zeros_like(q)])


# --- tunnelling ------------------------------------------------------------------------------


def tunnelling(params) -> dict:
    """Balls fired at a thin wall at v dt / (w + 2 r) = ratio, with random phases: how many pass?"""
    w, r, dt = 0.01, 0.05, 0.01
    rng = np.random.default_rng(params["seed"])
    rows = []
    for ratio in params["tunnelling_ratios"]:
        shots = params["tunnelling_shots"]
        speed = ratio * (w + 2 * r) / dt
        lane = 2 * (r + speed * dt) + 1.0
        q = np.zeros((shots, 3))
        q[:, 0] = -(0.5 * w + r) - speed * dt * (1 + rng.uniform(0, 1, shots))
        q[:, 1] = lane * np.arange(shots)
        v = np.zeros((shots, 3))
        v[:, 0] = speed
        wall = Box.from_center([0.0, 0.5 * lane * (shots - 1), 0.0], [w, lane * shots, 1.0], name="wall")
        traj = simulate(Model(np.ones(shots), np.full(shots, r)), SIE, np.stack([q, v]), 0.0, dt=dt,
                        n_steps=math.ceil((w + 2 * r) / (speed * dt) + 3), save_every=10**9,
                        collisions=solver_world([wall], 1.0))
        rows.append({"ratio": ratio, "solver_miss_rate": float(np.mean(traj.y[-1][0][:, 0] > 0)),
                     "overlap_no_bisection_analytic": analytic_miss_rate(ratio)})
    return {"wall": w, "radius": r, "dt": dt, "rows": rows}


# --- cost ------------------------------------------------------------------------------------


def cost(params, progress) -> dict:
    rows = []
    for n in params["cost_sizes"]:
        scene = ball_pit(n, params["seed"])
        row = {"balls": n}
        for method in ("event", "solver"):
            world = dataclasses.replace(scene.collisions, method=method)
            simulate(scene.model, SIE, scene.y0, 0.0, dt=scene.dt, n_steps=1, collisions=world)  # compile, set up
            times = []
            for _ in range(3):
                start = time.perf_counter()
                simulate(scene.model, SIE, scene.y0, 0.0, dt=scene.dt, n_steps=params["cost_steps"],
                         save_every=10**9, collisions=world)
                times.append((time.perf_counter() - start) / params["cost_steps"])
            row[f"{method}_per_step_s"] = float(np.median(times))
        rows.append(row)
        progress(f"cost, {n:,} balls")
    return {"rows": rows, "dt": 1 / 60}


# --- inelastic collapse ----------------------------------------------------------------------


def collapse(params, progress) -> dict:
    """The crowded pit with the event loop at each rest speed: impacts, and the wall time they cost.

    A pile of balls at eps < 1 coming to rest is a chain of ever smaller impacts: a ball
    bouncing alone on the floor from v needs log(v / v_rest) / log(1 / eps) bounces to fall
    below the rest speed v_rest, and balls squeezed between others collapse inelastically,
    ever more impacts in ever less time (McNamara and Young 1994), cut off only by v_rest. A
    step that needs more than the cap stops the run (``cap_reached_s``, the step's start).
    """
    balls, side, steps = params["collapse_pit"]
    scene = ball_pit(balls, params["seed"], side=side)
    simulate(scene.model, SIE, scene.y0, 0.0, dt=scene.dt, n_steps=1, collisions=scene.collisions)  # compile
    rows = []
    for rest in params["collapse_rest_speeds"]:
        world = dataclasses.replace(scene.collisions, rest_speed=rest)
        row = {"rest_speed": rest, "cap_reached_s": None}
        start = time.perf_counter()
        try:
            traj = simulate(scene.model, SIE, scene.y0, 0.0, dt=scene.dt, n_steps=steps, save_every=10**9,
                            collisions=world)
        except ImpactCapError as error:
            row["cap_reached_s"] = error.t
        else:
            wall, log = time.perf_counter() - start, traj.collisions
            row.update(impacts=log.count(), impacts_per_second=log.count() / (steps * scene.dt), wall_s=wall,
                       us_per_impact=1e6 * wall / max(log.count(), 1),
                       most_impacts_in_a_step=log.most_impacts_in_a_step, resting_corrections=log.resting_corrections)
        rows.append(row)
        progress(f"collapse, rest speed {rest:g} m/s")
    return {"balls": balls, "side": side, "steps": steps, "dt": scene.dt, "restitution": RESTITUTION_PIT,
            "rows": rows}


def compute(params: dict, progress=None) -> dict:
    progress = progress or (lambda message: None)
    record = {}
    for name, part in (("restitution", restitution), ("cradle", cradle), ("resting", resting),
                       ("small_steps", small_steps), ("tunnelling", tunnelling)):
        record[name] = part(params)
        progress(name)
    record["cost"] = cost(params, progress)
    record["collapse"] = collapse(params, progress)
    return record


# --- figures ---------------------------------------------------------------------------------


def plot(record: dict, out) -> list[str]:
    import matplotlib.pyplot as plt

    names = []
    # restitution and the cradle, by iterations (one line per substeps)
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.2))
    rest = record["restitution"]
    for s in sorted({row["substeps"] for row in rest["solver"]}):
        rows = [row for row in rest["solver"] if row["substeps"] == s]
        a.plot([row["iterations"] for row in rows], [row["max_error"] for row in rows], "o-",
               label=_plural(s, "substep"))
    a.axhline(rest["event_loop_max_error"], color="k", ls="--", label="event loop")
    a.set(xscale="log", yscale="log", xlabel="iterations per substep", ylabel="largest |c.o.r. error|",
          title="The lecture's nine balls at dt = 1/60 s")
    a.legend(fontsize=8)
    cr = record["cradle"]
    for s in sorted({row["substeps"] for row in cr["solver"]}):
        rows = [row for row in cr["solver"] if row["substeps"] == s]
        b.plot([row["iterations"] for row in rows], [row["energy_kept"] for row in rows], "o-",
               label=_plural(s, "substep"))
        c.plot([row["iterations"] for row in rows], [row["last_ball_speed"] for row in rows], "o-",
               label=_plural(s, "substep"))
    b.axhline(cr["event_loop"]["energy_kept"], color="k", ls="--", label="event loop")
    c.axhline(cr["event_loop"]["last_ball_speed"], color="k", ls="--", label="event loop")
    b.set(xscale="log", xlabel="iterations per substep", ylabel="kinetic energy kept (fraction)", ylim=(0, 1.05),
          title="Newton's cradle, 5 balls, eps = 1")
    c.set(xscale="log", xlabel="iterations per substep", ylabel="last ball's speed / first ball's",
          ylim=(0, 1.05), title="Newton's cradle: the last ball")
    b.legend(fontsize=8)
    for ax in (a, b, c):
        plotting.integer_ticks(ax, [row["iterations"] for row in rest["solver"] + cr["solver"]])
    names += plotting.save_figure(fig, out, "contacts_restitution_cradle")

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    col = record["resting"]["column"]
    game = [row for row in col if abs(row["dt"] - 1 / 60) < 1e-12]
    for s in sorted({row["substeps"] for row in game}):
        rows = [row for row in game if row["substeps"] == s]
        a.plot([row["iterations"] for row in rows], [1e3 * row["floor_penetration"] for row in rows], "o-",
               label=_plural(s, "substep"))
    a.axhline(1e3 * game[0]["soft_deflection"], color="k", ls="--", label="n g / omega^2 (soft contact at rest)")
    a.set(xscale="log", xlabel="iterations per substep", ylabel="floor penetration after 15 s, mm",
          title="Column of 10 balls at dt = 1/60 s")
    plotting.integer_ticks(a, [row["iterations"] for row in game])
    a.legend(fontsize=8)
    by_dt = [row for row in col if row["iterations"] == DEFAULTS.iterations and row["substeps"] == DEFAULTS.substeps]
    floor = 1e-17  # an energy change of exactly 0 is drawn here
    b.plot([row["dt"] for row in by_dt], [max(abs(row["energy_gained"]) / row["potential_energy"], floor)
                                          for row in by_dt], "o-", label="column of 10, defaults")
    b.axhline(1e-6, color="tab:red", ls=":", label="the issue's bound, 1e-6")
    pile_row = record["resting"]["pile"]
    b.plot([pile_row["dt"]], [max(abs(pile_row["energy_gained"]) / pile_row["potential_energy"], floor)], "s",
           color="tab:green", label=f"pile of {pile_row['balls']:,} balls, defaults")
    b.set(xscale="log", yscale="log", xlabel="dt, s", ylabel="|energy change| / potential energy",
          title="10 s at rest, after settling (0 drawn at 1e-17)")
    b.set_ylim(top=1e-1)  # room for the legend above the bound
    b.legend(fontsize=8, loc="upper right", title=f"defaults: {DEFAULTS.describe()}", title_fontsize=8)
    names += plotting.save_figure(fig, out, "contacts_resting")

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    small = record["small_steps"]["rows"]
    for ax, (system, key, label) in zip(axes, (
            ("column", "error", "relative distance from rest at 2 s"),
            ("chain", "stretch", "largest relative spring stretch in 2 s"))):
        lost = []  # each sweep's diverged runs (no value): crosses above the curves
        for sub_first, style in ((True, "o-"), (False, "s--")):
            # n -> its run, in order of n (the run of 1 x 1 belongs to both sweeps)
            by_n = {row["substeps"] * row["iterations"]: row for row in small if row["system"] == system
                    and ((row["iterations"] == 1) if sub_first else (row["substeps"] == 1))}
            ns = sorted(by_n)
            line, = ax.plot(ns, [max(by_n[n][key], 1e-16) if by_n[n][key] is not None else np.nan for n in ns],
                            style, label="n substeps x 1 iteration" if sub_first else "1 step x n iterations")
            if diverged := [n for n in ns if by_n[n][key] is None]:
                lost.append((diverged, line.get_color()))
        ax.set(xscale="log", yscale="log", xlabel="n (sweeps per step: equal cost)", ylabel=label)
        low, high = ax.get_ylim()
        if high < 10 * low:  # less than a decade: a log axis would label it 9.5 x 10^-2, 9.6 x 10^-2, ...
            ax.set_yscale("linear")
        if lost:
            plotting.diverged_band(ax, lost)
            plotting.diverged_key(ax, "diverged (in the sweep's colour)")
        plotting.integer_ticks(ax, [row["substeps"] * row["iterations"] for row in small if row["system"] == system])
        ax.legend(fontsize=8)
    axes[0].set_title("Small steps: the ball column settling")
    axes[1].set_title("Small steps: a chain on stiff springs (x: diverged)")
    names += plotting.save_figure(fig, out, "contacts_small_steps")

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    tun = record["tunnelling"]["rows"]
    x = [row["ratio"] for row in tun]
    dense = np.geomspace(min(x), max(x), 200)
    a.plot(dense, [analytic_miss_rate(r) for r in dense], "k--", label="overlap testing, sampled: 1 - (w+2r)/(v dt)")
    a.plot(x, [row["solver_miss_rate"] for row in tun], "o", color="tab:blue", label="solver (speculative contacts)")
    a.set(xscale="log", xlabel="v dt / (w + 2r)", ylabel="miss rate", ylim=(-0.03, 1.03),
          title="Tunnelling through a thin wall")
    a.legend(fontsize=8)
    cost_rows = record["cost"]["rows"]
    for method, marker in (("event", "o-"), ("solver", "s-")):
        b.plot([row["balls"] for row in cost_rows], [1e3 * row[f"{method}_per_step_s"] for row in cost_rows], marker,
               label=f"{'event loop' if method == 'event' else 'contact solver (defaults)'}")
    b.axhline(1e3 * record["cost"]["dt"], color="tab:red", ls=":", label="real time (dt = 1/60 s)")
    b.set(xscale="log", yscale="log", xlabel="balls in the pit", ylabel="wall time per step, ms",
          title="Cost per step (ball pits of steplab bench)")
    b.legend(fontsize=8)
    names += plotting.save_figure(fig, out, "contacts_tunnelling_cost")
    if "collapse" in record:
        names += _plot_collapse(record["collapse"], out)
    return names


def _plot_collapse(part: dict, out) -> list[str]:
    import matplotlib.pyplot as plt

    rows = [row for row in part["rows"] if row["cap_reached_s"] is None]
    capped = [row["rest_speed"] for row in part["rows"] if row["cap_reached_s"] is not None]
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.4))
    rest = [row["rest_speed"] for row in rows]
    a.plot(rest, [row["impacts_per_second"] for row in rows], "o-", color="tab:blue", label="event loop, impacts")
    a.plot(rest, [row["resting_corrections"] / (part["steps"] * part["dt"]) for row in rows], "s--",
           color="tab:gray", label="resting contacts settled")
    for x in capped:
        a.axvline(x, color="tab:red", ls=":", label="impact cap reached" if x == capped[0] else None)
    a.set(xscale="log", yscale="log", xlabel="rest speed (m/s)", ylabel="per simulated second",
          title=f"Inelastic collapse: {part['balls']:,} balls in a {part['side']:g} m box")
    a.invert_xaxis()
    a.legend(fontsize=8, loc="best")
    b.plot(rest, [row["us_per_impact"] for row in rows], "o-", color="tab:blue", label="wall time per impact")
    b.set(xscale="log", xlabel="rest speed (m/s)", ylabel="wall time per impact (us)", ylim=(0, None),
          title="The event loop's cost (the impacts' wall time, all stages)")
    b.invert_xaxis()
    twin = b.twinx()
    twin.plot(rest, [row["wall_s"] for row in rows], "s--", color="tab:orange", label="wall time of the run")
    twin.set(ylabel=f"wall time for {part['steps'] * part['dt']:g} simulated s (s)", ylim=(0, None))
    lines = b.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    b.legend(lines, [line.get_label() for line in lines], fontsize=8, loc="lower left")
    fig.tight_layout()
    return plotting.save_figure(fig, out, "contacts_collapse")


def summary(record: dict) -> list[tuple[str, str]]:
    cr = record["cradle"]["solver"]
    most = max(cr, key=lambda row: (row["iterations"], row["substeps"]))
    pile_row = record["resting"]["pile"]
    cost_rows = record["cost"]["rows"]
    return [
        ("c.o.r. error, solver (worst setting) / event loop",
         f"{max(r['max_error'] for r in record['restitution']['solver']):.3f} / "
         f"{record['restitution']['event_loop_max_error']:.3f}"),
        (f"cradle at eps = 1, solver {most['iterations']} x {most['substeps']}",
         f"{most['moving']} balls move, {100 * most['energy_kept']:.0f} % of the energy kept "
         "(event loop: 1 ball, 100 %)"),
        (f"pile of {pile_row['balls']:,} at rest, |dE| over 10 s / PE",
         f"{abs(pile_row['energy_gained']) / pile_row['potential_energy']:.1e}"),
        ("tunnelling, solver's largest miss rate",
         f"{max(r['solver_miss_rate'] for r in record['tunnelling']['rows']):g}"),
        (f"per step at {cost_rows[-1]['balls']:,} balls, event / solver",
         f"{1e3 * cost_rows[-1]['event_per_step_s']:.3g} / {1e3 * cost_rows[-1]['solver_per_step_s']:.3g} ms"),
    ]


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def contacts_table(data: dict) -> str:
    rows = [["event loop", "-", f"{data['event_cor']:.3f}", "1", "100 %"]]
    for row in data["rows"]:
        rows.append([f"solver, {_plural(row['iterations'], 'iteration')}", f"{row['substeps']}", f"{row['cor']:.3f}",
                     f"{row['moving']}", f"{100 * row['energy_kept']:.0f} %"])
    return markdown_table(["method", "substeps", "largest c.o.r. error", "cradle: balls moving",
                           "cradle: energy kept"], rows)


def _table_slice(record: dict) -> dict:
    cor = {(r["iterations"], r["substeps"]): r["max_error"] for r in record["restitution"]["solver"]}
    rows = record["cradle"]["solver"]
    # the corners and the middle of the sweep: fewest, default-like and most iterations and substeps
    keep = {min(r["iterations"] for r in rows), 4, max(r["iterations"] for r in rows)}
    return {"event_cor": record["restitution"]["event_loop_max_error"],
            "rows": [{"iterations": r["iterations"], "substeps": r["substeps"], "cor": cor[(r["iterations"],
                      r["substeps"])], "moving": r["moving"], "energy_kept": r["energy_kept"]}
                     for r in rows if r["iterations"] in keep and r["substeps"] in (1, 4, 16)]}


def cost_table(data: list) -> str:
    return markdown_table(["balls", "event loop, ms/step", "solver, ms/step", "solver, x real time"],
                          [[f"{r['balls']:,}", f"{1e3 * r['event_per_step_s']:.3g}",
                            f"{1e3 * r['solver_per_step_s']:.3g}", f"{(1 / 60) / r['solver_per_step_s']:.2f}"]
                           for r in data])


TABLES = (Table("contacts", _table_slice, contacts_table),
          Table("contacts_cost", lambda record: record["cost"]["rows"], cost_table))

STUDY = Study("contacts", "Contacts: the engines' contact solver against the event loop",
              parameters, compute, plot, summary, tables=TABLES)
