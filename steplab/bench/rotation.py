"""10^5 free tumbling bodies: one compiled exponential-map step against the memory-traffic bound (issue 25).

Two compiled steps, timed in the same rounds as the bound, each inside its own loop, as the
large systems are: the marginal cost (t(2K) - t(K)) / K of K more steps, which leaves out
entering and leaving the loop.

- The contender, ``vs_memory_bound_rotation_1e5``: the Numba kernel of
  :mod:`steplab.integrators.rotation_compiled` (``simulate_rotation(backend="numba")``), the
  state as a structure of arrays, the loop over bodies vectorised; bit for bit NumPy's step.
- Beside it in the record: the XLA loop (:func:`steplab.integrators.rotation.compiled_steps`,
  ``backend="jax"``) on the rows (R, 4) and (R, 3), and the same loop with the exponential's
  trigonometric branch (every |r|/2 above the series' radius: one scalar libm sin and cos per
  body, float64 being unvectorised on XLA's CPU backend), the old cost.

The bound streams the bytes a step must move (:func:`steplab.peers.memory_stream`): q and omega
read and written in place (56 bytes a body), the principal moments read (24 bytes), 8 MB in
all at 10^5 bodies; no step can move fewer. (8 MB fits in a large last-level cache: the bound
is then that cache's bandwidth, the same for both sides.) NumPy streams them in two passes (the
in-place multiply, then the sum), so the record adds a tighter bound beside it: the same bytes
in one compiled pass over the kernel's own arrays
(:func:`~steplab.integrators.rotation_compiled.stream_pass`, vectorised as the kernel is). The
record also counts the step's floating-point operations per body (:data:`FLOPS_PER_BODY`), for
the rate each side reaches.
"""

from __future__ import annotations

import numpy as np

from steplab.core.timing import Times, interleaved_samples, ready

from .config import SEED, Config
from .record import Record, beside, final_difference
from .timing import marginal_times

#: the issue's size: 10^5 free bodies
TUMBLING_BODIES = 100_000
#: a frame, s; with |omega| ~ 1.6 rad/s, h |omega| ~ 0.03: the exponential map's series branch
TUMBLING_DT = 1 / 60
#: floating-point operations of one body's step, counted in the kernel's source (a division and
#: a square root count one each): I omega 3, omega x I omega 9, the omega update 12 (three
#: divisions), h omega and x^2 9, the two series 29, the vector part of exp 6, the Hamilton
#: product 28, the norm 8 and the normalisation 4 (divisions)
FLOPS_PER_BODY = 108


def tumbling_bodies(config: Config, record: Record, progress) -> None:
    """The exponential-map step of 10^5 free tumbling bodies against the memory bound, in the same rounds."""
    import jax.numpy as jnp

    from steplab import peers
    from steplab.integrators import get_rotation
    from steplab.integrators.rotation import compiled_steps, simulate_rotation
    from steplab.integrators.rotation_compiled import exponential_map_steps, free_bodies, stream_pass
    from steplab.physics.rigid_body import RotationModel

    rng = np.random.default_rng(SEED)
    n, k, dt = TUMBLING_BODIES, config.loop_steps, TUMBLING_DT
    inertia = np.sort(rng.uniform(1.0, 2.0, (n, 3)), axis=1)  # I3 <= 2 <= I1 + I2: bodies
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    omega = rng.normal(size=(n, 3))
    method, model = get_rotation("exponential-map"), RotationModel(inertia)
    runs = {m: compiled_steps(method, model, dt, m * k) for m in (1, 2)}
    qj, omegaj = jnp.asarray(q), jnp.asarray(omega)
    fast = omegaj * 100.0  # h |omega| ~ 3 rad: the exponential's trigonometric branch
    # the kernel steps its state in place: one state for each loop length, each tumbling on
    kernel = {m: free_bodies(q, omega, inertia) for m in (1, 2)}
    read_write, read_only = q.nbytes + omega.nbytes, inertia.nbytes
    samples = interleaved_samples({
        1: lambda: exponential_map_steps(kernel[1], dt, k),
        2: lambda: exponential_map_steps(kernel[2], dt, 2 * k),
        "xla 1": lambda: ready(runs[1](qj, omegaj)[0]),
        "xla 2": lambda: ready(runs[2](qj, omegaj)[0]),
        "trigonometric": lambda: ready(runs[1](qj, fast)[0]),
        "stream": peers.memory_stream(read_write, read_only),
        "compiled stream": lambda: stream_pass(kernel[1]),
    }, config.repeats)
    per_step, estimate = marginal_times(samples[1], samples[2], k)
    xla, _ = marginal_times(samples["xla 1"], samples["xla 2"], k)
    bound = Times.of(samples["stream"])
    # after the rounds, every body still took the series (h |omega| <= 1 rad): the branch timed
    largest_turn = max(float(np.max(np.linalg.norm(kernel[m].omega, axis=0))) * dt for m in (1, 2))
    _, q_numpy, omega_numpy = simulate_rotation(method, model, q, omega, dt, k)
    q_loop, omega_loop = runs[1](qj, omegaj)
    checked = free_bodies(q, omega, inertia)
    exponential_map_steps(checked, dt, k)
    difference = max(final_difference(checked.q.T, q_numpy[-1]), final_difference(checked.omega.T, omega_numpy[-1]))
    record.compare("vs_memory_bound_rotation_1e5", "large system",
                   f"{n:,} free tumbling bodies, one exponential-map step (compiled Numba kernel, structure of arrays)",
                   "memory-traffic bound (NumPy, in place)", per_step, bound, difference, dt=dt,
                   bytes_read_and_written=read_write, bytes_read=read_only, flops_per_body=FLOPS_PER_BODY,
                   largest_omega_dt=largest_turn,
                   # the tighter bound: the same bytes in one compiled pass
                   compiled_stream=beside(per_step, Times.of(samples["compiled stream"])),
                   # the XLA loop on the rows, per step: its marginal cost, and with the trigonometric branch
                   step_xla_seconds=xla.median, step_xla_min_seconds=xla.minimum,
                   xla_difference_from_numpy=max(final_difference(q_loop, q_numpy[-1]),
                                                 final_difference(omega_loop, omega_numpy[-1])),
                   step_trigonometric_seconds=float(np.median(samples["trigonometric"])) / k,
                   difference_from_numpy="largest |difference| from the NumPy loop after K steps",
                   per_step_estimate=estimate)
    progress("rotation: done")
