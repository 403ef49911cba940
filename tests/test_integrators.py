"""Integrators against exact solutions, analytic error formulas and independent references.

Parametrised over the registry (``helpers.FIXED_STEP`` etc.), so a newly registered
integrator is held to its declared order, backend agreement and the rest automatically.
"""

from __future__ import annotations

import math

import helpers
import numpy as np
import pytest
from helpers import (
    FIRST_ORDER,
    FIXED_STEP,
    REFERENCES,
    SECOND_ORDER_OR_HIGHER,
    SYMPLECTIC,
    fit_order,
    lecture_projectile,
    max_error,
    mixed_problem,
    oscillator,
    oscillator_energy,
    projectile_solution,
    soft_tetrahedron,
)
from numpy.testing import assert_allclose, assert_array_equal
from steplab.integrators import (
    INTEGRATORS,
    ButcherTableau,
    DivergenceError,
    ExplicitRungeKutta,
    Integrator,
    NotConstantForceError,
    Stepper,
    UnknownIntegratorError,
    get_integrator,
    simulate,
)
from steplab.physics import Model, from_lecture_state, lecture_state, projectile
from steplab.physics.friction import Friction

OMEGA = 2 * math.pi  # of helpers.oscillator() (period 1 s)
RUNGE_KUTTA = [name for name in FIXED_STEP if isinstance(INTEGRATORS[name], ExplicitRungeKutta)]


def damped():
    return oscillator(damping=0.2 * 2 * math.pi, velocity=0.3, direction=(2.0, -1.0, 2.0))


# --- (1) measured order of convergence --------------------------------------------------------

CONVERGENCE_DTS = [1 / 40, 1 / 80, 1 / 160, 1 / 320, 1 / 640]


def measured_order(problem, name, t_end=1.0, dts=CONVERGENCE_DTS):
    """Slope of log(max error over the run) against log(dt).

    The error is the largest deviation from the exact solution at any step of [0, t_end]:
    a single end time can hide the leading error term (at a whole period, the O(dt) error
    of semi-implicit Euler cancels and it looks 2nd order).
    """
    errors = []
    for dt in dts:
        run = simulate(problem.model, name, problem.y0, problem.t0, problem.t0 + t_end, dt)
        errors.append(max_error(run.y, problem.exact(run.t)))
    return fit_order(dts, errors), errors


@pytest.mark.parametrize("name", FIXED_STEP)
@pytest.mark.parametrize("make_problem", [oscillator, damped], ids=["oscillator", "damped"])
def test_convergence_order_matches_declared_order(name, make_problem):
    order, errors = measured_order(make_problem(), name)
    assert errors[-1] > 1e3 * np.finfo(float).eps  # truncation, not round-off, dominates
    assert order == pytest.approx(INTEGRATORS[name].order, abs=0.15), errors


@pytest.mark.parametrize("name", FIRST_ORDER)
def test_first_order_methods_on_the_projectile(name):
    problem = lecture_projectile()
    order, errors = measured_order(problem, name, t_end=2.0)
    assert order == pytest.approx(1.0, abs=0.15)
    # under a constant force the global error is exactly linear in dt
    assert_allclose(np.array(errors) / CONVERGENCE_DTS, errors[0] / CONVERGENCE_DTS[0], rtol=1e-6)


@pytest.mark.parametrize("name, sign", [("euler", -1.0), ("semi-implicit-euler", +1.0)])
def test_euler_projectile_error_is_half_g_t_dt(name, sign):
    """Analytically, n Euler steps give p_n = p(t) - g t dt / 2 (explicit) and
    p(t) + g t dt / 2 (semi-implicit), with exact velocities."""
    problem = lecture_projectile()
    dt, t_end = 0.2, 10.4
    run = simulate(problem.model, name, problem.y0, problem.t0, t_end, dt)
    exact = problem.exact(run.t)
    tau = run.t - problem.t0
    g = np.array(helpers.LECTURE_G)
    expected_error = sign * 0.5 * g * (tau * dt)[:, None, None]
    assert_allclose(run.y[:, 0] - exact[:, 0], expected_error, atol=1e-11)
    assert_allclose(run.y[:, 1], exact[:, 1], atol=1e-12)


# --- (3) the lecture's explicit Euler example -------------------------------------------------


