"""``steplab check``: the largest stable dt of each fixed-step integrator on a scene, from its stiffest mode."""

from __future__ import annotations

import dataclasses
import json

from .args import json_argument, positive, scene_argument
from .table import table


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="predict the largest stable dt of each fixed-step integrator on a scene")
    scene_argument(p)
    p.add_argument("--integrator", help="only this integrator (default: every fixed-step one)")
    p.add_argument("--dt", type=positive, help="the dt to check, s (default: the scene's)")
    json_argument(p)


def command(args) -> int:
    from steplab.integrators import INTEGRATORS, Stepper
    from steplab.integrators.stable_dt import stable_steps
    from steplab.physics.scene import load_scene

    from .run import integrator_named

    scene = load_scene(args.scene)
    if args.integrator is not None:
        steppers = [integrator_named(args.integrator)]
        if not isinstance(steppers[0], Stepper):
            raise ValueError(f"--integrator {args.integrator}: {steppers[0].name} is not a fixed-step integrator "
                             "(it has no step size to limit)")
    else:
        steppers = [m for m in INTEGRATORS.values() if isinstance(m, Stepper)]
    dt = args.dt if args.dt is not None else scene.dt
    mode, rows = stable_steps(scene.model, scene.y0[0], steppers)
    report = {"scene": scene.name, "dt": dt, "omega_max": mode.omega, "damping_ratio": mode.damping_ratio,
              "integrators": [dataclasses.asdict(r) | {"stable": r.stable(dt)} for r in rows]}
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
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


def _limit(value) -> str:
    """A stability limit: "no limit" (stable at every dt), "none (grows)" (stable at none), or the number."""
    return "no limit" if value is None else "none (grows)" if value == 0 else f"{value:.4g}"


def _verdict(dt: float, dt_max) -> str:
    if dt_max is None:
        return "stable (no limit)"
    if dt_max == 0:
        return "UNSTABLE (grows at every dt)"
    return f"{'stable' if dt <= dt_max else 'UNSTABLE'} ({dt / dt_max:.3g} x dt_max)"
