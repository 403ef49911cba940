"""The ``steplab`` command line.

Bad input (an unknown integrator, a malformed scene, a non-positive dt...) ends with
one line on stderr and exit status 2; a simulation that diverges, or whose step holds
more impacts than the cap, and a ``recommend`` that finds nothing meeting the tolerance
end with one line and status 1. Never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import warnings
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 1
#: 128 + SIGINT, what a shell reports for a Ctrl-C
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (usage stays in --help)."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _positive(text: str) -> float:
    value = _finite(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from steplab.physics.collision.detectors import DETECTOR_NAMES
    from steplab.physics.collision.methods import COLLISION_METHODS

    parser = _Parser(prog="steplab", description="How wrong, how unstable and how slow is a "
                     "game-physics step? Integrators, scenes and studies.")
    parser.add_argument("--version", action="version", version=f"steplab {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("integrators", help="list the integrators with their properties")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")

    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")

    p = sub.add_parser("run", help="simulate a scene and write its trajectory")
    p.add_argument("scene", help="built-in scene name (see `steplab scenes`) or path to a TOML file")
    p.add_argument("--integrator", help="integrator name (default: the scene's)")
    p.add_argument("--dt", type=_positive, help="time step, s (default: the scene's)")
    ends = p.add_mutually_exclusive_group()
    ends.add_argument("--t-end", type=_finite, help="end time, s (default: the scene's)")
    ends.add_argument("--steps", type=_count, metavar="N", help="run exactly N steps of dt instead of to --t-end")
    p.add_argument("--backend", choices=("numpy", "jax"), default="numpy",
                   help="numpy: step by step; jax: compiled loop (default: numpy)")
    p.add_argument("--precision", choices=("float64", "float32"), default="float64",
                   help="floating-point precision (default: float64)")
    p.add_argument("--save-every", type=_count, default=1, metavar="K",
                   help="keep every K-th state in the trajectory (default: 1)")
    p.add_argument("--max-steps", type=_count, default=None, metavar="N",
                   help="refuse runs of more than N steps (default: 10,000,000)")
    p.add_argument("--out", type=Path, help="write the trajectory to FILE.npz or FILE.csv (and the "
                   "collisions, if any, to FILE.collisions.csv)")
    p.add_argument("--detector", choices=DETECTOR_NAMES,
                   help="collision detection (overlap: overlap testing with bisection; swept: intersection "
                   "testing; default: the scene's [collisions], else none)")
    p.add_argument("--method", choices=tuple(COLLISION_METHODS),
                   help="collision handling (event: the lecture's event loop, each impact at its time; "
                   "solver: the engines' contact solver; default: the scene's)")
    p.add_argument("--iterations", type=_count, metavar="N",
                   help="contact solver: sweeps per substep (default: the scene's, else 1, Box2D v3's)")
    p.add_argument("--substeps", type=_count, metavar="N",
                   help="contact solver: substeps per step (default: the scene's, else 4)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")

    p = sub.add_parser("check", help="predict the largest stable dt of each fixed-step integrator on a scene")
    p.add_argument("scene", help="built-in scene name or path to a TOML file")
    p.add_argument("--integrator", help="only this integrator (default: every fixed-step one)")
    p.add_argument("--dt", type=_positive, help="the dt to check, s (default: the scene's)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")

    p = sub.add_parser("animate", help="render a simulation as an animation (GIF or MP4), alone or side by side")
    p.add_argument("scene", help="built-in scene name or path to a TOML file")
    p.add_argument("--integrator", help="integrator name (default: the scene's)")
    p.add_argument("--compare", metavar="A,B",
                   help="side by side: integrators (euler,velocity-verlet) or detectors (overlap,swept)")
    p.add_argument("--detector", choices=DETECTOR_NAMES, help="collision detector (default: the scene's)")
    p.add_argument("--dt", type=_positive, help="time step, s (default: the scene's)")
    p.add_argument("--t-end", type=_finite, help="end time, s (default: the scene's)")
    p.add_argument("--fps", type=_count, default=30, help="frames per second (default: 30)")
    p.add_argument("--view", choices=("xy", "xz", "yz"), help="plane shown (default: the two axes moved along most)")
    p.add_argument("--out", type=Path, required=True, help="FILE.gif or FILE.mp4 (MP4 through imageio-ffmpeg's ffmpeg)")

    p = sub.add_parser("paper", help="regenerate paper/paper.md, its figures and HTML from study results")
    p.add_argument("--results", type=Path, default=Path("results"), help="results folder (default: results/)")
    p.add_argument("--paper-dir", type=Path, default=Path("paper"), help="paper folder (default: paper/)")
    p.add_argument("--no-tutorial", action="store_true", help="do not re-run the tutorial's code blocks")
    p.add_argument("--pdf", action="store_true", help="also print the HTML to PDF (needs Debian's chromium)")

    p = sub.add_parser("report", help="write a static HTML site of the results: index, studies, errata, bench")
    p.add_argument("--results", type=Path, default=Path("results"), help="results folder (default: results/)")
    p.add_argument("--out", type=Path, required=True, help="site folder (serve with python -m http.server -d DIR)")

    p = sub.add_parser("recommend", help="the cheapest integrator and dt that meet an error tolerance")
    p.add_argument("scene", help="built-in scene name or path to a TOML file")
    p.add_argument("--tol", type=_positive, required=True, help="largest final position error, m (with "
                   "collisions: largest position error over the run)")
    p.add_argument("--t-end", type=_finite, help="end time, s (default: the scene's)")
    p.add_argument("--dt-max", type=_positive, metavar="DT",
                   help="largest dt to consider, s, e.g. a frame, 1/60 (default: a quarter of the run)")
    p.add_argument("--integrators", metavar="A,B", help="candidates (default: every fixed-step integrator)")
    p.add_argument("--detector", choices=DETECTOR_NAMES,
                   help="collision detector to measure with (default: the scene's; none: without collisions)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")

    p = sub.add_parser("study", help="run one study (see --list)")
    p.add_argument("name", nargs="?", help="study name")
    p.add_argument("--list", action="store_true", help="list the studies")
    _study_options(p)

    p = sub.add_parser("reproduce", help="run every study and write the results")
    _study_options(p)

    p = sub.add_parser("export", help="write a scene as another engine's model file (MJCF for MuJoCo)")
    p.add_argument("scene", help="built-in scene name or path to a TOML file")
    p.add_argument("--to", choices=("mjcf",), required=True, help="the format: mjcf (MuJoCo's XML)")
    p.add_argument("--integrator", choices=("Euler", "RK4", "implicit", "implicitfast", "discrete"),
                   help="MuJoCo's integrator (default: the one that equals the scene's, else Euler)")
    p.add_argument("--out", type=Path, help="write to FILE (default: print the file)")

    p = sub.add_parser("bench", help="time steplab against diffrax, scipy, Numba and the memory bound")
    p.add_argument("--quick", action="store_true", help="fewer repeats and batches (under about a minute)")
    p.add_argument("--json", type=Path, metavar="FILE", help="write every ratio and the medians behind it to FILE")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown (the README's)")
    p.add_argument("--from", dest="source", type=Path, metavar="FILE",
                   help="print the table of a record written by --json instead of running")
    return parser


def _study_options(p) -> None:
    p.add_argument("--quick", action="store_true", help="a short version (under a minute, for CI)")
    p.add_argument("--out", type=Path, default=Path("results"), help="results folder (default: results/)")
    p.add_argument("--force", action="store_true", help="re-run even if the cached result is current")
    where = p.add_mutually_exclusive_group()  # on a Dask cluster (studies/distributed.py); default: this process
    where.add_argument("--workers", type=_count, metavar="N", help="run the sweeps' tasks on a local Dask cluster "
                       "of N worker processes (timing studies run alone afterwards)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="run them on the Dask cluster whose scheduler is "
                       "at ADDRESS (e.g. tcp://host:8786; see the README)")


def main(argv=None) -> int:
    # a name that is not UTF-8 (a surrogate escape from argv) prints escaped, never crashes
    if callable(getattr(sys.stdout, "reconfigure", None)):
        sys.stdout.reconfigure(errors="backslashreplace")
    command = None
    try:  # Ctrl-C anywhere from here on ends with one line and status 130, never a traceback
        args = build_parser().parse_args(argv)
        command = args.command
        import numpy as np

        from steplab.core.registry import PluginWarning

        # runs detect non-finite states themselves: no floating-point warnings on stderr;
        # a skipped plugin is one warning line, not a warning with its source line
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.showwarning = _show_warning
            warnings.simplefilter("default", PluginWarning)
            return _run_command(args)
    except KeyboardInterrupt:
        return _fail(command, "interrupted", EXIT_INTERRUPTED)


def _run_command(args) -> int:
    from steplab.integrators import UnknownIntegratorError
    from steplab.integrators.exact import NotConstantForceError
    from steplab.integrators.references import ReferenceFailedError
    from steplab.integrators.simulate import DivergenceError
    from steplab.paper import PaperError
    from steplab.physics.collision import ImpactCapError
    from steplab.physics.scene import SceneError
    from steplab.studies.recommend import NoFixedStepError

    # `--integrator package.module:Name` finds a module of the current folder, as `python -m`
    # would; appended, never first, so a folder there never shadows an installed package
    if str(Path.cwd()) not in sys.path:
        sys.path.append(str(Path.cwd()))
    command = {"integrators": cmd_integrators, "scenes": cmd_scenes, "run": cmd_run, "check": cmd_check,
               "animate": cmd_animate, "paper": cmd_paper, "recommend": cmd_recommend, "study": cmd_study,
               "reproduce": cmd_reproduce, "bench": cmd_bench, "report": cmd_report,
               "export": cmd_export}[args.command]
    try:
        return command(args) or 0
    except (SceneError, UnknownIntegratorError, NotConstantForceError, PaperError, ValueError) as err:
        return _fail(args.command, str(err), EXIT_BAD_INPUT)
    # FloatingPointError: the contact solver's state became non-finite inside a step
    except (DivergenceError, ReferenceFailedError, NoFixedStepError, ImpactCapError, FloatingPointError) as err:
        return _fail(args.command, str(err), EXIT_DIVERGED)
    except OSError as err:  # an unwritable --out or results folder, a full disk
        where = f"{err.filename}: " if err.filename else ""
        return _fail(args.command, f"{where}{err.strerror or err}", EXIT_BAD_INPUT)
    except MemoryError:
        return _fail(args.command, "out of memory (try a smaller scene, a shorter run or --save-every)",
                     EXIT_BAD_INPUT)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """A plugin warning as one line on stderr; any other warning as Python prints it."""
    from steplab.core.registry import PluginWarning

    if issubclass(category, PluginWarning):
        print(f"steplab: warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _fail(command: str | None, message: str, status: int) -> int:
    """Print one line (a message's own line breaks escaped) and return ``status``."""
    message = str(message).replace("\r", "\\r").replace("\n", "\\n")
    print(f"steplab {command}: error: {message}" if command else f"steplab: error: {message}", file=sys.stderr)
    return status


def _version() -> str:
    import steplab

    return steplab.__version__


# --- integrators / scenes -------------------------------------------------------------


def cmd_integrators(args) -> int:
    from steplab.integrators import INTEGRATORS

    # where each comes from: "steplab", or the plugin's distribution and entry point
    rows = [method.describe() | {"source": INTEGRATORS.origin(name)} for name, method in INTEGRATORS.items()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'name':<20} {'kind':<11} {'order':>5} {'evals/step':>10}  {'symplectic':<10} {'implicit':<8} "
          "description")
    for r in rows:
        order = "-" if r["order"] is None else str(r["order"])
        evals = "adaptive" if r["evaluations_per_step"] is None else str(r["evaluations_per_step"])
        if r["implicit"] and r["kind"] == "fixed-step":
            evals += "/iter"
        print(f"{r['name']:<20} {r['kind']:<11} {order:>5} {evals:>10}  {_yes(r['symplectic']):<10} "
              f"{_yes(r['implicit']):<8} {r['description']}"
              + ("" if r["source"] == "steplab" else f" [plugin: {r['source']}]"))
    return 0


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def cmd_scenes(args) -> int:
    from steplab.physics.scene import builtin_scenes, load_scene

    rows = []
    for name in builtin_scenes():
        scene = load_scene(name)
        rows.append({"name": name, "bodies": scene.model.n_bodies,
                     "forces": [f.name for f in scene.model.forces], "integrator": scene.integrator,
                     "dt": scene.dt, "t_start": scene.t_start, "t_end": scene.t_end,
                     "description": scene.description})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        print(f"{r['name']:<16} {r['bodies']:>4} bodies  {', '.join(r['forces']) or 'no forces':<24} "
              f"{r['description']}")
    return 0


