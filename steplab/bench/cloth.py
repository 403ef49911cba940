"""The bench's cloth under XPBD (issue 28): steplab's step against the memory-traffic bound, a Numba loop and Newton.

The cloth is the large-system one (:func:`.systems.cloth_model`: 160 x 160 = 25,600
particles, 101,442 springs with dampers, two pinned corners), stepped at dt = 1/600 s (a
frame in 10 substeps, :data:`CLOTH_DT`) by ``xpbd`` with one substep and one iteration
(Macklin et al.'s "small steps" unit). Each side is timed as the large systems are, the
marginal cost (t(2K) - t(K)) / K of K more steps, in the same interleaved rounds (the memory
bound excepted, below):

- steplab: :func:`~steplab.integrators.position_based.cloth_benchmark_step`, the compiled step
  every ``xpbd`` step runs (predict, the Gauss-Seidel sweep in colour order, update), in place;
- the memory-traffic bound: NumPy streaming the bytes a step must move
  (:func:`steplab.peers.memory_stream`), the state q, v read and written in place and the
  columns the sweep reads (uint32 i, j; rest length, gamma, denominator), inverse masses and
  external field read. The positions each projection reads and writes are cache traffic, not
  counted: the sweep is bound by its loads and stores, not by memory (docs/performance.md).
  These 5.3 MB fit in the L3 cache, so this comparison alone is timed cold
  (:mod:`.cold`): one step and one pass of the bound, each after the caches are flushed by
  reading a buffer four times the largest cache, so both move their bytes from memory. The
  same pair warm (each side's marginal cost repeated back to back, the bound at cache
  speed) is kept in the record's ``warm`` beside it, the warm step against the cold bound in
  ``warm_step_against_cold_bound`` (the room the target leaves the cold step for memory traffic
  its work does not hide is 1.5 less that ratio, in bounds), and, in ``compiled_stream``, the cold step
  against a tighter bound: the same bytes moved in one compiled pass through the step's own table
  (:attr:`~steplab.integrators.position_based.InPlaceStep.stream`; NumPy's two passes take 6 to
  25 % longer), timed in the same cold rounds. The target stays on NumPy's bound, as the
  other memory-bound ratios' do;
- a plain Numba loop: the whole step (predict, one sweep over the constraints in the same
  order, update) written out as one compiled loop over the steps, in place
  (:func:`numba_xpbd_loop`, the bench's independent copy of the step, as :mod:`steplab.peers`
  keeps one of semi-implicit Euler);
- NVIDIA Newton's SolverXPBD with one iteration on the same cloth, on the CPU
  (:mod:`steplab.engines.newton_engine`), when the extra ``steplab[newton]`` is installed.

Newton's sweep is Jacobi, steplab's Gauss-Seidel: the two are different methods on a cloth
(the record's ``difference``), alike in work per step (one pass over the springs, one over
the particles). Newton also runs SolverSemiImplicit beside steplab's compiled semi-implicit
Euler loop on the same cloth at dt = 5e-4 s (its stable step), and each Newton solver is
identified on the small cloth scene (:func:`identify_on_cloth`).
"""

from __future__ import annotations

import functools

import numpy as np

from steplab.core.timing import Times, ready

from .cold import EVICTION_FACTOR, cold_samples, evictor, largest_cache_bytes
from .config import Config
from .record import Record, beside, final_difference
from .systems import cloth_model
from .timing import marginal_times, settled_samples

#: s: a 1/60 s frame in 10 substeps, as Newton's cloth_hanging example steps XPBD. steplab's
#: Gauss-Seidel sweep is stable at every dt; Newton's Jacobi one diverges on this cloth at
#: 1/240 s (k h^2 / m = 0.87: the summed corrections overshoot) and at 1/60 s
CLOTH_DT = 1 / 600
#: semi-implicit Euler's step on the cloth, s (the large-system comparison's, below its limit 3.2 ms)
SEMI_IMPLICIT_DT = 5e-4
#: steps of the identification on the small cloth: the methods part by 1e-3 and more, while
#: float32 round-off stays near its own size
IDENTIFICATION_STEPS = 40
#: a Newton solver equals a steplab method when their difference is within this many times
#: the float32 round-off of the problem (steplab's semi-implicit Euler in float32 against float64)
ROUND_OFF_FACTOR = 4.0


@functools.cache
def numba_xpbd_loop():
    """:func:`_xpbd_loop` compiled (on first use, cached on disk: importing the bench never needs Numba)."""
    import numba

    return numba.njit(cache=True)(_xpbd_loop)


