"""Stacking study: boxes that stack, slide, roll and tumble in the contact solver (issue 26).

Every number is measured against an analytic answer (:mod:`.stacking_theory`) or a stated
tolerance, on the stacking scenes of ``physics/scenes/`` (60 Hz, the solver's defaults unless
swept):

- **rolling** (``rolling-sphere``): a ball launched sliding rolls at 5/7 v0 from
  t = 2 v0 / (7 mu g); its final speed, its largest distance from the closed form (v, omega r,
  and x at the end) and the time it starts rolling, against dt, in both modes: the contact
  solver and the event loop (whose resting contact slides in closed form over each step, so it
  meets the closed form to round-off at every dt);
- **incline** (``box-incline`` at several angles and frictions): a box sticks for
  tan theta <= mu, else slides at g (sin theta - mu cos theta);
- **columns** (``box-column``, 10 and 20 boxes) at rest for 10 s, measured as the engines'
  stacks are (:func:`steplab.engines.stacks.stack_measures`: standing, drift, jitter after the
  first second), with the penetration and the top box's sink beside the soft contacts' static
  deflection, against substeps, iterations and dt;
- **pyramid** (``box-pyramid``, 210 boxes): does it stand (the top box moves less than 1 cm
  after the first second, :data:`steplab.engines.stacks.STANDING_TOLERANCE`), its sink beside
  the prediction, and the cost per step;
- **mass ratio** (``mass-ratio-stack``): the heavy top box's sink against substeps and iterations;
- **tumbling** (``tumbling-boxes``): the energy lost (never gained: at most ENERGY_GAIN_TOLERANCE
  above the start at any saved time) and the time to rest (the kinetic energy below REST_ENERGY);
- **Newton's cradle** of rigid spheres, the event loop against the solver, and the
  symmetric three-ball impact of Smith et al., "Reflections on Simultaneous Impact" (SIGGRAPH
  2012), for what each impact model keeps: momentum, energy, symmetry, break-away;
- **engines** on the column, the pyramid and the mass-ratio stack through
  :func:`steplab.engines.stacks.run_stack`, where the engines are installed.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import NamedTuple

import numpy as np
from steplab.physics import quaternion as quat
from steplab.physics.collision.solver_settings import ContactSolver
from steplab.physics.scene import Scene, load_scene, parse_scene
from steplab.physics.scene_library import SCENES

from steplab.engines.stacks import SETTLE

from . import plotting
from . import stacking_theory as theory
from .runner import Study
from .tables import Table, markdown_table

G = theory.G
#: the solver's defaults, which every part runs unless it sweeps them
DEFAULTS = ContactSolver()
#: a box pile is at rest once its kinetic energy stays below this, J
REST_ENERGY = 1e-3
#: the largest energy above the start a tumbling run may show at a saved time, relative (the
#: soft contacts store a little energy while they compress)
ENERGY_GAIN_TOLERANCE = 1e-3
#: a body moves when faster than this, m/s (the cradle)
MOVING = 1e-3


def parameters(quick: bool) -> dict:
    if quick:
        return {"rolling_dts": [1 / 30, 1 / 60, 1 / 120], "incline_angles": [10.0, 30.0], "incline_mus": [0.2, 0.5],
                "incline_s": 1.0, "column_rows": [10], "column_substeps": [1, 4], "column_iterations": [1, 4],
                "column_dts": [1 / 60], "rest_s": 3.0, "pyramid_rows": 20, "pyramid_s": 2.0,
                "mass_ratio_substeps": [1, 4], "mass_ratio_iterations": [1], "mass_ratio_s": 3.0,
                "tumbling_s": 3.0, "cradle_settings": [[1, 4], [30, 16]], "engines_s": None}
    return {"rolling_dts": [1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480],
            "incline_angles": [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0], "incline_mus": [0.2, 0.5], "incline_s": 2.0,
            "column_rows": [10, 20], "column_substeps": [1, 2, 4, 8], "column_iterations": [1, 4],
            "column_dts": [1 / 30, 1 / 60, 1 / 120], "rest_s": 10.0, "pyramid_rows": 20, "pyramid_s": 10.0,
            "mass_ratio_substeps": [1, 2, 4, 8, 16], "mass_ratio_iterations": [1, 4], "mass_ratio_s": 10.0,
            "tumbling_s": 5.0, "cradle_settings": [[1, 1], [1, 4], [4, 4], [30, 16], [100, 16]],
            # each stack's run in the engines, s (MuJoCo's PGS takes 0.2 to 0.5 s a step on the pyramid)
            "engines_s": {"box-column": 10.0, "box-pyramid": 2.0, "mass-ratio-stack": 10.0}}


# --- running a scene -----------------------------------------------------------------------


class Run(NamedTuple):
    """A scene's run at its saved times: centres and velocities (K, N, 3), orientations (K, R, 4)
    and angular velocities (K, R, 3, world frame) of its rotating bodies, the wall time per step."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    orientations: np.ndarray
    omega: np.ndarray
    seconds_per_step: float


