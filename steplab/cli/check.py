"""``steplab check``: the largest stable dt of each fixed-step integrator on a scene, from its stiffest mode."""

from __future__ import annotations

import dataclasses
import json

from .args import (
    json_argument,
    nonempty,
    positive,
    rotation_argument,
    rotation_named,
    run_steps,
    scene_argument,
    time_span,
)
from .table import table


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="predict the largest stable dt of each fixed-step integrator on a scene",
                       description="Predict the largest stable dt of each fixed-step integrator on a scene, from its "
                       "stiffest mode; with rotating bodies, the rotation method's too; with springs at body-frame "
                       "points, each integrator paired with the rotation method (--rotation): 'composes', or how "
                       "fast the pair grows a step (JSON: integrators[].coupled).")
    scene_argument(p)
    p.add_argument("--integrator", type=nonempty, help="only this integrator (default: every fixed-step one)")
    p.add_argument("--dt", type=positive, help="the dt to check, s (default: the scene's)")
    rotation_argument(p)
    json_argument(p)


def command(args) -> int:
    from steplab.integrators import INTEGRATORS, Stepper
    from steplab.integrators.simulate import check_initial_state
    from steplab.integrators.stable_dt import StableStep, stable_steps
    from steplab.physics.scene import load_scene

    from .run import integrator_named, scene_method

    scene = load_scene(args.scene)
    scene_method(scene)  # the scene's [simulation.<integrator>] table, refused as run refuses it
    rotation = rotation_named(scene, args)
    world = scene.collisions
    if world is not None:  # run's refusal of a rotation method the contact solver's substeps cannot take
        world = world.with_rotation(rotation.name)
        world.check_solver()
    # the dts run refuses: longer than the run, too small to advance time, more steps than a float counts
    dt, t_end = time_span(scene, args)
    steps = run_steps(scene, dt, t_end)
    if args.integrator is not None:
        steppers = [integrator_named(args.integrator)]
        if world is not None:  # run's refusal: the contact solver's substeps are semi-implicit Euler's
            world.check_solver(steppers[0])
        if _coupled(scene):  # run's refusal: only a fixed-step Stepper evaluates forces at the lever arms
            from steplab.integrators.attached import check_attached_integrator

            check_attached_integrator(steppers[0])
        if getattr(steppers[0], "kind", None) == "position-based":  # nothing to predict: no dt limit
            note = (f"{steppers[0].name} is position-based: its constraint projection is implicit, stable at "
                    "every dt on springs (stiffness then depends on dt and iterations: see the integrators' "
                    "documentation)")
            if args.json:  # the report's row, each limit None (no limit); no mode is computed
                row = dataclasses.asdict(StableStep(steppers[0].name, None, None, None, None))
                row |= {"stable": True, "note": note}
                print(json.dumps({"scene": scene.name, "dt": dt, "integrators": [row]}, indent=2))
            else:
                print(f"{scene.name}: {note}")
            return 0
        if not isinstance(steppers[0], Stepper):
            raise ValueError(f"--integrator {args.integrator}: {steppers[0].name} is not a fixed-step integrator "
                             "(it has no step size to limit)")
    else:
        steppers = [m for m in INTEGRATORS.values() if isinstance(m, Stepper)]
    check_initial_state(scene.model, scene.y0, scene.model.dtype)  # a state no run integrates has no stable dt
    mode, rows = stable_steps(scene.model, scene.y0[0], steppers, scene.rigid_bodies)
    report = {"scene": scene.name, "dt": dt, "omega_max": mode.omega, "damping_ratio": mode.damping_ratio,
              "integrators": [dataclasses.asdict(r) | {"stable": r.stable(dt)} for r in rows]}
    if _coupled(scene):  # springs at body-frame points without collisions: the coupled step's pair
        from steplab.integrators.coupled_stability import grows, pair_growth

        for row, stepper in zip(report["integrators"], steppers):  # every one a Stepper (above)
            row["coupled"] = pair_growth(scene.model, scene.rigid_bodies, stepper, rotation, scene.y0, dt, steps)
            row["stable"] = row["stable"] and not grows(row["coupled"])
    if scene.rigid_bodies is not None:
        report["rotation"] = rotation_limit(rotation, scene.rigid_bodies, dt)
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    if "rotation" in report:
        from steplab.integrators.rotation_stability import ENERGY_GROWTH, OMEGA_DT_GRID, STEPS

        r = report["rotation"]
        grid = f"omega dt from {OMEGA_DT_GRID[0]:g} to {OMEGA_DT_GRID[-1]:g}"
        limit = (f"no limit ({grid})" if r["dt_max"] is None else f"none (grows at every {grid})"
                 if r["dt_max"] == 0 else f"dt_max = {r['dt_max']:.4g} s")
        print(f"{scene.name}: rotation {r['method']}, measured along each spinning body's own spin (stable: energy "
              f"within +{100 * ENERGY_GROWTH:g} % over {STEPS} steps): {limit}; at dt = {dt:g} s "
              f"{'stable' if r['stable'] else 'UNSTABLE'}")
    if mode.omega is None:
        print(f"{scene.name}: no oscillating mode (no springs or other restoring force): the model sets "
              f"no limit on dt = {dt:g} s")
        return 0
    damped = f", damping ratio {mode.damping_ratio:.3g}" if mode.damping_ratio else ", undamped"
    print(f"{scene.name}: stiffest mode omega_max = {mode.omega:.6g} rad/s{damped}; dt = {dt:g} s "
          f"(omega_max dt = {mode.omega * dt:.4g})")
    rows = [(r["integrator"], limit_text(r["omega_dt_max"]), limit_text(r["dt_max"]), limit_text(r["dt_max_damped"]),
             _verdict(dt, r["dt_max_damped"], r.get("coupled"))) for r in report["integrators"]]
    header = ("integrator", "limit omega dt", "dt_max (s)", "damped dt_max (s)", "at this dt")
    if "coupled" in report["integrators"][0]:
        print(f"  with {rotation.name}: on springs at body-frame points a pair that does not compose steps each "
              f"system with the other held; its growth a step is the coupled step's, linearised at the start")
        rows = [row[:4] + (_pair(r["coupled"]),) + row[4:] for row, r in zip(rows, report["integrators"])]
        header = header[:4] + (f"with {rotation.name}",) + header[4:]
    print(table(rows, header, right=(1, 2, 3), indent="  "))
    return 0