# --- run ------------------------------------------------------------------------------


def cmd_run(args) -> int:
    import numpy as np

    from steplab.integrators import get_integrator, simulate
    from steplab.integrators.simulate import MAX_STEPS
    from steplab.integrators.stable_dt import dt_warning
    from steplab.io import check_trajectory_path, save_trajectory
    from steplab.physics.collision import ImpactCapError
    from steplab.physics.scene import load_scene

    if args.out is not None:
        check_trajectory_path(args.out)  # before the run, not after it
    scene = load_scene(args.scene)
    integrator = get_integrator(args.integrator or scene.integrator)
    dt = args.dt if args.dt is not None else scene.dt
    t_end = args.t_end if args.t_end is not None else scene.t_end
    if not t_end > scene.t_start:
        raise ValueError(f"--t-end {t_end:g} must be later than the scene's t_start = {scene.t_start:g}")
    dtype = np.dtype(args.precision)
    world = _with_method(_collision_world(scene, args.detector, args.backend), args)
    warning = dt_warning(scene.model, scene.y0[0], integrator, dt)  # before the run: it may be long
    if warning is not None:
        print(f"steplab run: warning: {warning}", file=sys.stderr)
    run_warnings = [] if warning is None else [warning]
    end = {"n_steps": args.steps} if args.steps is not None else {"t_end": t_end}
    kept = []  # the run's collision step, whose log tells what happened before a stop
    energy_start = float(scene.model.energy(scene.y0))
    try:
        traj = simulate(scene.model, integrator, scene.y0, scene.t_start, dt=dt, **end, backend=args.backend,
                        dtype=dtype, save_every=args.save_every, max_steps=args.max_steps or MAX_STEPS,
                        progress=not args.json and sys.stderr.isatty(),
                        stepper=None if world is None else _keeping(world.stepper, kept))
    except ImpactCapError as err:  # stopped, never dropped: one line, status 1 (and the record)
        if args.json:
            log = kept[0].log if kept else None
            print(json.dumps({"scene": scene.name, "integrator": integrator.name, "dt": dt,
                              "detector": world.detector, "error": str(err), "stopped_at": err.t,
                              "warnings": run_warnings + [str(err)], "energy_start": energy_start,
                              "collisions": log.summary() if log is not None else None}, indent=2))
        return _fail(args.command, str(err), EXIT_DIVERGED)
    energy_end = float(scene.model.energy(traj.y[-1].astype(float)))
    collisions = traj.collisions.summary() if traj.collisions is not None else None
    summary = {
        "scene": scene.name, "integrator": integrator.name, "dt": dt, "steps": traj.steps,
        "t_start": scene.t_start, "t_end": float(traj.t[-1]), "backend": traj.backend,
        "precision": args.precision, "bodies": list(scene.model.names),
        "final_positions": traj.positions[-1].tolist(), "final_velocities": traj.velocities[-1].tolist(),
        "energy_start": energy_start, "energy_end": energy_end,
        "energy_change": energy_end - energy_start,
        "energy_relative_change": (energy_end - energy_start) / abs(energy_start) if energy_start else None,
        "wall_time": traj.wall_time, "detector": world.detector if world is not None else "none",
        "method": world.method if world is not None else None,
        "solver": dataclasses.asdict(world.solver) if world is not None and world.method == "solver" else None,
        "collisions": collisions, "warnings": run_warnings,
    }
    if args.out is not None:
        save_trajectory(args.out, traj, scene.model, {k: summary[k] for k in (
            "scene", "integrator", "dt", "steps", "t_start", "t_end", "backend", "precision", "detector",
            "collisions")})
        summary["out"] = str(args.out)
        if traj.collisions is not None:
            from steplab.core.records import write_atomic

            path = args.out.with_name(args.out.stem + ".collisions.csv")
            write_atomic(path, traj.collisions.to_csv().encode())
            summary["collisions_out"] = str(path)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_run(summary)
    return 0


