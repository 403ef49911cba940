"""The comparisons of ``steplab bench``, one function per section of the report.

1. the small system (one oscillator, 10^5 steps) against diffrax, Numba and a Python loop;
2. large systems (10^6 particles, a 10^5-spring cloth) against Numba and the memory bound;
3. accuracy-matched: time to a final error of 1e-8 m against scipy and diffrax;
4. broadphase against scipy's cKDTree; 5. compile times; 6. batching with ``jax.vmap``;
7. collisions: ball pits of 10^3 to 10^5 spheres against MuJoCo and pybullet (:mod:`.collisions`);
8. implicit Euler's step on the cloth against semi-implicit Euler's (:mod:`.implicit`, issue 16);
9. start-up: the light commands in fresh processes beside ``import numpy`` (:mod:`.startup`, issue 29);
10. rotation: 10^5 free tumbling bodies, one exponential-map step against the memory bound (:mod:`.rotation`);
11. stacking: the 20-row pyramid and 10^3 and 10^4 boxes falling into a box, beside MuJoCo and pybullet
    (:mod:`.stacking`).
12. the cloth under XPBD: its step against the memory bound, a Numba loop and NVIDIA Newton (:mod:`.cloth`, issue 28);
13. Newton's rigid-body solvers on the rotation study's tumbling box (:mod:`.newton_rotation`, issue 28).

Each section takes the :class:`.Config`, the :class:`.Record` and a progress callback.
"""

from __future__ import annotations

import math
import time

import numpy as np

from steplab.core.timing import Times, interleaved_times, ready
from steplab.integrators.references import solve_adaptive
from steplab.integrators.simulate import final_state_function

from .cloth import xpbd_cloth
from .collisions import ball_pits
from .config import COMPILE_TARGET_SECONDS, SEED, Config
from .implicit import implicit_euler_cloth
from .newton_rotation import newton_tumbling
from .profile import compiled_text, loop_kernels
from .record import Record, final_difference, size_label
from .rotation import tumbling_bodies
from .stacking import stacking
from .startup import startup
from .systems import cloth_model, particles_model, step_bytes
from .timing import marginal_times, settled_samples, settled_times

# --- 1. the small system: one oscillator, 10^5 steps ---------------------------------------------


def small_system(config: Config, record: Record, progress) -> None:
    """steplab's compiled loop against diffrax, Numba and a Python loop, method by method."""
    import jax.numpy as jnp

    from steplab import peers
    from steplab.studies.problems import oscillator_problem

    problem = oscillator_problem(0.0)
    model = problem.model.cast(jnp)
    y0, n, dt = jnp.asarray(problem.y0), config.small_steps, config.small_dt
    system = peers.PointMasses.from_model(problem.model)
    calls, finals, compiled = {}, {}, {}
    for method in peers.DIFFRAX_METHODS:
        run = final_state_function(model, method)
        solve = peers.diffrax_fixed_step(model, method, 0.0, dt, n)
        compiled[method] = run, solve  # their programs' texts below, without compiling them again
        calls[("steplab", method)] = lambda run=run: ready(run(y0, 0.0, dt, n)[0])
        calls[("diffrax", method)] = lambda solve=solve: ready(solve(y0)[0])
        finals[("steplab", method)] = run(y0, 0.0, dt, n)[0]
        finals[("diffrax", method)], steps = solve(y0)
        if int(steps) != n:
            raise RuntimeError(f"diffrax took {int(steps)} steps instead of {n}")
    sie = "semi-implicit-euler"
    calls[("numba", sie)] = lambda: peers.numba_semi_implicit_euler(system, problem.y0, dt, n)
    finals[("numba", sie)] = calls[("numba", sie)]()
    progress("small system: compiled")
    t = settled_times(calls, config)
    what = f"one oscillator, {n:,} steps of dt = {dt:g} s"
    for method in peers.DIFFRAX_METHODS:
        key, (run, solve) = method.replace("-", "_"), compiled[method]
        kernels = {"steplab_loop_kernels": loop_kernels(compiled_text(run, y0, 0.0, dt, n)),
                   "peer_loop_kernels": loop_kernels(compiled_text(solve, y0))}
        record.compare(f"vs_diffrax_{key}", "small system", f"{method}: {what}", f"diffrax {_diffrax_name(method)}",
                       t[("steplab", method)], t[("diffrax", method)],
                       final_difference(finals[("steplab", method)], finals[("diffrax", method)]), **kernels)
    record.compare("vs_numba_semi_implicit_euler", "small system", f"{sie}: {what}", "Numba loop",
                   t[("steplab", sie)], t[("numba", sie)],
                   final_difference(finals[("steplab", sie)], finals[("numba", sie)]))
    # the plain Python loop is slow: fewer rounds, each interleaved with a steplab run
    m, (run, _) = config.python_steps, compiled[sie]  # n traced: the same program for m steps
    python = {"steplab": lambda: ready(run(y0, 0.0, dt, m)[0]),
              "python": lambda: peers.numpy_semi_implicit_euler(system, problem.y0, dt, m)}
    tp = settled_times(python, config, config.python_repeats)
    record.compare("vs_python_loop_semi_implicit_euler", "small system",
                   f"{sie}: one oscillator, {m:,} steps of dt = {dt:g} s", "Python loop over NumPy",
                   tp["steplab"], tp["python"], final_difference(python["steplab"](), python["python"]()))


