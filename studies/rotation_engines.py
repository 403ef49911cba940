"""The engines on rotation: MuJoCo, Bullet, Box2D and Chipmunk named as steplab's rotation methods.

Part of the rotation study (its record's ``engines``), measured with the engines that are
installed (:data:`steplab.engines.ROTATION_SETTINGS`, each adapter's ``rotation_settings``):

- identification, as the engines study identifies translation: each engine setting and each
  of steplab's rotation methods take the same steps of the same dt from the same (q, omega)
  on two torque-free problems, the Dzhanibekov box of the ``dzhanibekov`` scene turned to a
  general orientation (a tumble: the 3-D engines only) and the same box spun about its major
  axis (a spin in a plane: every engine). The distance of two runs is the largest, over the
  saved states, of the angle between their orientations relative to the angle turned so far
  (max |omega| t, at least 1 rad: the round-off of an angle grows with it) and of
  |omega_e - omega_m| / max |omega_m|; the setting *equals* the methods within
  :data:`.engines.SAME_METHOD` of its precision on every problem it can run, and otherwise is
  "none", with its nearest method;
- drift: the energy and |L| of the Dzhanibekov box and of Bullet's gyroscopic demo body over
  ``drift_time`` seconds at the scene's dt, each 3-D engine setting beside each steplab method.

:func:`measure` is what the rotation study calls; without an engine it measures the others
and says which are missing in one line (``missing``).
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import ROTATIONS, DivergenceError, get_rotation
from steplab.integrators.rotation import simulate_rotation
from steplab.physics import Model
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import RigidBodies, RotationModel, rotational_energy
from steplab.physics.scene import load_scene

from . import plotting
from .engines import SAME_METHOD
from .tables import Table, format_value, markdown_table

#: the general orientation the tumble starts from: a turn of TILT_ANGLE rad about TILT_AXIS
#: (so that no axis of the body is a world axis and a frame mix-up cannot cancel)
TILT_AXIS, TILT_ANGLE = (1.0, 2.0, 3.0), 0.7
#: the box of the spin problem turns about its major axis (body z) at the flip's |omega|
SPIN_AXIS = 2
#: the Bullet demo body's mass, kg (the disc's and the bar's of :func:`.rotation.bullet_body`), and
#: its radius, m; the engines get its moments, and the box of those moments as its shape
DEMO_MASS, DEMO_RADIUS = 1.5, 0.5


def parameters(quick: bool) -> dict:
    """The engines' part of the rotation study's parameters."""
    from steplab.engines import ROTATION_SETTINGS

    return {"settings": list(ROTATION_SETTINGS), "identification_steps": 200,
            "drift_time": 30.0 if quick else 1000.0, "drift_saves": 30 if quick else 100}


# --- the problems ------------------------------------------------------------------------


def flip_box():
    """The ``dzhanibekov`` scene: its model, its box (RigidBodies) and its dt."""
    scene = load_scene("dzhanibekov", collisions=False)
    return scene.model, scene.rigid_bodies, scene.dt


def problems() -> dict:
    """name -> (model, RigidBodies, dt): the tilted tumble of the flip box and its spin about its major axis."""
    model, box, dt = flip_box()
    axis = np.array(TILT_AXIS) / np.linalg.norm(TILT_AXIS)
    tilt = quat.multiply(np, quat.from_axis_angle(np, axis[None], TILT_ANGLE), box.orientations)
    # the same motion in the body, seen from the tilted frame: omega_world = R_tilt omega_body
    tumble = RigidBodies(box.index, box.inertia, tilt, quat.rotate(np, tilt, box.body_angular_velocities()),
                         box.shapes)
    spin_axis = np.eye(3)[SPIN_AXIS][None]
    turn = quat.from_axis_angle(np, spin_axis, TILT_ANGLE)
    spin = RigidBodies(box.index, box.inertia, turn, np.linalg.norm(box.angular_velocities) * spin_axis, box.shapes)
    return {"tumble": (model, tumble, dt), "spin": (model, spin, dt)}


def demo_body(inertia, omega) -> tuple:
    """Bullet's gyroscopic demo body (principal moments ``inertia``, world omega) as (model, RigidBodies)."""
    model = Model([DEMO_MASS], [DEMO_RADIUS], [])
    return model, RigidBodies(np.array([0]), np.array([inertia], float), quat.IDENTITY[None].copy(),
                              np.array([omega], float), ("box",))