def variant(name: str, replace: dict[str, str]) -> Scene:
    """Built-in scene ``name`` with lines of its file replaced (each must occur exactly once)."""
    text = SCENES[name].read_text()
    for old, new in replace.items():
        if text.count(old) != 1:
            raise ValueError(f"scene {name}: {old!r} occurs {text.count(old)} times, not once")
        text = text.replace(old, new)
    return parse_scene(text, f"{name} (varied)", name=name)


def with_solver(scene: Scene, **settings) -> Scene:
    """``scene`` with its contact solver's settings changed (iterations, substeps, ...)."""
    solver = dataclasses.replace(scene.collisions.solver, **settings)
    return dataclasses.replace(scene, collisions=dataclasses.replace(scene.collisions, solver=solver))


def run(scene: Scene, t_end: float | None = None, dt: float | None = None, every: int = 1) -> Run:
    """Run ``scene`` (its integrator, collisions and rotating bodies) to ``t_end`` with steps of
    ``dt`` (default the scene's), keeping every ``every``-th state.

    Under the contact solver the rotation is the solver's (the rigid step turns the bodies with
    their contacts and records them at the saved steps); elsewhere (no collisions, or the event
    loop, whose spheres do not spin) each body turns freely beside its translation."""
    from steplab.integrators import simulate
    from steplab.integrators.scene_rotation import rotate_scene

    dt, t_end, world, kept = dt or scene.dt, t_end or scene.t_end, scene.collisions, []

    def stepper(model, integrator):
        step = world.stepper(model, integrator)
        if hasattr(step, "record_every"):  # the rigid solver: its rotation at the saved steps only
            step.record_every = every
        kept.append(step)
        return step

    start = time.perf_counter()
    traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, t_end, dt, save_every=every,
                    stepper=stepper if world is not None else None)
    seconds = (time.perf_counter() - start) / max(traj.steps, 1)
    bodies, shape = scene.rigid_bodies, (len(traj.t), 0)
    if bodies is None:
        orientations, omega = np.zeros(shape + (4,)), np.zeros(shape + (3,))
    elif kept and hasattr(kept[0], "rotation_at"):
        orientations, omega = kept[0].rotation_at(np.rint((traj.t - traj.t[0]) / traj.dt).astype(int))
        orientations, omega = orientations[:, bodies.index], omega[:, bodies.index]
    else:
        rotation = rotate_scene(scene, traj)
        orientations, omega = rotation.orientations, rotation.angular_velocities
    return Run(traj.t, traj.positions, traj.velocities, orientations, omega, seconds)


def kinetic_energy(scene: Scene, r: Run) -> np.ndarray:
    """Translational plus rotational kinetic energy at each saved time, J."""
    from steplab.physics.rigid_body import rotational_energy

    energy = 0.5 * np.einsum("n,knd->k", scene.model.masses, r.v**2)
    if scene.rigid_bodies is not None:
        body = quat.rotate_inverse(np, r.orientations, r.omega)
        energy = energy + rotational_energy(np, scene.rigid_bodies.inertia, body).sum(axis=1)
    return energy


def box_sizes(scene: Scene) -> np.ndarray:
    """The edges (a, b, c) of each rotating box, m, back from its principal moments m/12 (b^2 + c^2, ...)."""
    bodies = scene.rigid_bodies
    s = 12 * bodies.inertia / scene.model.masses[bodies.index][:, None]
    return np.sqrt(np.maximum(0.5 * (s.sum(axis=1, keepdims=True) - 2 * s), 0.0))


def corner_heights(q, orientations, sizes) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and the highest corner's z of each box, m: z -+ sum_i |R_zi| h_i."""
    axes = quat.rotate(np, orientations[..., None, :], np.eye(3))  # (..., 3 body axes, 3)
    reach = np.sum(np.abs(axes[..., 2]) * 0.5 * sizes, axis=-1)
    return q[..., 2] - reach, q[..., 2] + reach


# --- rolling and the incline ---------------------------------------------------------------


def rolling(p: dict) -> dict:
    """The rolling ball's speed, spin and position against the closed form at each dt, in both modes:
    the contact solver (``rows``, the scene's method) and the event loop (``event_rows``), whose
    resting contact slides in closed form over each step (:mod:`steplab.physics.collision.resting`)."""
    scene = load_scene("rolling-sphere")
    v0, radius = float(scene.y0[1, 0, 0]), float(scene.model.radii[0])
    mu = scene.collisions.pair_properties.friction
    answer = theory.sliding_to_rolling(v0, mu, radius)
    modes = {"rows": scene, "event_rows": dataclasses.replace(
        scene, collisions=dataclasses.replace(scene.collisions, method="event"))}
    out, series = {}, {}
    for key, mode in modes.items():
        out[key] = []
        for dt in p["rolling_dts"]:
            r = run(mode, dt=dt)
            v, spin = r.v[:, 0, 0], r.omega[:, 0, 1] * radius  # rolling along +x spins about +y
            exact_v, exact_spin = theory.rolling_speed(v0, mu, radius, r.t)
            rolling_now = np.abs(v - spin) < 1e-3 * v0
            k = int(np.argmax(rolling_now)) if rolling_now.any() else None
            out[key].append({
                "dt": dt, "final_speed": float(v[-1]), "final_spin_speed": float(spin[-1]),
                "speed_error": abs(float(v[-1]) / answer["v_roll"] - 1),
                "t_roll": float(r.t[k]) if k is not None else None,
                "t_roll_error": abs(float(r.t[k]) - answer["t_roll"]) if k is not None else None,
                # the largest distance from the closed form at the saved times: v, omega r, and x at the end
                "max_velocity_error": float(max(np.max(np.abs(v - exact_v)), np.max(np.abs(spin - exact_spin)))),
                "final_position_error": abs(float(r.q[-1, 0, 0]) - rolling_distance(v0, mu, float(r.t[-1])))})
            if abs(dt - scene.dt) < 1e-15:
                series[key] = {"t": r.t.tolist(), "speed": v.tolist(), "spin_speed": spin.tolist()}
    return {"v0": v0, "mu": mu, "radius": radius, **answer, **out, "at_60_hz": series["rows"],
            "event_at_60_hz": series["event_rows"]}


