"""``steplab recommend``: the cheapest integrator and dt that meet an error tolerance on a scene."""

from __future__ import annotations

import json
import sys

from .args import (
    DETECTORS,
    comma_list,
    json_argument,
    positive,
    rotation_argument,
    rotation_named,
    scene_argument,
    time_arguments,
    time_span,
)
from .errors import EXIT_DIVERGED


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="the cheapest integrator and dt that meet an error tolerance")
    scene_argument(p)
    p.add_argument("--tol", type=positive, required=True, help="largest final position error, m (with "
                   "collisions: largest position error over the run)")
    time_arguments(p, dt=False)
    p.add_argument("--dt-max", type=positive, metavar="DT",
                   help="largest dt to consider, s, e.g. a frame, 1/60 (default: a quarter of the run)")
    p.add_argument("--integrators", type=comma_list, metavar="A,B",
                   help="candidates (default: every fixed-step integrator)")
    p.add_argument("--detector", choices=DETECTORS, metavar="NAME", help="collision detector to measure "
                   "with, one of %(choices)s (default: the scene's; none: without collisions)")
    rotation_argument(p)
    json_argument(p)


def command(args) -> int:
    from steplab.physics.attachments import attached_forces
    from steplab.physics.scene import load_scene
    from steplab.studies.problems import problem_of
    from steplab.studies.recommend import recommend

    from .run import collision_world, scene_method

    scene = load_scene(args.scene)
    scene_method(scene)  # the scene's [simulation.<integrator>] table, refused as run refuses it
    rotation = rotation_named(scene, args)
    _, t_end = time_span(scene, args)
    integrators = None
    if args.integrators is not None:
        from steplab.studies.recommend_collisions import check_integrators

        integrators = check_integrators(args.integrators)  # a list of names, none empty (comma_list)
    world = collision_world(scene, args.detector, "numpy")
    if world is not None:  # the solver turns the bodies with --rotation, as in run, and refuses what run refuses
        world = world.with_rotation(rotation.name)
        world.check_solver()
    if attached_forces(scene.model):  # the rotation steps with the translation: measured together
        if world is not None:  # run steps them in the contact solver: not measured so
            raise ValueError("recommend measures springs and dampers at body-frame points (offsets) without "
                             "collisions only; use --detector none")
        return _with_attachments(args, scene, t_end, integrators, rotation)
    if world is not None:
        return _with_collisions(args, scene, t_end, world, integrators, rotation)
    result = _with_rotation(recommend(problem_of(scene, t_end), args.tol, dt_max=args.dt_max,
                                      integrators=integrators), scene, rotation)
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
    _print_rotation(result)
    return 0


def _with_rotation(result: dict, scene, rotation) -> dict:
    """``result`` with, for a scene with rotating bodies, whether ``rotation`` is stable at its dt
    (the tolerance is on the translation only; the rotation method's limit is its own)."""
    if scene.rigid_bodies is not None and result.get("dt") is not None:
        from .check import rotation_limit

        result["rotation"] = rotation_limit(rotation, scene.rigid_bodies, result["dt"])
    return result


def _print_rotation(result: dict) -> None:
    from .check import limit_text

    if "rotation" in result:
        r = result["rotation"]
        unit = " s" if r["dt_max"] else ""  # "no limit" and "none (grows)" (stable at no dt) take none
        print(f"  rotation {r['method']}: {'stable' if r['stable'] else 'UNSTABLE'} at this dt (its dt_max: "
              f"{limit_text(r['dt_max'])}{unit}); the tolerance bounds the translation only")


def _with_collisions(args, scene, t_end, world, integrators, rotation) -> int:
    """``recommend`` measured with the scene's collisions; status 1 with the evidence when nothing passes."""
    from steplab.studies.recommend_collisions import CollisionProblem, NoCollisionStepError, recommend_with_collisions

    from .run import plural

    try:
        problem = CollisionProblem(scene.model, scene.y0, scene.t_start, t_end, world, scene.rigid_bodies)
        r = recommend_with_collisions(problem, args.tol,
                                      scene_dt=scene.dt, dt_max=args.dt_max, integrators=integrators,
                                      progress=not args.json and sys.stderr.isatty())
    except NoCollisionStepError as err:
        if not args.json:
            raise
        print(json.dumps(err.evidence | {"error": str(err)}, indent=2))
        return EXIT_DIVERGED
    r = _with_rotation(r, scene, rotation)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    ref = r["reference"]
    measured = (f"largest position error {r['error']:.3g} m <= {args.tol:g} m" if r["regime"] == "trajectories"
                else f"energy error {100 * r['energy_error']:.3g} %, largest penetration {r['penetration']:.3g} m")
    how = ("contact solver", "NumPy contact solver") if world.method == "solver" else (
        f"{r['detector']} detector", "NumPy event loop")
    print(f"{scene.name}: {r['integrator']} with dt = {r['dt']:.6g} s ({r['steps']} steps), {how[0]}: "
          f"{measured}, {plural(r['impacts'], 'impact')} (reference: {ref['impacts']}), "
          f"{r['seconds'] * 1e3:.3g} ms ({how[1]}, median)")
    print(f"  reference: {ref['integrator']} at dt = {ref['dt']:.3g} s, converged to {ref['convergence']:.3g} m "
          f"against dt = {2 * ref['dt']:.3g} s ({plural(ref['impacts_at_2dt'], 'impact')} there)")
    if "note" in r:
        print(f"  note: {r['note']}")
    _print_rotation(r)
    return 0


def _with_attachments(args, scene, t_end, integrators, rotation) -> int:
    """``recommend`` on springs or dampers at body-frame points, the translation and the rotation measured
    together; status 1 with the evidence when nothing passes."""
    from steplab.studies.recommend_attached import NoAttachedStepError, recommend_attached

    try:
        r = recommend_attached(scene, t_end, args.tol, rotation=rotation, dt_max=args.dt_max,
                               integrators=integrators, progress=not args.json and sys.stderr.isatty())
    except NoAttachedStepError as err:
        if not args.json:
            raise
        print(json.dumps(err.evidence | {"error": str(err)}, indent=2))
        return EXIT_DIVERGED
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    ref = r["reference"]
    print(f"{scene.name}: {r['integrator']} with rotation {r['rotation']}, dt = {r['dt']:.6g} s ({r['steps']} "
          f"steps), coupled: largest error {r['error']:.3g} m <= {args.tol:g} m (positions "
          f"{r['position_error']:.3g} m, lever arms {r['arm_error']:.3g} m), {r['seconds'] * 1e3:.3g} ms "
          "(NumPy loop, median)")
    print(f"  reference: {ref['integrator']} with {ref['rotation']} at dt = {ref['dt']:.3g} s, converged to "
          f"{ref['convergence']:.3g} m against dt = {2 * ref['dt']:.3g} s")
    for name, why in r["skipped"].items():
        print(f"  skipped {name}: {why}")
    return 0