def _keeping(make_step, kept: list):
    """``make_step`` (a stepper factory for ``simulate``) that also appends the step it builds to ``kept``."""
    def stepper(model, integrator):
        step = make_step(model, integrator)
        kept.append(step)
        return step

    return stepper


def _with_method(world, args):
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


def _collision_world(scene, detector, backend):
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


def _print_run(s: dict) -> None:
    steps = f"{s['steps']} step{'s' if s['steps'] != 1 else ''}" if s["steps"] else "reference solve"
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
    print(f"  energy: {s['energy_start']:.6g} J -> {s['energy_end']:.6g} J, change {change:+.4g} J{rel}")
    if s.get("collisions") is not None:
        c = s["collisions"]
        extra = "".join(f", {c[k]} {label}" for k, label in (("triggers", "trigger entries"),
                                                            ("cancelled", "cancelled")) if c[k])
        if s.get("method") == "solver":
            from steplab.physics.collision.solver_settings import ContactSolver

            print(f"  collisions (contact solver, {ContactSolver(**s['solver']).describe()}): "
                  f"{_plural(c['impacts'], 'impact')}{extra}, at most {c['most_impacts_in_a_step']} in one step, "
                  f"largest residual {c['largest_residual']:.3g} m/s")
        else:
            # the most resolved in one step counts impacts and resting-contact corrections together
            print(f"  collisions ({s['detector']}): {_plural(c['impacts'], 'impact')}{extra}, "
                  f"{_plural(c['resting_corrections'], 'resting-contact correction')}, "
                  f"at most {c['most_impacts_in_a_step']} of them in one step")
    print(f"  wall time: {s['wall_time'] * 1e3:.3g} ms")
    if "out" in s:
        print(f"  trajectory written to {s['out']}")
    if "collisions_out" in s:
        print(f"  collisions written to {s['collisions_out']}")