# --- runs ---------------------------------------------------------------------------------


def steplab_run(name: str, bodies: RigidBodies, dt: float, n: int, save_every: int = 1, backend: str = "numpy"):
    """``name``'s run from the bodies' state: (t, q (K, R, 4), world omega (K, R, 3))."""
    t, q, omega = simulate_rotation(get_rotation(name), RotationModel(bodies.inertia), bodies.orientations,
                                    bodies.body_angular_velocities(), dt, n, save_every=save_every,
                                    backend=backend, check=False)
    return t, q, quat.rotate(np, q, omega)


def engine_run(setting, model, bodies: RigidBodies, dt: float, n: int, save_every: int = 1):
    """The engine setting's run from the bodies' state: (t, q, world omega), as :func:`steplab_run`.

    Raises UnsupportedFeatureError (a planar engine on a tumble) and DivergenceError.
    """
    y0 = np.zeros((2, len(model.masses), 3))
    run = setting.build(model, None, dt, y0, bodies=bodies)
    try:
        trajectory, rotation = run.advance_rotating(y0, dt, n, save_every=save_every)
    finally:
        run.close()
    return trajectory.t, rotation.orientations, rotation.angular_velocities


def distance(a, b) -> float:
    """The largest, over saved states, of the angle between the orientations over the angle turned
    (max |omega_b| t, at least 1 rad) and of |omega_a - omega_b| / max |omega_b|."""
    (t, qa, wa), (_, qb, wb) = a, b
    with np.errstate(invalid="ignore"):
        turned = np.maximum(1.0, np.max(np.linalg.norm(wb, axis=-1)) * (t - t[0]))
        angle = float(np.max(quat.angle_between(np, qa, qb) / turned[:, None]))
        spin = float(np.max(np.abs(wa - wb)) / np.max(np.abs(wb)))
    value = max(angle, spin)
    return value if np.isfinite(value) else float("inf")


def identify(setting, params: dict, references: dict | None = None) -> dict:
    """Which steplab rotation method the engine setting steps (see the module's description).

    ``references``: problem -> method -> steplab's run (default: computed here).
    """
    from steplab.engines import UnsupportedFeatureError

    n = params["identification_steps"]
    cases = problems()
    references = reference_runs(params) if references is None else references
    differences, unsupported, diverged = {}, {}, []
    for label, (model, bodies, dt) in cases.items():
        try:
            run = engine_run(setting, model, bodies, dt, n)
        except UnsupportedFeatureError as err:
            unsupported[label] = str(err)
            continue
        except DivergenceError:
            diverged.append(label)
            continue
        differences[label] = {m: _finite(distance(run, ref)) for m, ref in references[label].items()}
    # judged over the problems the engine ran: where it diverged every method is "infinitely far", and the
    # nearest would be whichever came first
    methods = list(next(iter(references.values())))
    worst = {m: max((d[m] for d in differences.values() if d[m] is not None), default=None) for m in methods}
    judged = {m: w for m, w in worst.items() if w is not None}
    nearest = min(judged, key=judged.get) if judged else None
    tolerance = SAME_METHOD[setting.adapter.precision]
    return {"key": setting.key, "label": setting.label, "engine": setting.engine, "expected": setting.equals,
            "note": setting.deviation, "precision": setting.adapter.precision, "tolerance": tolerance,
            "nearest": nearest, "difference": None if nearest is None else judged[nearest],
            "equals": [] if diverged else [m for m in methods if m in judged and judged[m] <= tolerance],
            "differences": differences, "diverged": diverged, "unsupported": unsupported}


def reference_runs(params: dict) -> dict:
    """problem -> steplab method -> its run on the problem (:func:`steplab_run`), for :func:`identify`."""
    from steplab.integrators import ROTATIONS

    n = params["identification_steps"]
    return {label: {m: steplab_run(m, bodies, dt, n) for m in ROTATIONS}
            for label, (_, bodies, dt) in problems().items()}