def rolling_distance(v0: float, mu: float, t: float) -> float:
    """How far the ball of :func:`.stacking_theory.sliding_to_rolling` has gone at ``t``, m:
    v0 t - mu g t^2 / 2 while it slides, then x_roll + 5/7 v0 (t - t_roll)."""
    answer = theory.sliding_to_rolling(v0, mu, 1.0)  # the centre's motion does not depend on the radius
    if t <= answer["t_roll"]:
        return v0 * t - 0.5 * mu * G * t * t
    return answer["x_roll"] + answer["v_roll"] * (t - answer["t_roll"])


def incline_toml(theta_deg: float, mus: list[float], t_end: float) -> str:
    """The box-incline scene at ``theta_deg``: one 1 kg box per friction, on the floor turned about y."""
    th = math.radians(theta_deg)
    normal = [math.sin(th), 0.0, math.cos(th)]
    orientation = [math.cos(th / 2), 0.0, math.sin(th / 2), 0.0]  # body z onto the normal
    parts = [f'[simulation]\ndt = {1 / 60!r}\nt_end = {t_end!r}\n\n[forces.gravity]\n\n'
             f'[collisions]\nmethod = "solver"\nrestitution = 0.0\n\n'
             f'[[collisions.planes]]\nname = "incline"\nnormal = {normal!r}\nmaterial = "ramp"\n']
    for k, mu in enumerate(mus):
        centre = [0.1 * normal[0], 1.0 * k, 0.1 * normal[2]]
        parts.append(f'[[bodies]]\nname = "box{k}"\nmass = 1.0\nradius = 0.3\nposition = {centre!r}\nshape = "box"\n'
                     f'size = [0.4, 0.4, 0.2]\norientation = {orientation!r}\nmaterial = "box{k}"\n\n'
                     f'[[collisions.materials]]\npair = ["box{k}", "ramp"]\nrestitution = 0.0\nfriction = {mu!r}\n')
    return "\n".join(parts)


def incline(p: dict) -> dict:
    """Acceleration down the incline (the fit of the downhill distance to s0 + v0 t + a t^2 / 2
    after the first 0.25 s) against the closed form, at each angle and friction."""
    rows = []
    for theta in p["incline_angles"]:
        scene = parse_scene(incline_toml(theta, p["incline_mus"], p["incline_s"]), f"incline {theta:g}")
        r = run(scene)
        th = math.radians(theta)
        downhill = r.q @ np.array([math.cos(th), 0.0, -math.sin(th)])
        late = r.t >= 0.25
        for k, mu in enumerate(p["incline_mus"]):
            a = 2 * np.polyfit(r.t[late], downhill[late, k], 2)[0]
            predicted = theory.incline_acceleration(th, mu)
            rows.append({"theta_deg": theta, "mu": mu, "sticks": math.tan(th) <= mu, "acceleration": float(a),
                         "predicted": predicted, "error": abs(float(a) - predicted),
                         "distance": float(downhill[-1, k] - downhill[0, k])})
    return {"rows": rows, "max_error": max(row["error"] for row in rows)}


# --- stacks at rest --------------------------------------------------------------------------


def at_rest(scene: Scene, t_end: float, dt: float | None = None, series: bool = False) -> dict:
    """A stack run from rest to ``t_end``, saved every step, measured as the engines' stacks are
    (:func:`steplab.engines.stacks.stack_measures`: standing, top_drift, drift, jitter, deflection
    at its SETTLE, at_rest_after), and besides: penetration, the deepest overlap of a box with the
    floor or a box it stood on at the start (from the corners, exact for upright boxes); sink,
    the top box's drop at the end; the wall time per step; with ``series``, the top box's height
    change at 10 Hz (``t``, ``top_height``). A run that diverges gives its time (``diverged_at``)
    and None for the measures."""
    from steplab.integrators.simulate import DivergenceError

    from steplab.engines.stacks import stack_measures

    try:
        r = run(scene, t_end, dt)
    except DivergenceError as err:
        return {"diverged_at": err.t, "standing": False, "top_drift": None, "drift": None, "jitter": None,
                "deflection": None, "at_rest_after": None, "penetration": None, "sink": None,
                "seconds_per_step": None}
    measures = stack_measures(r.t - r.t[0], r.q, r.v, np.array([0.0, 0.0, 1.0]))
    low, high = corner_heights(r.q[-1], r.orientations[-1], box_sizes(scene))
    overlap = [-low[i] if j < 0 else high[j] - low[i] for i, j in supporters(scene)]
    top = measures["top"]
    out = {"diverged_at": None, **measures, "penetration": float(max(overlap)),
           "sink": float(scene.y0[0][top, 2] - r.q[-1, top, 2]), "seconds_per_step": r.seconds_per_step}
    if series:
        every = max(1, round(0.1 / (r.t[1] - r.t[0])))
        out |= {"t": r.t[::every].tolist(), "top_height": (r.q[::every, top, 2] - r.q[0, top, 2]).tolist()}
    return out


