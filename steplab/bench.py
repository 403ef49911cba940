"""``steplab bench``: steplab side by side with diffrax, scipy, Numba and the memory bound.

Each comparison runs the same method with the same dt and the same number of steps (the
accuracy-matched ones instead reach the same final error), in this one process. Every
contender is compiled and called once before timing; then the contenders are called in
turn, round after round, and each one's median is taken, so a burst of load from
elsewhere on the machine hits all of them alike. A ratio is steplab's median over the
peer's: below 1, steplab is faster. Each comparison also records how far apart the two
final states are, to show they computed the same thing.

The targets of issue 6 are reported as met or missed, never asserted: timings belong
in a benchmark, not in a unit test.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import sys
import time
from collections.abc import Callable

import numpy as np

#: seed of every random scene the bench builds
SEED = 20240611
#: largest acceptable ratio, steplab / peer, per comparison (issue 6, "Targets")
TARGETS = {
    "vs_diffrax_semi_implicit_euler": 0.5,
    "vs_diffrax_euler": 0.5,
    "vs_diffrax_rk4": 0.5,
    "vs_numba_semi_implicit_euler": 1.5,
    "vs_memory_bound_1e6": 1.5,
    "vs_scipy_at_1e-8": 0.05,
    "vs_ckdtree_1e5": 0.5,
}
#: longest acceptable JIT compilation of a built-in scene, s
COMPILE_TARGET_SECONDS = 2.0
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
    #: (t(2K) - t(K)) / K, which leaves out the cost of entering and leaving the loop
    loop_steps: int = 4
    #: final position error the accuracy-matched comparison asks for, m
    tolerance: float = 1e-8
    #: built-in scenes whose compile time is measured (None: all of them)
    compile_scenes: tuple[str, ...] | None = None


FULL = Config(small_steps=100_000, particles=1_000_000, cloth_side=160, broadphase_n=100_000, periods=100,
              max_log2_steps=22, batch=256, batch_steps=2_500, repeats=9, python_repeats=3, python_steps=100_000)
#: the systems the targets are stated for, with fewer rounds, smaller batches, 20 oscillator
#: periods for the accuracy match and 10^4 steps for the Python loop: under a minute
QUICK = Config(small_steps=100_000, particles=1_000_000, cloth_side=160, broadphase_n=100_000, periods=20,
               max_log2_steps=20, batch=64, batch_steps=2_500, repeats=5, python_repeats=2, python_steps=10_000)


# --- timing ------------------------------------------------------------------------------------


def interleaved_samples(calls: dict[str, Callable[[], object]], repeats: int) -> dict[str, list[float]]:
    """Wall times of each call: one warm-up call each, then ``repeats`` rounds in turn.

    Every call must block until its result exists (``block_until_ready`` for JAX).
    """
    for call in calls.values():
        call()
    samples = {name: [] for name in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            samples[name].append(time.perf_counter() - start)
    return samples


@dataclasses.dataclass(frozen=True)
class Times:
    """Seconds of one contender over the interleaved rounds: the median, and the minimum.

    On a shared machine a call the scheduler preempts loses whole time slices (4 ms at
    250 Hz), so times cluster at the true cost plus multiples of the slice. The median is
    the headline (the issue's contract); the minimum is the least-disturbed round, and the
    ratio of minimums is reported beside the ratio of medians.
    """

    median: float
    minimum: float
    rounds: int

    @classmethod
    def of(cls, samples) -> Times:
        return cls(float(np.median(samples)), float(np.min(samples)), len(samples))

    @classmethod
    def exactly(cls, seconds: float) -> Times:
        return cls(seconds, seconds, 1)


def interleaved_times(calls: dict[str, Callable[[], object]], repeats: int) -> dict[str, Times]:
    """:class:`Times` of each call, the calls interleaved (see :func:`interleaved_samples`)."""
    return {name: Times.of(s) for name, s in interleaved_samples(calls, repeats).items()}


def interleaved_medians(calls: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median wall time of each call, the calls interleaved (see :func:`interleaved_samples`)."""
    return {name: t.median for name, t in interleaved_times(calls, repeats).items()}


def _ready(x):
    import jax

    return jax.block_until_ready(x)


def loop_kernels(compiled_text: str) -> list[dict]:
    """The operations XLA runs per iteration of each while loop in a compiled program.

    From ``jax.jit(f).lower(...).compile().as_text()``: for each while loop, the number of
    fused kernels and of buffer copies in its body, and the loops nested in it. On the CPU
    each costs a roughly fixed few nanoseconds, which for a small system is the step's cost.
    """
    computations, current = {}, None
    for line in compiled_text.splitlines():
        head = re.match(r"^(?:ENTRY )?%(\S+) ", line)
        if head and line.rstrip().endswith("{"):
            current = computations.setdefault(head.group(1), [])
        elif line.startswith("}"):
            current = None
        elif current is not None:
            current.append(line)
    loops = []
    for lines in computations.values():
        for line in lines:
            body = re.search(r" while\(.*body=%([\w.\-]+)", line)
            if body:
                ops = computations.get(body.group(1), [])
                names = [re.match(r"\s*(?:ROOT )?%(\S+) =", op) for op in ops
                         if " fusion(" in op or " copy(" in op]
                loops.append({"kernels": sum(" fusion(" in op for op in ops),
                              "copies": sum(" copy(" in op for op in ops),
                              "nested_loops": sum(" while(" in op for op in ops),
                              "ops": [m.group(1) for m in names if m]})
    return loops


def _compiled_text(jitted, *args) -> str:
    return jitted.lower(*args).compile().as_text()


def _difference(a, b) -> float:
    """Largest |difference| of two final states (positions and velocities), or of two arrays."""
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)), initial=0.0))