def invariants(run, inertia) -> tuple[list, list]:
    """Relative change of the energy and of |L| at each saved state of a run (None where not finite)."""
    _, q, omega = run
    body = quat.rotate_inverse(np, q, omega)
    with np.errstate(all="ignore"):
        energy = rotational_energy(np, inertia, body)[:, 0]
        momentum = np.linalg.norm(inertia * body, axis=-1)[:, 0]
        return ([_finite(x) for x in energy / energy[0] - 1], [_finite(x) for x in momentum / momentum[0] - 1])


def drift(params: dict, demo: tuple, backend: str) -> list[dict]:
    """Energy and |L| over ``drift_time`` of the flip box and the demo body: each 3-D setting, each method."""
    from steplab.integrators import ROTATIONS

    from steplab.engines import ROTATION_SETTINGS

    model, box, dt = flip_box()
    bodies = {"flip box": (model, box), "Bullet demo body": demo_body(*demo)}
    n_saves = params["drift_saves"]
    every = max(1, int(round(params["drift_time"] / dt / n_saves)))
    n = every * n_saves
    rows = []
    engines = [key for key in params["settings"] if not ROTATION_SETTINGS[key].adapter.planar]
    # steplab's methods run both bodies as one batch; each engine runs each body alone
    together = RigidBodies(np.arange(len(bodies)), *(np.concatenate([getattr(rigid, field) for _, rigid in
                                                                     bodies.values()])
                                                     for field in ("inertia", "orientations", "angular_velocities")))
    for name in ROTATIONS:
        t, q, omega = steplab_run(name, together, dt, n, every, backend)
        for k, (body, (_, rigid)) in enumerate(bodies.items()):
            rows.append(_drift_row(body, "steplab", name, (t, q[:, k:k + 1], omega[:, k:k + 1]), rigid.inertia))
    for key in engines:
        for body, (model, rigid) in bodies.items():
            try:
                run = engine_run(ROTATION_SETTINGS[key], model, rigid, dt, n, every)
            except DivergenceError as err:
                rows.append({"body": body, "kind": "engine", "name": key, "diverged_at": err.t})
                continue
            rows.append(_drift_row(body, "engine", key, run, rigid.inertia))
    return rows


def _drift_row(body: str, kind: str, name: str, run, inertia) -> dict:
    energy, momentum = invariants(run, inertia)
    row = {"body": body, "kind": kind, "name": name, "time": run[0].tolist(), "energy": energy, "momentum": momentum}
    if None in energy:  # steplab's runs go on past a divergence, as NaN
        row["diverged_at"] = row["time"][energy.index(None)]
    return row


def measure(params: dict, demo: tuple, backend: str = "numpy") -> dict:
    """The rotation study's ``engines`` record: identification and drift of the installed settings.

    ``demo``: (principal moments, world omega) of Bullet's gyroscopic demo body;
    ``backend``: steplab's drift runs (the compiled loop for long runs).
    """
    from steplab.engines import ENGINES, ROTATION_SETTINGS

    absent = sorted({ROTATION_SETTINGS[k].adapter.distribution for k in params["settings"]
                     if not ROTATION_SETTINGS[k].available})
    present = {**params, "settings": [k for k in params["settings"] if ROTATION_SETTINGS[k].available]}
    missing = (f"not measured, not installed: {', '.join(absent)} (pip install -e \".[engines]\")" if absent
               else None)
    references = reference_runs(params) if present["settings"] else {}
    identification = [identify(ROTATION_SETTINGS[k], params, references) for k in present["settings"]]
    return {"missing": missing, "settings": present["settings"],
            "colours": {k: ENGINES.lookup(ROTATION_SETTINGS[k].engine).colour for k in present["settings"]},
            "identification": identification, "drift": drift(present, demo, backend) if present["settings"] else [],
            "drift_time": params["drift_time"], "identification_steps": params["identification_steps"]}


def _finite(x):
    x = float(x)
    return x if np.isfinite(x) else None