def test_lecture_explicit_euler_step():
    problem = lecture_projectile()
    run = simulate(problem.model, "euler", problem.y0, 5.0, 5.2, 0.2)
    assert run.steps == 1 and run.t[-1] == pytest.approx(5.2)
    s = lecture_state(run.y[-1], [2.5])  # S = (mV, p)
    assert_allclose(s[1], [10.0 + 0.2 * 7.68, 0.0, 2.0 + 0.2 * 29.0], rtol=1e-15)  # z = 7.8
    assert_allclose(s[0], [19.2, 0.0, 72.5 - 0.2 * 24.525], rtol=1e-14)  # mV_z = 67.595
    # the slide's truncation error for dt = 0.2: 7.8 - 7.6038 = 0.1962
    assert s[1][2] - problem.exact(5.2)[0, 0, 2] == pytest.approx(0.1962, abs=1e-12)
    # and the same step done by hand on S with the lecture's ExplicitEuler: S + dt dS/dt
    s0 = lecture_state(problem.y0, [2.5])
    ds = np.array([[0.0, 0.0, 2.5 * -9.81], [7.68, 0.0, 29.0]])
    assert_allclose(from_lecture_state(s0 + 0.2 * ds, [2.5]), run.y[-1], rtol=1e-15)


def test_lecture_explicit_euler_table():
    """The slide "Explicit Euler Integration - Computing Solution Over Time", to its
    two decimals (rows t = 5.2, 5.4, 5.6 and 10.4; p_x of the last row is a typo there)."""
    problem = lecture_projectile()
    run = simulate(problem.model, "euler", problem.y0, 5.0, 10.4, 0.2)
    assert run.steps == 27 and run.t[-1] == pytest.approx(10.4)
    rows = {1: (11.54, 7.80, 67.60, 27.04), 2: (13.07, 13.21, 62.69, 25.08),
            3: (14.61, 18.22, 57.79, 23.11), 27: (None, 20.87, -59.93, -23.97)}
    for k, (px, pz, mvz, vz) in rows.items():
        q, v = run.y[k, 0, 0], run.y[k, 1, 0]
        if px is not None:
            assert q[0] == pytest.approx(px, abs=0.006)
        assert q[2] == pytest.approx(pz, abs=0.006)
        assert 2.5 * v[2] == pytest.approx(mvz, abs=0.006)
        assert v[2] == pytest.approx(vz, abs=0.006)


# --- (4) exact methods for a constant force ---------------------------------------------------


@pytest.mark.parametrize("name", SECOND_ORDER_OR_HIGHER)
def test_second_order_methods_are_exact_for_constant_force(name):
    """Velocity/position Verlet, RK4 (and every method of order >= 2) reproduce the
    quadratic projectile trajectory to round-off, however many steps they take."""
    problem = lecture_projectile()
    run = simulate(problem.model, name, problem.y0, 5.0, 15.0, 0.01)
    assert run.steps == 1000
    p, v = projectile(run.t, helpers.LECTURE_P0, helpers.LECTURE_V0, helpers.LECTURE_G, t_init=5.0)
    assert_allclose(run.y[:, 0, 0], p, rtol=1e-12, atol=1e-10)
    assert_allclose(run.y[:, 1, 0], v, rtol=1e-12, atol=1e-10)
    assert_allclose(run.y, problem.exact(run.t), rtol=1e-12, atol=1e-10)


def test_exact_integrator_matches_closed_form():
    problem = lecture_projectile()
    run = simulate(problem.model, "exact", problem.y0, 5.0, 10.4, 0.2)
    assert run.steps == 0 and len(run.t) == 28
    assert_allclose(run.y, problem.exact(run.t), rtol=1e-14, atol=1e-12)


def test_exact_integrator_with_pinned_body():
    problem = lecture_projectile()
    model = Model([2.5, 1.0], [0.1, 0.1], problem.model.forces, pinned=[False, True])
    y0 = np.concatenate([problem.y0, [[[0.0, 0.0, 5.0]], [[0.0, 0.0, 0.0]]]], axis=1)
    run = simulate(model, "exact", y0, 5.0, 6.0, 0.5)
    assert_allclose(run.y[:, :, :1], problem.exact(run.t), rtol=1e-14)
    assert_array_equal(run.y[:, 0, 1], [[0.0, 0.0, 5.0]] * 3)  # the pinned body does not fall


