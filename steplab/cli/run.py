"""``steplab run``: simulate a scene, print its summary (or JSON), write its trajectory."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from .args import (
    DETECTORS,
    count,
    json_argument,
    nonempty,
    pathname,
    rotation_argument,
    rotation_named,
    scene_argument,
    solver_arguments,
    time_arguments,
    time_span,
)
from .errors import EXIT_DIVERGED, fail


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="simulate a scene and write its trajectory")
    scene_argument(p)
    p.add_argument("--integrator", type=nonempty, help="integrator name, or package.module:Name (default: the scene's, "
                   "with its [simulation.<integrator>] settings such as xpbd's substeps and iterations)")
    time_arguments(p, steps=True)
    p.add_argument("--backend", choices=("numpy", "jax"), default="numpy",
                   help="numpy: step by step; jax: compiled loop (default: numpy)")
    p.add_argument("--precision", choices=("float64", "float32"), default="float64",
                   help="floating-point precision (default: float64); the adaptive references (scipy-*, diffrax-*) "
                        "solve in float64 and store in it, the contact solver steps in float64 and carries the "
                        "state from step to step in it")
    p.add_argument("--save-every", type=count, default=1, metavar="K",
                   help="keep every K-th state in the trajectory (default: 1)")
    p.add_argument("--max-steps", type=count, default=None, metavar="N",
                   help="refuse runs of more than N steps (default: 10,000,000)")
    p.add_argument("--out", type=pathname, help="write the trajectory to FILE.npz or FILE.csv (and the "
                   "collisions, if any, to FILE.collisions.csv)")
    p.add_argument("--detector", choices=DETECTORS, metavar="NAME",
                   help="collision detection, one of %(choices)s (overlap: overlap testing with bisection; swept: "
                   "intersection testing; default: the scene's [collisions], else none)")
    solver_arguments(p)
    rotation_argument(p)
    json_argument(p, "print the summary as JSON")


def command(args) -> int:
    import numpy as np

    from steplab.integrators.attached import scene_stepper
    from steplab.integrators.run_summary import RunSettings, run_summary, stopped_summary
    from steplab.integrators.scene_rotation import rotation_arrays, run_rotation
    from steplab.integrators.simulate import MAX_STEPS, simulate, step_count
    from steplab.integrators.stable_dt import dt_warning
    from steplab.io import check_trajectory_path, save_trajectory
    from steplab.physics.scene import load_scene

    if args.out is not None:
        check_trajectory_path(args.out)  # before the run, not after it
    scene = load_scene(args.scene)
    integrator = scene_method(scene, args.integrator)
    rotation_method = rotation_named(scene, args)
    dt, t_end = time_span(scene, args)
    world = collision_world(scene, args.detector, args.backend)
    integrator, world = with_sweeps(integrator, world, args)
    if world is not None:  # the solver turns the bodies with the run's rotation method
        world = world.with_rotation(rotation_method.name)
        world.check_solver(integrator)  # its refusals alone, not after a warning about the run
    warning = dt_warning(scene.model, scene.y0[0], integrator, dt, scene.rigid_bodies)  # before the run: it may be long
    if warning is not None:
        print(f"steplab run: warning: {warning}", file=sys.stderr)
    run_warnings = [] if warning is None else [warning]
    end = {"n_steps": args.steps} if args.steps is not None else {"t_end": t_end}
    kept = []  # the run's collision step, whose log tells what happened before a stop (or its attached step)
    energy_start = float(scene.model.energy(scene.y0, scene.rigid_bodies))  # with the spin's 1/2 omega . I omega
    settings = RunSettings(scene, integrator, dt, world, args.precision, energy_start, run_warnings)
    attached = _attached(scene, world)  # forces at body-frame points: the rotation steps with the translation
    if attached and world is None:  # a pair whose stages do not match may grow at any dt
        pair = _pair_warning(scene, integrator, rotation_method, dt, args.steps or step_count(scene.t_start, t_end, dt))
        if pair is not None:
            print(f"steplab run: warning: {pair}", file=sys.stderr)
            run_warnings.append(pair)
    # the collision step (the contact solver turns attached forces' lever arms itself), else the coupled one
    stepper = scene_stepper(scene, kept, world, rotation_method, args.save_every)
    try:
        traj = simulate(scene.model, integrator, scene.y0, scene.t_start, dt=dt, **end, backend=args.backend,
                        dtype=np.dtype(args.precision), save_every=args.save_every,
                        max_steps=args.max_steps or MAX_STEPS, progress=not args.json and sys.stderr.isatty(),
                        stepper=stepper)
    except Exception as err:
        if world is None:
            raise
        from steplab.physics.collision import ImpactCapError  # loaded already: the world made the run

        if not isinstance(err, ImpactCapError):
            raise
        if args.json:  # stopped, never dropped: one line, status 1 (and the record)
            print(json.dumps(stopped_summary(settings, err, kept[0].log if kept else None), indent=2))
        return fail(args.command, str(err), EXIT_DIVERGED)
    # the bodies as the attached step or the contact solver turned them, else free beside the translation
    rotation = run_rotation(scene, traj, kept[0] if kept else None, rotation_method, backend=args.backend)
    if attached:  # the energy at the end with the lever arms at the final orientations
        settings = dataclasses.replace(settings, scene=dataclasses.replace(scene, model=kept[0].final_model()))
    summary = run_summary(settings, traj, rotation)
    if args.out is not None:
        extra = None
        if rotation is not None:
            extra = rotation_arrays(rotation, scene.model.n_bodies)
        save_trajectory(args.out, traj, scene.model, {k: summary[k] for k in (
            "scene", "integrator", "dt", "steps", "t_start", "t_end", "backend", "precision", "detector",
            "collisions", "rotation") if k in summary}, extra)
        summary["out"] = str(args.out)
        if traj.collisions is not None:
            from steplab.core.records import write_atomic

            path = args.out.with_name(args.out.stem + ".collisions.csv")
            write_atomic(path, traj.collisions.to_csv().encode())
            summary["collisions_out"] = str(path)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_summary(summary)
    return 0


def scene_method(scene, name: str | None = None):
    """The integrator a run of ``scene`` uses, for every command that runs or judges one: ``name``
    (--integrator) with its own defaults, or the scene's integrator with its [simulation.<integrator>]
    settings, checked by ``integrators.settings.scene_integrator`` (an unknown key or a value the
    method refuses is one line, status 2)."""
    from steplab.integrators.settings import scene_integrator

    name = name or scene.integrator
    if name != scene.integrator:
        return integrator_named(name)
    importable = _importable(name)
    if importable != name:  # path/file.py:Name: the module it names, with the scene's settings
        scene = dataclasses.replace(scene, integrator=importable)
    return scene_integrator(scene)


def integrator_named(name: str):
    """The integrator ``name`` (see ``get_integrator``); ``path/file.py:Name`` is the module
    ``file``, imported from the file's folder, as the natural spelling of a file of one's own."""
    from steplab.integrators import get_integrator

    return get_integrator(_importable(name))


def _importable(name: str) -> str:
    """``name``, or for ``path/file.py:Name`` the spelling ``file:Name`` with the file's folder on sys.path."""
    from steplab.integrators import UnknownIntegratorError

    module, colon, attribute = name.partition(":")
    if colon and module.endswith(".py"):
        path = Path(module)
        if not path.is_file():
            raise UnknownIntegratorError(f"integrator {name!r}: no file {module} here; name a module as "
                                         f"package.module:Name, without .py")
        if str(path.resolve().parent) not in sys.path:
            sys.path.append(str(path.resolve().parent))
        name = f"{path.stem}:{attribute}"
    return name


