"""Runs with collision detection and response: detector x scene.

Needs ``physics.collision`` and scenes with a ``[collisions]`` table; where a commit has
neither, ``setup`` raises ``NotImplementedError`` and asv records the benchmark as skipped.
"""

from __future__ import annotations

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
