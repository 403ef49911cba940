"""Force models against hand-computed cases, finite differences and autodiff; the Model."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import LECTURE_G, LECTURE_MASS, LECTURE_P0, LECTURE_V0, mixed_problem, soft_tetrahedron
from numpy.testing import assert_allclose, assert_array_equal
from steplab.physics import (
    CentralGravity,
    Dampers,
    Drag,
    Friction,
    Gravity,
    Model,
    Springs,
    State,
    from_lecture_state,
    kepler_orbit,
    lecture_derivative,
    lecture_state,
    projectile,
)
from steplab.physics.drag import AIR_DENSITY
from steplab.physics.friction import CONTACT_DISTANCE

BACKENDS = [pytest.param(np, id="numpy"), pytest.param(jnp, id="jax")]


def arr(x):
    return np.asarray(x, dtype=float)


def pair(i, j):
    return np.array(i), np.array(j)


# --- gravity -------------------------------------------------------------------------------


def test_gravity_is_weight_m_g():
    m = arr([2.5, 1.0, 0.2])
    q, v = np.zeros((3, 3)), np.ones((3, 3))
    f = Gravity(arr(LECTURE_G)).force(np, q, v, m)
    assert_allclose(f, [[0, 0, -24.525], [0, 0, -9.81], [0, 0, -1.962]], rtol=1e-15)


def test_gravity_default_is_earth_minus_z():
    f = Gravity().force(np, np.zeros((1, 3)), np.zeros((1, 3)), arr([1.0]))
    assert_array_equal(f, [[0.0, 0.0, -9.81]])


# --- springs -------------------------------------------------------------------------------


def test_hooke_spring_stretched_pulls_together_equal_and_opposite():
    # body 0 at the origin, body 1 at (3, 4, 0): l = 5, d = (0.6, 0.8, 0)
    q = arr([[0, 0, 0], [3, 4, 0]])
    springs = Springs(*pair([0], [1]), stiffness=arr([10.0]), rest_length=arr([2.0]))
    f = springs.force(np, q, np.zeros_like(q), arr([1, 1]))
    # F = k (l - l_rest) d = 10 * 3 * (0.6, 0.8, 0) on body 0, -F on body 1
    assert_allclose(f, [[18, 24, 0], [-18, -24, 0]], rtol=1e-14)


def test_hooke_spring_compressed_pushes_apart():
    q = arr([[0, 0, 0], [3, 4, 0]])
    springs = Springs(*pair([0], [1]), stiffness=arr([10.0]), rest_length=arr([7.0]))
    f = springs.force(np, q, np.zeros_like(q), arr([1, 1]))
    assert_allclose(f, [[-12, -16, 0], [12, 16, 0]], rtol=1e-14)


def test_springs_accumulate_on_shared_bodies():
    # a chain 0 - 1 - 2 along x, both springs stretched by 1 m, k = 2 and 5
    q = arr([[0, 0, 0], [2, 0, 0], [4, 0, 0]])
    springs = Springs(*pair([0, 1], [1, 2]), stiffness=arr([2.0, 5.0]), rest_length=arr([1.0, 1.0]))
    f = springs.force(np, q, np.zeros_like(q), arr([1, 1, 1]))
    assert_allclose(f, [[2, 0, 0], [-2 + 5, 0, 0], [-5, 0, 0]], rtol=1e-14)


# --- dampers -------------------------------------------------------------------------------


def test_damper_resists_relative_velocity_along_axis():
    q = arr([[0, 0, 0], [3, 4, 0]])  # d = (0.6, 0.8, 0)
    v = arr([[1, 0, 0], [0, 2, 5]])  # V2 - V1 = (-1, 2, 5), (V2 - V1).d = -0.6 + 1.6 = 1
    dampers = Dampers(*pair([0], [1]), damping=arr([3.0]))
    f = dampers.force(np, q, v, arr([1, 1]))
    # F = c ((V2 - V1).d) d = 3 * 1 * (0.6, 0.8, 0) on body 0 (drawn after body 1), -F on body 1
    assert_allclose(f, [[1.8, 2.4, 0], [-1.8, -2.4, 0]], rtol=1e-14)


def test_damper_ignores_motion_perpendicular_to_axis():
    q = arr([[0, 0, 0], [0, 0, 2]])
    v = arr([[1, -1, 0], [0, 3, 0]])  # relative velocity perpendicular to d = z
    f = Dampers(*pair([0], [1]), damping=arr([7.0])).force(np, q, v, arr([1, 1]))
    assert_array_equal(f, np.zeros((2, 3)))


# --- drag ----------------------------------------------------------------------------------


def test_drag_matches_the_lecture_formula():
    rho, cd, r = 1.225, 0.4, 0.11
    V = arr([3.0, -1.0, 4.0])
    speed = math.sqrt(26.0)
    expected = -0.5 * rho * speed**2 * cd * math.pi * r**2 * V / speed
    drag = Drag.from_coefficients(arr([r]), density=rho, drag_coefficient=cd)
    f = drag.force(np, np.zeros((1, 3)), V[None], arr([1.0]))
    assert_allclose(f[0], expected, rtol=1e-14)


def test_drag_defaults_and_mask():
    drag = Drag.from_coefficients(arr([0.1, 0.2]), mask=[False, True])
    assert AIR_DENSITY == 1.225
    assert_allclose(drag.beta, [0.0, 0.5 * 1.225 * 0.4 * math.pi * 0.04], rtol=1e-15)
    v = arr([[5, 0, 0], [0, 0, -2]])
    f = drag.force(np, np.zeros((2, 3)), v, arr([1, 1]))
    assert_array_equal(f[0], 0.0)
    assert_allclose(f[1], [0, 0, drag.beta[1] * 4], rtol=1e-15)  # opposes V: +z for V = -2 z


# --- friction ------------------------------------------------------------------------------

MU_S, MU_D, RADIUS, MASS = 0.5, 0.3, 0.1, 2.0
WEIGHT = MASS * 9.81


def ground(**kw):
    params = dict(mu_static=MU_S, mu_dynamic=MU_D, normal=arr([0, 0, 1]), height=0.0, radii=arr([RADIUS]))
    params.update(kw)
    return Friction(**params)


def friction_on(applied, v=(0, 0, 0), z=RADIUS, xp=np, friction=None):
    friction = friction or ground()
    friction = friction.cast(xp, np.float64)
    q = xp.asarray([[0.3, -0.2, z]])
    return np.asarray(friction.force(xp, q, xp.asarray([v], dtype=float), xp.asarray([MASS]),
                                     xp.asarray([applied], dtype=float)))[0]


@pytest.mark.parametrize("xp", BACKENDS)
def test_static_friction_cancels_a_small_push(xp):
    push = 1.5  # < mu_s |F_n| = 9.81
    out = friction_on([push, 0, -WEIGHT], xp=xp)
    # support cancels the weight, friction cancels the push: min(mu_s |F_n|, |F_t|) = |F_t|
    assert_allclose(out, [-push, 0, WEIGHT], rtol=1e-14)


@pytest.mark.parametrize("xp", BACKENDS)
def test_static_friction_saturates_at_mu_s_times_normal_force(xp):
    push = arr([30.0, 40.0, 0.0])  # |F_t| = 50 > mu_s |F_n| = 9.81
    out = friction_on(push + [0, 0, -WEIGHT], xp=xp)
    assert_allclose(out, [-0.6 * MU_S * WEIGHT, -0.8 * MU_S * WEIGHT, WEIGHT], rtol=1e-14)


@pytest.mark.parametrize("xp", BACKENDS)
def test_dynamic_friction_opposes_tangential_velocity(xp):
    # sliding along (-3, 4)/5; the normal velocity component does not count, nor does F_t
    out = friction_on([10.0, 0, -WEIGHT], v=(-3.0, 4.0, -0.7), xp=xp)
    assert_allclose(out, [0.6 * MU_D * WEIGHT, -0.8 * MU_D * WEIGHT, WEIGHT], rtol=1e-14)


@pytest.mark.parametrize("xp", BACKENDS)
def test_no_friction_off_the_ground_or_pulled_away(xp):
    assert_array_equal(friction_on([5.0, 0, -WEIGHT], z=RADIUS + 0.01, xp=xp), 0.0)
    assert_array_equal(friction_on([5.0, 0, +3.0], xp=xp), 0.0)  # net force lifts it
    assert_array_equal(friction_on([5.0, 0, 0.0], xp=xp), 0.0)  # not pressed into the ground


def test_contact_distance_boundary():
    assert friction_on([0, 0, -WEIGHT], z=RADIUS + 0.5 * CONTACT_DISTANCE)[2] == pytest.approx(WEIGHT)
    assert_array_equal(friction_on([0, 0, -WEIGHT], z=RADIUS + 3 * CONTACT_DISTANCE), 0.0)


@pytest.mark.parametrize("xp", BACKENDS)
def test_friction_with_zero_tangential_velocity_and_force_is_finite_support_only(xp):
    out = friction_on([0.0, 0.0, -WEIGHT], v=(0.0, 0.0, 0.0), xp=xp)
    assert np.all(np.isfinite(out))
    assert_array_equal(out, [0.0, 0.0, WEIGHT])


@pytest.mark.parametrize("angle_deg, sticks", [(20.0, True), (35.0, False)])
def test_block_on_an_incline(angle_deg, sticks):
    """A plane with a general normal and offset: at rest, the block sticks while
    tan(angle) < mu_s; otherwise friction saturates and the net force along the slope
    is m g (sin - mu_s cos)."""
    a = math.radians(angle_deg)
    n = arr([0.0, math.sin(a), math.cos(a)])  # tilted about x
    height = 0.4
    friction = Friction(MU_S, MU_D, n, height, arr([RADIUS]))
    model = Model([MASS], [RADIUS], [Gravity(), friction])
    q = ((height + RADIUS) * n)[None]
    f = model.net_force(0.0, q, np.zeros((1, 3)))[0]
    assert f @ n == pytest.approx(0.0, abs=1e-12)  # support cancels the normal part
    if sticks:
        assert_allclose(f, 0.0, atol=1e-12)
    else:
        downhill = arr([0.0, math.cos(a), -math.sin(a)])  # in the plane, pointing down the slope
        downhill = downhill if downhill @ arr([0, 0, -1]) > 0 else -downhill
        expected = WEIGHT * (math.sin(a) - MU_S * math.cos(a))
        assert_allclose(f, expected * downhill, atol=1e-12)


def test_friction_in_a_model_sees_the_sum_of_the_other_forces():
    """A block on the ground pulled sideways by a spring to a pinned anchor: static
    friction holds it against a weak spring; a strong spring wins by |F_t| - mu_s |F_n|."""

    def model(k):
        springs = Springs(*pair([0], [1]), stiffness=arr([k]), rest_length=arr([0.5]))
        friction = Friction(MU_S, MU_D, arr([0, 0, 1]), 0.0, arr([0.05, RADIUS]))
        return Model([1.0, MASS], [0.05, RADIUS], [Gravity(), springs, friction], pinned=[True, False])

    q = arr([[-1.0, 0.0, RADIUS], [0.0, 0.0, RADIUS]])  # spring stretched by 0.5 m along x
    v = np.zeros((2, 3))
    weak = model(2.0)  # pull 1 N < 9.81 N
    assert_allclose(weak.net_force(0.0, q, v)[1], 0.0, atol=1e-13)
    assert_allclose(weak.acceleration(0.0, q, v)[1], 0.0, atol=1e-13)
    strong = model(40.0)  # pull 20 N > 9.81 N
    assert_allclose(strong.net_force(0.0, q, v)[1], [-20.0 + MU_S * WEIGHT, 0, 0], atol=1e-12)
    assert_allclose(strong.acceleration(0.0, q, v)[1], [(-20.0 + MU_S * WEIGHT) / MASS, 0, 0], atol=1e-12)
    assert_array_equal(strong.acceleration(0.0, q, v)[0], 0.0)  # the anchor is pinned


# --- central gravity (Kepler) ---------------------------------------------------------------


def test_central_gravity_is_inverse_square_towards_the_center():
    center = arr([1.0, 2.0, 3.0])
    gravity = CentralGravity(4.0, center)
    q = center + arr([[3, 4, 0], [0, 0, -2]])
    f = gravity.force(np, q, np.zeros((2, 3)), arr([2.0, 1.0]))
    # |F| = mu m / r^2 along -r: 4 * 2 / 25 towards the centre; 4 * 1 / 4 upwards
    assert_allclose(f, [[-8 / 25 * 0.6, -8 / 25 * 0.8, 0], [0, 0, 1.0]], rtol=1e-15)
    assert gravity.potential(np, q, arr([2.0, 1.0])) == pytest.approx(-(4 * 2 / 5 + 4 * 1 / 2), rel=1e-15)
    at_center = gravity.force(np, center[None], np.zeros((1, 3)), arr([1.0]))
    assert_array_equal(at_center, 0.0)  # no direction at r = 0: zero, not NaN
    assert np.all(np.isfinite(gravity.jacobian(np, center[None], np.zeros((1, 3)), arr([1.0]))[0]))


def test_central_gravity_jacobian_and_potential_match_autodiff(rng):
    q, v, _, _, m = random_pairs_case(rng)
    gravity = CentralGravity(3.0, arr([0.1, -0.2, 0.3]))
    jq, jv = gravity.jacobian(np, q, v, m)
    assert jv is None
    assert_allclose(jq, central_difference(lambda x: gravity.force(np, x, v, m), q), rtol=1e-6, atol=1e-7)
    g = gravity.cast(jnp, np.float64)
    grad = jax.grad(lambda x: g.potential(jnp, x, jnp.asarray(m)))(jnp.asarray(q))
    assert_allclose(g.force(jnp, jnp.asarray(q), jnp.asarray(v), jnp.asarray(m)), -np.asarray(grad), rtol=1e-13)


def test_kepler_orbit_against_scipy_and_the_conservation_laws():
    from scipy.integrate import solve_ivp

    mu, q0, v0 = 2.5, arr([0.3, -1.1, 0.4]), arr([0.9, 0.5, -0.6])  # a bound, inclined orbit
    times = np.linspace(0.0, 7.0, 15)

    def rhs(t, y):
        r = y[:3]
        return np.concatenate([y[3:], -mu * r / np.linalg.norm(r) ** 3])

    ref = solve_ivp(rhs, (0.0, 7.0), np.concatenate([q0, v0]), method="DOP853", rtol=1e-13, atol=1e-13,
                    t_eval=times)
    q, v = kepler_orbit(times + 4.0, q0, v0, mu, t_init=4.0)
    assert_allclose(q, ref.y[:3].T, atol=1e-10)
    assert_allclose(v, ref.y[3:].T, atol=1e-10)
    energy = 0.5 * np.sum(v * v, axis=1) - mu / np.linalg.norm(q, axis=1)
    assert_allclose(energy, energy[0], rtol=1e-13)
    assert_allclose(np.cross(q, v), np.cross(q0, v0)[None].repeat(len(times), 0), atol=1e-13)
    with pytest.raises(ValueError, match="bound"):
        kepler_orbit(1.0, q0, 10 * v0, mu)  # hyperbolic


# --- singular configurations ---------------------------------------------------------------


@pytest.mark.parametrize("xp", BACKENDS)
def test_singular_cases_give_finite_zeros(xp):
    springs = Springs(*pair([0], [1]), arr([100.0]), arr([1.0])).cast(xp, np.float64)
    dampers = Dampers(*pair([0], [1]), arr([5.0])).cast(xp, np.float64)
    drag = Drag(arr([0.3, 0.1])).cast(xp, np.float64)

    def evaluate(same, moving, m):
        rest = xp.zeros((2, 3))
        forces = (springs.force(xp, same, moving, m), dampers.force(xp, same, moving, m),
                  drag.force(xp, same, rest, m))
        jacobians = (springs.jacobian(xp, same, moving, m)[0], *dampers.jacobian(xp, same, moving, m),
                     drag.jacobian(xp, same, rest, m)[1])
        return forces, jacobians

    if xp is jnp:
        evaluate = jax.jit(evaluate)
    same = xp.asarray([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]])  # zero length, coincident bodies
    moving = xp.asarray([[0.0, 1.0, 0.0], [2.0, 0.0, -1.0]])
    forces, jacobians = evaluate(same, moving, xp.asarray([1.0, 2.0]))
    for f in forces:
        assert_array_equal(np.asarray(f), np.zeros((2, 3)))
    for j in jacobians:
        assert np.all(np.isfinite(np.asarray(j)))
    assert_array_equal(np.asarray(jacobians[-1]), 0.0)  # drag at rest: d F / d V = 0


def test_drags_autodiff_derivative_at_rest_is_its_analytic_zero_and_elsewhere_its_blocks():
    """JAX differentiating drag's -beta |v| v through |v| at rest gave 0 / 0 = NaN (an implicit diffrax
    reference then rejected every step): now 0 at rest, and the analytic blocks -beta (|v| I + v v^T / |v|)
    where the body moves."""
    drag = Drag(arr([0.3, 0.1])).cast(jnp, np.float64)
    q, m = jnp.zeros((2, 3)), jnp.ones(2)
    for v in (jnp.zeros((2, 3)), jnp.asarray([[0.0, 0.0, 0.0], [2.0, -1.0, 0.5]])):
        auto = jax.jacfwd(lambda v: drag.force(jnp, q, v, m))(v)  # (2, 3, 2, 3)
        blocks = np.asarray(drag.jacobian_blocks(jnp, q, v, m).dv)
        assert_allclose(np.asarray(auto[[0, 1], :, [0, 1], :]), blocks, rtol=1e-14, atol=0)
        assert_array_equal(np.asarray(auto[0, :, 1, :]), 0.0)


# --- Jacobians -----------------------------------------------------------------------------


def central_difference(fun, x, h=1e-6):
    """d fun / d x, shape fun(x).shape + x.shape, by central differences."""
    x = np.asarray(x, float)
    f0 = np.asarray(fun(x))
    out = np.empty(f0.shape + x.shape)
    for idx in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[idx] = h
        out[(Ellipsis,) + idx] = (np.asarray(fun(x + e)) - np.asarray(fun(x - e))) / (2 * h)
    return out


def random_pairs_case(rng, n=5):
    q = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    i = np.array([0, 0, 1, 2, 3, 4, 1])
    j = np.array([1, 2, 3, 4, 4, 0, 2])
    return q, v, i, j, arr(rng.uniform(0.5, 2.0, n))


def test_spring_jacobian_matches_finite_differences(rng):
    q, v, i, j, m = random_pairs_case(rng)
    length = np.linalg.norm(q[j] - q[i], axis=1)
    rest = length * rng.choice([0.5, 1.5], size=len(i))  # stretched and compressed
    springs = Springs(i, j, rng.uniform(1, 10, len(i)), rest)
    jq, jv = springs.jacobian(np, q, v, m)
    assert jv is None
    fd = central_difference(lambda x: springs.force(np, x, v, m), q)
    assert_allclose(jq, fd, rtol=1e-6, atol=1e-7)


def test_damper_jacobians_match_finite_differences(rng):
    q, v, i, j, m = random_pairs_case(rng)
    dampers = Dampers(i, j, rng.uniform(0.5, 3, len(i)))
    jq, jv = dampers.jacobian(np, q, v, m)
    assert_allclose(jq, central_difference(lambda x: dampers.force(np, x, v, m), q), rtol=1e-6, atol=1e-7)
    assert_allclose(jv, central_difference(lambda x: dampers.force(np, q, x, m), v), rtol=1e-6, atol=1e-7)


def test_drag_jacobian_matches_finite_differences(rng):
    q, v, _, _, m = random_pairs_case(rng)
    drag = Drag(rng.uniform(0.01, 0.1, 5))
    jq, jv = drag.jacobian(np, q, v, m)
    assert jq is None
    assert_allclose(jv, central_difference(lambda x: drag.force(np, q, x, m), v), rtol=1e-6, atol=1e-8)


def test_jacobians_match_jax_autodiff(rng):
    q, v, i, j, m = random_pairs_case(rng)
    forces = [Springs(i, j, rng.uniform(1, 10, len(i)), rng.uniform(0.2, 2, len(i))),
              Dampers(i, j, rng.uniform(0.5, 3, len(i))), Drag(rng.uniform(0.01, 0.1, 5))]
    qj, vj, mj = jnp.asarray(q), jnp.asarray(v), jnp.asarray(m)
    for force in forces:
        f = force.cast(jnp, np.float64)
        jq, jv = jax.jit(lambda q, v, f=f: f.jacobian(jnp, q, v, mj))(qj, vj)
        auto_q = jax.jit(jax.jacfwd(lambda x, f=f: f.force(jnp, x, vj, mj)))(qj)
        auto_v = jax.jit(jax.jacfwd(lambda x, f=f: f.force(jnp, qj, x, mj)))(vj)
        assert_allclose(np.asarray(jq) if jq is not None else 0.0, auto_q, rtol=1e-12, atol=1e-12)
        assert_allclose(np.asarray(jv) if jv is not None else 0.0, auto_v, rtol=1e-12, atol=1e-12)


def test_model_jacobian_is_the_acceleration_derivative():
    problem = mixed_problem()
    model, (q, v) = problem.model, problem.y0
    dadq, dadv = model.jacobian(0.0, q, v)
    n3 = 3 * model.n_bodies
    fd_q = central_difference(lambda x: model.acceleration(0.0, x, v), q).reshape(n3, n3)
    fd_v = central_difference(lambda x: model.acceleration(0.0, q, x), v).reshape(n3, n3)
    assert_allclose(dadq, fd_q, rtol=1e-6, atol=1e-6)
    assert_allclose(dadv, fd_v, rtol=1e-6, atol=1e-7)
    assert_array_equal(dadq[:3], 0.0)  # body 0 is pinned
    assert_array_equal(dadv[:3], 0.0)


# --- conservation and potentials -----------------------------------------------------------


def test_internal_forces_conserve_momentum_and_angular_momentum(rng):
    forces, (q, v), m = soft_tetrahedron(gravity=False)
    q, v = q + rng.normal(scale=0.2, size=q.shape), rng.normal(size=v.shape)
    model = Model(m, np.full(4, 0.05), forces)
    f = model.net_force(0.0, q, v)
    assert np.abs(f).max() > 1.0  # a non-trivial case
    assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)
    # central pair forces exert no net torque either
    assert_allclose(np.cross(q, f).sum(axis=0), 0.0, atol=1e-12)


def test_potential_energies_hand_computed():
    q = arr([[0, 0, 0], [3, 4, 12]])
    m = arr([2.0, 0.5])
    gravity = Gravity(arr([0.0, 0.0, -9.81]))
    assert gravity.potential(np, q, m) == pytest.approx(0.5 * 9.81 * 12, rel=1e-15)  # m g h
    springs = Springs(*pair([0], [1]), arr([10.0]), arr([10.0]))  # l = 13
    assert springs.potential(np, q, m) == pytest.approx(0.5 * 10 * 3**2, rel=1e-15)
    assert Dampers(*pair([0], [1]), arr([1.0])).potential(np, q, m) is None
    model = Model(m, [0.1, 0.1], [gravity, springs, Drag(arr([0.1, 0.1]))])
    v = arr([[1, 0, 0], [0, 2, 0]])
    assert model.energy(np.stack([q, v])) == pytest.approx(58.86 + 45 + 0.5 * 2 + 0.5 * 0.5 * 4, rel=1e-14)


def test_conservative_forces_are_minus_the_potential_gradient(rng):
    forces, (q, v), m = soft_tetrahedron(damping=0.0, gravity=True)
    model = Model(m, np.full(4, 0.05), forces, xp=jnp)
    qj = jnp.asarray(q + rng.normal(scale=0.2, size=q.shape))
    grad = jax.jit(jax.grad(model.potential_energy))(qj)
    force = jax.jit(lambda x: model.net_force(0.0, x, jnp.zeros_like(x)))(qj)
    assert_allclose(np.asarray(force), -np.asarray(grad),
                    rtol=1e-12, atol=1e-12)


# --- the Model -----------------------------------------------------------------------------


@pytest.mark.parametrize("xp", BACKENDS)
def test_gravity_only_model_accelerates_exactly_at_g(xp, rng):
    g = arr([0.3, -0.1, -9.81])
    model = Model([1.0, 2.0, 3.0], [0.1] * 3, [Gravity(g)], pinned=[False, True, False], xp=xp)
    assert len(model.forces) == 1 and isinstance(model.forces[0], Gravity)
    assert not any(isinstance(f, (Springs, Dampers)) for f in model.forces)  # no spring arrays
    q, v = xp.asarray(rng.normal(size=(3, 3))), xp.asarray(rng.normal(size=(3, 3)))
    a = np.asarray(model.acceleration(0.0, q, v))
    assert_array_equal(a, [g, [0, 0, 0], g])  # exactly g, bit for bit; the pinned body stays
    assert_array_equal(np.asarray(model.constant_acceleration), [g, [0, 0, 0], g])
    dq, dv = model.jacobian(0.0, q, v)
    assert_array_equal(np.asarray(dq), 0.0)
    assert_array_equal(np.asarray(dv), 0.0)


def test_model_without_forces_and_with_nonconstant_forces():
    free = Model([1.0], [0.1])
    assert_array_equal(free.acceleration(0.0, np.ones((1, 3)), np.ones((1, 3))), 0.0)
    assert_array_equal(free.constant_acceleration, 0.0)
    springs = Model([1.0, 4.0], [0.1, 0.1], [Springs(*pair([0], [1]), arr([8.0]), arr([1.0]))])
    assert springs.constant_acceleration is None
    # a = F / m with F = +-(8, 0, 0) for a spring stretched by 1 m along x
    a = springs.acceleration(0.0, arr([[0, 0, 0], [2, 0, 0]]), np.zeros((2, 3)))
    assert_allclose(a, [[8, 0, 0], [-2, 0, 0]], rtol=1e-15)


def mixed_with_friction():
    problem = mixed_problem()
    base = problem.model
    friction = Friction(MU_S, MU_D, arr([0, 0, 1]), 0.0, np.asarray(base.radii))
    model = Model(np.asarray(base.masses), np.asarray(base.radii), [*base._source_forces, friction],
                  pinned=base.pinned)
    y = problem.y0.copy()
    y[0, 2] = [0.0, 0.0, 0.11]  # the drag body rests on the ground, sliding
    y[1, 2] = [2.0, 1.0, 0.0]
    return model, y


def test_model_numpy_and_jax_agree_to_round_off():
    model, y = mixed_with_friction()
    jmodel = model.cast(jnp)
    assert jmodel.xp is jnp and jmodel.dtype == np.float64
    yj = jnp.asarray(y)
    # compiled, as the JAX runs use them (and far faster than op-by-op dispatch)
    net_force, vector_field, jacobian, energy = (
        jax.jit(f) for f in (jmodel.net_force, jmodel.vector_field, jmodel.jacobian, jmodel.energy))
    assert_allclose(np.asarray(net_force(0.0, yj[0], yj[1])), model.net_force(0.0, y[0], y[1]),
                    rtol=1e-13, atol=1e-12)
    assert_allclose(np.asarray(vector_field(0.0, yj)), model.vector_field(0.0, y), rtol=1e-13, atol=1e-12)
    for a, b in zip(jacobian(0.0, yj[0], yj[1]), model.jacobian(0.0, y[0], y[1])):
        assert_allclose(np.asarray(a), b, rtol=1e-13, atol=1e-12)
    assert float(energy(yj)) == pytest.approx(float(model.energy(y)), rel=1e-14)


def test_model_float32_cast():
    model, y = mixed_with_friction()
    for xp in (np, jnp):
        m32 = model.cast(xp, np.float32)
        y32 = xp.asarray(y, dtype=np.float32)
        acceleration = m32.acceleration if xp is np else jax.jit(m32.acceleration)
        a32 = acceleration(0.0, y32[0], y32[1])
        assert a32.dtype == np.float32
        assert_allclose(np.asarray(a32), model.acceleration(0.0, y[0], y[1]), rtol=1e-4, atol=1e-4)


# --- the lecture's state view --------------------------------------------------------------


def test_lecture_state_round_trip_and_layout(rng):
    y = rng.normal(size=(2, 3, 3))
    masses = arr([2.0, 0.5, 3.0])
    s = lecture_state(y, masses)
    assert s.shape == (6, 3)
    assert_allclose(s[0::2], masses[:, None] * y[1], rtol=1e-15)  # m_i V_i
    assert_array_equal(s[1::2], y[0])  # p_i
    assert_allclose(from_lecture_state(s, masses), y, rtol=1e-15)
    state = State(y[0], y[1], masses, np.full(3, 0.1))
    assert_array_equal(state.y, y)
    assert_array_equal(state.lecture(), s)


def test_lecture_derivative_is_force_and_velocity():
    model = Model([LECTURE_MASS], [0.1], [Gravity(arr(LECTURE_G))])
    y = arr([[LECTURE_P0], [LECTURE_V0]])
    assert_allclose(lecture_state(y, [LECTURE_MASS]), [[19.2, 0, 72.5], [10, 0, 2]], rtol=1e-15)
    ds = lecture_derivative(model, 5.0, y)
    assert_allclose(ds, [[0, 0, -24.525], [7.68, 0, 29.0]], rtol=1e-15)
    # for free bodies, dS/dt is the time derivative of S: (m a, v) = (F, V)
    assert_allclose(lecture_state(model.vector_field(5.0, y), [LECTURE_MASS]), ds, rtol=1e-15)


def test_lecture_derivative_multi_body_order():
    forces, y, m = soft_tetrahedron()
    model = Model(m, np.full(4, 0.05), forces)
    ds = lecture_derivative(model, 0.0, y)
    assert_allclose(ds[0::2], model.net_force(0.0, y[0], y[1]), rtol=1e-15)
    assert_array_equal(ds[1::2], y[1])


def test_projectile_closed_form_hand_values():
    # the lecture's exact solution at t = 5.2 s (slide "Truncation Error Example"): z = 7.6038
    p, v = projectile(5.2, LECTURE_P0, LECTURE_V0, LECTURE_G, t_init=5.0)
    assert_allclose(p, [10 + 7.68 * 0.2, 0, 2 + 29 * 0.2 - 0.5 * 9.81 * 0.04], rtol=1e-14)
    assert_allclose(v, [7.68, 0, 29 - 9.81 * 0.2], rtol=1e-14)
    assert p[2] == pytest.approx(7.6038, abs=5e-5)
    ps, vs = projectile(arr([5.0, 6.0]), LECTURE_P0, LECTURE_V0, LECTURE_G, t_init=5.0)
    assert ps.shape == vs.shape == (2, 3)
    assert_allclose(ps[0], LECTURE_P0)
    assert_allclose(vs[1], [7.68, 0, 29 - 9.81], rtol=1e-14)
