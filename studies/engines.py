"""Build or buy: MuJoCo, Bullet, Box2D and Chipmunk measured as steplab measures its own methods.

The lecture asks "Physics engine -- build or buy?". Each engine setting
(:data:`steplab.engines.SETTINGS`) is a system under test (:mod:`.system`) and goes through
the same measurements, by the same code, as steplab's integrators:

- identification: the engine and every steplab fixed-step method are stepped side by
  side from the same state at the same dt on free fall and on the oscillator with and
  without damping; the engine "equals" the method whose trajectory it reproduces to its
  own round-off (or "none", with the smallest difference measured);
- order: the slope of the global error against dt on the oscillator
  (:func:`.truncation.error_curve`);
- the largest stable omega dt on the oscillator, undamped and at zeta = 0.1, by
  bisection on long runs (:func:`.stability_limits.measured_limit`);
- the energy error over 10^4 periods of the oscillator (:func:`.stability.energy_history`);
- tunnelling: the fraction of spheres shot through a thin wall against v dt / (w + 2r)
  (:func:`.tunnelling.shoot`), with continuous detection off and on where the engine
  has the switch;
- the lecture's drop test: the first bounce h / H against eps^2 for the nine balls
  (:func:`.restitution.drop`), and what makes an engine deviate (each setting's
  ``deviation``, declared by its adapter);
- cost per body-step on a collision-heavy scene: spheres falling into a box, a planar
  pit every engine can run and the bench's 3-D pit (:func:`falling_balls`), against steplab's event loop (and
  its contact solver, where the collision world has one).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from pathlib import Path

import numpy as np
from steplab.integrators import INTEGRATORS, DivergenceError, Stepper, simulate

from . import plotting, restitution, stability, truncation, tunnelling
from .problems import oscillator_problem, projectile_problem
from .runner import Study, run_tasks
from .stability_limits import measured_limit, oscillator_mode
from .system import engine_system, steplab_system
from .tables import Table, format_value, markdown_table

#: a trajectory within this relative difference of a steplab method's, in the engine's
#: precision, is that method (round-off of 100 steps; the nearest other method differs
#: by 1e-3 or more at omega dt = 0.1)
SAME_METHOD = {"float64": 1e-12, "float32": 1e-5}
def _settings() -> list[str]:
    from steplab.engines import SETTINGS

    return list(SETTINGS)


def _adapter_source_hash() -> str:
    """SHA-256 of the engine adapters' source: part of the parameters, so an adapter edit re-runs the study."""
    import steplab.engines

    digest = hashlib.sha256()
    for path in sorted(Path(steplab.engines.__file__).parent.glob("*.py")):
        digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()


def solver_available() -> bool:
    """Whether steplab's collision world has a contact solver (``CollisionWorld.method``)."""
    from steplab.physics.collision.world import CollisionWorld

    return "method" in {f.name for f in dataclasses.fields(CollisionWorld)}


def unavailable() -> str | None:
    """Why the study cannot run here (an engine not installed), or None."""
    from steplab.engines import INSTALL_HINT, missing

    absent = missing()
    if absent:
        return (f"the engines study needs {', '.join(absent)}, not installed: install the extra with "
                f"{INSTALL_HINT}")
    return None


def parameters(quick: bool) -> dict:
    from steplab.engines import ENGINES
    from steplab.engines.base import version

    periods = 10 if quick else 10_000
    return {
        "settings": _settings(),
        "engine_versions": {cls.distribution: version(cls.distribution) for cls in ENGINES.values()
                            if cls.distribution is not None},
        "adapter_source": _adapter_source_hash(),
        "integrators": [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)],
        # identification: free fall (the lecture projectile) and the oscillator at omega dt = 0.1
        "identification_steps": 100, "free_fall_dt": 0.01, "omega_dt": 0.1, "damping_ratio": 0.1,
        # order on the oscillator (1.125 periods)
        "min_log2_steps": 2, "max_log2_steps": 10 if quick else 14,
        # stability: long runs of 5000 steps measure the limit to 1 % (tests/test_studies.py)
        "damping_ratios": [0.0, 0.1], "long_run_steps": 300 if quick else 5000,
        "stability_rtol": 1e-2 if quick else 1e-5,
        "energy_periods": periods, "energy_steps": round(periods * 2 * math.pi / 0.1),
        # tunnelling: a 1 cm wall, r = 5 cm, dt = 10 ms (v dt stays below Box2D's 2 m cap)
        "radius": 0.05, "wall": 0.01, "tunnelling_dt": 0.01, "trials": 8 if quick else 40,
        "ratios": [0.5, 2.0, 8.0] if quick else np.round(np.geomspace(0.25, 16, 9), 4).tolist(),
        # the drop test (the lecture's table), dt = 1 ms
        "balls": ["range golf ball", "wooden ball"] if quick else [name for name, *_ in restitution.LECTURE_TABLE],
        "drop_dt": 0.001,
        # cost: spheres falling into a box, one frame of 1/60 s per step
        "pit_balls": 60 if quick else 1000, "pit_steps": 5 if quick else 60, "pit_repeats": 2 if quick else 3,
        "solver": solver_available(),
    }


