"""Many contact-solver runs as one: a sweep of scenes or settings, one compiled call per step.

A study that sweeps the solver's settings (iterations x substeps on Newton's cradle, dt on a
resting column) runs small scenes many times over. Here each run is a *member*: its own
:class:`.solver_step.SolverStep` (world, settings, warm start, log) finds its contacts and
concludes its events as a single run does, but the substeps of every member are taken by
one call of the kernel (:func:`.solver_step.solve_members`), members spread over the cores.
The results are those of the members run one at a time, bit for bit (the kernel's
arithmetic per member is the same; tests/test_contact_solver.py checks it). Every member's
forces must be constant (gravity, wind): then a whole step is one call.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .solver_step import SolverStep, solve_members


def run_batch(steps: Sequence[SolverStep], y0s: Sequence[np.ndarray], t_start: float, dts, n_steps: int,
              save_every: int | None = None) -> list[np.ndarray]:
    """Run every member ``steps[m]`` from ``y0s[m]`` for ``n_steps`` steps of ``dts[m]`` (or one dt for all).

    Returns, per member, the saved states, shape (n_steps // save_every + 1, 2, N_m, 3):
    the start and every ``save_every``-th step (default: the start and the end only).
    The members' logs (``steps[m].log``) hold their impacts, as after :func:`simulate`.
    """
    if not steps:
        return []
    for member in steps:
        if not isinstance(member, SolverStep) or member.field is None:
            raise ValueError("a solver batch needs contact-solver steps whose forces are all constant "
                             "(run the others one at a time)")
    dts = np.broadcast_to(np.asarray(dts, dtype=float), (len(steps),))
    every = save_every or n_steps
    ys = [np.asarray(y, dtype=float) for y in y0s]
    saved = [[y] for y in ys]
    sizes = np.array([len(member.radii) for member in steps])
    bodies = np.concatenate([[0], np.cumsum(sizes)])
    inverse_mass = np.concatenate([member.inverse_masses for member in steps])
    accel = np.ascontiguousarray(np.concatenate([member.field for member in steps]))
    settings = [member.settings for member in steps]
    for k in range(n_steps):
        starts = [member.prepare(t_start + k * dt, y, dt) for member, y, dt in zip(steps, ys, dts)]
        results = solve_members(starts, settings, bodies, inverse_mass, accel, parallel=True)
        ys = [member.conclude(start, *result) for member, start, result in zip(steps, starts, results)]
        if (k + 1) % every == 0:
            for m, y in enumerate(ys):
                saved[m].append(y)
    return [np.stack(s) for s in saved]