def supporters(scene: Scene) -> list[tuple[int, int]]:
    """(box, a box it stands on at the start; -1: the floor), each pair once."""
    contacts = theory.stack_contacts(scene.y0[0], box_sizes(scene))
    return sorted({(int(i), int(j)) for i, j in zip(contacts.upper, contacts.lower)})


def predicted_sink(scene: Scene, sticking: bool = False) -> float:
    """The top box's static deflection on the soft contacts (:func:`.stacking_theory.static_deflection`),
    on the normal springs alone or (``sticking``) with friction holding every contact point, m."""
    top = int(np.argmax(scene.y0[0][:, 2]))
    sink = theory.static_deflection(scene.y0[0], box_sizes(scene), scene.model.masses,
                                    scene.collisions.solver.contact_hertz, sticking=sticking)
    return float(sink[top])


def columns(p: dict, progress) -> dict:
    rows = []
    for n in p["column_rows"]:
        base = variant("box-column", {"rows = 10": f"rows = {n}"})
        prediction = predicted_sink(base)
        sweep = [(s, i, 1 / 60) for s in p["column_substeps"] for i in p["column_iterations"]]
        sweep += [(DEFAULTS.substeps, DEFAULTS.iterations, dt) for dt in p["column_dts"] if abs(dt - 1 / 60) > 1e-15]
        for substeps, iterations, dt in sweep:
            scene = with_solver(base, substeps=substeps, iterations=iterations)
            rows.append({"boxes": n, "substeps": substeps, "iterations": iterations, "dt": dt,
                         "predicted_sink": prediction, **at_rest(scene, p["rest_s"], dt)})
        progress(f"columns of {n}")
    return {"rows": rows}


def pyramid(p: dict) -> dict:
    """The pyramid at the solver's defaults: standing, sink against the prediction, cost; and the
    top box's height at 10 Hz for the figure."""
    scene = variant("box-pyramid", {"rows = 20": f"rows = {p['pyramid_rows']}"})
    return {"boxes": scene.model.n_bodies, "rows": p["pyramid_rows"], "settings": DEFAULTS.describe(),
            "predicted_sink": predicted_sink(scene), "predicted_sink_sticking": predicted_sink(scene, sticking=True),
            **at_rest(scene, p["pyramid_s"], series=True)}


def mass_ratio(p: dict) -> dict:
    base = load_scene("mass-ratio-stack")
    prediction = predicted_sink(base)
    rows = []
    for iterations in p["mass_ratio_iterations"]:
        for substeps in p["mass_ratio_substeps"]:
            scene = with_solver(base, substeps=substeps, iterations=iterations)
            rest = at_rest(scene, p["mass_ratio_s"])
            rows.append({"substeps": substeps, "iterations": iterations, "predicted_sink": prediction, **rest,
                         "sink_error": None if rest["sink"] is None else abs(rest["sink"] / prediction - 1)})
    return {"masses": base.model.masses.tolist(), "predicted_sink": prediction, "rows": rows}


# --- tumbling ----------------------------------------------------------------------------------


def tumbling(p: dict) -> dict:
    scene = load_scene("tumbling-boxes")
    r = run(scene, p["tumbling_s"])
    kinetic = kinetic_energy(scene, r)
    potential = G * np.einsum("n,kn->k", scene.model.masses, r.q[:, :, 2])
    energy = kinetic + potential
    moving = np.nonzero(kinetic >= REST_ENERGY)[0]
    at_rest_from = float(r.t[moving[-1] + 1]) if len(moving) and moving[-1] + 1 < len(r.t) else (
        None if len(moving) else 0.0)
    sizes = box_sizes(scene)
    low, _ = corner_heights(r.q[-1], r.orientations[-1], sizes)
    return {"boxes": scene.model.n_bodies, "energy_start": float(energy[0]), "energy_end": float(energy[-1]),
            "energy_lost": float(energy[0] - energy[-1]),
            "largest_gain": float(np.max(energy - energy[0]) / energy[0]),
            "gains_energy": bool(np.max(energy - energy[0]) > ENERGY_GAIN_TOLERANCE * energy[0]),
            "time_to_rest": at_rest_from, "floor_penetration": float(max(0.0, -low.min())),
            # each box on a face: between all flat (smallest edge up) and all on end
            "rest_energy_range": [float(G * scene.model.masses @ (0.5 * sizes.min(axis=1))),
                                  float(G * scene.model.masses @ (0.5 * sizes.max(axis=1)))],
            "t": r.t.tolist()[::3], "energy": energy.tolist()[::3], "kinetic": kinetic.tolist()[::3]}


# --- Newton's cradle ----------------------------------------------------------------------------