def test_exact_integrator_refuses_a_spring_scene():
    problem = oscillator()
    with pytest.raises(NotConstantForceError, match="springs"):
        simulate(problem.model, "exact", problem.y0, 0.0, 1.0, 0.1)


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_simulate_refuses_a_state_of_another_shape_and_a_save_every_that_is_not_a_count(backend):
    # a y0 of another model ran on, silently, where the forces broadcast; save_every = 2.5 returned
    # uninitialised memory as states (NumPy) or a while_loop type error (JAX)
    problem = oscillator()
    for y0 in (problem.y0[0], np.zeros((2, 5, 3)), problem.y0.ravel()):
        with pytest.raises(ValueError, match=r"y0 must have shape \(2, 2, 3\) .* got \("):
            simulate(problem.model, "rk4", y0, 0.0, 0.1, 0.01, backend=backend)
    for save_every in (2.5, 0, -1, True):
        with pytest.raises(ValueError, match="save_every must be a whole number"):
            simulate(problem.model, "rk4", problem.y0, 0.0, 0.1, 0.01, backend=backend, save_every=save_every)


def test_a_users_stepper_that_returns_the_state_alone_or_has_no_name_is_one_line():
    # notebook 5's likeliest slip: return y_next without the carry; the state was unpacked along its
    # first axis and a force failed steps later ("invalid index to scalar variable"); no name failed
    # only when the trajectory was made, after the whole run
    import dataclasses

    @dataclasses.dataclass(frozen=True)
    class Forgetful(Stepper):
        name, order, evaluations = "forgetful", 1, 1

        def step(self, model, t, y, dt, carry):
            return model.xp.stack([y[0] + dt * y[1], y[1]])

    @dataclasses.dataclass(frozen=True)
    class Nameless(Stepper):
        order, evaluations = 1, 1

        def step(self, model, t, y, dt, carry):
            return y, carry

    problem = oscillator()
    for backend in ("numpy", "jax"):  # on JAX, it failed in lax.scan's carry-structure check
        with pytest.raises(TypeError, match=r"forgetful: step\(model, t, y, dt, carry\) must return \(y_next, "
                                            r"carry\) .* it returned an array of shape \(2, 2, 3\)"):
            simulate(problem.model, Forgetful(), problem.y0, 0.0, 0.1, 0.01, backend=backend)
    with pytest.raises(UnknownIntegratorError, match='Nameless needs a class attribute name = "..."'):
        simulate(problem.model, Nameless(), problem.y0, 0.0, 0.1, 0.01)


# --- (5) energy behaviour on the oscillator ---------------------------------------------------


@pytest.mark.parametrize("name", SYMPLECTIC)
def test_symplectic_methods_keep_energy_bounded(name):
    dt, steps = 0.01, 100_000
    problem = oscillator()
    # compiled (JAX) so 10^5 steps are quick; 37 is coprime to the 100 steps per period
    run = simulate(problem.model, name, problem.y0, 0.0, steps * dt, dt, backend="jax", save_every=37)
    assert run.steps == steps
    energy = oscillator_energy(run.y)
    assert energy[0] == pytest.approx(0.5 * OMEGA**2 * 0.5**2, rel=1e-14)
    error = np.abs(energy / energy[0] - 1)
    bound = (OMEGA * dt) ** INTEGRATORS[name].order
    assert error.max() < bound
    tenth = len(error) // 10
    assert error[-tenth:].max() <= 1.01 * error[:tenth].max()  # not growing


def test_explicit_euler_energy_grows_geometrically():
    """On the linear oscillator explicit Euler multiplies the energy by exactly
    1 + (omega dt)^2 every step (its step matrix is a rotation scaled by that root)."""
    dt, steps = 0.01, 2000
    problem = oscillator(amplitude=1e-3)  # stays far from zero spring length
    run = simulate(problem.model, "euler", problem.y0, 0.0, steps * dt, dt, save_every=100)
    energy = oscillator_energy(run.y)
    n = np.arange(0, steps + 1, 100)
    assert_allclose(energy / energy[0], (1 + (OMEGA * dt) ** 2) ** n, rtol=1e-9)
    assert energy[-1] / energy[0] > 1000


def test_implicit_euler_dissipates_energy():
    problem = oscillator()
    run = simulate(problem.model, "implicit-euler", problem.y0, 0.0, 5.0, 0.01)
    energy = oscillator_energy(run.y)
    assert np.all(np.diff(energy) < 0)
    assert energy[-1] < 0.5 * energy[0]


# --- (6) NumPy and JAX backends; float32 ------------------------------------------------------

MIXED_T_END, MIXED_DT = 0.2, 0.005


@pytest.fixture(scope="module")
def mixed_numpy_runs():
    problem = mixed_problem()
    return problem, {name: simulate(problem.model, name, problem.y0, 0.0, MIXED_T_END, MIXED_DT)
                     for name in FIXED_STEP}