def _diffrax_name(method: str) -> str:
    return {"semi-implicit-euler": "SemiImplicitEuler", "euler": "Euler", "rk4": "RK4 (AbstractERK tableau)"}[method]


# --- 2. large systems: 10^6 particles, a cloth of 10^5 springs ---------------------------------


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

    from steplab import peers

    k = config.loop_steps
    system = peers.PointMasses.from_model(model)
    start = time.perf_counter()
    jmodel = model.cast(jnp)
    run = final_state_function(jmodel, "semi-implicit-euler")
    yj = jnp.asarray(y0)
    run(yj, 0.0, dt, 1)[0].block_until_ready()
    record.data["compile_seconds"][f"step, {label}"] = time.perf_counter() - start
    # the same loop without its per-step divergence check: what the check costs
    unchecked = final_state_function(jmodel, "semi-implicit-euler", check=False)
    kernel = peers.numba_kernel()
    buffer = np.array(y0)  # Numba steps this buffer in place, as a game engine would
    read_write, read_only = step_bytes(model, system)
    stream = peers.memory_stream(read_write, read_only)
    samples = settled_samples({
        ("steplab", 1): lambda: ready(run(yj, 0.0, dt, k)[0]),
        ("steplab", 2): lambda: ready(run(yj, 0.0, dt, 2 * k)[0]),
        ("numba", 1): lambda: kernel(buffer[0], buffer[1], *system.arrays, dt, k),
        ("numba", 2): lambda: kernel(buffer[0], buffer[1], *system.arrays, dt, 2 * k),
        ("unchecked", 1): lambda: ready(unchecked(yj, 0.0, dt, k)[0]),
        ("unchecked", 2): lambda: ready(unchecked(yj, 0.0, dt, 2 * k)[0]),
        "stream": stream,
    }, config.repeats, config.max_rounds, config.round_budget_seconds)
    t = {name: float(np.median(s)) for name, s in samples.items()}
    per_step, estimate = {}, {}
    for name in ("steplab", "numba", "unchecked"):
        per_step[name], estimate[name] = marginal_times(samples[(name, 1)], samples[(name, 2)], k)
    bound = Times.of(samples["stream"])
    difference = final_difference(run(yj, 0.0, dt, k)[0], peers.numba_semi_implicit_euler(system, y0, dt, k))
    calls = {"steplab_call_seconds": {f"{k} steps": t[("steplab", 1)], f"{2 * k} steps": t[("steplab", 2)]},
             "numba_call_seconds": {f"{k} steps": t[("numba", 1)], f"{2 * k} steps": t[("numba", 2)]},
             "per_step_estimate": estimate,
             # the profile: what the compiled loop runs per step, and the step without the
             # loop's per-step divergence check (the rest of the gap is the step itself)
             "steplab_loop_kernels": loop_kernels(compiled_text(run, yj, 0.0, dt, k)),
             "steplab_step_without_divergence_check": per_step["unchecked"].median}
    record.compare(f"vs_memory_bound_{label}", "large system", what, "memory-traffic bound (NumPy, in place)",
                   per_step["steplab"], bound, None, bytes_read_and_written=read_write, bytes_read=read_only,
                   bandwidth_bytes_per_s=(2 * read_write + read_only) / bound.median, dt=dt, **calls)
    record.compare(f"vs_numba_{label}", "large system", what, "Numba loop, in place", per_step["steplab"],
                   per_step["numba"], difference, dt=dt, **calls)


# --- 3. accuracy-matched: time to reach a final error ----------------------------------------


def _fixed_step_search(problem, method: str, truth, tol: float, max_log2: int):
    """Fewest steps (to 1/64) with final position error <= tol, or None within 2^max_log2 steps."""
    import jax.numpy as jnp


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
            "call": lambda: ready(run(y0, problem.t_start, span / hi, hi)[0])}