def numba_xpbd_step(model, y0, dt: float):
    """:func:`_xpbd_loop` stepping in place, as an :class:`~steplab.integrators.position_based.InPlaceStep`, on the
    bodies and constraints as steplab's xpbd carry holds them (the bodies in the sweep's rows,
    :mod:`steplab.integrators.arrangement`; the constraints in its order): the same bytes in the same places,
    so the two steps differ only in their code."""
    from steplab.integrators.position_based import XPBD, InPlaceStep

    carry = XPBD(substeps=1, iterations=1).init(model, 0.0, y0)
    state, external = carry.in_rows(y0)  # stepped in place, as a game engine would
    arrays, loop = (carry.inverse_mass, external, carry.constraints), numba_xpbd_loop()

    def steps(n: int = 1) -> None:
        loop(state[0], state[1], *arrays, dt, n)

    read = carry.inverse_mass.nbytes + external.nbytes + sum(a.nbytes for a in carry.constraints)
    return InPlaceStep(state, carry.rows, steps, state.nbytes, read)


def _xpbd_loop(q, v, inverse_mass, external, constraints, dt, n):
    """``n`` steps of XPBD with one substep and one iteration, in place on q, v (N, 3).

    Per step: dx = dt (v + dt a_ext); one Gauss-Seidel sweep over the constraints moving dx
    (the multipliers start at 0, so with one iteration dlambda = (-C - gamma grad C . dx) /
    ((1 + gamma) w + alpha / dt^2), gamma = alpha beta / dt); q += dx, v = dx / dt.
    """
    i, j, rest_length, compliance, damping = constraints
    dx = np.empty_like(q)
    for _ in range(n):
        for b in range(q.shape[0]):
            for c in range(3):
                dx[b, c] = dt * (v[b, c] + dt * external[b, c])
        for p in range(i.shape[0]):
            a, b = i[p], j[p]
            w = inverse_mass[a] + inverse_mass[b]
            u0, u1, u2 = dx[b, 0] - dx[a, 0], dx[b, 1] - dx[a, 1], dx[b, 2] - dx[a, 2]
            d0, d1, d2 = q[b, 0] - q[a, 0] + u0, q[b, 1] - q[a, 1] + u1, q[b, 2] - q[a, 2] + u2
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if w == 0.0 or length == 0.0:
                continue
            n0, n1, n2 = d0 / length, d1 / length, d2 / length
            alpha_tilde = compliance[p] / (dt * dt)
            gamma = compliance[p] * damping[p] / dt
            dlam = (-(length - rest_length[p]) - gamma * (n0 * u0 + n1 * u1 + n2 * u2)) / (
                (1.0 + gamma) * w + alpha_tilde)
            wa, wb = inverse_mass[a] * dlam, inverse_mass[b] * dlam
            dx[a, 0] -= wa * n0
            dx[a, 1] -= wa * n1
            dx[a, 2] -= wa * n2
            dx[b, 0] += wb * n0
            dx[b, 1] += wb * n1
            dx[b, 2] += wb * n2
        for b in range(q.shape[0]):
            for c in range(3):
                q[b, c] += dx[b, c]
                v[b, c] = dx[b, c] / dt


def streams(stream, n: int) -> None:
    """``n`` passes of the memory bound's ``stream`` back to back (its marginal cost: warm, at cache speed)."""
    for _ in range(n):
        stream()


def newton_run(model, dt: float, y, **options):
    """Newton on the cloth (an adapter of :mod:`steplab.engines.newton_engine`), or None when not installed."""
    from steplab.engines import ENGINES, build

    if not ENGINES["newton"].available():
        return None
    run = build("newton", model, None, dt, y, **options)
    run.set_state(y)
    return run