@pytest.mark.parametrize("name", FIXED_STEP)
def test_numpy_and_jax_backends_agree(name, mixed_numpy_runs):
    """Oscillator with damper, projectile with drag and a moving soft body with dampers,
    all under gravity, in one model (one compilation per integrator)."""
    problem, runs = mixed_numpy_runs
    ref = runs[name]
    run = simulate(problem.model, name, problem.y0, 0.0, MIXED_T_END, MIXED_DT, backend="jax")
    assert run.backend == "jax" and ref.backend == "numpy" and run.y.dtype == np.float64
    assert run.steps == ref.steps == 40
    assert_array_equal(run.t, ref.t)
    assert_allclose(run.y, ref.y, rtol=1e-12, atol=1e-12 * np.abs(ref.y).max())


@pytest.mark.parametrize("name", FIXED_STEP)
def test_float32_numpy_within_float32_precision(name, mixed_numpy_runs):
    problem, runs = mixed_numpy_runs
    ref = runs[name]
    run = simulate(problem.model, name, problem.y0, 0.0, MIXED_T_END, MIXED_DT, dtype=np.float32)
    assert run.y.dtype == np.float32
    scale = np.abs(ref.y).max()
    error = max_error(run.y, ref.y)
    assert error < 10 * np.finfo(np.float32).eps * scale
    assert error > 10 * np.finfo(np.float64).eps * scale  # really computed in float32


@pytest.mark.parametrize("name", ["semi-implicit-euler", "implicit-euler"])
def test_float32_jax_within_float32_precision(name, mixed_numpy_runs):
    problem, runs = mixed_numpy_runs
    ref = runs[name]
    run = simulate(problem.model, name, problem.y0, 0.0, MIXED_T_END, MIXED_DT, backend="jax",
                   dtype=np.float32)
    assert run.y.dtype == np.float32
    assert max_error(run.y, ref.y) < 10 * np.finfo(np.float32).eps * np.abs(ref.y).max()


@pytest.mark.parametrize("name", ["semi-implicit-euler", "rk4"])
def test_backends_agree_with_ground_friction(name):
    """The reactive (ground contact) path: a block sliding on the ground, tied by a
    spring to a pinned post, under gravity."""
    from steplab.physics import Gravity, Springs

    radii = np.array([0.05, 0.1])
    model = Model([1.0, 2.0], radii,
                  [Gravity(), Springs(np.array([0]), np.array([1]), np.array([30.0]), np.array([0.5])),
                   Friction(0.5, 0.3, np.array([0.0, 0.0, 1.0]), 0.0, radii)], pinned=[True, False])
    y0 = np.array([[[0.0, 0.0, 0.1], [1.0, 0.2, 0.1]], [[0.0, 0.0, 0.0], [0.0, 1.5, 0.0]]])
    ref = simulate(model, name, y0, 0.0, 0.2, 0.005)
    run = simulate(model, name, y0, 0.0, 0.2, 0.005, backend="jax")
    assert_allclose(run.y, ref.y, rtol=1e-12, atol=1e-13)
    assert_allclose(ref.y[:, 0, 1, 2], 0.1, atol=1e-15)  # stays on the ground
    assert np.abs(ref.y[-1, 1, 1]).max() > 0.1  # and really moves


# --- (7) stiffness: implicit Euler ------------------------------------------------------------


def stiff_soft_body():
    """4 vertices of 0.1 kg on springs of k = 10^5 N/m: omega ~ 1.9e3 rad/s."""
    forces, y0, m = soft_tetrahedron(stiffness=1e5, damping=0.0, mass=0.1, deform=0.05, speed=0.5)
    y0[1, 0] = 0.0
    return Model(m, np.full(4, 0.05), forces, pinned=[True, False, False, False]), y0


@pytest.mark.parametrize("name", ["euler", "semi-implicit-euler"])
def test_stiff_soft_body_diverges_with_explicit_methods(name):
    model, y0 = stiff_soft_body()
    with pytest.raises(DivergenceError) as info:
        simulate(model, name, y0, 0.0, 2.0, 0.01)
    assert info.value.integrator == name and info.value.step < 200


def test_implicit_euler_keeps_stiff_soft_body_stable():
    model, y0 = stiff_soft_body()
    run = simulate(model, "implicit-euler", y0, 0.0, 2.0, 0.01)
    assert np.all(np.isfinite(run.y))
    assert np.abs(run.y[:, 0]).max() < 10.0  # no blow-up
    energy = np.array([float(model.energy(y)) for y in run.y])
    assert np.all(np.diff(energy) <= 1e-9 * energy[0])  # A-stable and dissipative
    assert_array_equal(run.y[:, 0, 0], np.broadcast_to(y0[0, 0], run.y[:, 0, 0].shape))  # pinned


