"""``steplab animate``: a simulation as a GIF or MP4, alone or side by side."""

from __future__ import annotations

from pathlib import Path

from .args import DETECTORS, count, scene_argument, time_arguments, time_span


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="render a simulation as an animation (GIF or MP4), alone or side by side")
    scene_argument(p)
    p.add_argument("--integrator", help="integrator name (default: the scene's)")
    p.add_argument("--compare", metavar="A,B",
                   help="side by side: integrators (euler,velocity-verlet) or detectors (overlap,swept)")
    p.add_argument("--detector", choices=DETECTORS, metavar="NAME",
                   help="collision detector, one of %(choices)s (default: the scene's)")
    time_arguments(p)
    p.add_argument("--fps", type=count, default=30, help="frames per second (default: 30)")
    p.add_argument("--view", choices=("xy", "xz", "yz"), help="plane shown (default: the two axes moved along most)")
    p.add_argument("--out", type=Path, required=True, help="FILE.gif or FILE.mp4 (MP4 through imageio-ffmpeg's ffmpeg)")


def command(args) -> int:
    from steplab.animate import animate, check_format
    from steplab.integrators.simulate import simulate
    from steplab.physics.scene import load_scene

    from .run import collision_world, integrator_named

    check_format(args.out)  # before the runs: a format that cannot be written is one line, status 2
    scene = load_scene(args.scene)
    dt, t_end = time_span(scene, args)
    # each panel: (integrator, detector); --compare varies one of them
    panels = [(args.integrator or scene.integrator, args.detector)]
    if args.compare:
        names = [n.strip() for n in args.compare.split(",")]
        if len(names) < 2:
            raise ValueError(f"--compare needs at least two comma-separated integrators or detectors, "
                             f"got {args.compare!r}")
        if all(n in DETECTORS for n in names):
            panels = [(panels[0][0], n) for n in names]
        else:
            panels = [(n, args.detector) for n in names]
    steps = int((t_end - scene.t_start) / dt)
    runs = []
    for name, detector in panels:
        method = integrator_named(name)
        world = collision_world(scene, detector, "numpy")
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
