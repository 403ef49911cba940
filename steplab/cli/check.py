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
    p = sub.add_parser(name, help="predict the largest stable dt of each fixed-step integrator on a scene")
    scene_argument(p)
    p.add_argument("--integrator", type=nonempty, help="only this integrator (default: every fixed-step one)")
    p.add_argument("--dt", type=positive, help="the dt to check, s (default: the scene's)")
    rotation_argument(p)
    json_argument(p)


def command(args) -> int:
    from steplab.integrators import INTEGRATORS, Stepper
    from steplab.integrators.stable_dt import stable_steps
    from steplab.physics.scene import load_scene

    from .run import integrator_named, scene_method

    scene = load_scene(args.scene)
    scene_method(scene)  # the scene's [simulation.<integrator>] table, refused as run refuses it
    rotation = rotation_named(scene, args)
    # the dts run refuses: longer than the run, too small to advance time, more steps than a float counts
    dt, t_end = time_span(scene, args)
    run_steps(scene, dt, t_end)
    if args.integrator is not None:
        steppers = [integrator_named(args.integrator)]
        if getattr(steppers[0], "kind", None) == "position-based":  # nothing to predict: no dt limit
            print(f"{scene.name}: {steppers[0].name} is position-based: its constraint projection is implicit, "
                  "stable at every dt on springs (stiffness then depends on dt and iterations: see the "
                  "integrators' documentation)")
            return 0
        if not isinstance(steppers[0], Stepper):
            raise ValueError(f"--integrator {args.integrator}: {steppers[0].name} is not a fixed-step integrator "
                             "(it has no step size to limit)")
    else:
        steppers = [m for m in INTEGRATORS.values() if isinstance(m, Stepper)]
    mode, rows = stable_steps(scene.model, scene.y0[0], steppers, scene.rigid_bodies)
    report = {"scene": scene.name, "dt": dt, "omega_max": mode.omega, "damping_ratio": mode.damping_ratio,
              "integrators": [dataclasses.asdict(r) | {"stable": r.stable(dt)} for r in rows]}
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
    print(table([(r["integrator"], _limit(r["omega_dt_max"]), _limit(r["dt_max"]), _limit(r["dt_max_damped"]),
                  _verdict(dt, r["dt_max_damped"])) for r in report["integrators"]],
                ("integrator", "limit omega dt", "dt_max (s)", "damped dt_max (s)", "at this dt"),
                right=(1, 2, 3), indent="  "))
    return 0


def rotation_limit(method, bodies, dt: float) -> dict:
    """The largest stable dt (s) of the rotation ``method`` on the scene's spinning ``bodies``."""
    from steplab.integrators.rotation_stability import stable_rotation_dt

    dt_max = stable_rotation_dt(method, bodies)
    dt_max = None if dt_max is None else float(dt_max)
    return {"method": method.name, "dt_max": dt_max, "stable": dt_max is None or bool(dt <= dt_max)}


def _limit(value) -> str:
    """A stability limit: "no limit" (stable at every dt), "none (grows)" (stable at none), or the number."""
    return "no limit" if value is None else "none (grows)" if value == 0 else f"{value:.4g}"


def _verdict(dt: float, dt_max) -> str:
    if dt_max is None:
        return "stable (no limit)"
    if dt_max == 0:
        return "UNSTABLE (grows at every dt)"
    return f"{'stable' if dt <= dt_max else 'UNSTABLE'} ({dt / dt_max:.3g} x dt_max)"