def test_implicit_euler_converges_first_order_on_a_soft_body():
    forces, y0, m = soft_tetrahedron(stiffness=50.0, damping=0.5, mass=0.25)
    model = Model(m, np.full(4, 0.05), forces)
    t_end = 0.25
    reference = simulate(model, "scipy-dop853", y0, 0.0, t_end, t_end).y[-1]
    dts = [t_end / (80 * 2**k) for k in range(5)]
    errors = [max_error(simulate(model, "implicit-euler", y0, 0.0, t_end, dt, save_every=10**6).y[-1], reference)
              for dt in dts]
    assert fit_order(dts, errors) == pytest.approx(1.0, abs=0.15)


# --- (8) divergence is reported ---------------------------------------------------------------


def linear_euler_growth(omega, dt, x0, steps):
    """Explicit Euler on x'' = -omega^2 x, done independently: max(|x|, |v|) after each step."""
    x, v, sizes = x0, 0.0, []
    for _ in range(steps):
        x, v = x + dt * v, v - dt * omega**2 * x
        sizes.append(max(abs(x), abs(v)))
    return np.array(sizes)


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_divergence_error_names_integrator_dt_step_and_time(backend):
    omega, dt, t_start = 100.0, 0.1, 2.0
    # a zero-rest-length spring is exactly linear: F = -k x; explicit Euler grows the
    # state about tenfold per step here
    problem = oscillator(stiffness=omega**2, rest_length=0.0, amplitude=1.0, with_exact=False)
    with pytest.raises(DivergenceError) as info:
        simulate(problem.model, "euler", problem.y0, t_start, 100.0, dt, backend=backend)
    err = info.value
    assert isinstance(err, ArithmeticError)
    assert (err.integrator, err.dt) == ("euler", dt)
    assert err.t == pytest.approx(t_start + err.step * dt)
    # The reported step is the first one beyond *some* divergence limit between "clearly
    # diverged" (10^6 times the initial size) and overflow: every earlier state is below
    # a value the reported one exceeds.
    sizes = linear_euler_growth(omega, dt, 1.0, err.step)
    before = sizes[:-1].max(initial=0.0)
    assert max(before, 1e6) < sizes[-1]
    assert before <= math.sqrt(np.finfo(float).max)
    message = str(err)
    assert "'euler'" in message and "dt = 0.1" in message
    assert f"step {err.step}" in message and f"t = {t_start + err.step * dt:g}" in message


def test_divergence_step_is_the_same_on_both_backends():
    problem = oscillator(stiffness=1e4, rest_length=0.0, amplitude=1.0, with_exact=False)
    steps = []
    for backend in ("numpy", "jax"):
        with pytest.raises(DivergenceError) as info:
            simulate(problem.model, "semi-implicit-euler", problem.y0, 0.0, 100.0, 0.05, backend=backend)
        steps.append(info.value.step)
    assert steps[0] == steps[1]


# --- (9) the adaptive references --------------------------------------------------------------

REFERENCE_T_END, REFERENCE_DT = 2.0, 0.1


@pytest.fixture(scope="module", params=REFERENCES)
def reference_run(request):
    name = request.param
    problem = oscillator(velocity=0.7)
    run = simulate(problem.model, name, problem.y0, 0.0, REFERENCE_T_END, REFERENCE_DT)
    method = INTEGRATORS[name]
    scale = np.abs(run.y).max()
    tolerance = method.atol + method.rtol * scale
    return name, run, problem.exact(run.t), tolerance


def test_reference_matches_exact_oscillator_at_the_end(reference_run):
    name, run, exact, tolerance = reference_run
    assert run.steps == 0 and run.integrator == name and len(run.t) == 21
    assert max_error(run.y[-1], exact[-1]) < 100 * tolerance


def test_reference_matches_exact_oscillator_at_every_saved_time(reference_run):
    # diffrax would fill SaveAt(ts=...) by interpolating inside its adaptive steps, and the
    # Dopri8 / Kvaerno5 interpolants are 100-1000x worse than the steps: the references
    # step onto every saved time instead, which this test guards.
    name, run, exact, tolerance = reference_run
    assert max_error(run.y, exact) < 100 * tolerance


def test_references_are_tight_in_absolute_terms(reference_run):
    name, run, exact, _ = reference_run
    assert max_error(run.y, exact) < 1e-6


DIFFRAX_REFERENCES = [name for name in REFERENCES if name.startswith("diffrax-")]


