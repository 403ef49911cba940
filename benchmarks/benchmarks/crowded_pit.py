"""The crowded ball pit (issue 27): the event loop's cost per impact, and its wall time over MuJoCo's.

2,000 balls dropped into a 6 m box pile up and come to rest: 59,312 impacts in the first
simulated second, each resolved at its time by the incremental event loop's compiled step.
MuJoCo (PGS, sparse Jacobian, 10 iterations) steps the same bodies from the same state in
the same process (``steplab bench``'s :func:`steplab.bench.collisions.crowded_pit`), so the
ratio is measured on one machine at one moment. Needs MuJoCo (``pip install -e ".[engines]"``);
without it ``setup_cache`` raises ``NotImplementedError`` and asv records the benchmark as skipped.
"""

from __future__ import annotations

import dataclasses

from steplab.bench.timing import pin_threads

# one thread per side, as ``steplab bench`` runs its ratios: before JAX or Numba is imported
pin_threads()

#: the full bench's crowded pit: balls, box side (m), steps of dt = 1/60 s
CROWDED_PIT = (2_000, 6.0, 60)


class CrowdedPit:
    """steplab's event loop beside MuJoCo on the crowded pit, measured once in ``setup_cache``."""

    timeout = 900

    def setup_cache(self):
        try:
            import mujoco  # noqa: F401

            from steplab.bench.collisions import crowded_pit
        except ImportError:  # no MuJoCo, or a steplab before the crowded pit
            raise NotImplementedError("needs MuJoCo and steplab.bench.collisions.crowded_pit") from None
        from steplab.integrators import simulate

        from steplab.bench import QUICK, Record
        from steplab.bench.ball_pit_scene import ball_pit
        from steplab.bench.collisions import WARM_UP_PIT

        warm = ball_pit(WARM_UP_PIT[0])  # every kernel compiled before the clock starts
        simulate(warm.model, warm.integrator, warm.y0, 0.0, dt=warm.dt, n_steps=WARM_UP_PIT[1],
                 collisions=warm.collisions)
        config = dataclasses.replace(QUICK, crowded_pit=CROWDED_PIT, collision_repeats=1)
        record = Record(config, quick=True)
        crowded_pit(config, record)
        pit = record.data["collisions"]["crowded_pit_2000"]
        return {"vs_mujoco": record.data["ratios"]["vs_mujoco_crowded_pit_2000"],
                "us_per_impact": 1e6 * pit["seconds_per_impact"], "impacts": pit["impacts"]}

    def track_vs_mujoco(self, numbers):
        """steplab's wall time over MuJoCo's on the same steps (the target: at most 3)."""
        return numbers["vs_mujoco"]

    track_vs_mujoco.unit = "ratio"

    def track_us_per_impact(self, numbers):
        """The event loop's wall time per impact (the target: at most 20 us)."""
        return numbers["us_per_impact"]

    track_us_per_impact.unit = "us"

    def track_impacts(self, numbers):
        """Impacts in the simulated second: the same whatever the machine (a change is a change of results)."""
        return numbers["impacts"]

    track_impacts.unit = "impacts"
