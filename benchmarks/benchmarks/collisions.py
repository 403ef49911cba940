"""Runs with collision detection and response: detector x scene, and ball pits of 10^3 and 10^4 spheres.

Needs ``physics.collision`` and scenes with a ``[collisions]`` table; where a commit has
neither, ``setup`` raises ``NotImplementedError`` and asv records the benchmark as skipped.
"""

from __future__ import annotations

import dataclasses
import time

from steplab.integrators import simulate
from steplab.physics.scene import builtin_scenes, load_scene

#: steps per timed run
STEPS = 100


class CollisionRun:
    params = (["overlap", "swept"], ["drop", "n-balls", "newtons-cradle", "billiards"])
    param_names = ["detector", "scene"]
    timeout = 300

    def setup(self, detector, scene):
        if scene not in builtin_scenes():
            raise NotImplementedError(f"no built-in scene {scene!r}")
        self.scene = load_scene(scene)
        if getattr(self.scene, "collisions", None) is None:
            raise NotImplementedError(f"scene {scene!r} has no [collisions] (or steplab has no collisions)")
        self.world = self.scene.collisions.with_detector(detector)

    def time_100_steps(self, detector, scene):
        s = self.scene
        simulate(s.model, s.integrator, s.y0, s.t_start, s.t_start + STEPS * s.dt, s.dt, collisions=self.world)


#: steps per timed run of a ball pit (its first 0.1 s at dt = 1/60 s)
PIT_STEPS = 6


class BallPit:
    """N spheres falling into a walled box (``steplab bench``'s ball pits), by each collision method:
    the swept event loop and the contact solver (default settings).

    The scene is steplab.bench.ball_pit_scene's: r = 0.1 m, eps = 0.8, dt = 1/60 s,
    semi-implicit Euler. ``setup`` builds it and runs a small pit first, so that every
    Numba kernel is compiled before the clock starts.
    """

    params = ([1_000, 10_000], ["event", "solver"])
    param_names = ["balls", "method"]
    number = 1  # one run of 10^4 balls takes about a second
    repeat = (1, 5, 30.0)
    timeout = 600

    def setup(self, balls, method):
        try:
            from steplab.bench.ball_pit_scene import ball_pit
        except ImportError:  # an older steplab
            raise NotImplementedError("steplab.bench.ball_pit_scene is not available") from None
        warm = ball_pit(50)
        self.world = self._world(warm, method)
        self._run(warm, 30)
        self.scene = ball_pit(balls)
        self.world = self._world(self.scene, method)

    @staticmethod
    def _world(scene, method):
        if method == "event":
            return scene.collisions
        if "method" not in {f.name for f in dataclasses.fields(scene.collisions)}:  # an older steplab
            raise NotImplementedError(f"no collision method {method!r} in this steplab")
        return dataclasses.replace(scene.collisions, method=method)

    def _run(self, scene, steps):
        return simulate(scene.model, scene.integrator, scene.y0, scene.t_start, dt=scene.dt, n_steps=steps,
                        save_every=steps, collisions=self.world)

    def time_steps(self, balls, method):
        self._run(self.scene, PIT_STEPS)

    def track_real_time_factor(self, balls, method):
        """Simulated seconds per wall second over the first PIT_STEPS steps (1: real time)."""
        start = time.perf_counter()
        self._run(self.scene, PIT_STEPS)
        return PIT_STEPS * self.scene.dt / (time.perf_counter() - start)

    track_real_time_factor.unit = "simulated s per wall s"
