"""The one compiled loop: fixed steps of a stepper as a jitted JAX program.

Every compiled run of a fixed-step method goes through :func:`compiled_loop`:
``simulate(backend="jax")`` (states saved every so many steps), the sweeps over dt of
the studies (only the final state, with ``dt`` and ``n`` traced so one compilation
serves the whole sweep), the stability study's long energy runs (an observer evaluated
after every step instead of the states) and the bench (the same loop, with the check
turned off to measure what the check costs).

A partitioned method (semi-implicit Euler, the Verlets: ``Stepper.partitioned``) is
carried as the pair (q, v), as diffrax carries it, not as the stacked (2, N, 3) array
a stepper takes and returns: the stack its step builds and the halves the next step
slices from it cancel when XLA compiles the loop, and each half is updated in its own
buffer, in place. A stacked carry costs a copy of the whole state every step (the
stack cannot overwrite the array it is read from), which at 10^6 bodies is most of a
step. A method that updates the stacked y as a whole (Euler, the Runge-Kutta methods)
is carried stacked: split, its step would need the stack and the two slices as
kernels of their own. The pair is stacked once, on the way out.

After every step the loop checks the state: a component that is non-finite or beyond
``limit`` marks the run as diverged, and the loop returns the 1-based index of that
first bad step (or -1). See :func:`within_limit` for how.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

from .base import check_step_result

#: the "no bad step" value of the loop's first-bad-step counter
NO_BAD_STEP = -1
#: from this many components a state is checked by a sum of squares first (see within_limit)
LARGE_STATE = 2**14


def compiled_loop(model, integrator, **options):
    """:func:`fixed_step_loop`, jitted: ``run(y0, t_start, dt, n, limit) -> (out, first bad step)``."""
    import jax

    return jax.jit(fixed_step_loop(model, integrator, **options))


def run_once(loop, y0, t_start, dt, n, limit):
    """Compile ``loop`` (a :func:`compiled_loop`) for these arguments, then run it once.

    Returns (saved states, first bad step or -1, compile seconds, run seconds): compilation is
    timed apart from the run, and the run up to its result (``block_until_ready``).
    """
    import jax.numpy as jnp

    args = (jnp.asarray(y0), jnp.asarray(t_start, y0.dtype), jnp.asarray(dt, y0.dtype), n,
            jnp.asarray(limit, y0.dtype))
    start = time.perf_counter()
    compiled = loop.lower(*args).compile()
    compile_time = time.perf_counter() - start
    start = time.perf_counter()
    ys, bad = compiled(*args)
    ys.block_until_ready()
    return ys, int(bad), compile_time, time.perf_counter() - start


def within_limit(parts, limit):
    """True when every component of the arrays ``parts`` is finite and at most ``limit`` in magnitude.

    One reduction for a small state: NaN fails ``|y| <= limit``. XLA:CPU reduces a large
    boolean array through a tree of reduce-window kernels, a pass over the state and
    then more, but sums floats in one vectorized pass; so a large state is checked by
    its sum of squares S first. Every |y_i| <= sqrt(S), so S <= (limit / 2)^2 proves the
    state sane (the factor 2 covers the sum's round-off, and S < inf rules out NaN, inf
    and an overflow of the squares); only a state that fails it, near divergence, gets
    the exact test.
    """
    import jax.numpy as jnp
    from jax import lax

    def exact():
        return functools.reduce(jnp.logical_and, [jnp.all(jnp.abs(x) <= limit) for x in parts])

    if sum(x.size for x in parts) < LARGE_STATE:
        return exact()
    squares = sum(jnp.sum(x * x) for x in parts)
    dtype = parts[0].dtype
    bound = jnp.minimum((jnp.asarray(limit, dtype) / 2) ** 2, jnp.finfo(dtype).max)
    return lax.cond(squares <= bound, lambda: jnp.asarray(True), exact)


def fixed_step_loop(model, integrator, *, chunks: int | None = None, save_every: int = 1,
                    observe: Callable | None = None, check: bool = True, halt: bool = False):
    """The loop as a function to trace: ``run(y0, t_start, dt, n, limit) -> (out, first bad step)``.

    :func:`compiled_loop` jits it as it is, every argument traced. A caller that wants
    some arguments fixed at compile time jits a closure over it instead: XLA rounds a
    step with a constant ``dt`` differently (it folds ``dt / 2`` and the like), and the
    stability study's records were made with a constant ``dt``.

    Parameters
    ----------
    model : physics.Model
        On the JAX backend.
    integrator : Stepper
    chunks : int, optional
        None: ``out`` is the final state y_n, and ``n`` may be traced (a ``fori_loop``,
        one compilation for every n and dt). An int: the loop is ``chunks`` scan
        iterations of up to ``save_every`` steps each (the last chunk may be shorter),
        and ``out`` stacks ``observe(y)`` after every chunk, shape ``(chunks, ...)``, so
        memory grows with the number of saved values only.
    save_every : int
        Steps per chunk. With 1, each scan iteration is one step, and the loop runs
        exactly ``chunks`` steps (pass n = chunks).
    observe : callable, optional
        ``observe(y) -> array``, what is saved after each chunk (default: the state).
        With ``save_every=1`` it is evaluated after every step (the energy of a long run).
    check : bool
        Check every step for divergence. Off, the loop carries no counter and the
        first bad step is always -1 (the bench measures the check's cost this way).
    halt : bool
        Stop stepping once a step is bad (the state stays the last one computed): an
        implicit method's Newton iteration would otherwise spend its whole budget on
        NaN at every remaining step.

    Notes
    -----
    Step k (0-based) starts at ``t_start + k dt``, the time the NumPy loop gives it, so
    both backends run the same operations in the same order; XLA's fusion still rounds
    a few of them differently, so the two agree to round-off, not bit for bit.
    """
    import jax.numpy as jnp
    from jax import lax

    observe = observe or (lambda y: y)
    if getattr(integrator, "partitioned", False):
        def split(y):
            return y[0], y[1]

        def join(parts):
            return jnp.stack(parts)
    else:
        def split(y):
            return (y,)

        def join(parts):
            return parts[0]

    def advance(k, parts, carry, t_start, dt):
        y = join(parts)
        result = integrator.step(model, t_start + k * dt, y, dt, carry)
        check_step_result(integrator, result, y.shape)  # at trace time: shapes only
        y, carry = result
        return split(y), carry

    def run(y0, t_start, dt, n, limit):
        def one_step(k, state):
            if not check:
                return advance(k, *state, t_start, dt)
            parts, carry, bad = state
            if halt:
                parts, carry = lax.cond(bad < 0, lambda: advance(k, parts, carry, t_start, dt),
                                        lambda: (parts, carry))
            else:
                parts, carry = advance(k, parts, carry, t_start, dt)
            ok = within_limit(parts, limit)
            return parts, carry, jnp.where((bad < 0) & ~ok, k + 1, bad)

        state = (split(y0), integrator.init(model, t_start, y0))
        if check:
            state += (jnp.asarray(NO_BAD_STEP, dtype=jnp.int64),)

        def first_bad(state):
            return state[2] if check else jnp.asarray(NO_BAD_STEP, dtype=jnp.int64)

        if chunks is None:
            state = lax.fori_loop(0, n, one_step, state)
            return join(state[0]), first_bad(state)

        def chunk(state, c):
            if save_every == 1:  # one step per scan iteration: no inner loop
                state = one_step(c, state)
            else:
                first = c * save_every
                state = lax.fori_loop(first, jnp.minimum(first + save_every, n), one_step, state)
            return state, observe(join(state[0]))

        state, out = lax.scan(chunk, state, jnp.arange(chunks))
        return out, first_bad(state)

    return run
