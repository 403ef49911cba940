"""``steplab animate``: a simulation as a GIF or MP4, alone or side by side."""

from __future__ import annotations

from .args import (
    DETECTORS,
    comma_list,
    count,
    nonempty,
    pathname,
    run_steps,
    scene_argument,
    time_arguments,
    time_span,
)

#: the most steps of dt one panel's run may take (an animation draws at most steplab.animate.MAX_FRAMES
#: = 150 frames of it: 100,000 steps are already some 670 steps a frame); a longer run is refused, one line
MAX_STEPS = 100_000


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="render a simulation as an animation (GIF or MP4), alone or side by side",
                       description=f"Render a simulation as an animation. Each panel runs at most {MAX_STEPS:,} "
                       "steps of --dt from the scene's t_start to --t-end, drawn as at most 150 frames "
                       "(played at --fps).")
    scene_argument(p)
    p.add_argument("--integrator", type=nonempty, help="integrator name (default: the scene's)")
    p.add_argument("--compare", type=comma_list, metavar="A,B",
                   help="side by side: integrators (euler,velocity-verlet) or detectors (overlap,swept)")
    p.add_argument("--detector", choices=DETECTORS, metavar="NAME",
                   help="collision detector, one of %(choices)s (default: the scene's)")
    time_arguments(p)
    p.add_argument("--fps", type=count, default=30, help="frames per second, 1 to 100 (default: 30)")
    p.add_argument("--view", choices=("xy", "xz", "yz"), help="plane shown (default: the two axes moved along most)")
    p.add_argument("--out", type=pathname, required=True,
                   help="FILE.gif or FILE.mp4 (MP4 through imageio-ffmpeg's ffmpeg)")


def command(args) -> int:

    from steplab.animate import animate, check_format, check_fps
    from steplab.integrators import DEFAULT_ROTATION, get_rotation
    from steplab.integrators.attached import attached_stepper, scene_stepper
    from steplab.integrators.scene_rotation import run_rotation
    from steplab.integrators.simulate import simulate
    from steplab.physics.scene import load_scene

    from .run import _attached, collision_world, scene_method

    check_format(args.out)  # before the runs: a format that cannot be written is one line, status 2
    check_fps(args.fps)
    scene = load_scene(args.scene)
    dt, t_end = time_span(scene, args)
    # each panel: (integrator, detector); --compare varies one of them
    panels = [(args.integrator, args.detector)]  # None: the scene's, with its [simulation.<integrator>] settings
    if args.compare:
        names = args.compare  # comma_list: none empty
        if len(names) < 2:
            raise ValueError(f"--compare needs at least two comma-separated integrators or detectors, "
                             f"got {','.join(names)!r}")
        if all(n in DETECTORS for n in names):
            panels = [(panels[0][0], n) for n in names]
        else:
            panels = [(n, args.detector) for n in names]
    steps = run_steps(scene, dt, t_end, MAX_STEPS, "steplab animate")
    # every panel's refusals before any run: its integrator, springs at body-frame points with collisions
    # other than the contact solver's (refused as run refuses them), an integrator its step refuses (the
    # coupled step, the contact solver)
    methods = [scene_method(scene, name) for name, _ in panels]
    rotation = get_rotation(scene.rotation or DEFAULT_ROTATION)  # run's, without --rotation
    worlds = [collision_world(scene, detector, "numpy") for _, detector in panels]
    worlds = [world if world is None else world.with_rotation(rotation.name)  # the contact solver turns them so
              for world in worlds]
    attached = [_attached(scene, world) for world in worlds]
    for method, world, coupled in zip(methods, worlds, attached):  # a method the panel's step refuses
        if world is not None:  # an adaptive one, or the contact solver's other than semi-implicit Euler
            world.stepper(scene.model, method)
        elif coupled:  # their lever arms turn with the bodies: the rotation steps with the translation
            attached_stepper(scene.rigid_bodies, rotation)(scene.model, method)
    save_every = max(1, steps // 300)
    runs, rotations = [], []
    for method, world, coupled, (_, detector) in zip(methods, worlds, attached, panels):
        kept = []  # the step the run built: the attached one or the contact solver's keeps the rotation
        traj = simulate(scene.model, method, scene.y0, scene.t_start, t_end, dt, save_every=save_every,
                        stepper=scene_stepper(scene, kept, world, rotation, save_every))
        # the bodies as the attached step or the contact solver turned them, else free beside the translation
        rotations.append(run_rotation(scene, traj, kept[0] if kept else None, rotation))
        label = f"{scene.name}: {method.name}, dt = {dt:g} s"
        if world is not None or detector is not None:
            label += (", contact solver" if world is not None and world.method == "solver"
                      else f", {world.detector if world is not None else 'no'} detector")
        if rotations[-1] is not None:  # on a line of its own: the title is as wide as the panel
            label += f"\nrotation: {rotation.name}" + (" (coupled)" if coupled else "")
        runs.append((label, traj))
    shapes = scene.collisions.shapes if scene.collisions is not None else ()
    rigid = scene.collisions.rigid if scene.collisions is not None else None  # the bodies' half extents
    path = animate(runs, scene.model, args.out, fps=args.fps, view=args.view, shapes=shapes,
                   rotations=rotations if scene.rigid_bodies is not None else None,
                   half=rigid.half if rigid is not None else None)
    print(f"animation written to {path} ({'; '.join(label.replace(chr(10), ', ') for label, _ in runs)})")
    return 0