@pytest.mark.parametrize("name", DIFFRAX_REFERENCES)
def test_diffrax_reference_in_float32_rounds_its_float64_solve(name):
    """`steplab run soft-cube --integrator diffrax-dopri8 --backend jax --precision float32 --steps 20`: a
    float32 solve can never meet rtol 1e-12, so it spent its million steps (seconds to minutes) and failed.
    It solves in float64, as the scipy references do, and the trajectory is the float64 one in float32."""
    from steplab.physics.scene import load_scene

    scene = load_scene("soft-cube")
    ref = simulate(scene.model, name, scene.y0, scene.t_start, dt=scene.dt, n_steps=20)
    run = simulate(scene.model, name, scene.y0, scene.t_start, dt=scene.dt, n_steps=20, dtype=np.float32)
    assert run.y.dtype == np.float32 and run.steps == 0 and len(run.t) == len(ref.t) == 21
    # the model's parameters are rounded to float32 too: a few float32 epsilons of the state's scale
    assert max_error(run.y, ref.y) < 10 * np.finfo(np.float32).eps * np.abs(ref.y).max()


def cloth_scene(tmp_path, side):
    """physics/scenes/cloth.toml with a side x side grid: 6 side^2 numbers of state."""
    from steplab.physics.scene import load_scene

    path = tmp_path / f"cloth{side}.toml"
    path.write_text(f"""[simulation]\nintegrator = "semi-implicit-euler"\ndt = 0.002\nt_end = 3.0\n
[[soft_bodies]]\nname = "cloth"\nshape = "grid"\nrows = {side}\ncols = {side}\nspacing = 0.1
origin = [0.0, 0.0, 2.0]\nconnect = "edges"\nmass = 0.5\nradius = 0.02\nstiffness = 100.0\ndamping = 0.05
pinned = [0, {side - 1}]\n\n[forces.gravity]\n""")
    return load_scene(path)


@pytest.mark.parametrize("side", [4, 8])  # 96 numbers: dense LU Newton solves; 384: matrix-free GMRES
def test_kvaerno5_steps_a_cloth_like_an_explicit_solver_and_agrees_with_it(tmp_path, side):
    """`run cloth --integrator diffrax-kvaerno5 --steps 20` took 215 s: diffrax's VeryChord reported every
    stage that needed a third chord iteration as diverged, and every such step was rejected and cut fivefold
    (463 steps, 235 rejected, on the 4 x 4 cloth; 613 on 8 x 8, where dopri8 takes 20)."""
    import jax.numpy as jnp
    from steplab.integrators import references

    scene = cloth_scene(tmp_path, side)
    model = scene.model.cast(jnp, jnp.float64)
    ts = jnp.asarray(scene.t_start + scene.dt * np.arange(21))
    y0 = jnp.asarray(scene.y0, dtype=jnp.float64)
    solver = references.kvaerno5(y0.size)
    linear_solver = solver.root_finder.linear_solver
    assert type(linear_solver).__name__ == ("GMRES" if y0.size > references.DENSE_NEWTON_MAX_SIZE else
                                            "AutoLinearSolver")
    sol = references.solve_adaptive(model.vector_field, ts, y0, "diffrax-kvaerno5", 1e-10, 1e-10)
    # scipy's DOP853, an independent explicit solver (and no second XLA compile)
    ref = references.solve_adaptive(scene.model.vector_field, np.asarray(ts), scene.y0, "scipy-dop853", 1e-12, 1e-12)
    assert bool(sol.success) and bool(ref.success)
    assert int(sol.steps) <= 60  # 20 saved times; 20 steps on 4 x 4, 38 on 8 x 8 (29 accepted)
    # measured 1e-11 (4 x 4) to 3e-9 (12 x 12) of the scale 2 m: tolerance 1e-10 a step
    assert max_error(sol.ys, ref.ys) < 1e-8


def test_kvaerno5_solves_the_mixed_problem_with_a_body_at_rest_under_drag(monkeypatch):
    """The mixed problem's pinned anchor is at rest under drag |v| v, whose JAX derivative through |v| was
    0 / 0 = NaN there: every Newton solve failed and every step was rejected until the budget was spent
    (1,000,000 steps, some 14 minutes). Now it agrees with scipy's Radau (its Jacobian analytic). A
    budget of 1,000 steps keeps the old behaviour short."""
    from steplab.integrators import references

    monkeypatch.setattr(references, "MAX_REFERENCE_STEPS", 1000)
    problem = mixed_problem()
    ours = simulate(problem.model, "diffrax-kvaerno5", problem.y0, 0.0, 0.2, 0.005)
    theirs = simulate(problem.model, "scipy-radau", problem.y0, 0.0, 0.2, 0.005)
    assert max_error(ours.y, theirs.y) < 1e-8 * np.abs(theirs.y).max()  # measured 9e-11 of it


