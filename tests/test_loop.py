"""The one compiled loop, ``simulate(..., n_steps=N)`` and the one entry to the adaptive references."""

import numpy as np
import pytest
from helpers import FIXED_STEP, lecture_projectile, oscillator
from steplab.integrators import simulate
from steplab.integrators.references import solve_adaptive
from steplab.integrators.simulate import final_state_function

from steplab.cli import main

#: a few steps whose count t_end / dt rounds badly in floating point: 3 x 0.1 = 0.30000000000000004,
#: 600 x (1/60) s = 10 s (one frame-rate second), 7 x 0.7
ROUNDING_CASES = [(0.1, 3), (1 / 60, 600), (0.7, 7)]


@pytest.mark.parametrize("dt, n", ROUNDING_CASES)
def test_n_steps_runs_exactly_n_steps_and_matches_the_t_end_run(dt, n):
    problem = lecture_projectile()
    t0 = problem.t0
    traj = simulate(problem.model, "rk4", problem.y0, t0, dt=dt, n_steps=n, save_every=n)
    assert traj.steps == n and len(traj.t) == 2 and traj.t[-1] == t0 + n * dt
    # RK4 is exact on the projectile (a quadratic in t): the state is the exact one at t0 + n dt
    np.testing.assert_allclose(traj.y[-1], problem.exact(np.array([t0 + n * dt]))[0], rtol=1e-12, atol=1e-10)
    by_time = simulate(problem.model, "rk4", problem.y0, t0, t0 + n * dt, dt, save_every=n)
    assert by_time.steps == n and np.array_equal(by_time.y, traj.y)


def test_n_steps_and_t_end_are_one_or_the_other():
    problem = lecture_projectile()
    with pytest.raises(ValueError, match="exactly one of them"):
        simulate(problem.model, "euler", problem.y0, 0.0, 1.0, 0.1, n_steps=10)
    with pytest.raises(ValueError, match="exactly one of them"):
        simulate(problem.model, "euler", problem.y0, 0.0, dt=0.1)
    with pytest.raises(ValueError, match="whole number"):
        simulate(problem.model, "euler", problem.y0, 0.0, dt=0.1, n_steps=2.5)


def test_run_steps_on_the_command_line(capsys):
    assert main(["run", "projectile", "--dt", "0.1", "--steps", "3", "--json"]) == 0
    assert '"steps": 3' in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:  # argparse: not both
        main(["run", "projectile", "--steps", "3", "--t-end", "1"])
    assert info.value.code == 2


@pytest.mark.parametrize("name", [n for n in ("semi-implicit-euler", "velocity-verlet", "rk4") if n in FIXED_STEP])
def test_compiled_loop_follows_the_numpy_loop(name):
    # XLA fuses the arithmetic of a step, so the two backends agree to round-off, not bit for
    # bit; the compiled runs (saved states, final state alone) are one loop and agree exactly
    problem = oscillator(velocity=0.7)
    dt, n = 0.01, 64
    numpy_run = simulate(problem.model, name, problem.y0, 0.0, dt=dt, n_steps=n)
    jax_run = simulate(problem.model, name, problem.y0, 0.0, dt=dt, n_steps=n, backend="jax", save_every=8)
    np.testing.assert_allclose(jax_run.y, numpy_run.y[::8], rtol=0, atol=1e-13)
    import jax.numpy as jnp

    y, bad = final_state_function(problem.model.cast(jnp), name)(jnp.asarray(problem.y0), 0.0, dt, n)
    assert int(bad) == -1 and np.array_equal(np.asarray(y), jax_run.y[-1])


@pytest.mark.parametrize("method", ["diffrax-tsit5", "scipy-dop853", "scipy-rk45"])
def test_reference_entry_reaches_the_exact_oscillator(method):
    import jax.numpy as jnp

    problem = oscillator(velocity=0.7)
    ts, rtol = np.linspace(0.0, 2.0, 5), 1e-10
    model = problem.model.cast(jnp) if method.startswith("diffrax") else problem.model  # diffrax traces it
    sol = solve_adaptive(model.vector_field, ts, problem.y0, method, rtol, rtol)
    assert bool(sol.success) and np.shape(sol.ys) == (5,) + problem.y0.shape
    scale = np.abs(problem.y0).max()
    np.testing.assert_allclose(np.asarray(sol.ys), problem.exact(ts), rtol=0, atol=100 * rtol * scale)
    if method.startswith("diffrax"):
        return  # the end-only diffrax solve is the work-precision study's and the bench's (tested there)
    end = solve_adaptive(model.vector_field, ts[[0, -1]], problem.y0, method, rtol, rtol, at_saved_times=False)
    assert int(end.steps) > 0 and np.shape(end.ys) == (1,) + problem.y0.shape
    np.testing.assert_allclose(np.asarray(end.ys[-1]), problem.exact(ts[-1:])[0], rtol=0, atol=100 * rtol * scale)


def test_reference_entry_names_the_methods_it_knows():
    problem = oscillator()
    with pytest.raises(ValueError, match="unknown adaptive method 'diffrax Tsit5'.*diffrax-tsit5"):
        solve_adaptive(problem.model.vector_field, [0.0, 1.0], problem.y0, "diffrax Tsit5", 1e-6, 1e-6)


@pytest.mark.parametrize("bodies", [2, 3000])  # the one exact reduction, and the sum-of-squares test first
def test_divergence_check_is_exact_at_any_size(bodies):
    import jax.numpy as jnp
    from steplab.integrators.loop import LARGE_STATE, within_limit

    assert (6 * bodies >= LARGE_STATE) == (bodies == 3000)
    rng = np.random.default_rng(8)
    q, v = rng.uniform(-1.0, 1.0, (2, bodies, 3))

    def ok(limit, change=None):
        x = q.copy()
        if change is not None:
            x[bodies - 1, 2] = change
        return bool(within_limit((jnp.asarray(x), jnp.asarray(v)), limit))

    assert ok(1.0) and ok(10.0, 10.0) and ok(1e200, -1e200)  # 1e200^2 overflows; still within
    assert ok(1e6) and not ok(1e6, 1e6 * (1 + 1e-9))  # S far below, and near, (limit / 2)^2
    assert not ok(10.0, np.nextafter(10.0, 11.0))  # a hair beyond the limit
    assert not ok(10.0, np.nan) and not ok(10.0, np.inf) and not ok(1e200, np.nextafter(1e200, np.inf))


def test_first_bad_step_of_a_large_state():
    # no forces: q_k = k dt v exactly; one of 3,000 bodies passes |q| = 10.5 at step 11
    import jax.numpy as jnp
    from steplab.integrators import SemiImplicitEuler
    from steplab.integrators.loop import compiled_loop
    from steplab.physics import Model

    n = 3000
    y0 = np.zeros((2, n, 3))
    y0[1, 1234, 0] = 1.0
    run = compiled_loop(Model(np.ones(n), np.ones(n), xp=jnp), SemiImplicitEuler())
    y, bad = run(jnp.asarray(y0), 0.0, 1.0, 20, 10.5)
    assert int(bad) == 11 and float(y[0, 1234, 0]) == 20.0
