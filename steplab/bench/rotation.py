"""10^5 free tumbling bodies: one compiled exponential-map step against the memory-traffic bound (issue 25).

The step is timed inside the compiled rotation loop (:func:`steplab.integrators.rotation.compiled_steps`,
what ``simulate_rotation(backend="jax")`` runs), as the large systems are: the marginal cost
(t(2K) - t(K)) / K of K more steps, which leaves out entering and leaving the loop. The bound
streams the bytes a step must move (:func:`steplab.peers.memory_stream`): q and omega read and
written in place, the principal moments read. The record adds the same loop with the
exponential's trigonometric branch (every |r|/2 above the series' radius: one scalar libm
sin and cos per body, float64 being unvectorised on XLA's CPU backend), the old cost.

What is left is float64 arithmetic, not memory: about 110 flops per body (the gyroscopic
term, two 8-term series, the product and the normalisation) against the 80 bytes per body
the bound moves.
"""

from __future__ import annotations

import numpy as np

from steplab.core.timing import Times, interleaved_samples, ready

from .config import SEED, Config
from .record import Record, final_difference
from .timing import marginal_times

#: the issue's size: 10^5 free bodies
TUMBLING_BODIES = 100_000
#: a frame, s; with |omega| ~ 1.6 rad/s, h |omega| ~ 0.03: the exponential map's series branch
TUMBLING_DT = 1 / 60


def tumbling_bodies(config: Config, record: Record, progress) -> None:
    """The exponential-map step of 10^5 free tumbling bodies against the memory bound, in the same rounds."""
    import jax.numpy as jnp

    from steplab import peers
    from steplab.integrators import get_rotation
    from steplab.integrators.rotation import compiled_steps, simulate_rotation
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
    read_write, read_only = q.nbytes + omega.nbytes, inertia.nbytes
    samples = interleaved_samples({
        1: lambda: ready(runs[1](qj, omegaj)[0]),
        2: lambda: ready(runs[2](qj, omegaj)[0]),
        "trigonometric": lambda: ready(runs[1](qj, fast)[0]),
        "stream": peers.memory_stream(read_write, read_only),
    }, config.repeats)
    per_step, estimate = marginal_times(samples[1], samples[2], k)
    bound = Times.of(samples["stream"])
    _, q_numpy, omega_numpy = simulate_rotation(method, model, q, omega, dt, k)
    q_loop, omega_loop = runs[1](qj, omegaj)
    difference = max(final_difference(q_loop, q_numpy[-1]), final_difference(omega_loop, omega_numpy[-1]))
    record.compare("vs_memory_bound_rotation_1e5", "large system",
                   f"{n:,} free tumbling bodies, one exponential-map step (compiled loop)",
                   "memory-traffic bound (NumPy, in place)", per_step, bound, difference, dt=dt,
                   bytes_read_and_written=read_write, bytes_read=read_only,
                   # the same loop with the exponential's trigonometric branch, per step
                   step_trigonometric_seconds=float(np.median(samples["trigonometric"])) / k,
                   difference_from_numpy="largest |difference| from the NumPy loop after K steps",
                   per_step_estimate=estimate)
    progress("rotation: done")