# --- the measurements -------------------------------------------------------------------


def identification_problems(params: dict) -> dict:
    """Free fall and the oscillator (undamped, damped), each with its dt and every steplab
    fixed-step method's trajectory over ``identification_steps`` steps: computed once, shared by
    every setting's :func:`identify`."""
    n = params["identification_steps"]
    problems = {"free fall": (projectile_problem(), params["free_fall_dt"])}
    for zeta in (0.0, params["damping_ratio"]):
        p = oscillator_problem(zeta)
        problems[f"oscillator, zeta = {zeta:g}"] = (p, params["omega_dt"] / p.omega)
    return {label: (problem, dt, {m: simulate(problem.model, m, problem.y0, problem.t_start, dt=dt, n_steps=n).y
                                  for m in params["integrators"]})
            for label, (problem, dt) in problems.items()}


def identify(system, params: dict, problems: dict | None = None) -> dict:
    """Which steplab method the system steps: relative differences of whole trajectories.

    For each problem (free fall; the oscillator, undamped and damped) the system and each
    steplab fixed-step method take the same steps from the same state; the difference is
    max |y_system - y_method| / max |y_method| over every saved state. The method with the
    smallest worst difference over the problems is the nearest; the system *equals* it
    when that is within SAME_METHOD of the system's precision. ``problems``: from
    :func:`identification_problems` (default: computed here).
    """
    n = params["identification_steps"]
    problems = identification_problems(params) if problems is None else problems
    differences: dict[str, dict[str, float | None]] = {}
    diverged = []
    for label, (problem, dt, references) in problems.items():
        try:
            run = system.build(problem.model, None, dt, problem.y0)
            ys = run.advance(problem.y0, dt, n, t_start=problem.t_start).y
        except DivergenceError:
            ys = None
        if ys is None or not np.all(np.isfinite(ys)):  # no trajectory to compare: no method is nearer there
            ys = None
            diverged.append(label)
        for method, ref in references.items():
            difference = None if ys is None else float(np.max(np.abs(ys - ref)) / np.max(np.abs(ref)))
            differences.setdefault(method, {})[label] = difference
    # judged over the problems the system ran: where it diverged every method is "infinitely far", and the
    # nearest would be whichever came first
    worst = {m: max((v for v in d.values() if v is not None), default=None) for m, d in differences.items()}
    judged = {m: w for m, w in worst.items() if w is not None and np.isfinite(w)}
    nearest = min(judged, key=judged.get) if judged else None
    tolerance = SAME_METHOD[system.precision]
    equal = [] if diverged else [m for m in params["integrators"] if m in judged and judged[m] <= tolerance]
    return {"nearest": nearest, "difference": None if nearest is None else judged[nearest], "equals": equal,
            "tolerance": tolerance, "differences": differences, "diverged": diverged, "precision": system.precision}


def order(system, params: dict) -> dict:
    """The fitted order on the oscillator (steplab's fit, the system's own precision's noise floor)."""
    problem = oscillator_problem(0.0)
    truth = problem.exact_final()
    points = truncation.error_curve(problem, system, "float64", truth, params["min_log2_steps"],
                                    params["max_log2_steps"])
    eps = np.finfo(np.dtype(system.precision)).eps
    noise = truncation.ROUNDOFF_NOISE * eps * max(1.0, float(np.max(np.abs(truth))))
    return {"order": truncation.fit_order(points, noise), "points": points}