class Record:
    """The numbers of one bench run, as ``--json`` writes them."""

    def __init__(self, config: Config, quick: bool):
        self.data = {"quick": quick, "config": dataclasses.asdict(config), "ratios": {}, "seconds": {},
                     "targets": {}, "details": {}, "compile_seconds": {}, "order": []}

    def compare(self, name: str, group: str, what: str, peer: str, steplab: Times, peer_times: Times,
                difference: float | None = None, **details) -> None:
        """Record ratio ``name`` = steplab's median / the peer's, both medians and what was compared.

        ``difference`` is the largest |difference| of the two final states (None where the
        peer computes no state, as for the memory bound).
        """
        self.data["ratios"][name] = steplab.median / peer_times.median
        self.data["seconds"][name] = {
            "steplab": steplab.median, "peer": peer_times.median, "peer_name": peer, "group": group, "what": what,
            "difference": difference, "steplab_min": steplab.minimum, "peer_min": peer_times.minimum,
            "ratio_of_minimums": steplab.minimum / peer_times.minimum, "rounds": steplab.rounds, **details}
        self.data["order"].append(name)
        self._check_target(name)

    def alias(self, name: str, source: str) -> None:
        """A contract name for another comparison's numbers (e.g. the worse of two problems)."""
        self.data["ratios"][name] = self.data["ratios"][source]
        self.data["seconds"][name] = self.data["seconds"][source] | {"alias_of": source}
        self._check_target(name)

    def _check_target(self, name: str) -> None:
        if name in TARGETS:
            ratio = self.data["ratios"][name]
            self.data["targets"][name] = {"target": TARGETS[name], "ratio": ratio, "met": ratio <= TARGETS[name]}
            source = self.data["seconds"][name].get("alias_of")
            if source is not None:
                self.data["targets"][name]["alias_of"] = source


# --- 1. the small system: one oscillator, 10^5 steps ---------------------------------------------


def small_system(config: Config, record: Record, progress) -> None:
    """steplab's compiled loop against diffrax, Numba and a Python loop, method by method."""
    import jax.numpy as jnp

    from steplab.integrators.simulate import final_state_function
    from steplab.studies.problems import oscillator_problem

    from . import peers

    problem = oscillator_problem(0.0)
    model = problem.model.cast(jnp)
    y0, n, dt = jnp.asarray(problem.y0), config.small_steps, config.small_dt
    system = peers.PointMasses.from_model(problem.model)
    calls, finals = {}, {}
    for method in peers.DIFFRAX_METHODS:
        run = final_state_function(model, method)
        solve = peers.diffrax_fixed_step(model, method, 0.0, dt, n)
        calls[("steplab", method)] = lambda run=run: _ready(run(y0, 0.0, dt, n)[0])
        calls[("diffrax", method)] = lambda solve=solve: _ready(solve(y0)[0])
        finals[("steplab", method)] = run(y0, 0.0, dt, n)[0]
        finals[("diffrax", method)], steps = solve(y0)
        if int(steps) != n:
            raise RuntimeError(f"diffrax took {int(steps)} steps instead of {n}")
    sie = "semi-implicit-euler"
    calls[("numba", sie)] = lambda: peers.numba_semi_implicit_euler(system, problem.y0, dt, n)
    finals[("numba", sie)] = calls[("numba", sie)]()
    progress("small system: compiled")
    t = interleaved_times(calls, config.repeats)
    what = f"one oscillator, {n:,} steps of dt = {dt:g} s"
    for method in peers.DIFFRAX_METHODS:
        key = method.replace("-", "_")
        kernels = {"steplab_loop_kernels": loop_kernels(_compiled_text(final_state_function(model, method),
                                                                       y0, 0.0, dt, n)),
                   "peer_loop_kernels": loop_kernels(_compiled_text(peers.diffrax_fixed_step(model, method, 0.0, dt, n),
                                                                    y0))}
        record.compare(f"vs_diffrax_{key}", "small system", f"{method}: {what}", f"diffrax {_diffrax_name(method)}",
                       t[("steplab", method)], t[("diffrax", method)],
                       _difference(finals[("steplab", method)], finals[("diffrax", method)]), **kernels)
    record.compare("vs_numba_semi_implicit_euler", "small system", f"{sie}: {what}", "Numba loop",
                   t[("steplab", sie)], t[("numba", sie)],
                   _difference(finals[("steplab", sie)], finals[("numba", sie)]))
    # the plain Python loop is slow: fewer rounds, each interleaved with a steplab run
    m, run = config.python_steps, final_state_function(model, sie)
    python = {"steplab": lambda: _ready(run(y0, 0.0, dt, m)[0]),
              "python": lambda: peers.numpy_semi_implicit_euler(system, problem.y0, dt, m)}
    tp = interleaved_times(python, config.python_repeats)
    record.compare("vs_python_loop_semi_implicit_euler", "small system",
                   f"{sie}: one oscillator, {m:,} steps of dt = {dt:g} s", "Python loop over NumPy",
                   tp["steplab"], tp["python"], _difference(python["steplab"](), python["python"]()))