def _plural(n: int, noun: str) -> str:
    """``1 impact``, ``2 impacts``, ``0 impacts``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:10.5g}" for x in v) + ")"


# --- check --------------------------------------------------------------------------


def cmd_check(args) -> int:
    from steplab.integrators import INTEGRATORS, Stepper, get_integrator
    from steplab.integrators.stable_dt import stable_steps
    from steplab.physics.scene import load_scene

    scene = load_scene(args.scene)
    if args.integrator is not None:
        steppers = [get_integrator(args.integrator)]
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
    print(f"  {'integrator':<20} {'limit omega dt':>14} {'dt_max (s)':>11} {'damped dt_max':>13}  dt")
    for r in report["integrators"]:
        limit = "none" if r["omega_dt_max"] is None else f"{r['omega_dt_max']:.4g}"
        print(f"  {r['integrator']:<20} {limit:>14} {_seconds(r['dt_max']):>11} "
              f"{_seconds(r['dt_max_damped']):>13}  {_verdict(dt, r['dt_max_damped'])}")
    return 0


def _seconds(dt_max) -> str:
    return "none" if dt_max is None else "0 (any dt)" if dt_max == 0 else f"{dt_max:.4g}"


def _verdict(dt: float, dt_max) -> str:
    if dt_max is None:
        return "stable (no limit)"
    if dt_max == 0:
        return "grows at every dt"
    return f"{'stable' if dt <= dt_max else 'UNSTABLE'} ({dt / dt_max:.3g} x dt_max)"


# --- animate ------------------------------------------------------------------------


def cmd_animate(args) -> int:
    from steplab.animate import animate, check_format
    from steplab.integrators import get_integrator, simulate
    from steplab.physics.collision import DETECTOR_NAMES
    from steplab.physics.scene import load_scene

    check_format(args.out)  # before the runs: a format that cannot be written is one line, status 2
    scene = load_scene(args.scene)
    dt = args.dt if args.dt is not None else scene.dt
    t_end = args.t_end if args.t_end is not None else scene.t_end
    if not t_end > scene.t_start:
        raise ValueError(f"--t-end {t_end:g} must be later than the scene's t_start = {scene.t_start:g}")
    # each panel: (integrator, detector); --compare varies one of them
    panels = [(args.integrator or scene.integrator, args.detector)]
    if args.compare:
        names = [n.strip() for n in args.compare.split(",")]
        if len(names) < 2:
            raise ValueError(f"--compare needs at least two comma-separated integrators or detectors, "
                             f"got {args.compare!r}")
        if all(n in DETECTOR_NAMES for n in names):
            panels = [(panels[0][0], n) for n in names]
        else:
            panels = [(n, args.detector) for n in names]
    steps = int((t_end - scene.t_start) / dt)
    runs = []
    for name, detector in panels:
        method = get_integrator(name)
        world = _collision_world(scene, detector, "numpy")
        traj = simulate(scene.model, method, scene.y0, scene.t_start, t_end, dt,
                        save_every=max(1, steps // 300), collisions=world)
        label = f"{scene.name}: {method.name}, dt = {dt:g} s"
        if world is not None or detector is not None:
            label += (", contact solver" if world is not None and world.method == "solver"
                      else f", {world.detector if world is not None else 'no'} detector")
        runs.append((label, traj))
    shapes = scene.collisions.shapes if scene.collisions is not None else ()
    path = animate(runs, scene.model, args.out, fps=args.fps, view=args.view, shapes=shapes)
    print(f"animation written to {path} ({'; '.join(label for label, _ in runs)})")
    return 0


# --- paper --------------------------------------------------------------------------


def cmd_paper(args) -> int:
    from steplab.paper import build

    if not (args.paper_dir / "paper.template.md").exists():
        raise ValueError(f"--paper-dir {args.paper_dir}: no paper.template.md there (run from the repository root)")
    for path in build(args.results, args.paper_dir, tutorial=not args.no_tutorial, pdf=args.pdf):
        print(f"wrote {path}")
    return 0


def cmd_report(args) -> int:
    from steplab.report import build, main_summary

    print(main_summary(build(args.results, args.out)))
    return 0


# --- recommend ----------------------------------------------------------------------


def cmd_recommend(args) -> int:
    import numpy as np

    from steplab.physics.scene import load_scene
    from steplab.studies.problems import Problem
    from steplab.studies.recommend import recommend

    scene = load_scene(args.scene)
    t_end = args.t_end if args.t_end is not None else scene.t_end
    if not t_end > scene.t_start:
        raise ValueError(f"--t-end {t_end:g} must be later than the scene's t_start = {scene.t_start:g}")
    integrators = None
    if args.integrators is not None:
        from steplab.studies.recommend_collisions import check_integrators

        integrators = check_integrators(n.strip() for n in args.integrators.split(","))
        if not integrators:
            raise ValueError("--integrators: give at least one fixed-step integrator")
    world = _collision_world(scene, args.detector, "numpy")
    if world is not None:
        return _recommend_with_collisions(args, scene, t_end, world, integrators)
    problem = Problem(scene.name, scene.description, scene.model, scene.y0, scene.t_start, t_end)
    if scene.model.constant_acceleration is not None:  # the closed form is the truth
        from steplab.physics import projectile

        accel = scene.model.constant_acceleration

        def solution(t):
            p, v = projectile(t, scene.y0[0], scene.y0[1], accel, scene.t_start)
            return np.stack([p, v])

        problem = dataclasses.replace(problem, solution=solution)
    result = recommend(problem, args.tol, dt_max=args.dt_max, integrators=integrators)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    if result["dt"] is None:
        print(f"{result['note']}; {result['integrator']} does at rtol = {result['rtol']:g}: error "
              f"{result['error']:.3g} m in {result['seconds'] * 1e3:.3g} ms")
    else:
        print(f"{scene.name}: {result['integrator']} with dt = {result['dt']:.6g} s ({result['steps']} steps) "
              f"reaches error {result['error']:.3g} m <= {args.tol:g} m in {result['seconds'] * 1e3:.3g} ms "
              "(compiled, median)")
    return 0


def _recommend_with_collisions(args, scene, t_end, world, integrators) -> int:
    """``recommend`` measured with the scene's collisions; status 1 with the evidence when nothing passes."""
    from steplab.studies.recommend_collisions import NoCollisionStepError, recommend_with_collisions

    try:
        r = recommend_with_collisions(scene.model, scene.y0, scene.t_start, t_end, world, args.tol,
                                      scene_dt=scene.dt, dt_max=args.dt_max, integrators=integrators,
                                      progress=not args.json and sys.stderr.isatty())
    except NoCollisionStepError as err:
        if not args.json:
            raise
        print(json.dumps(err.evidence | {"error": str(err)}, indent=2))
        return EXIT_DIVERGED
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    ref = r["reference"]
    measured = (f"largest position error {r['error']:.3g} m <= {args.tol:g} m" if r["regime"] == "trajectories"
                else f"energy error {100 * r['energy_error']:.3g} %, largest penetration {r['penetration']:.3g} m")
    print(f"{scene.name}: {r['integrator']} with dt = {r['dt']:.6g} s ({r['steps']} steps), {r['detector']} "
          f"detector: {measured}, {_plural(r['impacts'], 'impact')} (reference: {ref['impacts']}), "
          f"{r['seconds'] * 1e3:.3g} ms (NumPy event loop, median)")
    print(f"  reference: {ref['integrator']} at dt = {ref['dt']:.3g} s, converged to {ref['convergence']:.3g} m "
          f"against dt = {2 * ref['dt']:.3g} s ({_plural(ref['impacts_at_2dt'], 'impact')} there)")
    if "note" in r:
        print(f"  note: {r['note']}")
    return 0


