"""Stacking (issue 26): the 20-row pyramid and boxes falling into a walled box, in the contact solver.

``PyramidSteps.time_steps`` times 10 steps of the standing pyramid (from the start; the
first call, in ``setup``, compiles every kernel) for steplab and, where installed, MuJoCo
(PGS, and its default Newton solver) and pybullet, the settings of ``steplab bench``
(:mod:`steplab.bench.stacking`). ``BoxPit`` times the first steps of 10^3 and 10^4 boxes
falling into a box, on one thread; ``BoxPitOnCores`` the real-time factor of 10^4 boxes on 2
cores with 2 Numba threads (issue 26's target), timed in a child process. ``StackingRatios``
tracks ``steplab bench``'s ratios, each measured with its spread in one run of the section
(``setup_cache``).
"""

from __future__ import annotations

from steplab.bench.timing import pin_threads

# one thread per side, as ``steplab bench`` runs its ratios: before JAX or Numba is imported
pin_threads()

#: steps per timed call
STEPS = 10
PEERS = ["steplab", "mujoco_pgs", "mujoco_newton", "pybullet"]


def _runs(scene, contender):
    try:
        from steplab.bench.stacking import contenders
    except ImportError:  # an older steplab
        raise NotImplementedError("steplab.bench.stacking is not available") from None
    runs, _, missing = contenders(scene, [] if contender == "steplab" else [contender])
    if contender not in runs:
        raise NotImplementedError(missing[contender])
    return runs[contender]


class PyramidSteps:
    """10 steps of the 210-box pyramid at 60 Hz from rest, each contender with its bench settings."""

    params = (PEERS,)
    param_names = ["contender"]
    number = 1
    repeat = (1, 10, 60.0)
    timeout = 600

    def setup(self, contender):
        from steplab.physics.scene import builtin_scenes, load_scene

        if "box-pyramid" not in builtin_scenes():
            raise NotImplementedError("no built-in scene box-pyramid")
        self.run = _runs(load_scene("box-pyramid"), contender)
        self.run(1)  # compile, set up

    def time_steps(self, contender):
        self.run(STEPS)


class BoxPit:
    """The first 10 steps of N boxes (0.2 m cubes, random orientations) falling into a box, steplab's solver."""

    params = ([1_000, 10_000],)
    param_names = ["boxes"]
    number = 1
    repeat = (1, 5, 60.0)
    timeout = 600

    def setup(self, boxes):
        try:
            from steplab.bench.stacking import box_pit
        except ImportError:
            raise NotImplementedError("steplab.bench.stacking is not available") from None
        self.run = _runs(box_pit(boxes), "steplab")
        self.run(1)

    def time_steps(self, boxes):
        self.run(STEPS)


class StackingRatios:
    """``steplab bench``'s stacking ratios (steplab / peer, per step), measured once in ``setup_cache``."""

    unit = "ratio"
    timeout = 900

    def setup_cache(self):
        import dataclasses

        from steplab.bench import QUICK, Record
        from steplab.bench.stacking import stacking

        config = dataclasses.replace(QUICK, box_pit_runs=((1_000, 12),))
        record = Record(config, quick=True)
        stacking(config, record, lambda message: None)
        return record.data["ratios"]

    def track_pyramid_vs_mujoco_pgs(self, ratios):
        return ratios.get("vs_mujoco_pgs_pyramid_20", float("nan"))

    def track_pyramid_vs_mujoco_newton(self, ratios):
        return ratios.get("vs_mujoco_newton_pyramid_20", float("nan"))

    def track_pyramid_vs_pybullet(self, ratios):
        return ratios.get("vs_pybullet_pyramid_20", float("nan"))


class BoxPitOnCores:
    """Real time per wall time of the first 10 steps of 10^4 boxes falling into a box, on 2 cores with 2 Numba
    threads (:func:`steplab.bench.stacking.on_cores`: the median of three child processes, this one being pinned to
    one thread)."""

    unit = "x real time"
    timeout = 900

    def setup_cache(self):
        try:
            from steplab.bench.stacking import on_cores
        except ImportError:
            raise NotImplementedError("steplab.bench.stacking.on_cores is not available") from None
        return on_cores(10_000, STEPS, 3, 2)

    def track_box_pit_10k_real_time_on_2_cores(self, child):
        if "seconds_per_step" not in child:
            raise NotImplementedError(child.get("error", "no timing"))
        return (1 / 60) / child["seconds_per_step"]["median"]