def _diffrax_name(method: str) -> str:
    return {"semi-implicit-euler": "SemiImplicitEuler", "euler": "Euler", "rk4": "RK4 (AbstractERK tableau)"}[method]


# --- 2. large systems: 10^6 particles, a cloth of 10^5 springs ---------------------------------


def particles_model(n: int, seed: int = SEED):
    """``n`` spheres under gravity and quadratic drag, and a random initial state (2, n, 3)."""
    from steplab.physics import Drag, Gravity, Model

    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.01, 0.1, n)
    model = Model(rng.uniform(0.5, 2.0, n), radii, [Gravity(), Drag.from_coefficients(radii)])
    y0 = np.stack([rng.uniform(-100.0, 100.0, (n, 3)), rng.normal(0.0, 5.0, (n, 3))])
    return model, y0


def cloth_model(side: int):
    """A side x side cloth: structural and shear springs with dampers, gravity, two corners pinned.

    1 g per particle and 50 N/m springs: stable with semi-implicit Euler at dt = 5e-4 s
    (omega dt < 0.5 for a particle held by eight springs).
    """
    from steplab.physics import Gravity, Model
    from steplab.physics.soft_body import connect, grid

    mesh = grid(side, side, 1.0 / side, origin=(0.0, 0.0, 2.0))
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=50.0, damping=0.005)
    n = side * side
    pinned = np.zeros(n, bool)
    pinned[[0, side - 1]] = True
    model = Model(np.full(n, 1e-3), np.full(n, 0.2 / side), [Gravity(), springs, dampers], pinned=pinned)
    velocity = np.random.default_rng(SEED).normal(0.0, 0.01, (n, 3)) * ~pinned[:, None]
    return model, np.stack([mesh.vertices, velocity]), springs.i.size


def _step_bytes(model, system) -> tuple[int, int]:
    """Bytes one semi-implicit Euler step must move: (read and written, read only).

    The state q, v is read and written; the force data (1/m, drag factors, per-body gravity
    where bodies are pinned, spring and damper indices and coefficients) is only read.
    """
    state = 2 * model.n_bodies * 3 * 8
    data = system.inverse_masses.nbytes + system.spring_i.nbytes * 4 + system.damper_i.nbytes * 3
    if np.any(system.beta):
        data += system.beta.nbytes
    if np.asarray(model.pinned).any():
        data += system.field.nbytes  # gravity masked per body
    return state, data


def large_systems(config: Config, record: Record, progress) -> None:
    """One semi-implicit Euler step of 10^6 particles and of a 10^5-spring cloth."""
    model, y0 = particles_model(config.particles)
    _large_system("1e6", f"{model.n_bodies:,} particles under gravity and drag, one semi-implicit Euler step",
                  model, y0, 1e-3, config, record)
    progress("large system 1e6: done")
    model, y0, springs = cloth_model(config.cloth_side)
    _large_system("cloth_1e5_springs", f"cloth of {model.n_bodies:,} particles, {springs:,} springs and dampers, "
                  "gravity, one semi-implicit Euler step", model, y0, 5e-4, config, record)
    progress("large system cloth: done")