def xpbd_cloth(config: Config, record: Record, progress) -> None:
    """steplab's xpbd step on the cloth against the memory bound, a Numba loop and Newton's SolverXPBD."""
    from steplab import peers
    from steplab.integrators.position_based import cloth_benchmark_step

    model, y0, springs = cloth_model(config.cloth_side)
    dt, k = CLOTH_DT, config.loop_steps
    step = cloth_benchmark_step(model, y0, dt)  # XPBD(1, 1) in place on step.state: the kernel every xpbd step runs
    numba = numba_xpbd_step(model, y0, dt)
    read_write, read_only = step.bytes_read_and_written, step.bytes_read
    stream = peers.memory_stream(read_write, read_only)
    calls = {("steplab", 1): lambda: step.advance(k), ("steplab", 2): lambda: step.advance(2 * k),
             ("numba", 1): lambda: numba.advance(k), ("numba", 2): lambda: numba.advance(2 * k),
             ("stream", 1): lambda: streams(stream, k), ("stream", 2): lambda: streams(stream, 2 * k)}
    newton = newton_run(model, dt, y0, solver="xpbd", iterations=1)
    if newton is not None:
        calls |= {("newton", 1): lambda: newton.run(k, dt), ("newton", 2): lambda: newton.run(2 * k, dt)}
    progress("xpbd cloth: set up")
    samples = settled_samples(calls, config.repeats, config.max_rounds, config.round_budget_seconds)
    per_step = {name: marginal_times(samples[(name, 1)], samples[(name, 2)], k)[0]
                for name in ("steplab", "numba", "newton", "stream") if (name, 1) in samples}
    evict = evictor()
    cold = {name: Times.of(s) for name, s in cold_samples({"steplab": lambda: step.advance(1), "stream": stream,
                                                           "compiled stream": step.stream},
                                                          config.max_rounds, evict).items()}
    for contender in (step, numba):
        contender.set(y0)
        contender.advance(k)
    ours = step.y
    what = (f"cloth of {model.n_bodies:,} particles, {springs:,} springs and dampers, gravity, one xpbd step "
            f"(1 substep, 1 iteration) of dt = 1/600 s")
    record.compare("vs_memory_bound_xpbd_cloth", "cloth (XPBD)", what + ", from cold caches",
                   "memory-traffic bound (NumPy, in place), from cold caches", cold["steplab"], cold["stream"], None,
                   bytes_read_and_written=read_write, bytes_read=read_only, dt=dt, caches="cold",
                   eviction_bytes=EVICTION_FACTOR * largest_cache_bytes(),
                   warm=beside(per_step["steplab"], per_step["stream"]),
                   compiled_stream=beside(cold["steplab"], cold["compiled stream"]),
                   # the step's arithmetic alone (warm, its memory traffic from the caches) against the
                   # target's bound: how much of the bound's time the target leaves for unhidden traffic
                   warm_step_against_cold_bound=beside(per_step["steplab"], cold["stream"]))
    record.compare("vs_numba_xpbd_cloth", "cloth (XPBD)", what, "Numba loop of the whole step, in place",
                   per_step["steplab"], per_step["numba"], final_difference(ours, numba.y), dt=dt)
    if newton is None:
        record.data["details"]["newton"] = "newton is not installed (pip install steplab[newton]): not compared"
    else:
        newton.set_state(y0)
        newton.run(k, dt)
        # no `difference`: that field is for peers that compute the same thing; Newton's Jacobi
        # sweep in float32 is another method on the cloth (identify_on_cloth says how far)
        record.compare("vs_newton_xpbd_cloth", "cloth (XPBD)", what, newton.settings, per_step["steplab"],
                       per_step["newton"], None, dt=dt, final_state_apart=final_difference(ours, newton.state()))
        _semi_implicit_beside_newton(model, y0, config, record)
        settings = _newton_settings()
        references = cloth_references(settings)
        record.data["details"]["newton_identification"] = {s.key: identify_on_cloth(s, references)
                                                           for s in settings}
    progress("xpbd cloth: done")


def _newton_settings():
    from steplab.engines import ENGINES

    return ENGINES["newton"].study_settings


def _semi_implicit_beside_newton(model, y0, config: Config, record: Record) -> None:
    """Newton's SolverSemiImplicit against steplab's compiled semi-implicit Euler loop, the same cloth and dt."""
    import jax.numpy as jnp

    from steplab.integrators.simulate import final_state_function

    dt, k = SEMI_IMPLICIT_DT, config.loop_steps
    run, yj = final_state_function(model.cast(jnp), "semi-implicit-euler"), jnp.asarray(y0)
    newton = newton_run(model, dt, y0, solver="semi-implicit")
    samples = settled_samples({("steplab", 1): lambda: ready(run(yj, 0.0, dt, k)[0]),
                               ("steplab", 2): lambda: ready(run(yj, 0.0, dt, 2 * k)[0]),
                               ("newton", 1): lambda: newton.run(k, dt), ("newton", 2): lambda: newton.run(2 * k, dt)},
                              config.repeats, config.max_rounds, config.round_budget_seconds)
    ours, theirs = (marginal_times(samples[(name, 1)], samples[(name, 2)], k)[0] for name in ("steplab", "newton"))
    newton.set_state(y0)
    newton.run(k, dt)
    record.compare("vs_newton_semi_implicit_cloth", "cloth (XPBD)",
                   f"cloth of {model.n_bodies:,} particles, one semi-implicit Euler step of dt = {dt:g} s "
                   "(steplab's compiled loop)", newton.settings, ours, theirs, None, dt=dt,
                   # the same method in float32: apart by its round-off, not within the bench's 1e-9
                   final_state_apart=final_difference(run(yj, 0.0, dt, k)[0], newton.state()))