def stability_limit(system, zeta: float, params: dict) -> float | None:
    """The largest stable omega dt on the oscillator at damping ratio ``zeta`` (None: no limit found)."""
    return measured_limit(oscillator_mode(zeta), system, params["long_run_steps"],
                          params["stability_rtol"])["omega_dt_max"]


def energy(system, params: dict) -> dict:
    problem = oscillator_problem(0.0)
    return stability.energy_history(problem, system, params["energy_steps"], params["omega_dt"] / problem.omega)


def miss_rates(system, planar: bool, params: dict) -> list[dict]:
    """Fraction of shots through the wall at each v dt / (w + 2r) (stratified phases, one scene per ratio)."""
    trials = params["trials"]
    phases = (np.arange(trials) + 0.5) / trials
    out = []
    for ratio in params["ratios"]:
        shot = tunnelling.shoot(tunnelling.Shot(ratio, params["wall"], params["tunnelling_dt"], params["radius"]),
                                phases, "swept", batched=True, system=system, planar=planar)
        out.append({"ratio": ratio, "miss_rate": shot["misses"] / trials})
    return out


def drops(system, params: dict) -> list[dict]:
    """The first bounce of each ball: h / H against the lecture's eps^2."""
    cor = {name: float(c) for name, _, _, c in restitution.LECTURE_TABLE}
    drop_params = restitution.parameters(False)
    rows = []
    for ball in params["balls"]:
        eps = cor[ball]
        result = restitution.drop(eps, params["drop_dt"], "swept", 5, 1, "semi-implicit-euler", drop_params,
                                  system=system)
        h = result["apex_cm"][0] if result["apex_cm"] else 0.0
        rows.append({"ball": ball, "eps": eps, "eps_squared": eps**2, "h_over_H": h / drop_params["H_cm"]})
    return rows


#: the collision-heavy scene: balls of the bench's ball pit (issue 13) falling into a box, one
#: frame of 1/60 s per step: m, kg, m (the layer they start in), m/s, eps, m^2 of floor per
#: ball (in the planar pit: of the plane), s
PIT_RADIUS, PIT_MASS, PIT_LAYER, PIT_SPEED, PIT_RESTITUTION, PIT_AREA, PIT_DT = 0.1, 1.0, 2.0, 2.0, 0.8, 0.2, 1 / 60
#: balls and steps of the pit run before any pit is timed, once in each process that times,
#: so that steplab's event-loop kernels are compiled by then (as the bench's warm-up pit)
WARM_UP_PIT = (50, 30)