def _large_system(label: str, what: str, model, y0, dt: float, config: Config, record: Record) -> None:
    """One large system against Numba and against the memory bound.

    The step is timed inside steplab's compiled loop (``final_state_function``, what
    ``simulate(backend="jax")`` runs) as the marginal cost (t(2K) - t(K)) / K, which leaves
    out entering and leaving the loop; the Numba loop likewise, stepping one buffer in
    place. The memory bound is the time NumPy takes to stream the bytes the step must
    move (:func:`steplab.peers.memory_stream`): the state read and written in place, the
    force data read.
    """
    import jax.numpy as jnp

    from steplab.integrators.simulate import final_state_function

    from . import peers

    k = config.loop_steps
    system = peers.PointMasses.from_model(model)
    start = time.perf_counter()
    jmodel = model.cast(jnp)
    run = final_state_function(jmodel, "semi-implicit-euler")
    yj = jnp.asarray(y0)
    run(yj, 0.0, dt, 1)[0].block_until_ready()
    record.data["compile_seconds"][f"step, {label}"] = time.perf_counter() - start
    unchecked = _unchecked_loop(jmodel, "semi-implicit-euler")
    kernel = peers.numba_kernel()
    buffer = np.array(y0)  # Numba steps this buffer in place, as a game engine would
    read_write, read_only = _step_bytes(model, system)
    stream = peers.memory_stream(read_write, read_only)
    samples = interleaved_samples({
        ("steplab", 1): lambda: _ready(run(yj, 0.0, dt, k)[0]),
        ("steplab", 2): lambda: _ready(run(yj, 0.0, dt, 2 * k)[0]),
        ("numba", 1): lambda: kernel(buffer[0], buffer[1], *system.arrays, dt, k),
        ("numba", 2): lambda: kernel(buffer[0], buffer[1], *system.arrays, dt, 2 * k),
        ("unchecked", 1): lambda: _ready(unchecked(yj, 0.0, dt, k)),
        ("unchecked", 2): lambda: _ready(unchecked(yj, 0.0, dt, 2 * k)),
        "stream": stream,
    }, config.repeats)
    t = {name: float(np.median(s)) for name, s in samples.items()}
    # The marginal cost of k more steps: the median of the differences of the two calls of
    # a round (adjacent in time), and the difference of the two minimums. Where noise
    # swamps it (not positive), the average over 2k steps instead, an upper bound.
    per_step, estimate = {}, {}
    for name in ("steplab", "numba", "unchecked"):
        marginal = float(np.median(np.subtract(samples[(name, 2)], samples[(name, 1)]))) / k
        least = (min(samples[(name, 2)]) - min(samples[(name, 1)])) / k
        per_step[name] = Times(marginal if marginal > 0 else t[(name, 2)] / (2 * k),
                               least if least > 0 else min(samples[(name, 2)]) / (2 * k), config.repeats)
        estimate[name] = "marginal" if marginal > 0 else "average (noise swamped the marginal cost)"
    bound = Times.of(samples["stream"])
    difference = _difference(run(yj, 0.0, dt, k)[0], peers.numba_semi_implicit_euler(system, y0, dt, k))
    calls = {"steplab_call_seconds": {f"{k} steps": t[("steplab", 1)], f"{2 * k} steps": t[("steplab", 2)]},
             "numba_call_seconds": {f"{k} steps": t[("numba", 1)], f"{2 * k} steps": t[("numba", 2)]},
             "per_step_estimate": estimate,
             # the profile: what the compiled loop runs per step, and the step without the
             # loop's per-step divergence check (the rest of the gap is the step itself)
             "steplab_loop_kernels": loop_kernels(_compiled_text(run, yj, 0.0, dt, k)),
             "steplab_step_without_divergence_check": per_step["unchecked"].median}
    record.compare(f"vs_memory_bound_{label}", "large system", what, "memory-traffic bound (NumPy, in place)",
                   per_step["steplab"], bound, None, bytes_read_and_written=read_write, bytes_read=read_only,
                   bandwidth_bytes_per_s=(2 * read_write + read_only) / bound.median, dt=dt, **calls)
    record.compare(f"vs_numba_{label}", "large system", what, "Numba loop, in place", per_step["steplab"],
                   per_step["numba"], difference, dt=dt, **calls)


def _unchecked_loop(model, method: str):
    """steplab's compiled loop without its per-step divergence check: for profiling only."""
    import jax
    from jax import lax

    from steplab.integrators import get_integrator

    integrator = get_integrator(method)

    def run(y0, t_start, dt, n):
        def one_step(k, state):
            y, carry = state
            return integrator.step(model, t_start + k * dt, y, dt, carry)

        return lax.fori_loop(0, n, one_step, (y0, integrator.init(model, t_start, y0)))[0]

    return jax.jit(run)