def swinging_cloth():
    """The cloth scene (12 x 12 particles, springs and dampers, two pinned corners) with random
    velocities of 0.1 m/s (seeded): (model, y0, dt)."""
    from steplab.physics.scene import load_scene

    from .config import SEED

    scene = load_scene("cloth")
    y0, moving = scene.y0.copy(), ~scene.model.pinned
    y0[1, moving] = np.random.default_rng(SEED).normal(0.0, 0.1, (int(moving.sum()), 3))
    return scene.model, y0, scene.dt


def cloth_references(settings) -> dict:
    """Every steplab method's trajectory on :func:`swinging_cloth` over IDENTIFICATION_STEPS steps:
    the fixed-step methods (implicit Euler by conjugate gradients, the same converged step),
    ``xpbd`` and ``vbd`` with each setting's iterations, by label; and, under "float32", semi-implicit
    Euler in float32 (the problem's round-off). A method that diverges on the cloth is left out."""
    from steplab.integrators import DivergenceError, ImplicitEuler, simulate
    from steplab.integrators.position_based import XPBD
    from steplab.integrators.vertex_block_descent import VBD
    from steplab.studies.engines import parameters as engines_parameters

    model, y0, dt = swinging_cloth()
    methods = {m: m for m in engines_parameters(quick=True)["integrators"]}
    methods["implicit-euler"] = ImplicitEuler(linear_solver="cg")  # dense: 0.2 s a step here
    for iterations in sorted({s.options.get("iterations", 1) for s in settings}):
        methods[f"xpbd, {iterations} iteration(s)"] = XPBD(iterations=iterations)
        methods[f"vbd, {iterations} iteration(s)"] = VBD(iterations=iterations)
    references = {}
    for label, method in methods.items():
        try:
            references[label] = simulate(model, method, y0, 0.0, dt=dt, n_steps=IDENTIFICATION_STEPS).y
        except DivergenceError:
            continue
    references["float32"] = simulate(model, "semi-implicit-euler", y0, 0.0, dt=dt, n_steps=IDENTIFICATION_STEPS,
                                     dtype=np.float32).y
    return references


def identify_on_cloth(setting, references: dict) -> dict:
    """Which steplab method a Newton setting steps, on the small cloth scene (12 x 12, swinging).

    The setting takes IDENTIFICATION_STEPS steps of the scene's dt from the start of
    :func:`cloth_references`, against each of those methods'; the difference is
    :func:`steplab.studies.engines.identify`'s (max |y - y_method| / max |y_method|). The
    nearest method is *equal* when the difference is within ROUND_OFF_FACTOR times this
    problem's float32 round-off (steplab's semi-implicit Euler in float32 against float64,
    2.7e-5 here: the springs' stretch is a small difference of float32 positions).
    """
    from steplab.studies.engines import identify
    from steplab.studies.problems import Problem
    from steplab.studies.system import engine_system

    model, y0, dt = swinging_cloth()
    n = IDENTIFICATION_STEPS
    methods = {m: y for m, y in references.items() if m != "float32"}
    problem = Problem("cloth", "the cloth scene, swinging", model, y0, 0.0, n * dt)
    found = identify(engine_system(setting), {"identification_steps": n, "integrators": list(methods)},
                     {"cloth": (problem, dt, methods)})
    ours = references["semi-implicit-euler"]
    round_off = float(np.max(np.abs(references["float32"] - ours)) / np.max(np.abs(ours)))
    equal = found["difference"] <= ROUND_OFF_FACTOR * round_off
    return {"nearest": found["nearest"], "difference": found["difference"], "float32_round_off": round_off,
            "equals": found["nearest"] if equal else "none", "declared": setting.equals,
            "differences": {m: d["cloth"] for m, d in found["differences"].items()}}
