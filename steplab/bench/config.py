"""What one bench run measures: its sizes, its seed, and the targets of issues 6 and 13."""

from __future__ import annotations

import dataclasses

#: seed of every random scene the bench builds
SEED = 20240611
#: largest acceptable ratio, steplab / peer, per comparison (issue 6, "Targets")
TARGETS = {
    "vs_diffrax_semi_implicit_euler": 0.5,
    "vs_diffrax_euler": 0.5,
    "vs_diffrax_rk4": 0.5,
    "vs_numba_semi_implicit_euler": 1.5,
    "vs_memory_bound_1e6": 1.5,
    # issue 16: the cloth's semi-implicit Euler step against the memory-traffic bound and Numba
    "vs_memory_bound_cloth_1e5_springs": 3.0,
    "vs_numba_cloth_1e5_springs": 1.0,
    "vs_scipy_at_1e-8": 0.05,
    "vs_ckdtree_1e5": 0.5,
    # issue 16: one implicit Euler step on the cloth, at its largest useful dt, against a semi-implicit one
    "implicit_euler_cloth_step": 10.0,
    # issue 25: one exponential-map step of 10^5 free tumbling bodies against the memory-traffic bound
    "vs_memory_bound_rotation_1e5": 2.0,
    "implicit_euler_one_newton_cloth_step": 10.0,
    # issue 28: the 25,600-particle cloth's xpbd step (1 substep, 1 iteration) against the memory-traffic bound
    "vs_memory_bound_xpbd_cloth": 1.5,
}
#: targets against a peer that is an optional extra, checked where it ran (issue 28: steplab's
#: xpbd step on the cloth against NVIDIA Newton's SolverXPBD on the CPU, steplab[newton])
PEER_TARGETS = {"vs_newton_xpbd_cloth": 0.5}
#: smallest acceptable simulated seconds per wall second of a ball pit, by its balls
#: (issue 13, "Targets": 10^4 spheres at 0.25x real time, MuJoCo's PGS; 2,000 at 1x)
REAL_TIME_TARGETS = {2_000: 1.0, 10_000: 0.25}
#: the contact solver's (issue 14), default settings: balls -> at least this many times real time
SOLVER_REAL_TIME_TARGETS = {10_000: 1.0, 100_000: 0.1}
#: largest acceptable ratio solver / engine of wall times on a ball pit, where the engine runs
#: (issue 14: at least 4x MuJoCo's throughput on 10^4 spheres)
SOLVER_ENGINE_TARGETS = {("mujoco", 10_000): 0.25}
#: longest acceptable JIT compilation of a built-in scene, s
COMPILE_TARGET_SECONDS = 2.0
#: when a ratio is flagged as not to be trusted (``ratio_stable`` in the record): a side's
#: median more than ``spread`` above its minimum in the run, fewer than ``rounds`` rounds (no
#: spread to judge), or a known cause, noted here: the comparisons whose CPU-time ratio moved by
#: more than 15 % across three quick runs at load 10 to 14 (docs/performance.md has the table)
_MEMORY = ("moves under load: memory-bound, and CPU time still counts the waits for memory, which other "
           "processes' traffic lengthens (the streamed bound moved by up to 25 % between runs at load 10 to 14)")
_TINY = ("moves under load: steplab's side is a call of about 30 µs, whose speed depends on caches that "
         "other processes share (both sides moved by up to 50 % between runs at load 10 to 14)")
STABILITY = {"spread": 0.15, "rounds": 3, "known": {
    "vs_memory_bound_1e6": _MEMORY, "vs_numba_1e6": _MEMORY, "vs_memory_bound_cloth_1e5_springs": _MEMORY,
    "vs_memory_bound_rotation_1e5": _MEMORY, "vs_memory_bound_xpbd_cloth": _MEMORY,
    "vs_scipy_at_1e-8_drag_projectile": _TINY, "vs_diffrax_tsit5_at_1e-8_drag_projectile": _TINY}}
#: a side ran on one thread where its CPU seconds are at most this times its wall seconds in every
#: round (:func:`.record.clock`); a second thread busy all along would give 2
ONE_THREAD = 1.25
#: the ratios ``--json`` always carries (the issue's JSON contract)
REQUIRED_RATIOS = ("vs_diffrax_semi_implicit_euler", "vs_numba_semi_implicit_euler", "vs_memory_bound_1e6",
                   "vs_scipy_at_1e-8", "vs_ckdtree_1e5")


