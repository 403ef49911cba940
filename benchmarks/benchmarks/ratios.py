"""``steplab bench``'s ratios as ``track_`` benchmarks, so a regression against a peer shows in asv's history.

A ratio is steplab's time over the peer's on the same work (lower is better), both timed in
the same process, interleaved round by round (the project's rule: a speed target is a ratio
against a peer in the same run, never an absolute time). Each class runs one section of the
quick bench in its ``setup_cache`` and tracks that section's ratios, named as in the bench's
record; the ratio is on the clock the bench chose (CPU seconds where both sides ran on one
thread: ``seconds.<name>.clock`` in ``steplab bench --json``). The ``time_`` benchmarks of the
other modules are histories of one contender's own time, not comparisons. The sections with
their own modules: the cloth (:mod:`.cloth`), rotation (:mod:`.rotation`), stacking
(:mod:`.stacking`) and the crowded pit (:mod:`.crowded_pit`).
"""

from __future__ import annotations

from steplab.bench.timing import pin_threads

# one thread per side, as ``steplab bench`` runs: before this module imports JAX (asv times
# each benchmark in a process of its own)
pin_threads()

from steplab.peers import DIFFRAX_METHODS  # noqa: E402

#: the small system's ratios, named as in the bench's record (one per diffrax method, then Numba and Python)
SMALL_SYSTEM_RATIOS = [f"vs_diffrax_{method.replace('-', '_')}" for method in DIFFRAX_METHODS] + [
    "vs_numba_semi_implicit_euler", "vs_python_loop_semi_implicit_euler"]


def section_ratios(section: str, **overrides) -> dict[str, float]:
    """The ratios that one section of the quick bench (``steplab.bench.comparisons.<section>``) records."""
    import dataclasses

    from steplab.bench import QUICK, Record, comparisons, fair_diffrax

    fair_diffrax()  # Equinox's run-time checks off, as in ``steplab bench`` (before diffrax is imported)
    config = dataclasses.replace(QUICK, **overrides)
    record = Record(config, quick=True)
    getattr(comparisons, section)(config, record, lambda message: None)
    return record.data["ratios"]


class _SectionRatios:
    """One section's ratios, measured once in each class's own ``setup_cache``; a name the section
    does not record (an older steplab, a peer not installed) shows as n/a.

    asv keys a ``setup_cache`` by the module and line where it is defined, so each class defines
    its own: one inherited from here would be one cache, the first class's section's ratios, and
    every other class's names n/a (tests/test_asv_suite.py)."""

    unit = "ratio"
    param_names = ["ratio"]
    timeout = 900

    def track_ratio(self, ratios, ratio):
        return ratios.get(ratio, float("nan"))


class BenchRatio(_SectionRatios):
    """The small system (one oscillator, 10^5 steps) against diffrax, Numba and a Python loop."""

    params = SMALL_SYSTEM_RATIOS
    timeout = 300

    def setup_cache(self):
        return section_ratios("small_system")


class LargeSystemRatios(_SectionRatios):
    """One step of 10^6 particles and of the 10^5-spring cloth, against the memory bound and Numba."""

    params = ["vs_memory_bound_1e6", "vs_numba_1e6", "vs_memory_bound_cloth_1e5_springs",
              "vs_numba_cloth_1e5_springs"]

    def setup_cache(self):
        return section_ratios("large_systems")


class AccuracyMatchedRatios(_SectionRatios):
    """Time to a final error of 1e-8 m against scipy's DOP853 and diffrax's Tsit5 (the worse problem)."""

    params = ["vs_scipy_at_1e-8", "vs_diffrax_tsit5_at_1e-8"]

    def setup_cache(self):
        return section_ratios("accuracy_matched")


class BroadphaseRatio(_SectionRatios):
    """The fastest broadphase method on 10^5 spheres against scipy's cKDTree."""

    params = ["vs_ckdtree_1e5"]

    def setup_cache(self):
        return section_ratios("broadphase")


class BatchingRatios(_SectionRatios):
    """Many simulations in one vmapped call against a Python loop of single compiled runs."""

    params = ["batched_vs_loop_initial_conditions", "batched_vs_loop_dt", "batched_vs_loop_springs"]

    def setup_cache(self):
        return section_ratios("batching")


class ImplicitClothRatios(_SectionRatios):
    """One implicit Euler step of the cloth (Newton to rtol, and one Newton iteration) against a semi-implicit one."""

    params = ["implicit_euler_cloth_step", "implicit_euler_one_newton_cloth_step"]

    def setup_cache(self):
        return section_ratios("implicit_euler_cloth")


class BallPitRatios(_SectionRatios):
    """10^3 balls for 12 steps: the event loop and the contact solver against MuJoCo and pybullet
    (names without a peer installed show as n/a)."""

    params = ["vs_mujoco_ball_pit_1e3", "vs_pybullet_ball_pit_1e3", "solver_vs_mujoco_ball_pit_1e3",
              "solver_vs_pybullet_ball_pit_1e3", "solver_vs_event_loop_ball_pit_1e3"]

    def setup_cache(self):
        return section_ratios("ball_pits", collision_runs=((1_000, 12),))