def _pair_warning(scene, integrator, rotation, dt: float, steps: int) -> str | None:
    """:func:`steplab.integrators.coupled_stability.pair_warning` of the run's coupled step, for a
    fixed-step integrator (the coupled step refuses any other, in one line)."""
    from steplab.integrators import Stepper
    from steplab.integrators.coupled_stability import pair_warning

    if not isinstance(integrator, Stepper):
        return None
    return pair_warning(scene.model, scene.rigid_bodies, integrator, rotation, scene.y0, dt, steps)


def _attached(scene, world) -> bool:
    """Whether ``scene`` has springs or dampers at body-frame points (offsets).

    Without collisions (``world`` None) the coupled step runs them (``integrators.attached``); with
    collisions only the contact solver on rigid bodies does (world.method "solver" with
    ``world.rigid``: :mod:`steplab.physics.collision.rigid_solver_step` turns their lever arms at each
    substep), and the caller steps with ``world.stepper``. The event loop and the sphere solver would
    keep the lever arms where they started: refused in one line.
    """
    from steplab.physics.attachments import attached_forces

    if not attached_forces(scene.model):
        return False
    if world is not None:
        world.check_attachments(scene.model)
    return True


def with_sweeps(integrator, world, args):
    """``(integrator, world)`` with --iterations and --substeps applied, and --method.

    The two flags set the integrator's own ``substeps`` / ``iterations`` when it has them (the
    position-based methods), else the contact solver's; a run that has both is ambiguous.
    """
    from steplab.integrators import INTEGRATORS
    from steplab.integrators.settings import configured

    sweeps = {k: getattr(args, k) for k in ("substeps", "iterations") if getattr(args, k)}
    fields = {f.name for f in dataclasses.fields(integrator)} if dataclasses.is_dataclass(integrator) else set()
    if not sweeps or not fields & {"substeps", "iterations"}:
        if sweeps and world is None:
            takers = ", ".join(n for n, m in INTEGRATORS.items() if getattr(m, "kind", None) == "position-based")
            raise ValueError(f"--iterations and --substeps set a position-based integrator's sweeps ({takers}) or "
                             f"the contact solver (a scene with collisions, --method solver); {integrator.name} "
                             "has no such setting")
        return integrator, with_method(world, args)
    if world is not None and (args.method or world.method) == "solver":
        raise ValueError(f"--iterations and --substeps: both {integrator.name} and the contact solver have them; "
                         f"set one of the two in the scene ([simulation.{integrator.name}] or [collisions.solver])")
    flags = " and ".join(f"--{k}" for k in sweeps)
    rest = argparse.Namespace(**(vars(args) | {"iterations": None, "substeps": None}))  # the integrator's
    return configured(integrator, sweeps, flags), with_method(world, rest)