@dataclasses.dataclass(frozen=True)
class Config:
    """Sizes and repeats of one bench run."""

    #: steps of the small system (one oscillator; its dt is small_dt)
    small_steps: int
    #: particles of the large system (gravity and drag)
    particles: int
    #: the cloth is a side x side grid with structural and shear springs (160: 101,442 springs)
    cloth_side: int
    #: spheres of the broadphase comparison
    broadphase_n: int
    #: oscillator periods of the accuracy-matched comparison
    periods: float
    #: fixed-step searches stop at 2^max_log2_steps steps
    max_log2_steps: int
    #: simulations in one batched call, and their steps
    batch: int
    batch_steps: int
    #: timed rounds per comparison (the plain Python loop and scipy get python_repeats)
    repeats: int
    python_repeats: int
    #: steps of the plain-Python-loop comparison (steplab runs the same number there)
    python_steps: int
    small_dt: float = 1e-3
    #: steps per timed call of the large systems; the per-step cost is the marginal one,
    #: (t(2K) - t(K)) / K, which leaves out the cost of entering and leaving the loop.
    #: 32, not 4: a call of 10^6 particles costs 40 to 150 ms before its first step (a fresh
    #: 48 MB output paged in), whose noise swamped 4 steps of 5 ms (docs/performance.md, the bench section)
    loop_steps: int = 32
    #: rounds are added after ``repeats`` until every contender's minimum settles, up to
    #: max_rounds rounds or round_budget_seconds per comparison (:mod:`.timing`)
    max_rounds: int = 25
    round_budget_seconds: float = 8.0
    #: final position error the accuracy-matched comparison asks for, m
    tolerance: float = 1e-8
    #: built-in scenes whose compile time is measured (None: all of them)
    compile_scenes: tuple[str, ...] | None = None
    #: the collision bench: (balls, steps of dt = 1/60 s) of each ball pit (:mod:`.ball_pit_scene`)
    collision_runs: tuple[tuple[int, int], ...] = ((1_000, 60), (10_000, 60))
    #: timed rounds of each ball pit (one run of 10^4 balls takes seconds)
    collision_repeats: int = 1
    #: the largest pit the engines are set up for: MuJoCo's compiler takes time quadratic
    #: in the free bodies (12 s for 10^4) and its broadphase 2 bytes per pair (20 GB for 10^5)
    collision_peer_max_balls: int = 10_000
    #: the crowded pit beside MuJoCo (:func:`.collisions.crowded_pit`): (balls, side of the box in m,
    #: steps of dt = 1/60 s), the full run's 2,000 balls in a 6 m box for one second; None: left out
    crowded_pit: tuple[int, float, int] | None = None
    #: implicit Euler on the cloth (:mod:`.implicit`): search both methods' largest useful dt
    #: (about 30 s), or time them at dt = 0.2 s / these step counts, the last full run's finding
    implicit_search: bool = False
    implicit_steps: int = 28
    semi_implicit_steps: int = 80
    #: the stacking section (:mod:`.stacking`, issue 26): the pyramid's rows (the issue's 20) and its
    #: steps per timed call, the box pits (boxes, steps of dt = 1/60 s), and the largest pit the
    #: engines are set up for
    stack_pyramid_rows: int = 20
    stack_steps: int = 10
    box_pit_runs: tuple[tuple[int, int], ...] = ((1_000, 30), (10_000, 10))
    box_pit_peer_max: int = 1_000


FULL = Config(small_steps=100_000, particles=1_000_000, cloth_side=160, broadphase_n=100_000, periods=100,
              max_log2_steps=22, batch=256, batch_steps=2_500, repeats=9, python_repeats=3, python_steps=100_000,
              collision_runs=((1_000, 60), (2_000, 60), (10_000, 60), (100_000, 6)), collision_repeats=3,
              crowded_pit=(2_000, 6.0, 60),
              implicit_search=True, max_rounds=60, round_budget_seconds=30.0, stack_steps=30,
              box_pit_runs=((1_000, 60), (10_000, 30)))
#: the systems the targets are stated for, with fewer rounds, smaller batches, 20 oscillator
#: periods for the accuracy match and 10^4 steps for the Python loop: under a minute; the
#: ball pits of 10^3 and 10^4 balls for their first 0.2 and 0.1 s (a per-step cost), the
#: engines at 10^3 only (MuJoCo's compiler alone takes 12 to 25 s for 10^4 balls)
QUICK = Config(small_steps=100_000, particles=1_000_000, cloth_side=160, broadphase_n=100_000, periods=20,
               max_log2_steps=20, batch=64, batch_steps=2_500, repeats=5, python_repeats=2, python_steps=10_000,
               collision_runs=((1_000, 12), (10_000, 6)), collision_peer_max_balls=1_000)