# --- figure and table ---------------------------------------------------------------------


def plot(engines: dict, out, styles) -> list[str]:
    """The engines' figure: the identification distances, and the drift beside steplab's methods.

    ``styles(name) -> dict``: the matplotlib style of a steplab method (its own ``style``).
    """
    plt = plotting.plt
    ident = engines["identification"]
    if not ident:
        return []
    # the methods measured (an engine that diverged on every problem has none), in the registry's order
    measured = {m for row in ident for d in row["differences"].values() for m in d}
    methods = [m for m in ROTATIONS if m in measured]
    fig, axes = plt.subplots(2, 2, figsize=(13.5, 9.4))
    heat = axes[0, 0]
    floor = 1e-17
    values = np.array([[max([d[m] for d in row["differences"].values() if d[m] is not None] or [np.inf])
                        for m in methods] for row in ident])
    image = heat.imshow(np.log10(np.maximum(values, floor)), cmap="viridis_r", vmin=-16, vmax=0, aspect="auto")
    for i, row in enumerate(ident):
        for j, m in enumerate(methods):
            mark = "=" if m in row["equals"] else ""
            heat.text(j, i, f"{mark}{values[i, j]:.0e}", ha="center", va="center", fontsize=6.5,
                      color="white" if values[i, j] < 1e-8 else "black")
    heat.set_xticks(range(len(methods)), methods, rotation=35, ha="right", fontsize=8)
    heat.set_yticks(range(len(ident)), [row["label"] for row in ident], fontsize=8)
    heat.set_title(f"distance of (q, omega) runs, {engines['identification_steps']} steps at dt = 1/60 s\n"
                   "(=: equal to round-off in the engine's precision)", fontsize=10)
    fig.colorbar(image, ax=heat, label="log10 distance (rad; relative omega)")
    panels = ((axes[0, 1], "flip box", "energy"), (axes[1, 0], "flip box", "momentum"),
              (axes[1, 1], "Bullet demo body", "energy"))
    engine_styles = setting_styles(engines["settings"], engines["colours"])
    for ax, body, key in panels:
        rows = [row for row in engines["drift"] if row["body"] == body]
        curves = [[(t, max(abs(v), floor)) for t, v in zip(row.get("time", [])[1:], row.get(key, [])[1:])
                   if v is not None] for row in rows]
        top = scale_top(curves)
        for n, (row, pts) in enumerate(zip(rows, curves)):
            # markers evenly spaced along the drawn line (in fractions of the panel's diagonal), each
            # curve's starting elsewhere, so that curves drawn over each other stay visible
            every = (0.11 * (n % 7) / 7, 0.11)
            if row["kind"] == "steplab":
                style = styles(row["name"]) | {"lw": 0.9, "alpha": 0.8, "ms": 3.5, "markevery": every}
            else:
                style = engine_styles[row["name"]] | {"lw": 2.0, "ms": 6.5, "mfc": "none", "mew": 1.4,
                                                      "markevery": every, "label": f"{row['name']} (engine)"}
            ax.loglog(*zip(*pts) if pts else ([], []), **style)
            if "diverged_at" in row:  # where the run stopped, on the top edge
                ax.plot([row["diverged_at"]], [top / 2], marker="x", ms=7, color=style["color"], ls="none")
        ax.set_xlabel("time (s), dt = 1/60 s")
        ax.set_ylabel("|E / E0 - 1|" if key == "energy" else "| |L| / |L0| - 1 |")
        ax.set_title(f"{body}: {'energy' if key == 'energy' else '|L|'} (exact: 1e-17; x: diverged)", fontsize=10)
        ax.set_ylim(floor / 2, top)
        ax.grid(True, which="major", alpha=0.3)
    handles, labels = axes[0, 1].get_legend_handles_labels()
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    # below the panels, hiding no curve; an engine is drawn over the steplab method it equals
    fig.legend(handles, labels, loc="lower center", ncol=7, fontsize=7.5, frameon=False)
    return plotting.save_figure(fig, out, "rotation_engines")


