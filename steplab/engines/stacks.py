"""The engines on stacks of boxes: does the stack stand, how far does it drift, how much does it
jitter, and what does a step cost (issue 26, item 5).

:func:`run_stack` runs one engine setting on a stack scene (boxes as ``[[bodies]]`` with
``shape = "box"`` on a floor plane: the column, the pyramid, the mass-ratio stack) and measures,
after the first :data:`SETTLE` seconds (once the contacts have taken their static deflection):

- ``standing``: the top box (the one highest at the start) moves less than
  :data:`STANDING_TOLERANCE` from where it was at ``SETTLE``, at every saved time to the end;
- ``top_drift`` (m): the top box's largest such displacement; ``drift`` (m): the largest
  displacement of any box;
- ``jitter`` (m/s): the rms speed of all boxes over the saved states after ``SETTLE``;
- ``deflection`` (m): how far the top box has sunk at ``SETTLE`` below its start (the
  contacts' static compression plus any settling);
- ``at_rest_after`` (s): the first saved time from which the top box stays within
  ``STANDING_TOLERANCE`` to the end, at least ``SETTLE`` before it: a stack still bouncing at
  ``SETTLE`` may stand later, and a fallen one lies still (read it with ``top_drift``; None: the
  top box never comes to rest);
- ``seconds_per_step``: the median over rounds of :data:`COST_STEPS` steps, on the stack as it
  stands at the end (steplab's one timer, :func:`steplab.core.timing.median_time`).

Each adapter declares its stack settings (``stack_settings``): its defaults and one documented
tuned setting (MuJoCo: its default Newton solver and PGS). A 2-D engine runs the stack in its
plane (the scene's boxes must lie in one, as a pyramid of rows does).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from steplab.integrators.simulate import DivergenceError, step_count

from . import ENGINES, build_scene
from .base import Setting, scene_parts

#: s: the stack settles into its contacts' static deflection first; standing is judged after
SETTLE = 1.0
#: m: a stack stands while its top box moves less than this after SETTLE (issue 26's criterion)
STANDING_TOLERANCE = 0.01
#: s between the saved states the measures read (10 Hz: the drift is slow, the jitter rms)
SAMPLE_INTERVAL = 0.1
#: steps per timed round, and rounds, of the cost per step
COST_STEPS, COST_ROUNDS = 20, 5


def stack_setting(engine: str, setting: str | dict | None = None) -> Setting:
    """The engine's stack setting: None its first (the defaults), a key of its ``stack_settings``,
    or a dict of adapter options (an ad-hoc setting). ValueError naming the valid keys."""
    cls = ENGINES.lookup(engine)
    if isinstance(setting, dict):
        return Setting(f"{engine}-custom", f"{cls.display_name} {setting}", dict(setting), engine=engine, adapter=cls)
    settings = {s.key: s for s in cls.stack_settings}
    if setting is None:
        return cls.stack_settings[0]
    if setting not in settings:
        raise ValueError(f"unknown stack setting {setting!r} of {engine}; valid: {', '.join(settings)}")
    return settings[setting]


def build_stack(engine: str, scene, dt: float | None = None, setting: str | dict | None = None):
    """The adapter of ``engine`` on the stack ``scene`` in ``setting`` (see :func:`stack_setting`), at ``dt``
    (default the scene's): for a caller that times it beside steplab in one run."""
    chosen = stack_setting(engine, setting)
    return build_scene(engine, _at_dt(scene, dt), **chosen.options), chosen


def run_stack(engine: str, scene, dt: float | None = None, t_end: float | None = None,
              setting: str | dict | None = None) -> dict:
    """Run the stack ``scene`` in ``engine`` and measure it (see the module's description).

    Parameters
    ----------
    engine : str
        A key of :data:`steplab.engines.ENGINES` ("mujoco", "bullet", "box2d", "chipmunk").
    scene : steplab.physics.scene.Scene
        Boxes (rotating bodies of shape "box") on a floor; gravity sets "up".
    dt, t_end : float, optional
        s; default the scene's.
    setting : str or dict, optional
        A key of the adapter's ``stack_settings`` (default: its first, the engine's defaults), or
        adapter options.

    Returns
    -------
    dict
        ``engine``, ``setting``, ``label``, ``options``, ``settings`` (the adapter's line), ``boxes``,
        ``dt``, ``t_end``, ``steps``, ``standing``, ``top_drift``, ``drift``, ``jitter``,
        ``deflection``, ``at_rest_after``, ``top`` (the top box's index), ``seconds_per_step``,
        ``diverged_at`` (s, or None; the measures are then None and ``standing`` False).

    Raises
    ------
    UnsupportedFeatureError
        A feature the engine cannot express (a 2-D engine on a 3-D stack), one line.
    """
    dt = float(scene.dt if dt is None else dt)
    t_end = float(scene.t_end if t_end is None else t_end)
    if not t_end > SETTLE:
        raise ValueError(f"t_end must exceed the settling time {SETTLE:g} s, got {t_end:g} s")
    up = _up(scene)
    run, chosen = build_stack(engine, scene, dt, setting)
    every = max(1, int(round(SAMPLE_INTERVAL / dt)))
    n = step_count(scene.t_start, scene.t_start + t_end, dt)
    out = {"engine": engine, "setting": chosen.key, "label": chosen.label, "options": chosen.options,
           "settings": run.name, "boxes": int(np.sum(~np.asarray(scene.model.pinned))), "dt": dt, "t_end": t_end,
           "steps": n}
    try:
        trajectory = run.advance(scene.y0, dt, n, t_start=scene.t_start, save_every=every, log_contacts=False)
    except DivergenceError as err:
        run.close()
        return out | {"standing": False, "top_drift": None, "drift": None, "jitter": None, "deflection": None,
                      "at_rest_after": None, "top": None, "seconds_per_step": None, "diverged_at": err.t}
    measures = stack_measures(trajectory.t - scene.t_start, trajectory.positions, trajectory.velocities, up)
    cost = _cost(run, dt)
    run.close()
    return out | measures | {"seconds_per_step": cost, "diverged_at": None}


def stack_measures(t, positions, velocities, up) -> dict:
    """standing, top_drift, drift, jitter, deflection and at_rest_after of the saved states
    ``positions``, ``velocities`` (K, N, 3) at times ``t`` (from the start), ``up`` the unit
    vector against gravity; ``top`` is the box highest at the start."""
    t, q, v = np.asarray(t), np.asarray(positions), np.asarray(velocities)
    top = int(np.argmax(q[0] @ up))
    settled = int(np.searchsorted(t, SETTLE - 1e-9))  # the first saved state at or after SETTLE
    moved = np.linalg.norm(q[settled:] - q[settled], axis=-1)  # (K', N)
    # from each saved state k, the top box's largest displacement over the states after it
    path = q[:, top]
    reach = [float(np.max(np.linalg.norm(path[k:] - path[k], axis=-1))) for k in range(len(t))]
    # at rest for at least SETTLE before the end: a last instant proves nothing
    rest = [k for k in range(len(t)) if reach[k] < STANDING_TOLERANCE and t[-1] - t[k] >= SETTLE - 1e-9]
    return {"standing": bool(np.max(moved[:, top]) < STANDING_TOLERANCE), "top_drift": float(np.max(moved[:, top])),
            "drift": float(np.max(moved)), "jitter": float(np.sqrt(np.mean(np.sum(v[settled:] ** 2, axis=-1)))),
            "deflection": float((q[0, top] - q[settled, top]) @ up),
            "at_rest_after": float(t[rest[0]]) if rest else None, "top": top}


def _up(scene) -> np.ndarray:
    g = scene_parts(scene.model, None, "the stack").gravity
    if not np.any(g):
        raise ValueError("a stack needs gravity ([forces.gravity]): it sets which way is up")
    return -g / np.linalg.norm(g)


def _at_dt(scene, dt):
    return scene if dt is None or dt == scene.dt else dataclasses.replace(scene, dt=float(dt))


def _cost(run, dt: float) -> float:
    """Median seconds per step over COST_ROUNDS rounds of COST_STEPS steps."""
    from steplab.core.timing import median_time

    def steps():
        for _ in range(COST_STEPS):
            run.step(dt)

    return median_time(steps, COST_ROUNDS) / COST_STEPS