def falling_balls(n: int, planar: bool, seed: int = 20240611):
    """``n`` balls falling into a box, eps = 0.8: (model, collision world, y0).

    3-D: the bench's ball pit (steplab.bench.ball_pit_scene): a square floor of 0.2 m^2 per
    ball and four walls, the balls in a 2 m deep layer, thrown in random directions at up to
    2 m/s. Planar: its counterpart in the x-z plane, a floor 0.1 n m wide (0.2 m^2 of the
    2 m layer per ball) between two walls, random in-plane velocities; every engine runs it.
    """
    from steplab.physics import Gravity, Model
    from steplab.physics.collision import CollisionWorld, PairProperties, Plane

    r, rng = PIT_RADIUS, np.random.default_rng(seed)
    half = PIT_AREA * n / PIT_LAYER / 2 if planar else round(math.sqrt(PIT_AREA * n), 1) / 2
    y0 = np.zeros((2, n, 3))
    y0[0, :, 0] = rng.uniform(-half + r, half - r, n)
    y0[0, :, 1] = 0.0 if planar else rng.uniform(-half + r, half - r, n)
    y0[0, :, 2] = rng.uniform(r, r + PIT_LAYER, n)
    directions = rng.normal(size=(n, 3))
    if planar:
        directions[:, 1] = 0.0
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    y0[1] = directions * PIT_SPEED * rng.uniform(size=(n, 1))
    walls = [(np.array([1.0, 0.0, 0.0]), "wall -x"), (np.array([-1.0, 0.0, 0.0]), "wall +x")]
    if not planar:
        walls += [(np.array([0.0, 1.0, 0.0]), "wall -y"), (np.array([0.0, -1.0, 0.0]), "wall +y")]
    planes = (Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor"),) + tuple(Plane(nrm, -half, name) for nrm, name in walls)
    model = Model(np.full(n, PIT_MASS), np.full(n, r), [Gravity()])
    return model, CollisionWorld("swept", planes, pair_properties=PairProperties(PIT_RESTITUTION)), y0


def pit_cost(system, scene, steps: int, repeats: int) -> dict:
    """Wall time per step and per body-step of ``steps`` frames of a pit (best of ``repeats``)."""
    from steplab.engines import UnsupportedFeatureError

    model, world, y0 = scene
    try:
        run = system.build(model, world, PIT_DT, y0)
        run.advance(y0, PIT_DT, 1, save_every=1)  # set up and warmed up
        seconds = []
        for _ in range(repeats):
            traj = run.advance(y0, PIT_DT, steps, save_every=steps)
            seconds.append(traj.wall_time)
    except (UnsupportedFeatureError, DivergenceError) as err:
        return {"error": str(err)}
    best = min(seconds)
    n = model.n_bodies
    return {"per_step_seconds": best / steps, "per_body_step_seconds": best / (steps * n), "balls": n,
            "steps": steps, "real_time_factor": steps * PIT_DT / best}


def _measure(fn, *args):
    """``fn(*args)``, or the one-line reason an engine cannot run it."""
    from steplab.engines import UnsupportedFeatureError

    try:
        return fn(*args)
    except (UnsupportedFeatureError, DivergenceError) as err:
        return {"error": str(err)}


# --- the sweep as tasks -----------------------------------------------------------------

#: steplab's own detectors in the tunnelling comparison
DETECTORS = ("overlap", "swept")
#: the tasks that time a pit (:func:`timed`)
TIMED_KINDS = ("cost", "steplab_cost")


def tasks(params: dict) -> list[list]:
    """The sweep's independent measurements.

    Per setting: its energy run, each stability limit, its drops, order and miss rates; every
    setting's identification in one task (steplab's trajectories computed once); steplab's own
    miss rates per detector and its drop; then the timed pit costs, per setting and per steplab
    system. The longest runs (energy, limits) come first, so a cluster's workers finish together.
    """
    reason = unavailable()
    if reason:
        raise ValueError(reason)
    settings = params["settings"]
    return ([["energy", key] for key in settings]
            + [["limit", key, zeta] for key in settings for zeta in params["damping_ratios"]]
            + [[kind, key] for kind in ("drops", "order", "miss_rates") for key in settings]
            + [["identification"]] + [["steplab_miss_rates", detector] for detector in DETECTORS]
            + [["steplab_drops"]]
            + [["cost", key] for key in settings] + [["steplab_cost", name] for name in _steplab_systems(params)])


def timed(item: list) -> bool:
    """The pit costs measure wall time (an engine's, steplab's event loop's and contact solver's)."""
    return item[0] in TIMED_KINDS


def task(params: dict, item: list):
    """One measurement of :func:`tasks`, as part of the record."""
    from steplab.engines import SETTINGS

    kind = item[0]
    if kind == "identification":
        return {key: _describe_and_identify(SETTINGS[key], params, problems)
                for problems in [identification_problems(params)] for key in params["settings"]}
    if kind == "steplab_miss_rates":
        return _steplab_miss_rates(item[1], params)
    if kind == "steplab_drops":
        return drops(_steplab_systems(params)["event loop"], params)
    if kind == "steplab_cost":
        return _pit_costs(_steplab_systems(params)[item[1]], params)
    setting = SETTINGS[item[1]]
    system = engine_system(setting)
    if kind == "energy":
        return _energy_summary(energy(system, params))
    if kind == "limit":
        return stability_limit(system, item[2], params)
    if kind == "drops":
        return _measure(drops, system, params)
    if kind == "order":
        return order(system, params)["order"]
    if kind == "miss_rates":
        # a planar engine runs in the plane z = 0, its tunnelling lanes side by side in it
        return _measure(miss_rates, system, setting.adapter.planar, params)
    if kind == "cost":
        return _pit_costs(system, params)
    raise ValueError(f"unknown task {item!r} of the engines study")


def reduce(params: dict, results: list) -> dict:
    """The record from the results of :func:`tasks` (in their order): a row per setting, and steplab's own."""
    measured = {tuple(item): result for item, result in zip(tasks(params), results)}
    described = measured[("identification",)]
    rows = []
    for key in params["settings"]:
        about = described[key]
        rows.append({"setting": key, "label": about["label"], "engine": about["engine"],
                     "continuous": about["continuous"], "precision": about["precision"],
                     "settings": about["settings"], "identification": about["identification"],
                     "order": measured["order", key],
                     "omega_dt_max": {f"{zeta:g}": measured["limit", key, zeta] for zeta in params["damping_ratios"]},
                     "energy": measured["energy", key], "miss_rates": measured["miss_rates", key],
                     "drops": measured["drops", key], "cost": measured["cost", key],
                     "deviation": about["deviation"]})
    references = {"miss_rates": {detector: measured["steplab_miss_rates", detector] for detector in DETECTORS},
                  "drops": measured[("steplab_drops",)],
                  "cost": {name: measured["steplab_cost", name] for name in _steplab_systems(params)}}
    return {"rows": rows, "steplab": references}


def compute(params: dict, progress=None) -> dict:
    """Every task in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def _describe_and_identify(setting, params: dict, problems: dict) -> dict:
    """What a setting is (its engine, its precision, the engine's settings) and which steplab method it steps."""
    system = engine_system(setting)
    return {"label": setting.label, "engine": setting.engine, "continuous": setting.continuous,
            "precision": system.precision, "settings": system.build(*_probe_scene()).settings,
            "identification": identify(system, params, problems), "deviation": setting.deviation}


def _probe_scene():
    """A one-body scene every engine accepts, to read a setting's description."""
    from steplab.physics import Model

    return Model([1.0], [0.1]), None, 0.01, np.zeros((2, 1, 3))


def _energy_summary(e: dict) -> dict:
    return {k: e[k] for k in ("t", "relative_energy_error", "max_relative_energy_error",
                              "final_relative_energy_error", "diverged_at_step")}


def _steplab_systems(params: dict) -> dict:
    """steplab's own rows of the comparisons: its event loop (the swept detector), and its
    contact solver where the collision world has one."""
    systems = {"event loop": steplab_system("semi-implicit-euler", "steplab, swept detector")}
    if params["solver"]:
        systems["contact solver"] = steplab_system("semi-implicit-euler", "steplab, contact solver",
                                                   world_options={"method": "solver"})
    return systems


def _steplab_miss_rates(detector: str, params: dict) -> list[dict]:
    """steplab's miss rate with ``detector`` at each ratio, each shot its own run (no other
    shot's impact splits its steps)."""
    trials = params["trials"]
    phases = (np.arange(trials) + 0.5) / trials
    shots = [tunnelling.Shot(ratio, params["wall"], params["tunnelling_dt"], params["radius"])
             for ratio in params["ratios"]]
    return [{"ratio": shot.ratio, "miss_rate": tunnelling.shoot(shot, phases, detector)["misses"] / trials}
            for shot in shots]


def _pit_costs(system, params: dict) -> dict:
    """The system's cost on the planar and the 3-D pit, timed once steplab's kernels are compiled."""
    _compile_event_loop()
    return {label: pit_cost(system, scene, params["pit_steps"], params["pit_repeats"])
            for label, scene in _pits(params["pit_balls"]).items()}


@functools.cache
def _compile_event_loop() -> None:
    """Run the warm-up pit once per process, so steplab's event-loop kernels are compiled
    before anything in it is timed (as the bench's warm-up pit)."""
    model, world, y0 = falling_balls(WARM_UP_PIT[0], planar=False)
    simulate(model, "semi-implicit-euler", y0, 0.0, dt=PIT_DT, n_steps=WARM_UP_PIT[1], collisions=world)


@functools.cache
def _pits(balls: int) -> dict:
    """The planar and the 3-D pit of ``balls`` balls (built once per process, shared by every system's cost)."""
    return {"planar": falling_balls(balls, planar=True), "3-D": falling_balls(balls, planar=False)}


# --- figures ---------------------------------------------------------------------------

#: one colour per engine (its adapter's), one line style per setting within it
LINE_STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1)))
MARKERS = ("o", "s", "^", "D", "v")