# --- 3. accuracy-matched: time to reach a final error ----------------------------------------


def _fixed_step_search(problem, method: str, truth, tol: float, max_log2: int):
    """Fewest steps (to 1/64) with final position error <= tol, or None within 2^max_log2 steps."""
    import jax.numpy as jnp

    from steplab.integrators.simulate import final_state_function

    run = final_state_function(problem.model.cast(jnp), method)
    y0 = jnp.asarray(problem.y0)
    span = problem.t_end - problem.t_start

    def error(n):
        y, bad = run(y0, problem.t_start, span / n, n)
        return np.inf if int(bad) >= 0 else _position_error(y, truth)

    hi = next((2**k for k in range(4, max_log2 + 1) if error(2**k) <= tol), None)
    if hi is None:
        return None
    lo = hi // 2
    while hi - lo > max(1, hi // 64):
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if error(mid) <= tol else (mid, hi)
    return {"method": method, "steps": hi, "dt": span / hi, "error": error(hi),
            "call": lambda: _ready(run(y0, problem.t_start, span / hi, hi)[0])}


def _position_error(y, truth) -> float:
    return float(np.max(np.abs(np.asarray(y, dtype=float)[0] - truth[0])))


def _tolerance_search(solve, tol: float):
    """The loosest rtol on a 10^(1/4) grid whose solve reaches error <= tol: (rtol, error, info)."""
    previous = None
    for k in range(16, 53, 2):  # rtol 1e-4 .. 1e-13, by factors of sqrt(10)
        rtol = 10.0 ** (-k / 4)
        err, info = solve(rtol)
        if err <= tol:
            if previous is not None:  # one finer look between the last two points
                between = 10.0 ** (-(k - 1) / 4)
                err_b, info_b = solve(between)
                if err_b <= tol:
                    return between, err_b, info_b
            return rtol, err, info
        previous = rtol
    return None


def accuracy_matched(config: Config, record: Record, progress) -> None:
    """Time to a final position error of 1e-8 m: steplab's fastest method against scipy and diffrax."""
    from steplab.studies.problems import oscillator_problem, scene_problem

    # 100 periods and an eighth: at whole periods the mass is at rest at a turning point,
    # where a phase error hardly moves it and a method would look more accurate than it is
    problems = {"oscillator": oscillator_problem(0.0, t_end=config.periods + 0.125),
                "drag_projectile": scene_problem("drag-projectile", 2.5, "football with quadratic drag")}
    names = {"scipy": [], "diffrax": []}
    for label, problem in problems.items():
        for peer, name in _accuracy_problem(label, problem, config, record).items():
            names[peer].append(name)
        progress(f"accuracy-matched {label}: done")
    # the contract's headline ratio is the worse (larger) of the two problems
    for peer, headline in (("scipy", "vs_scipy_at_1e-8"), ("diffrax", "vs_diffrax_tsit5_at_1e-8")):
        record.alias(headline, max(names[peer], key=lambda n: record.data["ratios"][n]))


def _accuracy_problem(label: str, problem, config: Config, record: Record) -> dict[str, str]:
    import jax.numpy as jnp
    from scipy.integrate import solve_ivp

    from steplab.integrators import INTEGRATORS, Stepper
    from steplab.studies.problems import true_final

    from . import peers

    tol = config.tolerance
    truth, reference = true_final(problem)
    # Explicit methods of order >= 2: a first-order method needs about span / tol steps
    # (10^8 and more here), and implicit Euler is first order as well.
    found = [_fixed_step_search(problem, name, truth, tol, config.max_log2_steps)
             for name, method in INTEGRATORS.items()
             if isinstance(method, Stepper) and not method.implicit and method.order >= 2]
    found = [f for f in found if f is not None]
    if not found:
        raise RuntimeError(f"no fixed-step method reaches {tol:g} m on {label} within 2^{config.max_log2_steps} steps")
    first_look = interleaved_times({f["method"]: f["call"] for f in found}, 3)
    best = min(found, key=lambda f: first_look[f["method"]].minimum)

    y0 = np.asarray(problem.y0, float)
    span = (problem.t_start, problem.t_end)
    fun = lambda t, y: problem.model.vector_field(t, y.reshape(y0.shape)).ravel()  # noqa: E731
    scipy_call = lambda rtol: solve_ivp(fun, span, y0.ravel(), method="DOP853", rtol=rtol, atol=rtol)  # noqa: E731

    def scipy_solve(rtol):
        sol = scipy_call(rtol)
        return (_position_error(sol.y[:, -1].reshape(y0.shape), truth),
                {"steps": int(sol.t.size - 1), "evaluations": int(sol.nfev)})

    adaptive = peers.diffrax_adaptive(problem.model.cast(jnp), "Tsit5", *span)
    yj = jnp.asarray(y0)

    def diffrax_solve(rtol):
        y, steps = adaptive(yj, jnp.asarray(rtol))
        return _position_error(y, truth), {"steps": int(steps)}

    found_peers = {"scipy": _tolerance_search(scipy_solve, tol), "diffrax": _tolerance_search(diffrax_solve, tol)}
    for peer, result in found_peers.items():
        if result is None:
            raise RuntimeError(f"{peer} does not reach {tol:g} m on {label} at rtol >= 1e-13")
    s_rtol, d_rtol = found_peers["scipy"][0], found_peers["diffrax"][0]
    t = interleaved_times({"steplab": best["call"], "scipy": lambda: scipy_call(s_rtol),
                             "diffrax": lambda: _ready(adaptive(yj, jnp.asarray(d_rtol))[0])},
                            config.python_repeats)
    what = (f"{label.replace('_', ' ')} to t = {problem.t_end:g} s, final position error <= {tol:g} m: "
            f"steplab {best['method']} with {best['steps']:,} steps")
    common = {"steplab_method": best["method"], "steplab_steps": best["steps"], "steplab_error": best["error"],
              "candidates": {f["method"]: f["steps"] for f in found}, "reference": reference.get("reference")}
    names = {}
    for peer, peer_label in (("scipy", "scipy DOP853 (solve_ivp)"), ("diffrax", "diffrax Tsit5 (PID)")):
        rtol, err, info = found_peers[peer]
        name = f"vs_{peer}_{'tsit5_' if peer == 'diffrax' else ''}at_1e-8_{label}"
        record.compare(name, "accuracy-matched", what, f"{peer_label}, rtol=atol={rtol:.2g}",
                       t["steplab"], t[peer], None, peer_rtol=rtol, peer_error=err, **common,
                       **{f"peer_{key}": value for key, value in info.items()})
        names[peer] = name
    return names


# --- 4. broadphase ------------------------------------------------------------------------------


def broadphase(config: Config, record: Record, progress) -> None:
    """steplab's fastest broadphase method against scipy's cKDTree.query_pairs, uniform spheres."""
    try:
        from steplab.physics.broadphase import METHODS, find_pairs
    except ImportError:  # the broadphase is not part of this checkout
        record.data["details"]["broadphase"] = "physics.broadphase.find_pairs is not available"
        return
    from scipy.spatial import cKDTree

    n = config.broadphase_n
    rng = np.random.default_rng(SEED)
    centers = rng.uniform(0.0, 1.0, (n, 3))
    radius = 0.004 * (1e5 / n) ** (1 / 3)  # about 0.2 neighbours per sphere
    methods = [m for m in METHODS if m != "brute"]  # brute is O(n^2), the reference only
    for method in methods:  # compile any Numba kernels before timing
        find_pairs(centers[:256], radius, method)
    first_look = interleaved_times({m: (lambda m=m: find_pairs(centers, radius, m)) for m in methods}, 2)
    once = {m: first_look[m].minimum for m in methods}
    fastest = min(methods, key=once.get)
    calls = {"steplab": lambda: find_pairs(centers, radius, fastest),
             "ckdtree": lambda: cKDTree(centers).query_pairs(2 * radius, output_type="ndarray")}
    t = interleaved_times(calls, config.repeats)
    ours = {tuple(p) for p in calls["steplab"]().tolist()}
    theirs = {tuple(sorted(p)) for p in calls["ckdtree"]().tolist()}
    record.compare(f"vs_ckdtree_{_exponent(n)}", "broadphase",
                   f"{n:,} spheres of radius {radius:.3g} uniform in the unit cube, {len(ours):,} pairs",
                   "scipy cKDTree (build + query_pairs)", t["steplab"], t["ckdtree"], float(len(ours ^ theirs)),
                   steplab_method=fastest, single_call_seconds=once)
    if n != 100_000:  # the contract's key, whatever n this run used
        record.alias("vs_ckdtree_1e5", f"vs_ckdtree_{_exponent(n)}")
    progress("broadphase: done")


def _exponent(n: int) -> str:
    e = int(round(np.log10(n)))
    return f"1e{e}" if 10**e == n else str(n)


# --- 5. compile times, 6. batching ------------------------------------------------------------------


def compile_times(config: Config, record: Record, progress) -> None:
    """JIT compilation of every built-in scene's compiled loop (simulate's ``compile_time``)."""
    from steplab.integrators import Stepper, get_integrator, simulate
    from steplab.physics.scene import builtin_scenes, load_scene

    for name in config.compile_scenes or builtin_scenes():
        scene = load_scene(name)
        if not isinstance(get_integrator(scene.integrator), Stepper):
            continue
        traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, scene.t_start + 4 * scene.dt,
                        scene.dt, backend="jax")
        record.data["compile_seconds"][f"scene {name} ({scene.integrator})"] = traj.compile_time
    scenes = {k: v for k, v in record.data["compile_seconds"].items() if k.startswith("scene ")}
    worst = max(scenes.values())
    record.data["targets"]["compile_seconds_max"] = {"target": COMPILE_TARGET_SECONDS, "seconds": worst,
                                                     "scene": max(scenes, key=scenes.get),
                                                     "met": worst <= COMPILE_TARGET_SECONDS}
    progress("compile times: done")