def _position_error(y, truth) -> float:
    return float(np.max(np.abs(np.asarray(y, dtype=float)[0] - truth[0])))


def _solved_error(sol, truth) -> float:
    """The final position error of an adaptive solve, inf where it failed: a solve that stopped
    early ends wherever it stopped, which may lie near the truth without having reached t_end."""
    return _position_error(sol.ys[-1], truth) if bool(np.all(sol.success)) else math.inf


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

    from steplab import peers
    from steplab.integrators import INTEGRATORS, Stepper
    from steplab.studies.problems import true_final

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

    def scipy_call(rtol):
        return solve_adaptive(problem.model.vector_field, span, y0, "scipy-dop853", rtol, rtol, at_saved_times=False)

    def scipy_solve(rtol):
        sol = scipy_call(rtol)
        return _solved_error(sol, truth), {"steps": sol.steps, "evaluations": sol.evaluations}

    adaptive = peers.diffrax_adaptive(problem.model.cast(jnp), "diffrax-tsit5", *span)
    yj = jnp.asarray(y0)

    def diffrax_solve(rtol):
        y, steps = adaptive(yj, jnp.asarray(rtol))
        return _position_error(y, truth), {"steps": int(steps)}

    found_peers = {"scipy": _tolerance_search(scipy_solve, tol), "diffrax": _tolerance_search(diffrax_solve, tol)}
    for peer, result in found_peers.items():
        if result is None:
            raise RuntimeError(f"{peer} does not reach {tol:g} m on {label} at rtol >= 1e-13")
    s_rtol, d_rtol = found_peers["scipy"][0], found_peers["diffrax"][0]
    t = settled_times({"steplab": best["call"], "scipy": lambda: scipy_call(s_rtol),
                       "diffrax": lambda: ready(adaptive(yj, jnp.asarray(d_rtol))[0])}, config, config.python_repeats)
    what = (f"{label.replace('_', ' ')} to t = {problem.t_end:g} s, final position error <= {tol:g} m: "
            f"steplab {best['method']} with {best['steps']:,} steps")
    common = {"steplab_method": best["method"], "steplab_steps": best["steps"], "steplab_error": best["error"],
              "candidates": {f["method"]: f["steps"] for f in found}, "reference": reference.get("reference")}
    names = {}
    for peer, peer_label in (("scipy", "scipy-dop853 (solve_ivp)"), ("diffrax", "diffrax-tsit5 (PID)")):
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
    t = settled_times(calls, config)
    ours = {tuple(p) for p in calls["steplab"]().tolist()}
    theirs = {tuple(sorted(p)) for p in calls["ckdtree"]().tolist()}
    record.compare(f"vs_ckdtree_{size_label(n)}", "broadphase",
                   f"{n:,} spheres of radius {radius:.3g} uniform in the unit cube, {len(ours):,} pairs",
                   "scipy cKDTree (build + query_pairs)", t["steplab"], t["ckdtree"], float(len(ours ^ theirs)),
                   steplab_method=fastest, single_call_seconds=once)
    if n != 100_000:  # the contract's key, whatever n this run used
        record.alias("vs_ckdtree_1e5", f"vs_ckdtree_{size_label(n)}")
    progress("broadphase: done")


# --- 5. compile times, 6. batching ------------------------------------------------------------------


def compile_times(config: Config, record: Record, progress) -> None:
    """JIT compilation of every built-in scene's compiled loop (simulate's ``compile_time``)."""
    from steplab.integrators import Stepper, get_integrator, simulate
    from steplab.integrators.attached import scene_stepper
    from steplab.physics.scene import builtin_scenes, load_scene

    for name in config.compile_scenes or builtin_scenes():
        scene = load_scene(name)
        if not isinstance(get_integrator(scene.integrator), Stepper):
            continue
        traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, scene.t_start + 4 * scene.dt,
                        scene.dt, backend="jax", stepper=scene_stepper(scene))
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
        calls = {"batched": lambda batched=batched, args=args: ready(batched(*args)[0]),
                 "loop": lambda run=run, singles=singles: ready([run(*a)[0] for a in singles])}
        t = settled_times(calls, config)
        difference = final_difference(calls["batched"](), np.stack(calls["loop"]()))
        record.compare(f"batched_vs_loop_{label}", "batching", what, "Python loop of single compiled runs",
                       t["batched"], t["loop"], difference, speedup=t["loop"].median / t["batched"].median)
    progress("batching: done")


SECTIONS = (small_system, large_systems, accuracy_matched, broadphase, compile_times, batching, ball_pits,
            implicit_euler_cloth, startup, tumbling_bodies, stacking, xpbd_cloth, newton_tumbling)