def test_an_implicit_diffrax_reference_says_at_once_when_its_derivative_is_not_finite():
    """A vector field whose JAX derivative is NaN at the start (|y| at 0) would fail every Newton solve until
    the step budget was spent: one Jacobian-vector product says so first, naming the body."""
    import types

    import jax.numpy as jnp
    from steplab.integrators import references

    y0 = jnp.ones((2, 3, 3)).at[1, 2].set(0.0)
    model = types.SimpleNamespace(vector_field=lambda t, y: jnp.stack([y[1], -jnp.sqrt(y[1] * y[1])]))
    with pytest.raises(references.ReferenceFailedError) as err:
        references._check_autodiff_jacobian("diffrax-kvaerno5", model, 0.0, y0)
    assert str(err.value).startswith("diffrax-kvaerno5 failed: the vector field's derivative (JAX autodiff) is "
                                     "not finite at the initial state (velocity of body 2;")
    references._check_autodiff_jacobian("diffrax-kvaerno5", model, 0.0, y0.at[1, 2].set(1.0))  # finite: no error


# --- (10) Butcher tableaux and stability functions --------------------------------------------


def test_butcher_tableau_rejects_inconsistent_coefficients():
    with pytest.raises(ValueError, match=r"a_lower\[0\] \(a_21\) sums to 0.5"):
        ButcherTableau(a_lower=((0.5,),), b=(0.5, 0.5), c=(1.0,))  # row sum 0.5 != c_2
    with pytest.raises(ValueError, match="sum to"):
        ButcherTableau(a_lower=((1.0,),), b=(0.5, 0.4), c=(1.0,))  # sum(b) = 0.9
    with pytest.raises(ValueError, match="entries"):
        ButcherTableau(a_lower=((0.5, 0.0),), b=(0.5, 0.5), c=(0.5,))
    with pytest.raises(ValueError):
        ButcherTableau(a_lower=((1.0,),), b=(0.5, 0.5), c=(1.0, 2.0))
    ButcherTableau(a_lower=((2 / 3,),), b=(1 / 4, 3 / 4), c=(2 / 3,))  # Ralston's method is fine


Z = np.array([0.3, -1.2, 0.5j, -0.7 + 0.9j, -2.5 + 0.1j])


@pytest.mark.parametrize("name", RUNGE_KUTTA)
def test_stability_function_is_truncated_exponential(name):
    method = INTEGRATORS[name]
    p = method.order
    taylor = sum(Z**k / math.factorial(k) for k in range(p + 1))
    if method.tableau.stages == p:  # RK4, Heun, midpoint: R(z) is exactly the Taylor polynomial
        assert_allclose(method.tableau.stability_function(Z), taylor, rtol=1e-14)
    # in any case R(z) = exp(z) + O(z^(p+1))
    for z in (1e-2, 1e-2j):
        assert abs(method.tableau.stability_function(z) - taylor_at(z, p)) < 10 * abs(z) ** (p + 1)


def taylor_at(z, p):
    return sum(z**k / math.factorial(k) for k in range(p + 1))


@pytest.mark.parametrize("name", RUNGE_KUTTA)
def test_runge_kutta_step_applies_its_stability_function(name):
    """On x'' = -omega^2 x, w = v + i omega x obeys w' = i omega w, so one step of any
    Runge-Kutta method multiplies w by R(i omega dt)."""
    omega, dt = 3.0, 0.2
    problem = oscillator(stiffness=omega**2, rest_length=0.0, amplitude=0.8, velocity=-0.5, with_exact=False)
    run = simulate(problem.model, name, problem.y0, 0.0, dt, dt)
    w0 = -0.5 + 1j * omega * 0.8
    w1 = run.y[-1, 1, 1, 0] + 1j * omega * run.y[-1, 0, 1, 0]
    assert w1 == pytest.approx(INTEGRATORS[name].tableau.stability_function(1j * omega * dt) * w0, rel=1e-14)


# --- (11) the registry ------------------------------------------------------------------------


def test_unknown_integrator_lists_valid_names():
    with pytest.raises(KeyError) as info:
        get_integrator("runge-kutta-9")
    message = str(info.value)
    assert "runge-kutta-9" in message
    for name in INTEGRATORS:
        assert name in message
    with pytest.raises(KeyError):
        get_integrator(["rk4"])  # unhashable: still the same clear error