def cradle_toml(velocities, method: str, settings=(1, 4)) -> str:
    """Rigid spheres (1 kg, r = 0.1 m, frictionless, eps = 1) in a row along x, touching, in
    free space, with the given initial x velocities; the moving ones 1 cm away from the row."""
    iterations, substeps = settings
    solver = (f"\n[collisions.solver]\niterations = {iterations}\nsubsteps = {substeps}\n" if method == "solver"
              else "")
    x = 0.2 * np.arange(len(velocities)) - np.sign(velocities) * 0.01
    bodies = "".join(f'[[bodies]]\nname = "ball{k}"\nmass = 1.0\nradius = 0.1\nposition = [{float(x[k])!r}, 0.0, 0.0]\n'
                     f'velocity = [{float(v)!r}, 0.0, 0.0]\nshape = "sphere"\nangular_velocity = [0.0, 0.0, 0.0]\n\n'
                     for k, v in enumerate(velocities))
    return (f'[simulation]\ndt = {1 / 60!r}\nt_end = 0.5\n\n{bodies}'
            f'[collisions]\nmethod = "{method}"\nrestitution = 1.0\nfriction = 0.0\n{solver}')


def impact_outcome(v0, v1) -> dict:
    """What an impact model kept, after Smith et al. (2012): momentum, energy, the symmetry of a
    symmetric start (v -> -v mirrored), and break-away (the balls separate: none approaches its
    neighbour after the impact)."""
    v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
    return {"velocities": v1.tolist(), "momentum_error": abs(float(v1.sum() - v0.sum())),
            "energy_kept": float(np.sum(v1**2) / np.sum(v0**2)), "moving": int(np.sum(np.abs(v1) > MOVING)),
            "symmetry_error": float(np.max(np.abs(v1 + v1[::-1]))) if np.allclose(v0, -v0[::-1]) else None,
            "breaks_away": bool(np.all(np.diff(v1) >= -MOVING))}


def cradle(p: dict) -> dict:
    """A ball at 1 m/s into a row of four, and two balls at +-1 m/s into one at rest between them."""
    starts = {"cradle": [1.0, 0.0, 0.0, 0.0, 0.0], "symmetric": [1.0, 0.0, -1.0]}
    out = {}
    for name, v0 in starts.items():
        rows = [{"method": "event", **impact_outcome(v0, run(parse_scene(cradle_toml(v0, "event"))).v[-1, :, 0])}]
        for iterations, substeps in p["cradle_settings"]:
            scene = parse_scene(cradle_toml(v0, "solver", (iterations, substeps)))
            rows.append({"method": "solver", "iterations": iterations, "substeps": substeps,
                         **impact_outcome(v0, run(scene).v[-1, :, 0])})
        out[name] = {"v0": v0, "rows": rows}
    return out


# --- engines -----------------------------------------------------------------------------------


def engines(p: dict, progress) -> dict:
    """Each engine's stack settings (its defaults and its tuned one) on the column, the pyramid
    and the mass-ratio stack (:func:`steplab.engines.stacks.run_stack`), where installed; a 2-D
    engine runs a stack's plane."""
    if not p["engines_s"]:
        return {"rows": [], "skipped": ["--quick: the engines are not run"]}
    from steplab.engines import ENGINES, UnsupportedFeatureError
    from steplab.engines.stacks import run_stack

    rows, skipped = [], []
    for key, cls in ENGINES.items():
        if not cls.available():
            skipped.append(f"{cls.distribution} is not installed: not compared")
            continue
        for name, t_end in p["engines_s"].items():
            scene = load_scene(name)
            for setting in cls.stack_settings:
                try:
                    rows.append({"scene": name, **run_stack(key, scene, t_end=t_end, setting=setting.key)})
                except UnsupportedFeatureError as err:
                    skipped.append(f"{cls.display_name} on {name}: {err}")
        progress(f"engines: {key}")
    return {"rows": rows, "skipped": skipped}


def compute(p: dict, progress=None) -> dict:
    progress = progress or (lambda message: None)
    record = {}
    for name, part in (("rolling", rolling), ("incline", incline), ("cradle", cradle), ("tumbling", tumbling),
                       ("mass_ratio", mass_ratio)):
        record[name] = part(p)
        progress(name)
    record["columns"] = columns(p, progress)
    record["pyramid"] = pyramid(p)
    progress("pyramid")
    record["engines"] = engines(p, progress)
    return record


# --- figures -----------------------------------------------------------------------------------


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _nan(value):
    """A measure for a figure: NaN (not drawn) for a run that diverged (None)."""
    return np.nan if value is None else value