def with_method(world, args):
    """``world`` with the run's --method, --iterations and --substeps applied."""
    if world is None:
        if args.method or args.iterations or args.substeps:
            raise ValueError("--method, --iterations and --substeps need a scene with collisions (or --detector)")
        return None
    method = args.method or world.method
    if method != "solver" and (args.iterations or args.substeps):
        raise ValueError("--iterations and --substeps set the contact solver: add --method solver")
    changes = {k: getattr(args, k) for k in ("iterations", "substeps") if getattr(args, k)}
    return dataclasses.replace(world, method=method, solver=dataclasses.replace(world.solver, **changes))


def collision_world(scene, detector, backend):
    """The scene's collision world with ``detector`` (None: the scene's) applied, or None for no collisions."""
    world = scene.collisions
    if detector is not None:
        if world is None and detector != "none":
            from steplab.physics.collision import CollisionWorld

            world = CollisionWorld(detector=detector)  # bodies against each other, eps = 1
        elif world is not None:
            world = world.with_detector(detector)
    if world is None or world.detector == "none":
        return None
    if backend != "numpy":
        raise ValueError(f"scene {scene.name!r} has collisions ({world.detector} detector), which run on the "
                         f"NumPy backend only; use --backend numpy, or --detector none")
    return world


def print_summary(s: dict) -> None:
    steps = plural(s["steps"], "step") if s["steps"] else "reference solve"
    print(f"{s['scene']}: {s['integrator']}, dt = {s['dt']:g} s, {steps}, "
          f"t = {s['t_start']:g} -> {s['t_end']:g} s ({s['backend']}, {s['precision']})")
    shown = list(zip(s["bodies"], s["final_positions"], s["final_velocities"]))
    print(f"  {'body':<14} {'position (m)':>36}   {'velocity (m/s)':>36}")
    for name, p, v in shown[:8]:
        print(f"  {name:<14} {_vec(p):>36}   {_vec(v):>36}")
    if len(shown) > 8:
        print(f"  ... and {len(shown) - 8} more bodies")
    change = s["energy_change"]
    rel = f" ({100 * change / abs(s['energy_start']):+.3g} %)" if s["energy_start"] else ""
    if s.get("rotating_bodies"):
        _print_rotation(s)
    print(f"  energy: {s['energy_start']:.6g} J -> {s['energy_end']:.6g} J, change {change:+.4g} J{rel}")
    if s.get("collisions") is not None:
        c = s["collisions"]
        extra = "".join(f", {c[k]} {label}" for k, label in (("triggers", "trigger entries"),
                                                            ("cancelled", "cancelled")) if c[k])
        if s.get("method") == "solver":
            from steplab.physics.collision.solver_settings import ContactSolver

            print(f"  collisions (contact solver, {ContactSolver(**s['solver']).describe()}): "
                  f"{plural(c['impacts'], 'impact')}{extra}, at most {c['most_impacts_in_a_step']} in one step")
            print(f"  largest residual: {c['largest_residual']:.3g} m/s (the worst contact's complementarity "
                  "residual after a step's last sweep: 0 when converged, lowered by --iterations; a large one "
                  "costs energy at the contacts, not penetration)")
        else:
            # the most resolved in one step counts impacts and resting-contact corrections together
            print(f"  collisions ({s['detector']}): {plural(c['impacts'], 'impact')}{extra}, "
                  f"{plural(c['resting_corrections'], 'resting-contact correction')}, "
                  f"at most {c['most_impacts_in_a_step']} of them in one step")
    print(f"  wall time: {s['wall_time'] * 1e3:.3g} ms")
    if "out" in s:
        print(f"  trajectory written to {s['out']}")
    if "collisions_out" in s:
        print(f"  collisions written to {s['collisions_out']}")


def _print_rotation(s: dict) -> None:
    """The rotating bodies' final orientation and spin, and the angular momentum at both ends."""
    rotating = [row for row in zip(s["bodies"], s["final_orientations"], s["final_angular_velocities"])
                if row[0] in s["rotating_bodies"]]
    print(f"  rotation: {s['rotation']}")
    print(f"  {'body':<14} {'orientation [w, x, y, z]':>48}   {'angular velocity (rad/s, world)':>36}")
    for name, q, w in rotating[:8]:
        print(f"  {name:<14} {_vec(q):>48}   {_vec(w):>36}")
    if len(rotating) > 8:
        print(f"  ... and {len(rotating) - 8} more rotating bodies")
    about = "about the centre of mass" if len(s["bodies"]) == 1 else "total, about the origin"
    print(f"  angular momentum ({about}): {_vec(s['angular_momentum_start'])} -> "
          f"{_vec(s['angular_momentum_end'])} kg m^2/s")


def plural(n: int, noun: str) -> str:
    """``1 impact``, ``2 impacts``, ``0 impacts``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:10.5g}" for x in v) + ")"