def batching(config: Config, record: Record, progress) -> None:
    """Many simulations in one vmapped compiled call against a Python loop of single runs.

    Over initial conditions and over dt on the drag projectile (per-body forces), and over
    initial conditions on the oscillator (a spring: a gather and a scatter-add per step).
    """
    import jax
    import jax.numpy as jnp

    from steplab.integrators.simulate import final_state_function
    from steplab.physics.scene import load_scene
    from steplab.studies.problems import oscillator_problem

    b, n = config.batch, config.batch_steps
    projectile, oscillator = load_scene("drag-projectile"), oscillator_problem(0.0)
    launches = np.repeat(projectile.y0[None], b, axis=0)
    launches[:, 1, 0, :] *= np.linspace(0.5, 1.5, b)[:, None]  # b launch speeds, same direction
    amplitudes = np.repeat(oscillator.y0[None], b, axis=0)
    amplitudes[:, 0, 1, 0] += np.linspace(-0.4, 0.4, b)
    cases = (
        ("initial_conditions", projectile, "rk4", launches, 1e-3,
         f"drag projectile, rk4: {b} launch speeds, {n:,} steps each"),
        ("dt", projectile, "rk4", None, np.geomspace(1e-4, 1e-3, b),
         f"drag projectile, rk4: {b} values of dt, {n:,} steps each"),
        ("springs", oscillator, "semi-implicit-euler", amplitudes, 1e-3,
         f"oscillator (one spring), semi-implicit Euler: {b} amplitudes, {n:,} steps each"),
    )
    for label, problem, method, starts, dt, what in cases:
        run = final_state_function(problem.model.cast(jnp), method)
        if starts is not None:
            batched = jax.jit(jax.vmap(run, in_axes=(0, None, None, None)))
            args, singles = (jnp.asarray(starts), 0.0, dt, n), [(jnp.asarray(y), 0.0, dt, n) for y in starts]
        else:
            batched = jax.jit(jax.vmap(run, in_axes=(None, None, 0, None)))
            y0 = jnp.asarray(problem.y0)
            args, singles = (y0, 0.0, jnp.asarray(dt), n), [(y0, 0.0, jnp.asarray(h), n) for h in dt]
        # the loop's inputs are on the device before timing, as the batched call's are
        calls = {"batched": lambda batched=batched, args=args: _ready(batched(*args)[0]),
                 "loop": lambda run=run, singles=singles: _ready([run(*a)[0] for a in singles])}
        t = interleaved_times(calls, config.repeats)
        difference = _difference(calls["batched"](), np.stack(calls["loop"]()))
        record.compare(f"batched_vs_loop_{label}", "batching", what, "Python loop of single compiled runs",
                       t["batched"], t["loop"], difference, speedup=t["loop"].median / t["batched"].median)
    progress("batching: done")