# --- studies ------------------------------------------------------------------------


def cmd_study(args) -> int:
    from steplab.studies import STUDIES, run_study

    if args.list or args.name is None:
        for name, study in STUDIES.items():
            origin = STUDIES.origin(name)
            print(f"{study.name:<16} {study.title}" + ("" if origin == "steplab" else f" [plugin: {origin}]"))
        return 0
    if args.name not in STUDIES:
        raise ValueError(f"unknown study {args.name!r}; valid: {', '.join(STUDIES)}")
    reason = STUDIES[args.name].unavailable()
    if reason:  # an optional package missing: the line says how to install it
        raise ValueError(reason)
    if args.workers or args.scheduler:
        [record] = _on_cluster(args, [STUDIES[args.name]])
    else:
        record = run_study(STUDIES[args.name], args.out, quick=args.quick, force=args.force)
    _print_summary([record], args.out)
    return 0


def cmd_reproduce(args) -> int:
    if args.workers or args.scheduler:
        _print_summary(_on_cluster(args, _available_builtin_studies()), args.out)
        return 0
    from tqdm import tqdm

    from steplab.studies import builtin_studies, run_study

    records = []  # steplab's own studies, the paper's records; a plugin's study runs by name
    with tqdm(builtin_studies(), desc="reproduce", unit="study", disable=None) as bar:
        for study in bar:
            bar.set_postfix_str(study.name)
            reason = study.unavailable()
            if reason:
                bar.write(f"{study.name}: skipped: {reason}")
                continue
            records.append(run_study(study, args.out, quick=args.quick, force=args.force))
    _print_summary(records, args.out)
    return 0