def _coupled(scene) -> bool:
    """Whether ``scene`` runs the coupled step (:mod:`steplab.integrators.attached`): springs or dampers at
    body-frame points and no collisions (the contact solver turns those bodies in its own order)."""
    from steplab.physics.attachments import attached_forces

    return scene.collisions is None and scene.rigid_bodies is not None and bool(attached_forces(scene.model))


def _pair(coupled: dict) -> str:
    """The coupled column: "composes", the pair's growth a step, or why there is none."""
    rho = coupled["growth_per_step"]
    return coupled["verdict"] if rho is None else f"x{rho:.6g} a step"


def rotation_limit(method, bodies, dt: float) -> dict:
    """The largest stable dt (s) of the rotation ``method`` on the scene's spinning ``bodies``."""
    from steplab.integrators.rotation_stability import stable_rotation_dt

    dt_max = stable_rotation_dt(method, bodies)
    dt_max = None if dt_max is None else float(dt_max)
    return {"method": method.name, "dt_max": dt_max, "stable": dt_max is None or bool(dt <= dt_max)}


def limit_text(value) -> str:
    """A stability limit: "no limit" (stable at every dt), "none (grows)" (stable at none), or the number."""
    return "no limit" if value is None else "none (grows)" if value == 0 else f"{value:.4g}"


def _verdict(dt: float, dt_max, coupled: dict | None = None) -> str:
    if coupled is not None and coupled["verdict"] == "grows":
        from steplab.integrators.coupled_stability import fold

        return f"UNSTABLE (the pair grows {fold(coupled['log10_growth_over_run'])} over the run)"
    if coupled is not None and coupled["verdict"] == "not finite":
        return "UNSTABLE (the pair's step about the start is not finite)"
    if dt_max is None:
        return "stable (no limit)"
    if dt_max == 0:
        return "UNSTABLE (grows at every dt)"
    return f"{'stable' if dt <= dt_max else 'UNSTABLE'} ({dt / dt_max:.3g} x dt_max)"