SECTIONS = (small_system, large_systems, accuracy_matched, broadphase, compile_times, batching)


def run_bench(config: Config, quick: bool = False, progress: Callable[[str], None] | None = None) -> dict:
    """Run every comparison; returns the record ``--json`` writes."""
    from steplab.studies.runner import provenance

    progress = progress or (lambda message: None)
    record = Record(config, quick)
    start = time.perf_counter()
    for section in SECTIONS:
        begin = time.perf_counter()
        section(config, record, progress)
        record.data["details"].setdefault("section_seconds", {})[section.__name__] = time.perf_counter() - begin
    record.data["details"]["total_seconds"] = time.perf_counter() - start
    # what Equinox actually runs with (it reads EQX_ON_ERROR once, when first imported)
    from equinox import _config as equinox_config

    record.data["details"]["EQX_ON_ERROR"] = getattr(equinox_config, "EQX_ON_ERROR", None)
    record.data["provenance"] = provenance()
    return record.data


# --- output -------------------------------------------------------------------------------------


def rows(record: dict) -> list[dict]:
    """One row per comparison, in the order run: name, group, what, peer, medians, ratio, target."""
    out = []
    for name in record["order"]:
        s = record["seconds"][name]
        target = record["targets"].get(name) or next(
            (t for t in record["targets"].values() if t.get("alias_of") == name), None)
        out.append({"name": name, "group": s["group"], "what": s["what"], "peer": s["peer_name"],
                    "steplab": s["steplab"], "peer_seconds": s["peer"], "ratio": record["ratios"][name],
                    "ratio_of_minimums": s.get("ratio_of_minimums"),
                    "target": None if target is None else target["target"],
                    "met": None if target is None else target["met"]})
    return out