def test_get_integrator_accepts_objects_and_names():
    method = INTEGRATORS["rk4"]
    assert get_integrator(method) is method
    assert get_integrator("rk4") is method
    custom = type(INTEGRATORS["implicit-euler"])(rtol=1e-12)
    assert get_integrator(custom) is custom
    problem = oscillator()
    run = simulate(problem.model, custom, problem.y0, 0.0, 0.1, 0.01)
    assert run.integrator == "implicit-euler" and run.steps == 10


def test_registry_entries_are_integrators_with_declared_properties():
    for name, method in INTEGRATORS.items():
        assert isinstance(method, Integrator)
        assert method.name == name
        info = method.describe()
        assert info["name"] == name and info["order"] == method.order
        assert info["description"]
    assert set(FIXED_STEP) >= {"euler", "semi-implicit-euler", "velocity-verlet", "position-verlet",
                               "rk4", "implicit-euler"}


@pytest.mark.parametrize("name", [n for n in FIXED_STEP if not INTEGRATORS[n].implicit])
def test_declared_force_evaluations_per_step(name):
    problem = damped()
    model = problem.model.cast()
    calls = []
    acceleration = model.acceleration

    def counting(t, q, v):
        calls.append(t)
        return acceleration(t, q, v)

    model.acceleration = counting
    method = INTEGRATORS[name]
    assert isinstance(method, Stepper)
    carry = method.init(model, 0.0, problem.y0)
    y = problem.y0
    calls.clear()
    for k in range(5):
        y, carry = method.step(model, 0.01 * k, y, 0.01, carry)
    assert len(calls) == 5 * method.evaluations


# --- (12) time reversibility ------------------------------------------------------------------


@pytest.mark.parametrize("name", ["velocity-verlet", "position-verlet"])
def test_verlet_is_time_reversible(name):
    problem = oscillator(velocity=1.3)
    model, method, dt, n = problem.model, INTEGRATORS[name], 0.01, 1234  # not whole periods
    y = problem.y0
    carry = method.init(model, 0.0, y)
    for k in range(n):
        y, carry = method.step(model, k * dt, y, dt, carry)
    assert max_error(y, problem.y0) > 0.1  # it went somewhere
    carry = method.init(model, n * dt, y)
    for k in range(n, 0, -1):
        y, carry = method.step(model, k * dt, y, -dt, carry)
    assert_allclose(y, problem.y0, rtol=0, atol=1e-11)


def test_explicit_euler_is_not_time_reversible():
    """The control for the reversibility test: a non-symmetric method does not return."""
    problem = oscillator(velocity=1.3)
    method, dt, n = INTEGRATORS["euler"], 0.01, 1234
    y = problem.y0
    for k in range(n):
        y, _ = method.step(problem.model, k * dt, y, dt, None)
    for k in range(n, 0, -1):
        y, _ = method.step(problem.model, k * dt, y, -dt, None)
    assert max_error(y, problem.y0) > 1e-3


# --- the exact solutions the other tests rely on ----------------------------------------------


def test_helper_exact_solutions_solve_their_equations():
    """Guard the references themselves: they start at y0 and satisfy y' = f(t, y)."""
    for problem in (oscillator(), damped(), lecture_projectile()):
        assert_allclose(problem.exact(problem.t0), problem.y0, atol=1e-15)
        for t in problem.t0 + np.array([0.13, 0.77]):
            h = 1e-5
            derivative = (problem.exact(t + h) - problem.exact(t - h)) / (2 * h)
            assert_allclose(derivative, problem.model.vector_field(t, problem.exact(t)), atol=1e-7)
    assert_allclose(projectile_solution([5.0], (1, 2, 3), (0, 0, 0), (0, 0, -1), 5.0)[0, 0, 0], [1, 2, 3])


@pytest.mark.parametrize("name", ["implicit-damping-euler", "exponential-damping-euler"])
def test_a_dense_jacobian_too_large_to_hold_is_one_line(name):
    # 10^5 bodies: (3N)^2 matrices of 671 GiB each, a MemoryError from NumPy before
    from steplab.physics import Dampers, Gravity

    n = 100_000
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity(), Dampers(np.arange(n - 1), np.arange(1, n), np.ones(n - 1))])
    y0 = np.zeros((2, n, 3))
    y0[0, :, 0] = np.arange(n)
    with pytest.raises(ValueError, match=r"the dense Jacobian of 100,000 bodies needs \(3N\)\^2 matrices of 671 GiB "
                                         r"each \(at most 1 GiB"):
        simulate(model, name, y0, 0.0, dt=0.01, n_steps=1)