def _on_cluster(args, studies: list) -> list[dict]:
    """Run ``studies`` on ``--workers N`` (a local cluster) or ``--scheduler ADDRESS``; their records."""
    from steplab.cluster import connect
    from steplab.studies.distributed import run_studies

    with connect(args.workers, args.scheduler) as client:
        return run_studies(studies, args.out, client, quick=args.quick, force=args.force)


def _available_builtin_studies() -> list:
    """steplab's own studies that can run here (each one that cannot is named, with why)."""
    from steplab.studies import builtin_studies

    available = []
    for study in builtin_studies():
        reason = study.unavailable()
        if reason:
            print(f"{study.name}: skipped: {reason}")
        else:
            available.append(study)
    return available


def _print_summary(records, out: Path) -> None:
    for record in records:
        from steplab.studies import STUDIES

        state = "cached" if record.get("cached") else "computed"
        print(f"{record['study']} ({state}): {record['title']}")
        for label, value in STUDIES[record["study"]].summary(record):
            print(f"  {label:<40} {value}")
        for figure in record.get("figures", []):
            print(f"  figure: {figure}")
        print(f"  record: {Path(out) / (record['study'] + '.json')}")


# --- bench --------------------------------------------------------------------------


# --- export -------------------------------------------------------------------------

def cmd_export(args) -> int:
    from steplab.core.records import write_atomic
    from steplab.engines.mjcf import mjcf
    from steplab.engines.mujoco_engine import MujocoRun
    from steplab.physics.scene import load_scene

    scene = load_scene(args.scene)
    # MuJoCo's integrator that steps as the scene's integrator does (the engines study's identification)
    equivalent = MujocoRun.integrator_stepping_as(scene.integrator)
    integrator = args.integrator or equivalent or "Euler"
    text = mjcf(scene.model, scene.y0, scene.dt, scene.collisions, integrator, name=scene.name)
    if args.integrator is None and equivalent is None:
        print(f"steplab export: note: MuJoCo has no integrator that steps as {scene.integrator!r} does; "
              "writing Euler (semi-implicit Euler; choose with --integrator)", file=sys.stderr)
    if args.out is None:
        sys.stdout.write(text)
    else:
        write_atomic(args.out, text.encode())
        print(f"{scene.name}: MJCF written to {args.out} (MuJoCo {integrator}, dt = {scene.dt:g} s)")
    return 0


def cmd_bench(args) -> int:
    from steplab.bench import command

    return command(args)


if __name__ == "__main__":
    sys.exit(main())