def scale_top(curves) -> float:
    """The top of a log scale of relative drifts: a decade above the largest value of the curves
    [(x, y), ...] and at least 10 (a gaining method reaches 150 before it diverges)."""
    return 10.0 ** np.ceil(np.log10(max([10.0] + [3 * y for c in curves for _, y in c])))


#: the markers of an engine's settings, in the order the engine lists them
SETTING_MARKERS = ("o", "s", "D", "^", "v", "P")


def setting_styles(settings, colours: dict) -> dict:
    """Each engine setting's line style: its engine's colour (the adapter's ``colour``) in a shade of
    its own, darkest first, and a marker of its own, so that the settings of one engine differ."""
    from matplotlib import colors

    styles = {}
    for colour in dict.fromkeys(colours[k] for k in settings):
        same = [k for k in settings if colours[k] == colour]
        rgb = np.array(colors.to_rgb(colour))
        # towards black (negative) and towards white (positive), about the engine's colour
        for n, (key, mix) in enumerate(zip(same, np.linspace(-0.5, 0.45, len(same)) if len(same) > 1 else [0.0])):
            shade = rgb * (1 + mix) if mix < 0 else rgb + (1 - rgb) * mix
            styles[key] = {"color": tuple(shade), "marker": SETTING_MARKERS[n % len(SETTING_MARKERS)], "ls": "-"}
    return styles


def _identified(row: dict) -> str:
    if row["equals"]:
        return ", ".join(row["equals"])
    return f"none (diverged on {', '.join(row['diverged'])})" if row.get("diverged") else "none"


def _at_end(rows, body, name, key):
    row = next((r for r in rows if r["body"] == body and r["name"] == name), None)
    if row is None:
        return "n/a (planar)"
    if "diverged_at" in row:
        return f"diverged at {row['diverged_at']:.3g} s"
    return format_value(row[key][-1], "+.1e")


def engines_table(data: dict) -> str:
    """One row per engine setting and per steplab method: identification, then drift."""
    header = ["engine setting or method", "declared", "identified as", "nearest (distance)", "flip box dE/E",
              "flip box d|L|/|L|", "demo body dE/E", "demo body d|L|/|L|"]
    rows = []
    for row in data["identification"]:
        rows.append([row["label"], row["expected"] or "none", _identified(row),
                     "none" if row["nearest"] is None
                     else f"{row['nearest']} ({format_value(row['difference'], '.0e')})",
                     *(_at_end(data["drift"], b, row["key"], k) for b in ("flip box", "Bullet demo body")
                       for k in ("energy", "momentum"))])
    for name in dict.fromkeys(r["name"] for r in data["drift"] if r["kind"] == "steplab"):
        rows.append([f"steplab {name}", "", "", "", *(_at_end(data["drift"], b, name, k)
                                                      for b in ("flip box", "Bullet demo body")
                                                      for k in ("energy", "momentum"))])
    tolerances = ", ".join(sorted({f"{r['tolerance']:g} in {r['precision']}" for r in data["identification"]}))
    note = (f"\n\n(identification: {data['identification_steps']} steps of 1/60 s on the tilted flip box and on a "
            f"spin about its major axis, \"equals\" within {tolerances}; drift after {data['drift_time']:g} s at "
            "dt = 1/60 s; n/a: a planar engine cannot tumble.)")
    missing = f"\n\nEngines {data['missing']}." if data["missing"] else ""
    return markdown_table(header, rows) + note + missing


def _table_slice(engines: dict) -> dict:
    """What :func:`engines_table` draws from, and no more: each drift run's last values."""
    keep = ("body", "kind", "name", "diverged_at")
    drift = [{k: r[k] for k in keep if k in r} | {k: r[k][-1:] for k in ("energy", "momentum") if k in r}
             for r in engines["drift"]]
    identification = [{k: r[k] for k in ("key", "label", "expected", "equals", "nearest", "difference",
                                         "tolerance", "precision")} for r in engines["identification"]]
    return {k: engines[k] for k in ("drift_time", "identification_steps", "missing")} | {
        "drift": drift, "identification": identification}


TABLE = Table("rotation_engines", _table_slice, engines_table)