def _seconds(s: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if s >= scale:
            return f"{s / scale:.3g} {unit}"
    return f"{s:.2g} s"


def _verdict(row) -> str:
    if row["target"] is None:
        return ""
    return f"≤ {row['target']:g}: {'met' if row['met'] else 'missed'}"


def format_table(record: dict) -> str:
    lines = [f"{'group':<17} {'comparison':<40} {'peer':<44} {'steplab':>9} {'peer':>9} {'ratio':>7} "
             f"{'(min)':>7}  target on the ratio"]
    for r in rows(record):
        lines.append(f"{r['group']:<17} {r['name']:<40} {r['peer'][:44]:<44} {_seconds(r['steplab']):>9} "
                     f"{_seconds(r['peer_seconds']):>9} {r['ratio']:>7.3g} {_ratio(r['ratio_of_minimums']):>7}  "
                     f"{_verdict(r)}")
    lines += _footer(record)
    return "\n".join(lines)


def format_markdown(record: dict) -> str:
    lines = ["| comparison | what | peer | steplab | peer | ratio | ratio of minimums | target |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows(record):
        lines.append(f"| `{r['name']}` | {r['what']} | {r['peer']} | {_seconds(r['steplab'])} | "
                     f"{_seconds(r['peer_seconds'])} | {r['ratio']:.3g} | {_ratio(r['ratio_of_minimums'])} | "
                     f"{_verdict(r)} |")
    lines.append("")
    lines += [f"- {line}" for line in _footer(record)]
    return "\n".join(lines)


def _ratio(value) -> str:
    return "" if value is None else f"{value:.3g}"


def _footer(record: dict) -> list[str]:
    out = []
    c = record["targets"].get("compile_seconds_max")
    if c is not None:
        out.append(f"JIT compile time, slowest built-in scene: {c['seconds']:.3g} s ({c['scene']}); "
                   f"target ≤ {c['target']:g} s: {'met' if c['met'] else 'missed'}")
    others = {k: v for k, v in record["compile_seconds"].items() if not k.startswith("scene ")}
    if others:
        out.append("JIT compile time, " + ", ".join(f"{k}: {v:.3g} s" for k, v in others.items()))
    prov = record.get("provenance", {})
    mode = "quick" if record["quick"] else "full"
    out.append(f"ratio = steplab median / peer median (below 1: steplab faster), (min) the same of the "
               f"fastest rounds; {mode} run, "
               f"{record['config']['repeats']} interleaved rounds; {prov.get('cpu', '?')}, "
               f"jax {prov.get('packages', {}).get('jax', '?')}, commit {str(prov.get('git_commit'))[:10]}")
    return out


def fair_diffrax() -> None:
    """Turn off Equinox's run-time error checks for this process, as diffrax's FAQ asks.

    When comparing with other JAX code, the FAQ says to set ``EQX_ON_ERROR=nan`` before
    Equinox is imported: Equinox reads it once, at import, so this only acts before any
    diffrax use (the record says what Equinox actually ran with). Only ``steplab bench``, a process of its
    own, calls it: elsewhere diffrax must keep raising on a failed solve.
    """
    if "equinox" not in sys.modules:
        os.environ.setdefault("EQX_ON_ERROR", "nan")


def command(args) -> int:
    """``steplab bench``: run (or, with ``--from``, re-print) the comparisons."""
    fair_diffrax()
    if args.source is not None:
        record = json.loads(args.source.read_text())
    else:
        config = QUICK if args.quick else FULL
        log = (lambda message: print(f"[bench] {message}", file=sys.stderr, flush=True))
        record = run_bench(config, quick=args.quick, progress=log)
        if args.json is not None:
            from steplab.io import write_json

            write_json(args.json, record)
    print(format_markdown(record) if args.markdown else format_table(record))
    return 0