def plot(record: dict, out) -> list[str]:
    import matplotlib.pyplot as plt
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    names = []
    roll, inc = record["rolling"], record["incline"]
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(16, 4.4))
    series = roll["at_60_hz"]
    t = np.linspace(0.0, series["t"][-1], 400)
    v, spin = theory.rolling_speed(roll["v0"], roll["mu"], roll["radius"], t)
    a.plot(t, v, "k-", lw=1, label="v, exact")
    a.plot(t, spin, "k--", lw=1, label="omega r, exact")
    a.plot(series["t"], series["speed"], "o", ms=3, color="tab:blue", label="v, solver")
    a.plot(series["t"], series["spin_speed"], "s", ms=3, color="tab:orange", label="omega r, solver")
    if "event_at_60_hz" in roll:
        event = roll["event_at_60_hz"]
        a.plot(event["t"], event["speed"], "x", ms=5, color="tab:green", label="v, event loop")
        a.plot(event["t"], event["spin_speed"], "+", ms=6, color="tab:purple", label="omega r, event loop")
    a.axvline(roll["t_roll"], color="0.6", lw=0.8, ls=":", label=f"t = 2 v0 / (7 mu g) = {roll['t_roll']:.3f} s")
    a.set(xlabel="t, s", ylabel="speed, m/s", title=f"Sliding to rolling, dt = 1/60 s, mu = {roll['mu']:g}")
    a.legend(fontsize=8)
    for key, name, colour, marker in (("rows", "solver", "tab:blue", "o"), ("event_rows", "event loop", "tab:green",
                                                                           "x")):
        rows = roll.get(key, [])
        b.loglog([r["dt"] for r in rows], [max(r["speed_error"], 1e-17) for r in rows], f"{marker}-", color=colour,
                 label=f"{name}: |v_end / (5/7 v0) - 1|")
        if rows and "max_velocity_error" in rows[0]:
            b.loglog([r["dt"] for r in rows], [max(r["max_velocity_error"], 1e-17) for r in rows], f"{marker}--",
                     color=colour, alpha=0.6, label=f"{name}: largest |v - exact|, |omega r - exact|, m/s")
    b.axhline(0.005, color="tab:red", ls=":", label="the issue's 0.5 % at 60 Hz")
    b.set(xlabel="dt, s", ylabel="error (relative; dashed: m/s)", title="Rolling: error against dt",
          ylim=(1e-17, 1e-1))
    b.xaxis.set_minor_formatter(NullFormatter())
    b.legend(fontsize=8)
    dense = np.linspace(0.0, max(r["theta_deg"] for r in inc["rows"]), 300)
    for k, mu in enumerate(sorted({r["mu"] for r in inc["rows"]})):
        colour = f"C{k}"
        c.plot(dense, [theory.incline_acceleration(math.radians(th), mu) for th in dense], "-", color=colour, lw=1,
               label=f"mu = {mu:g}: g (sin - mu cos), 0 for tan <= mu")
        rows = [r for r in inc["rows"] if r["mu"] == mu]
        c.plot([r["theta_deg"] for r in rows], [r["acceleration"] for r in rows], "o", color=colour,
               label=f"mu = {mu:g}, solver")
    c.set(xlabel="incline angle theta, degrees", ylabel="acceleration down the incline, m/s^2",
          title="A box on an incline")
    c.legend(fontsize=8)
    names += plotting.save_figure(fig, out, "stacking_rolling_incline")

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.4))
    cols = [r for r in record["columns"]["rows"] if abs(r["dt"] - 1 / 60) < 1e-12]
    for n in sorted({r["boxes"] for r in cols}):
        for s in sorted({r["substeps"] for r in cols}):
            rows = [r for r in cols if r["boxes"] == n and r["substeps"] == s]
            label = f"{n} boxes, {_plural(s, 'substep')}"
            style = "o-" if n == min(r["boxes"] for r in cols) else "s--"
            its = [r["iterations"] for r in rows]
            axes[0].plot(its, [_nan(r["jitter"]) for r in rows], style, label=label)
            axes[1].plot(its, [_nan(r["sink"]) / r["predicted_sink"] for r in rows], style, label=label)
    axes[0].set(xscale="log", yscale="log", xlabel="iterations per substep", ylabel="rms speed after 1 s, m/s",
                title="Columns at rest, 60 Hz: jitter")
    axes[1].axhline(1.0, color="k", lw=0.8, ls=":", label="static deflection on the soft contacts")
    axes[1].set(xscale="log", yscale="log", xlabel="iterations per substep", ylabel="top box's sink / predicted",
                title="Columns: sink over the springs' prediction")
    for ax in axes[:2]:
        ax.legend(fontsize=6, ncol=2, loc="upper right")
        ax.set_ylim(top=ax.get_ylim()[1] * 30)  # room for the legend above the lines
        plotting.integer_ticks(ax, [r["iterations"] for r in cols])
    by_dt = [r for r in record["columns"]["rows"] if r["substeps"] == DEFAULTS.substeps
             and r["iterations"] == DEFAULTS.iterations]
    for n in sorted({r["boxes"] for r in by_dt}):
        rows = sorted((r for r in by_dt if r["boxes"] == n), key=lambda r: r["dt"])
        axes[2].loglog([r["dt"] for r in rows], [_nan(r["drift"]) for r in rows], "o-", label=f"{n}: drift")
        axes[2].loglog([r["dt"] for r in rows], [_nan(r["penetration"]) for r in rows], "s--",
                       label=f"{n}: deepest penetration")
    axes[2].set(xlabel="dt, s", ylabel="m", title=f"Columns against dt ({DEFAULTS.substeps} substeps x "
                f"{DEFAULTS.iterations})")
    axes[2].legend(fontsize=7, title="boxes", title_fontsize=7)
    names += plotting.save_figure(fig, out, "stacking_columns")

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(16, 4.4))
    pyr = record["pyramid"]
    a.plot(pyr["t"], 1e3 * np.array(pyr["top_height"]), "-", label="top box, solver")
    a.axhline(-1e3 * pyr["predicted_sink"], color="k", ls="--", label="predicted, normal springs alone")
    if "predicted_sink_sticking" in pyr:
        a.axhline(-1e3 * pyr["predicted_sink_sticking"], color="tab:red", ls=":",
                  label="predicted, contact points held by friction")
    a.axvspan(0.0, SETTLE, color="0.9", label="settling (first second)")
    a.set(xlabel="t, s", ylabel="top box's height change, mm",
          title=f"{pyr['rows']}-row pyramid ({pyr['boxes']} boxes): {'stands' if pyr['standing'] else 'falls'}")
    a.legend(fontsize=8)
    mr = record["mass_ratio"]
    for iterations in sorted({r["iterations"] for r in mr["rows"]}):
        rows = [r for r in mr["rows"] if r["iterations"] == iterations]
        b.plot([r["substeps"] for r in rows], [1e3 * _nan(r["sink"]) for r in rows], "o-",
               label=_plural(iterations, "iteration"))
    b.axhline(1e3 * mr["predicted_sink"], color="k", ls="--", label="predicted static deflection")
    b.set(xscale="log", yscale="log", xlabel="substeps", ylabel="heavy box's sink at the end, mm",
          title="100 kg on three 1 kg boxes")
    plotting.integer_ticks(b, [r["substeps"] for r in mr["rows"]])
    # the sinks span less than two decades: ticks at 1, 2 and 5 of each, in plain millimetres
    b.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    b.yaxis.set_major_formatter(ScalarFormatter())
    b.yaxis.set_minor_formatter(NullFormatter())
    b.legend(fontsize=8)
    tum = record["tumbling"]
    c.plot(tum["t"], tum["energy"], "-", label="total energy (potential from the floor)")
    c.plot(tum["t"], tum["kinetic"], "-", label="kinetic energy")
    c.axhspan(*tum["rest_energy_range"], color="tab:green", alpha=0.2, label="at rest on a face")
    c.set_yscale("symlog", linthresh=1e-3)  # the kinetic energy down to rest, and the total above it
    c.set(xlabel="t, s", ylabel="J",
          title=f"{tum['boxes']} boxes tumbling onto the floor")
    c.legend(fontsize=8)
    names += plotting.save_figure(fig, out, "stacking_pyramid_mass_ratio_tumbling")

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    for ax, (name, title) in zip(axes, (("cradle", "Newton's cradle: 1 ball at 1 m/s into 4"),
                                        ("symmetric", "Smith et al.'s symmetric impact: +-1 m/s into 1"))):
        rows = record["cradle"][name]["rows"]
        width = 0.8 / len(rows)
        x = np.arange(len(rows[0]["velocities"]))
        for k, r in enumerate(rows):
            label = "event loop" if r["method"] == "event" else (
                f"solver, {_plural(r['iterations'], 'iteration')} x {_plural(r['substeps'], 'substep')}")
            ax.bar(x + (k - (len(rows) - 1) / 2) * width, r["velocities"], width,
                   label=f"{label}: {100 * r['energy_kept']:.0f} % energy")
        ax.set(xticks=x, xticklabels=[f"ball {k + 1}" for k in x], ylabel="velocity after the impact, m/s",
               title=title)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.legend(fontsize=7)
    names += plotting.save_figure(fig, out, "stacking_cradle")
    return names


