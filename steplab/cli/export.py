"""``steplab export``: a scene as another engine's model file (MJCF for MuJoCo)."""

from __future__ import annotations

import sys

from .args import pathname, scene_argument


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="write a scene as another engine's model file (MJCF for MuJoCo)")
    scene_argument(p)
    p.add_argument("--to", choices=("mjcf",), required=True, help="the format: mjcf (MuJoCo's XML)")
    p.add_argument("--integrator", choices=("Euler", "RK4", "implicit", "implicitfast", "discrete"),
                   help="MuJoCo's integrator (default: the one that equals the scene's, else Euler)")
    p.add_argument("--out", type=pathname, help="write to FILE (default: print the file)")


def command(args) -> int:
    from steplab.core.records import write_atomic
    from steplab.engines.mjcf import MujocoOption, mjcf
    from steplab.engines.mujoco_engine import MujocoRun
    from steplab.physics.scene import load_scene

    from .run import scene_method

    scene = load_scene(args.scene)
    scene_method(scene)  # the scene's [simulation.<integrator>] table, refused as run refuses it
    # MuJoCo's integrator that steps as the scene's integrator does (the engines study's identification)
    equivalent = MujocoRun.integrator_stepping_as(scene.integrator)
    integrator = args.integrator or equivalent or "Euler"
    text = mjcf(scene.model, scene.y0, scene.dt, scene.collisions, MujocoOption(integrator), name=scene.name,
                bodies=scene.rigid_bodies)
    if args.out is None:
        sys.stdout.write(text)
    else:
        write_atomic(args.out, text.encode())
    # after the file: a path that cannot be written is its one line of error, with no note before it
    if args.integrator is None and equivalent is None:
        print(f"steplab export: note: MuJoCo has no integrator that steps as {scene.integrator!r} does; "
              "writing Euler (semi-implicit Euler; choose with --integrator)", file=sys.stderr)
    if args.out is not None:
        print(f"{scene.name}: MJCF written to {args.out} (MuJoCo {integrator}, dt = {scene.dt:g} s)")
    return 0