def _styles(rows) -> dict[str, dict]:
    seen: dict[str, int] = {}
    out = {}
    for r in rows:
        k = seen.get(r["engine"], 0)
        seen[r["engine"]] = k + 1
        out[r["setting"]] = {"color": _adapter_fact(r["engine"], "colour"), "ls": LINE_STYLES[k % 5],
                             "marker": MARKERS[k % 5]}
    return out


def _adapter_fact(engine: str, fact: str):
    """What the adapter of ``engine`` declares (its ``colour``, its ``display_name``); for a record
    of an engine no longer registered, grey and the key."""
    from steplab.engines import ENGINES

    if engine in ENGINES:
        return getattr(ENGINES[engine], fact)
    return {"colour": "tab:gray"}.get(fact, engine)


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    rows, ref, params = record["rows"], record["steplab"], record["parameters"]
    styles = _styles(rows)
    figures = []

    engines = list(dict.fromkeys(r["engine"] for r in rows))

    # 1. tunnelling, one panel per engine
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.6), sharex=True, sharey=True)
    grid = np.geomspace(min(params["ratios"]), max(params["ratios"]), 300)
    ticks = [x for x in (0.25, 0.5, 1, 2, 4, 8, 16, 32) if min(params["ratios"]) <= x <= max(params["ratios"])]
    for ax, engine in zip(axes.flat, engines):
        ax.plot(grid, np.maximum(0, 1 - 1 / grid), color="k", lw=3, alpha=0.2,
                label="1 - (w + 2r) / (v dt): any overlap at a step's end stops it")
        ax.plot(grid, np.maximum(0, 1 - 0.5 / grid), color="tab:brown", lw=3, alpha=0.35,
                label="1 - (w + 2r) / (2 v dt): only an overlap in the near half\n(pushed out along the nearest face)")
        for detector, colour in (("overlap", "k"), ("swept", "tab:red")):
            pts = ref["miss_rates"][detector]
            ax.plot([p["ratio"] for p in pts], [p["miss_rate"] for p in pts], color=colour, lw=0.8, marker="x",
                    ms=5, label=f"steplab, {detector} detector")
        for r in (r for r in rows if r["engine"] == engine and "error" not in r["miss_rates"]):
            s = styles[r["setting"]]
            ax.plot([p["ratio"] for p in r["miss_rates"]], [p["miss_rate"] for p in r["miss_rates"]],
                    color=s["color"], ls=s["ls"], marker=s["marker"], ms=5, mfc="none", lw=1.3, label=r["label"])
        ax.set_xscale("log")
        ax.set_xticks(ticks, [f"{x:g}" for x in ticks])
        ax.minorticks_off()
        ax.set_ylim(-0.04, 1.04)
        ax.set_title(_adapter_fact(engine, "display_name"), fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        ax.legend(handles[4:], labels[4:], fontsize=7, loc="lower right", framealpha=0.95)
    fig.legend(handles[:4], labels[:4], fontsize=8, loc="lower center", ncol=2)
    for ax in axes[1]:
        ax.set_xlabel("distance per step / wall thickened by the sphere,  v dt / (w + 2r)")
    for ax in axes[:, 0]:
        ax.set_ylabel(f"fraction of {params['trials']} shots through the wall")
    fig.suptitle(f"Tunnelling: spheres (r = {params['radius'] * 100:g} cm) shot at a {params['wall'] * 100:g} cm wall, "
                 f"dt = {params['tunnelling_dt'] * 1e3:g} ms")
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    figures += plotting.save_figure(fig, out, "engines_tunnelling")

    # 2. the drop test: the bounce's error against eps^2, one panel per engine
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.6), sharex=True)
    for ax, engine in zip(axes.flat, engines):
        ax.axhline(0.0, color="k", lw=1)
        pts = ref["drops"]
        ax.plot([p["eps_squared"] for p in pts], [p["h_over_H"] - p["eps_squared"] for p in pts], "kx", ms=7,
                label="steplab, swept detector, semi-implicit Euler")
        for r in (r for r in rows if r["engine"] == engine and "error" not in r["drops"]):
            s = styles[r["setting"]]
            ax.plot([p["eps_squared"] for p in r["drops"]], [p["h_over_H"] - p["eps_squared"] for p in r["drops"]],
                    color=s["color"], ls=s["ls"], lw=0.8, marker=s["marker"], mfc="none", ms=6, label=r["label"])
        ax.set_title(_adapter_fact(engine, "display_name"), fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in axes[1]:
        ax.set_xlabel("eps^2 of the lecture's ball (its c.o.r. squared)")
    for ax in axes[:, 0]:
        ax.set_ylabel("h / H - eps^2  (0: the lecture's bounce)")
    fig.suptitle(f"The lecture's drop test: first bounce height h over the drop H = 92 cm, dt = "
                 f"{params['drop_dt'] * 1e3:g} ms (each panel on its own scale)")
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "engines_drop")

    # 3. energy over 10^4 periods
    fig, ax = plt.subplots(figsize=(8.4, 5.0))
    for r in rows:
        e = r["energy"]
        s = styles[r["setting"]]
        label = r["label"] + (f" (diverges at step {e['diverged_at_step']})" if e["diverged_at_step"] else "")
        ax.loglog(np.asarray(e["t"]) * 1.0, np.maximum(e["relative_energy_error"], 1e-17), color=s["color"],
                  ls=s["ls"], lw=1.2, label=label)
    ax.set_xlabel("time t (s); the period is 1 s")
    ax.set_ylabel("relative energy error |E(t) - E(0)| / |E(0)|\n(largest in each window of steps)")
    ax.set_title(f"Energy of the oscillator over {params['energy_periods']:,} periods, omega dt = "
                 f"{params['omega_dt']:g}\n(settings that step the same method draw the same curve)")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "engines_energy")

    # 4. cost per body-step (markers on a log axis: a bar's length would mean nothing there)
    fig, ax = plt.subplots(figsize=(8.4, 5.0))
    own = sorted(ref["cost"], key=lambda k: k != "event loop")
    names = [r["label"] for r in rows] + [f"steplab, {k}" for k in own]
    costs = [r["cost"] for r in rows] + [ref["cost"][k] for k in own]
    colours = [_adapter_fact(r["engine"], "colour") for r in rows] + ["k"] * len(own)
    y = np.arange(len(names))
    for label, marker, filled in (("planar", "o", True), ("3-D", "s", False)):
        values = np.array([c[label].get("per_body_step_seconds", np.nan) * 1e6 for c in costs])
        ax.scatter(values, y, c=colours if filled else "none", edgecolors=colours, marker=marker, s=45, zorder=3,
                   label=f"{label} pit, {params['pit_balls']:,} balls")
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ticks = [0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.minorticks_off()
    lo = min(c[k].get("per_body_step_seconds", np.inf) for c in costs for k in ("planar", "3-D")) * 1e6
    hi = max(c[k].get("per_body_step_seconds", 0) for c in costs for k in ("planar", "3-D")) * 1e6
    ax.set_xlim(lo / 1.5, hi * 1.5)
    ax.set_xlabel("wall time per body per step (microseconds, best of "
                  f"{params['pit_repeats']} runs); no square: a 2-D engine")
    ax.set_title(f"Cost per body-step: spheres falling into a box, {params['pit_steps']} steps of 1/60 s")
    ax.legend(fontsize=8)
    ax.grid(True, axis="x", which="major", alpha=0.3)
    fig.tight_layout()
    figures += plotting.save_figure(fig, out, "engines_cost")
    return figures


# --- summary and the paper's table ------------------------------------------------------


#: what :func:`verdict` reads of an identification
VERDICT_KEYS = ("nearest", "difference", "equals", "diverged")


def verdict(identification: dict) -> str:
    """"equals NAME (difference)" or "none (nearest NAME, difference)", and the problems the system diverged on."""
    d = identification["difference"]
    if identification["equals"]:
        return f"{' = '.join(identification['equals'])} ({d:.0e})"
    diverged = identification.get("diverged")  # absent from records written before it was kept
    lost = f"; diverged on {', '.join(diverged)}" if diverged else ""
    if identification["nearest"] is None:
        return f"none{lost}"
    return f"none (nearest {identification['nearest']}, {d:.1e}{lost})"


def summary(record: dict) -> list[tuple[str, str]]:
    return [(r["label"], verdict(r["identification"])) for r in record["rows"]]


def _per_body_step(cost: dict) -> float | None:
    return cost.get("per_body_step_seconds")


def _misses_from(points) -> float | str | None:
    """The smallest v dt / (w + 2r) with a miss (None: never), or "n/a" where the engine could not run it."""
    if isinstance(points, dict):
        return "n/a"
    return min((p["ratio"] for p in points if p["miss_rate"] > 0), default=None)


def _bounce_errors(points) -> list[float] | None:
    """h/H - eps^2 of each ball (None where the engine could not run the drop)."""
    return None if isinstance(points, dict) else [p["h_over_H"] - p["eps_squared"] for p in points]


def select_engines(record: dict) -> dict:
    """The engines table's slice: per setting the numbers its cells show, nothing more."""
    rows = []
    for r in record["rows"]:
        errors = _bounce_errors(r["drops"])
        rows.append({"label": r["label"], "order": r["order"], "omega_dt_max": r["omega_dt_max"],
                     # "diverged": not in the records written before it was kept
                     "identification": {k: r["identification"][k] for k in VERDICT_KEYS if k in r["identification"]},
                     "max_energy_error": r["energy"]["max_relative_energy_error"],
                     "misses_from": _misses_from(r["miss_rates"]),
                     "worst_bounce_error": None if errors is None else max(errors, key=abs),
                     "per_body_step": _per_body_step(r["cost"]["planar"])})
    own = sorted(record["steplab"]["cost"], key=lambda k: k != "event loop")
    return {"rows": rows, "steplab": {k: _per_body_step(record["steplab"]["cost"][k]["planar"]) for k in own}}


def _microseconds(seconds) -> str:
    return "2-D only" if seconds is None else f"{seconds * 1e6:.3g}"


def engines_table(data: dict) -> str:
    """One row per engine setting: the steplab method it equals, and the measurements."""
    header = ["engine, setting", "steplab method (difference)", "order", "omega dt max, zeta = 0",
              "zeta = 0.1", "largest energy error, 10^4 periods", "misses at v dt / (w + 2r)", "worst h/H - eps^2",
              "us per body-step (planar)"]
    rows = []
    for r in data["rows"]:
        limits, start = r["omega_dt_max"], r["misses_from"]
        misses = "n/a" if start == "n/a" else "never" if start is None else f"from {start:g}"
        bounce = "n/a" if r["worst_bounce_error"] is None else f"{r['worst_bounce_error']:+.3f}"
        rows.append([r["label"], verdict(r["identification"]), format_value(r["order"], ".2f"),
                     format_value(limits["0"], ".4f"), format_value(limits["0.1"], ".4f"),
                     f"{r['max_energy_error']:.1e}", misses, bounce, _microseconds(r["per_body_step"])])
    for name, seconds in data["steplab"].items():
        rows.append([f"steplab, {name}", "-", "-", "-", "-", "-", "never (swept)", "-", _microseconds(seconds)])
    return markdown_table(header, rows) + (
        "\n\n(difference: the largest relative difference of the trajectories over free fall and the oscillator, "
        "undamped and at zeta = 0.1, 100 steps at omega dt = 0.1; \"none\": no steplab method within round-off. "
        "omega dt max: none = no limit found up to 100.)")


def select_drops(record: dict) -> list[dict]:
    out = []
    for r in record["rows"]:
        errors = _bounce_errors(r["drops"])
        out.append({"label": r["label"], "deviation": r["deviation"],
                    **({"error": r["drops"]["error"]} if errors is None else
                       {"smallest": min(errors), "largest": max(errors), "mean": float(np.mean(errors))})})
    return out


def drop_table(data: list[dict]) -> str:
    """The drop test per setting: how far the first bounce lands from eps^2, and why."""
    rows = [[r["label"], "n/a", "n/a", r["error"]] if "error" in r else
            [r["label"], f"{r['smallest']:+.3f} ... {r['largest']:+.3f}", f"{r['mean']:+.3f}", r["deviation"]]
            for r in data]
    return markdown_table(["engine, setting", "h/H - eps^2, nine balls", "mean", "why"], rows)


TABLES = (Table("engines_drop", select_drops, drop_table), Table("engines", select_engines, engines_table))


STUDY = Study("engines", "Build or buy: MuJoCo, Bullet, Box2D and Chipmunk measured as steplab's methods",
              parameters, compute, plot, summary, tables=TABLES, unavailable=unavailable,
              tasks=tasks, task=task, reduce=reduce, timed=timed)