def summary(record: dict) -> list[tuple[str, str]]:
    roll = next(r for r in record["rolling"]["rows"] if abs(r["dt"] - 1 / 60) < 1e-12)
    event = next((r for r in record["rolling"].get("event_rows", []) if abs(r["dt"] - 1 / 60) < 1e-12), None)
    pyr, tum = record["pyramid"], record["tumbling"]
    return [
        ("rolling at 60 Hz, |v / (5/7 v0) - 1|", f"{roll['speed_error']:.2e}"),
        *([("rolling at 60 Hz in the event loop: |v / (5/7 v0) - 1|; largest |v - exact| at the steps' ends",
            f"{event['speed_error']:.1e}; {event['max_velocity_error']:.1e} m/s")] if event else []),
        ("incline, largest acceleration error", f"{record['incline']['max_error']:.3g} m/s^2"),
        (f"pyramid of {pyr['boxes']}: stands, top moves after 1 s",
         f"{pyr['standing']}, {1e3 * pyr['top_drift']:.2f} mm"),
        ("pyramid's sink, measured / predicted (friction holding its points; normal springs alone)",
         f"{1e3 * pyr['sink']:.1f} / {1e3 * pyr.get('predicted_sink_sticking', np.nan):.1f}; "
         f"{1e3 * pyr['predicted_sink']:.1f} mm"),
        ("tumbling boxes: energy lost, time to rest",
         f"{tum['energy_lost']:.1f} J, "
         + (f"{tum['time_to_rest']:.2f} s" if tum["time_to_rest"] is not None else "not at rest")),
    ]


