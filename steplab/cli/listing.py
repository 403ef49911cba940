"""``steplab integrators`` and ``steplab scenes``: what there is to run, one aligned table each."""

from __future__ import annotations

import json

from .args import json_argument
from .table import table

#: the ``implicit`` column for each way a step finds its new state (Integrator.scheme)
IMPLICIT = {"explicit": "no", "linearly implicit": "linearly", "implicit": "yes", "exponential": "no (exp)"}


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="list the integrators with their properties" if name == "integrators"
                       else "list the built-in scenes")
    json_argument(p)


def command(args) -> int:
    return integrators(args) if args.command == "integrators" else scenes(args)


def integrators(args) -> int:
    from steplab.integrators import INTEGRATORS, ROTATIONS, Integrator

    if args.json:  # with what the table leaves out: each method's stability limit, a solver's tolerances
        rows = [method.describe() | {"source": INTEGRATORS.origin(name)} for name, method in INTEGRATORS.items()]
        # a rotation method's own "source" is its literature: kept as "reference", "source" says who registered it
        rows += [method.describe() | {"reference": method.source, "source": ROTATIONS.origin(name)}
                 for name, method in ROTATIONS.items()]
        print(json.dumps(rows, indent=2))
        return 0
    rows = []
    methods = [(method, INTEGRATORS.origin(name)) for name, method in INTEGRATORS.items()]
    methods += [(method, ROTATIONS.origin(name)) for name, method in ROTATIONS.items()]
    for method, source in methods:
        r = Integrator.describe(method)  # the class data alone: no stability limit is computed
        evals = "adaptive" if r["evaluations_per_step"] is None else str(r["evaluations_per_step"])
        if r["scheme"] == "implicit" and r["kind"] == "fixed-step":  # evaluations are per Newton iteration
            evals += "/iter"
        rows.append((r["name"], r["kind"], "-" if r["order"] is None else str(r["order"]), evals,
                     "yes" if r["symplectic"] else "no", IMPLICIT.get(r["scheme"], r["scheme"]),
                     r["description"] + ("" if source == "steplab" else f" [plugin: {source}]")))
    print(table(rows, ("name", "kind", "order", "evals/step", "symplectic", "implicit", "description"),
                right=(2, 3)))
    print("\nrotation methods, with the translation methods they pair with and the order of their stages:")
    print(table([(name, ", ".join(method.composes_with), method.stage_order) for name, method in ROTATIONS.items()],
                ("name", "composes with", "stage order"), indent="  "))
    return 0


def scenes(args) -> int:
    from steplab.physics.scene import builtin_scenes, load_scene

    rows = []
    for name in builtin_scenes():
        scene = load_scene(name, collisions=False)  # the table shows no collision settings
        rows.append({"name": name, "bodies": scene.model.n_bodies,
                     "forces": [f.name for f in scene.model.forces], "integrator": scene.integrator,
                     "dt": scene.dt, "t_start": scene.t_start, "t_end": scene.t_end,
                     "description": scene.description})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(table([(r["name"], str(r["bodies"]), ", ".join(r["forces"]) or "no forces", r["integrator"],
                  f"{r['dt']:g}", f"{r['t_end']:g}", r["description"]) for r in rows],
                ("name", "bodies", "forces", "integrator", "dt (s)", "t_end (s)", "description"), right=(1, 4, 5)))
    return 0