def rolling_table(rows: list) -> str:
    def cell(x, spec):
        return "-" if x is None else f"{x:{spec}}"

    return markdown_table(
        ["mode", "dt, s", "final speed / (5/7 v0) - 1, abs.", "largest error of v and omega r at the steps' ends, m/s",
         "final position's error, m", "first step's end rolling - t_roll, s"],
        [[r["mode"], f"1/{round(1 / r['dt'])}", cell(r["speed_error"], ".1e"), cell(r["max_velocity_error"], ".1e"),
          cell(r["final_position_error"], ".1e"), cell(r["t_roll_error"], ".2e")] for r in rows])


def _rolling_slice(record: dict) -> list:
    """The rolling ball's rows, the contact solver's and then the event loop's."""
    roll = record["rolling"]
    return [{"mode": mode, **{k: r.get(k) for k in ("dt", "speed_error", "max_velocity_error", "final_position_error",
                                                   "t_roll_error")}}
            for key, mode in (("rows", "contact solver"), ("event_rows", "event loop")) for r in roll.get(key, [])]


def stacking_table(data: dict) -> str:
    def cells(r):
        return [f"{1e3 * r['sink']:.1f}" if r["sink"] is not None else "diverged", f"{1e3 * r['predicted_sink']:.1f}",
                "yes" if r["standing"] else "no", f"{1e3 * r['top_drift']:.1f}" if r["top_drift"] is not None else "-",
                f"{r['jitter']:.1e}" if r["jitter"] is not None else "-"]

    def setting(r):
        return f"{_plural(r['substeps'], 'substep')} x {_plural(r['iterations'], 'iteration')}"

    rows = [[f"column of {r['boxes']}, {setting(r)}", *cells(r)] for r in data["columns"]]
    rows += [[f"mass ratio 100:1, {setting(r)}", *cells(r)] for r in data["mass_ratio"]]
    p = data["pyramid"]
    rows.append([f"pyramid of {p['boxes']}, {p['settings']}", *cells(p)])
    return markdown_table(["stack (60 Hz)", "top's sink, mm", "predicted, mm", "stands", "top moves after 1 s, mm",
                           "jitter, m/s"], rows)


#: the (substeps, iterations) of the columns' and the mass-ratio stack's rows in the paper's table
TABLE_SETTINGS = {"columns": ((1, 1), (4, 1), (4, 4), (8, 1)), "mass_ratio": ((1, 1), (4, 1), (16, 1), (4, 4), (16, 4))}


def _table_slice(record: dict) -> dict:
    keep = ("boxes", "substeps", "iterations", "sink", "predicted_sink", "standing", "top_drift", "jitter",
            "penetration")

    def picked(rows, part):
        return [{k: r[k] for k in keep if k in r} for r in rows if (r["substeps"], r["iterations"])
                in TABLE_SETTINGS[part] and abs(r.get("dt", 1 / 60) - 1 / 60) < 1e-12]

    return {"columns": picked(record["columns"]["rows"], "columns"),
            "mass_ratio": picked(record["mass_ratio"]["rows"], "mass_ratio"),
            "pyramid": {k: record["pyramid"][k] for k in keep[3:] + ("boxes", "settings")}}


def engines_table(rows: list) -> str:
    def cell(x, scale=1.0, spec=".2f"):
        return "-" if x is None else f"{scale * x:{spec}}"

    return markdown_table(
        ["stack", "engine, setting", "stands", "top moves after 1 s, mm", "sink at 1 s, mm", "jitter, m/s",
         "ms per step"],
        [[r["scene"], r["label"], "yes" if r["standing"] else "no", cell(r["top_drift"], 1e3),
          cell(r["deflection"], 1e3), cell(r["jitter"], 1.0, ".1e"), cell(r["seconds_per_step"], 1e3, ".3g")]
         for r in rows])


def _engines_slice(record: dict) -> list:
    """steplab's row at the solver's defaults (at 60 Hz) beside each engine setting's, stack by stack."""
    keep = ("standing", "top_drift", "deflection", "jitter", "seconds_per_step")
    ours = {"box-pyramid": record["pyramid"]}
    for r in record["columns"]["rows"]:
        if (r["boxes"], r["substeps"], r["iterations"]) == (10, DEFAULTS.substeps, DEFAULTS.iterations) and abs(
                r["dt"] - 1 / 60) < 1e-12:
            ours["box-column"] = r
    ours["mass-ratio-stack"] = next(r for r in record["mass_ratio"]["rows"] if (r["substeps"], r["iterations"]) == (
        DEFAULTS.substeps, DEFAULTS.iterations))
    rows = []
    for scene in ("box-column", "box-pyramid", "mass-ratio-stack"):
        if scene in ours:
            rows.append({"scene": scene, "label": f"steplab, {DEFAULTS.describe()}",
                         **{k: ours[scene][k] for k in keep}})
        rows += [{"scene": scene, "label": r["label"], **{k: r[k] for k in keep}} for r in record["engines"]["rows"]
                 if r["scene"] == scene]
    return rows


TABLES = (Table("stacking", _table_slice, stacking_table), Table("stacking_engines", _engines_slice, engines_table),
          Table("stacking_rolling", _rolling_slice, rolling_table))

STUDY = Study("stacking", "Stacking: boxes that stack, slide, roll and tumble in the contact solver",
              parameters, compute, plot, summary, tables=TABLES)
