"""Rotation methods and the exact torque-free motion, against Euler's equations, diffrax and invariants."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.spatial.transform import Rotation
from scipy.special import ellipk
from steplab.integrators import ROTATIONS, UnknownIntegratorError, get_rotation
from steplab.integrators.rotation import simulate_rotation
from steplab.integrators.rotation_reference import rotation_reference
from steplab.integrators.torque_free import TorqueFreeMotion, flip_period
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import (
    ForceAtPoint,
    InertiaError,
    RotationModel,
    check_inertia,
    check_orientation,
    principal_inertia,
    rotational_energy,
    torque_of_forces,
)

METHODS = list(ROTATIONS)
INERTIA = np.array([1.0, 2.0, 3.0])
#: a body spun near its intermediate axis (the Dzhanibekov flip), and two generic tumblers,
#: one precessing about axis 3 (L^2 > 2E I2) and one about axis 1
FLIP = np.array([0.05, 1.0, 0.05])
ABOUT_3 = np.array([0.3, 1.0, -0.2])
ABOUT_1 = np.array([1.0, 0.2, 0.1])
Q0 = quat.normalize(np, np.array([0.9, 0.1, -0.3, 0.2]))
FREE = RotationModel(INERTIA[None])


def euler_rhs(omega, inertia=INERTIA):
    return -np.cross(omega, inertia * omega) / inertia


# --- the exact solution ---------------------------------------------------------------------


@pytest.mark.parametrize("omega0", [FLIP, ABOUT_3, ABOUT_1, -ABOUT_3, np.array([-0.4, -0.9, 0.3])])
def test_exact_solution_satisfies_eulers_equations(omega0):
    motion = TorqueFreeMotion(INERTIA, Q0, omega0)
    ts = np.linspace(0.0, 2.5 * motion.period, 97)
    omega = motion.angular_velocity(ts)
    np.testing.assert_allclose(omega[0], omega0, rtol=0, atol=1e-14)
    # d/du (sn, cn, dn) = (cn dn, -sn dn, -m sn cn): the exact derivative of the solution
    a = motion.amplitude
    s, c, d = omega[:, 1] / a[1], omega[:, motion.cn_axis] / a[motion.cn_axis], omega[:, motion.polar] / a[motion.polar]
    rate = np.empty_like(omega)
    rate[:, 1] = a[1] * c * d
    rate[:, motion.cn_axis] = -a[motion.cn_axis] * s * d
    rate[:, motion.polar] = -a[motion.polar] * motion.m * s * c
    residual = motion.rate * rate - euler_rhs(omega)
    assert np.max(np.abs(residual)) <= 1e-10 * np.max(np.abs(omega0)) ** 2
    # the orientation: dq/dt = 1/2 q (0, omega), by an 8th-order central difference
    h = 1e-3
    weights = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
    shifts = np.arange(-4, 5) * h
    t_mid = ts[1:-1]
    q_all = motion.orientation((t_mid[:, None] + shifts).ravel()).reshape(len(t_mid), 9, 4)
    q_all *= np.sign(np.sum(q_all * q_all[:, 4:5], axis=-1, keepdims=True))  # one sign of q per point
    dq = np.einsum("k,tkc->tc", weights, q_all) / h
    expected = 0.5 * quat.multiply_vector(np, q_all[:, 4], motion.angular_velocity(t_mid))
    assert np.max(np.abs(dq - expected)) <= 1e-10


@pytest.mark.parametrize("omega0", [ABOUT_3, ABOUT_1])
def test_exact_solution_matches_diffrax(omega0):
    motion = TorqueFreeMotion(INERTIA, Q0, omega0)
    ts = np.linspace(0.0, 2 * motion.period, 17)
    q, omega = rotation_reference(FREE, Q0[None], omega0[None], ts, method="diffrax-dopri8")
    assert np.max(np.abs(omega[:, 0] - motion.angular_velocity(ts))) <= 1e-11
    assert np.max(quat.angle_between(np, q[:, 0], motion.orientation(ts))) <= 1e-11
    # and it keeps L fixed in space
    momentum = quat.rotate(np, motion.orientation(ts), INERTIA * motion.angular_velocity(ts))
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), rtol=0, atol=1e-13)


@pytest.mark.parametrize("omega0", [FLIP, ABOUT_3, ABOUT_1])
def test_flip_period_against_the_closed_form_and_an_ode_solve(omega0):
    i1, i2, i3 = INERTIA
    two_e, l2 = np.sum(INERTIA * omega0**2), np.sum((INERTIA * omega0) ** 2)
    if l2 > two_e * i2:  # the formula of issue 25
        m = (i2 - i1) * (two_e * i3 - l2) / ((i3 - i2) * (l2 - two_e * i1))
        closed = 4 * ellipk(m) * np.sqrt(i1 * i2 * i3 / ((i3 - i2) * (l2 - two_e * i1)))
    else:  # 1 and 3 swapped: the formula would be wrong here
        m = (i3 - i2) * (l2 - two_e * i1) / ((i2 - i1) * (two_e * i3 - l2))
        closed = 4 * ellipk(m) * np.sqrt(i1 * i2 * i3 / ((i2 - i1) * (two_e * i3 - l2)))
    assert flip_period(INERTIA, omega0) == pytest.approx(closed, rel=1e-14)
    # independently: the time between upward zero crossings of omega2 in a DOP853 solve
    sol = solve_ivp(lambda t, w: euler_rhs(w), (0, 3.2 * closed), omega0, method="DOP853", rtol=1e-13, atol=1e-13,
                    events=lambda t, w: w[1] - omega0[1] * 0.5)
    crossings = sol.t_events[0]
    assert np.diff(crossings[::2]) == pytest.approx(closed, rel=1e-9)


def test_exact_solution_refuses_what_it_cannot_solve():
    with pytest.raises(ValueError, match="I1 < I2 < I3"):
        TorqueFreeMotion([2.0, 1.0, 3.0], Q0, ABOUT_3)
    with pytest.raises(ValueError, match="steady spin"):
        TorqueFreeMotion(INERTIA, Q0, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="separatrix"):  # L^2 = 2E I2 = 72 exactly
        TorqueFreeMotion([3.0, 4.0, 6.0], Q0, [2.0, 0.0, 1.0])


# --- the methods ----------------------------------------------------------------------------


def test_registry_lists_every_method_with_its_theory():
    assert METHODS == ["explicit", "first-order-quaternion", "exponential-map", "implicit-gyroscopic",
                       "momentum-rescaled", "dlm", "implicit-midpoint", "rk4"]
    for name in METHODS:
        described = get_rotation(name).describe()
        assert described["kind"] == "rotation" and described["order"] in (1, 2, 4)
        assert described["source"] and described["stage_order"] and described["composes_with"]
    with pytest.raises(UnknownIntegratorError, match="unknown rotation method 'euler'; valid: explicit"):
        get_rotation("euler")


def test_implicit_midpoint_keeps_energy_and_momentum_over_1e5_steps():
    omega0 = np.array([FLIP, ABOUT_3, ABOUT_1])
    model = RotationModel(np.broadcast_to(INERTIA, (3, 3)))
    q0 = np.broadcast_to(Q0, (3, 4))
    _, q, omega = simulate_rotation(get_rotation("implicit-midpoint"), model, q0, omega0, 0.05, 100_000,
                                    save_every=10_000, backend="jax")
    energy = rotational_energy(np, model.inertia, omega)
    momentum = np.linalg.norm(model.inertia * omega, axis=-1)
    assert np.max(np.abs(energy / energy[0] - 1)) <= 1e-12
    assert np.max(np.abs(momentum / momentum[0] - 1)) <= 1e-12
    assert np.max(np.abs(quat.norm(np, q) - 1)) <= 1e-12


@pytest.mark.parametrize("name", METHODS)
def test_numpy_and_jax_agree(name):
    model = RotationModel(np.broadcast_to(INERTIA, (2, 3)),
                          (ForceAtPoint(np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, -9.81])),))
    args = (get_rotation(name), model, np.broadcast_to(Q0, (2, 4)), np.array([FLIP, 5 * ABOUT_1]), 0.01, 300)
    _, q, omega = simulate_rotation(*args, save_every=100)
    _, q_jax, omega_jax = simulate_rotation(*args, save_every=100, backend="jax")
    np.testing.assert_allclose(q_jax, q, rtol=0, atol=1e-13)
    np.testing.assert_allclose(omega_jax, omega, rtol=0, atol=1e-12)


def test_explicit_gains_energy_on_the_flip_and_implicit_gyroscopic_never_does():
    dt, steps = 0.05, 4000  # about eight flips
    _, _, omega = simulate_rotation(get_rotation("explicit"), FREE, Q0[None], FLIP[None], dt, steps)
    energy = rotational_energy(np, INERTIA, omega[:, 0])
    assert np.all(np.diff(energy) > 0) and energy[-1] > 1.05 * energy[0]
    _, _, omega = simulate_rotation(get_rotation("implicit-gyroscopic"), FREE, Q0[None], FLIP[None], dt, steps)
    energy = rotational_energy(np, INERTIA, omega[:, 0])
    assert np.all(np.diff(energy) <= 0) and energy[-1] < energy[0]


@pytest.mark.parametrize("name", METHODS)
def test_orientation_stays_unit(name):
    omega0 = np.array([FLIP, ABOUT_3, 3 * ABOUT_1])
    model = RotationModel(np.broadcast_to(INERTIA, (3, 3)))
    _, q, _ = simulate_rotation(get_rotation(name), model, np.broadcast_to(Q0, (3, 4)), omega0, 0.02, 3000)
    assert np.max(np.abs(quat.norm(np, q) - 1)) <= 1e-12


@pytest.mark.parametrize("name", ["momentum-rescaled", "dlm", "implicit-midpoint"])
def test_methods_that_keep_the_length_of_L(name):
    _, _, omega = simulate_rotation(get_rotation(name), FREE, Q0[None], FLIP[None], 0.1, 2000)
    momentum = np.linalg.norm(INERTIA * omega[:, 0], axis=-1)
    assert np.max(np.abs(momentum / momentum[0] - 1)) <= 1e-13


def test_dlm_keeps_the_angular_momentum_vector_in_space():
    """Each sub-flow of the splitting is an exact rotation, so R(q) I omega is constant to round-off
    (the implicit midpoint keeps |L| but not its direction: R(q) pi is cubic, not quadratic)."""
    _, q, omega = simulate_rotation(get_rotation("dlm"), FREE, Q0[None], FLIP[None], 0.1, 5000, save_every=50)
    momentum = quat.rotate(np, q[:, 0], INERTIA * omega[:, 0])
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), rtol=0, atol=1e-13)


@pytest.mark.parametrize("name", METHODS)
def test_orientation_error_converges_at_the_declared_order(name):
    method = get_rotation(name)
    motion = TorqueFreeMotion(INERTIA, Q0, ABOUT_3)
    t_end = 0.5 * motion.period
    # steps small enough for the asymptotic regime, large enough to stay above round-off
    steps = {1: [200, 400, 800, 1600], 2: [50, 100, 200, 400], 4: [20, 40, 80, 160]}[method.order]
    errors = []
    for n in steps:
        _, q, _ = simulate_rotation(method, FREE, Q0[None], ABOUT_3[None], t_end / n, n, save_every=n)
        errors.append(quat.angle_between(np, q[-1, 0], motion.orientation(t_end)[0]))
    slope = np.polyfit(np.log(t_end / np.array(steps)), np.log(errors), 1)[0]
    assert slope == pytest.approx(method.order, abs=0.15), errors


@pytest.mark.parametrize("name", METHODS)
def test_heavy_top_converges_to_the_reference_at_the_declared_order(name):
    """With torque: a top pivoted at the origin, its centre of mass d = 0.5 up the body z axis."""
    method = get_rotation(name)
    mass, gravity, d = 2.0, 9.81, 0.5
    inertia = np.array([[0.5 + mass * d * d, 0.5 + mass * d * d, 0.3]])  # about the pivot
    model = RotationModel(inertia, (ForceAtPoint(np.array([0.0, 0.0, d]), np.array([0.0, 0.0, -mass * gravity])),))
    q0 = quat.from_axis_angle(np, np.array([[1.0, 0.0, 0.0]]), 0.3)
    omega0 = np.array([[0.0, 0.0, 30.0]])
    t_end = 0.5
    ts = np.array([0.0, t_end])
    q_ref, omega_ref = rotation_reference(model, q0, omega0, ts, method="scipy-dop853")
    errors = []
    for n in (400, 800):
        _, q, omega = simulate_rotation(method, model, q0, omega0, t_end / n, n, save_every=n)
        errors.append(quat.angle_between(np, q[-1, 0], q_ref[-1, 0]))
    assert errors[1] < errors[0] * 2.0 ** -method.order * 1.5 or errors[1] < 1e-11, errors


class _Tether:
    """A zero-length spring of ``stiffness`` from the body-frame point ``point`` to the world point ``anchor``,
    the body's centre fixed: the torque (R r) x -k (R r - p), stiff in the orientation (xp-generic, for the
    methods; the checks below evaluate it independently with scipy's rotation)."""

    def __init__(self, point, anchor, stiffness):
        self.point, self.anchor, self.stiffness = np.asarray(point, float), np.asarray(anchor, float), stiffness

    def torque(self, xp, t, q, omega_body):
        arm = quat.rotate(xp, q, xp.asarray(self.point))
        return quat.cross(xp, arm, -self.stiffness * (arm - xp.asarray(self.anchor)))

    def independent_torque(self, q):
        """The body-frame torque at the unit quaternion q [w, x, y, z], with scipy's rotation."""
        rotation = Rotation.from_quat(np.roll(q, -1))
        arm = rotation.apply(self.point)
        return rotation.inv().apply(np.cross(arm, -self.stiffness * (arm - self.anchor)))

    def energy(self, q, omega):
        arms = Rotation.from_quat(np.roll(q, -1, axis=-1)).apply(self.point)
        return 0.5 * np.sum(INERTIA * omega**2, axis=-1) + 0.5 * self.stiffness * np.sum((arms - self.anchor) ** 2, -1)


#: a top spinning at 10 rad/s about its major axis z, its point r = 0.5 e_z tethered to the world point above
#: the centre by k = 6e4 N/m, tipped by 0.04 rad: the tether's wobble is omega_w = sqrt(k r^2 / I1) = 122 rad/s
TETHER = _Tether([0.0, 0.0, 0.5], [0.0, 0.0, 0.5], 6e4)
TETHERED_Q0 = quat.normalize(np, np.array([1.0, 0.02, 0.0, 0.0]))
TETHERED_OMEGA0 = np.array([0.0, 0.5, 10.0])


@pytest.mark.parametrize("dt", [0.02, 0.04])
def test_implicit_midpoint_solves_a_stiff_torque_past_the_fixed_point_limit(dt):
    """Newton's matrix takes the torque's derivative d (h tau(q_m)) / d pi1. Without it (before) the
    iteration was a fixed point in the torque, contracting by (h omega_w)^2 / 4 only: past h omega_w = 2
    (16 ms here) it diverged on the first step (at 20 and 40 ms: no convergence, DivergenceError at step 1)
    while the midpoint rule has its solution. Every step now solves the midpoint equations to round-off
    (1.7e-16 and 2.7e-16 of |pi| measured; the torque at the normalised midpoint orientation, evaluated with
    scipy), and the energy error is the method's O(h^2) without drift: 1.93e-4 and 7.51e-4 measured over 1 s
    (ratio 3.9; 5.0e-5 at 10 ms), where the wobble is 2.4 and 4.9 rad a step."""
    model = RotationModel(INERTIA[None], (TETHER,))
    n = int(round(1.0 / dt))
    _, q, omega = simulate_rotation(get_rotation("implicit-midpoint"), model, TETHERED_Q0[None],
                                    TETHERED_OMEGA0[None], dt, n)
    q, pi = q[:, 0], INERTIA * omega[:, 0]
    for k in range(n):
        pi_m = 0.5 * (pi[k] + pi[k + 1])
        q_m = (q[k] + q[k + 1]) / np.linalg.norm(q[k] + q[k + 1])
        residual = pi[k + 1] - pi[k] - dt * (np.cross(pi_m, pi_m / INERTIA) + TETHER.independent_torque(q_m))
        assert np.max(np.abs(residual)) <= 1e-13 * np.max(np.abs(pi[k])), k
    energy = TETHER.energy(q, omega[:, 0])
    assert np.max(np.abs(energy / energy[0] - 1)) <= {0.02: 4e-4, 0.04: 1.5e-3}[dt]


def test_implicit_midpoint_energy_error_on_the_stiff_tether_is_second_order():
    model = RotationModel(INERTIA[None], (TETHER,))
    errors = []
    for dt in (0.01, 0.02, 0.04):  # the last two past the old iteration's limit
        _, q, omega = simulate_rotation(get_rotation("implicit-midpoint"), model, TETHERED_Q0[None],
                                        TETHERED_OMEGA0[None], dt, int(round(1.0 / dt)))
        energy = TETHER.energy(q[:, 0], omega[:, 0])
        errors.append(np.max(np.abs(energy / energy[0] - 1)))
    ratios = np.array(errors[1:]) / errors[:-1]
    assert np.all(np.abs(ratios - 4) < 0.5), (errors, ratios)


@pytest.mark.parametrize("dt", [0.005, 0.04])
def test_implicit_midpoint_on_the_stiff_tether_agrees_on_numpy_and_jax(dt):
    """The compiled loop takes MIDPOINT_COMPILED_ITERATIONS Newton iterations, the finite-difference torque
    derivative among them: 6 suffice past the old limit for h |omega| < 1 (the count's own bound), to 1e-14 of
    |q| and |omega| measured after 1 s (9e-16 and 9e-16)."""
    model = RotationModel(np.broadcast_to(INERTIA, (2, 3)), (TETHER,))
    tipped_about_y = quat.normalize(np, np.array([1.0, 0.0, 0.03, 0.0]))
    q0, omega0 = np.stack([TETHERED_Q0, tipped_about_y]), np.stack([TETHERED_OMEGA0, [0.3, 0.0, -8.0]])
    n = int(round(1.0 / dt))
    args = (get_rotation("implicit-midpoint"), model, q0, omega0, dt, n)
    _, q, omega = simulate_rotation(*args, save_every=n)
    _, q_jax, omega_jax = simulate_rotation(*args, save_every=n, backend="jax")
    assert np.all(np.isfinite(omega))
    np.testing.assert_allclose(q_jax, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(omega_jax, omega, rtol=0, atol=1e-12 * np.max(np.abs(omega)))


# --- torques and inertia --------------------------------------------------------------------


def test_torque_of_a_couple_is_exact():
    """Two equal and opposite forces at +-r: no net force, torque 2 (R r) x F, for any orientation."""
    force, r = np.array([0.0, 3.0, 0.0]), np.array([0.25, 0.0, 0.0])
    for q, rotated_r in ((quat.IDENTITY, r), (np.array([0.0, 0.0, 0.0, 1.0]), -r),
                         (np.array([0.0, 0.0, 1.0, 0.0]), -r)):
        q2 = np.broadcast_to(q, (2, 4))
        torques = torque_of_forces(np, q2, np.array([r, -r]), np.array([force, -force]))
        assert np.array_equal(torques.sum(axis=0), 2 * np.cross(rotated_r, force))
    assert np.array_equal(torque_of_forces(np, quat.IDENTITY, r, force), [0.0, 0.0, 0.75])


def _solid_of_revolution(radius_at, z_lo, z_hi, mass):
    """I1 and I3 of a uniform solid of revolution about z, by quadrature over discs."""
    volume = quad(lambda z: np.pi * radius_at(z) ** 2, z_lo, z_hi, epsabs=0, epsrel=1e-13)[0]
    density = mass / volume
    i3 = quad(lambda z: density * np.pi * radius_at(z) ** 4 / 2, z_lo, z_hi, epsabs=0, epsrel=1e-13)[0]
    i1 = quad(lambda z: density * np.pi * radius_at(z) ** 2 * (radius_at(z) ** 2 / 4 + z * z), z_lo, z_hi,
              epsabs=0, epsrel=1e-13)[0]
    return np.array([i1, i1, i3])


def test_principal_inertia_against_quadrature():
    m, r, length = 3.0, 0.4, 1.3
    sphere = _solid_of_revolution(lambda z: np.sqrt(max(r * r - z * z, 0.0)), -r, r, m)
    np.testing.assert_allclose(principal_inertia("sphere", m, r), sphere, rtol=1e-10)
    cylinder = _solid_of_revolution(lambda z: r, -length / 2, length / 2, m)
    np.testing.assert_allclose(principal_inertia("cylinder", m, r, length=length), cylinder, rtol=1e-10)

    def capsule_radius(z):
        beyond = max(abs(z) - length / 2, 0.0)
        return np.sqrt(max(r * r - beyond * beyond, 0.0))

    capsule = _solid_of_revolution(capsule_radius, -length / 2 - r, length / 2 + r, m)
    np.testing.assert_allclose(principal_inertia("capsule", m, r, length=length), capsule, rtol=1e-9)
    # the box by Gauss-Legendre (exact for the quadratic integrand)
    size = np.array([0.3, 0.5, 0.9])
    x, w = np.polynomial.legendre.leggauss(3)
    pts = np.stack(np.meshgrid(*(0.5 * s * x for s in size), indexing="ij"), axis=-1).reshape(-1, 3)
    weights = np.einsum("i,j,k->ijk", w, w, w).ravel() / 8 * m
    box = [np.sum(weights * (pts[:, (k + 1) % 3] ** 2 + pts[:, (k + 2) % 3] ** 2)) for k in range(3)]
    np.testing.assert_allclose(principal_inertia("box", m, r, size=size), box, rtol=1e-13)


@pytest.mark.parametrize("inertia, message", [
    ([0.0, 1.0, 1.0], "must be > 0"), ([-1.0, 1.0, 1.0], "must be > 0"), ([np.nan, 1.0, 1.0], "must be finite"),
    ([np.inf, 1.0, 1.0], "must be finite"), ([1.0, 1.0, 2.5], "triangle inequality"), ([1.0, 2.0], "three"),
])
def test_bad_inertia_is_one_clear_line(inertia, message):
    with pytest.raises(InertiaError, match=message) as err:
        check_inertia(inertia)
    assert "\n" not in str(err.value)


def test_a_thin_plate_is_a_body():
    """I1 + I2 = I3 exactly in exact arithmetic, and to round-off from the box formula."""
    check_inertia(principal_inertia("box", 1.0, 1.0, size=[0.3, 0.7, 0.0]))


@pytest.mark.parametrize("q, message", [([0, 0, 0, 0], "non-zero"), ([1, 0, np.nan, 0], "finite"),
                                        ([1, 0, 0], "finite quaternion")])
def test_bad_orientation_is_one_clear_line(q, message):
    with pytest.raises(InertiaError, match=message):
        check_orientation(q)


def test_orientation_normalised_on_load_without_overflow():
    np.testing.assert_allclose(check_orientation([1e300, 0, 1e300, 0]), [2**-0.5, 0, 2**-0.5, 0], rtol=1e-15)
    np.testing.assert_allclose(check_orientation([0, 5e-324, 0, 0]), [0, 1, 0, 0])


def test_unknown_shape():
    with pytest.raises(InertiaError, match="unknown shape 'cone'; valid: sphere, box, capsule, cylinder"):
        principal_inertia("cone", 1.0, 1.0)


# --- quaternion algebra ---------------------------------------------------------------------


def test_quaternion_algebra_against_rotation_matrices():
    rng = np.random.default_rng(7)
    q = quat.normalize(np, rng.normal(size=(20, 4)))
    p = quat.normalize(np, rng.normal(size=(20, 4)))
    v = rng.normal(size=(20, 3))
    matrix = quat.to_matrix(np, q)
    np.testing.assert_allclose(quat.rotate(np, q, v), np.einsum("kij,kj->ki", matrix, v), atol=1e-14)
    np.testing.assert_allclose(quat.rotate_inverse(np, q, quat.rotate(np, q, v)), v, atol=1e-14)
    np.testing.assert_allclose(quat.to_matrix(np, quat.multiply(np, p, q)),
                               quat.to_matrix(np, p) @ matrix, atol=1e-14)
    np.testing.assert_allclose(np.einsum("kij,kil->kjl", matrix, matrix), np.broadcast_to(np.eye(3), (20, 3, 3)),
                               atol=1e-14)
    # exp: a rotation by |r| about r; exact at r = 0
    r = rng.normal(size=(20, 3))
    e = quat.exp(np, r)
    np.testing.assert_allclose(quat.rotate(np, e, r), r, atol=1e-14)  # the axis is fixed
    np.testing.assert_allclose(quat.angle_between(np, quat.IDENTITY, e), _wrapped(np.linalg.norm(r, axis=-1)),
                               atol=1e-13)
    assert np.array_equal(quat.exp(np, np.zeros(3)), quat.IDENTITY)
    # the Cayley transform is the midpoint map: unit, and 2 atan(|u|) * 2 about u
    u = 0.1 * rng.normal(size=(20, 3))
    c = quat.cayley(np, u)
    np.testing.assert_allclose(quat.norm(np, c), 1, atol=1e-15)
    np.testing.assert_allclose(quat.angle_between(np, quat.IDENTITY, c), 4 * np.arctan(np.linalg.norm(u, axis=-1)),
                               atol=1e-14)


def _wrapped(angle):
    """A rotation angle folded into [0, pi]."""
    angle = np.mod(angle, 2 * np.pi)
    return np.where(angle > np.pi, 2 * np.pi - angle, angle)


def test_quaternion_functions_run_on_jax():
    import jax.numpy as jnp

    rng = np.random.default_rng(3)
    q, v = quat.normalize(np, rng.normal(size=(5, 4))), rng.normal(size=(5, 3))
    for f, args in ((quat.rotate, (q, v)), (quat.exp, (v,)), (quat.cayley, (v,)), (quat.multiply, (q, q))):
        np.testing.assert_allclose(np.asarray(f(jnp, *map(jnp.asarray, args))), f(np, *args), atol=1e-15)


def test_stable_omega_dt_of_explicit_euler_about_the_major_axis_matches_its_linearisation():
    """About axis 3 of (1, 2, 3), a small transverse spin oscillates at Omega = omega3 sqrt((I3 - I2)(I3 - I1)/(I1 I2))
    = omega3; explicit Euler multiplies its energy by 1 + (Omega dt)^2 per step. From a transverse energy fraction of
    1e-6, the energy first exceeds 1.1 E0 after 1000 steps at Omega dt = sqrt(ln(1 + 0.1 / 1e-6) / 1000)."""
    from steplab.integrators.rotation_stability import OMEGA_DT_GRID, stable_omega_dt

    predicted = np.sqrt(np.log(1 + 0.1 / 1e-6) / 1000)
    limit = stable_omega_dt(get_rotation("explicit"), INERTIA, [[1e-3, 1e-3, 1.0]])[0]
    grid = np.array(OMEGA_DT_GRID)
    k = int(np.searchsorted(grid, limit))
    assert grid[k] == limit and grid[k] <= predicted < grid[k + 1]
    # exactly about a principal axis omega x I omega = 0: every method keeps the spin at any omega dt
    assert stable_omega_dt(get_rotation("explicit"), INERTIA, [[0.0, 0.0, 1.0]]) == [None]


def test_stable_rotation_dt_of_a_scene_is_the_limit_over_the_spin():
    from steplab.integrators.rotation_stability import stable_omega_dt, stable_rotation_dt
    from steplab.physics.rigid_body import RigidBodies

    omega = np.array([[1e-3, 1e-3, 1.0], [0.0, 0.0, 0.0]]) * 30.0
    bodies = RigidBodies(np.array([0, 1]), np.broadcast_to(INERTIA, (2, 3)), np.broadcast_to(quat.IDENTITY, (2, 4)),
                         omega)
    method = get_rotation("exponential-map")
    expected = stable_omega_dt(method, INERTIA, omega[:1])[0] / np.linalg.norm(omega[0])
    assert stable_rotation_dt(method, bodies) == pytest.approx(expected, rel=1e-15)


def _exp_textbook(r):
    """exp(r/2) = [cos(|r|/2), sin(|r|/2) r/|r|] by libm's cos and sin (r != 0)."""
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    return np.concatenate([np.cos(angle / 2), np.sin(angle / 2) * r / angle], axis=-1)


@pytest.mark.parametrize("largest", [1e-3, 0.5, 1.0, 1.0 + 1e-9, 3.0, 20.0])
def test_exponential_map_series_is_the_trigonometric_exponential_to_round_off(largest):
    """|r| <= 1 takes the Taylor series (r/2 <= EXP_SERIES_HALF_ANGLE), beyond it sin and cos: both are
    the textbook formula to an ulp or two, on NumPy and JAX alike."""
    import jax.numpy as jnp

    rng = np.random.default_rng(7)
    r = rng.normal(size=(2000, 3))
    r *= rng.uniform(1e-6, 1, (2000, 1)) * largest / np.max(np.linalg.norm(r, axis=-1))
    r[0] *= largest / np.linalg.norm(r[0])  # the largest angle exactly
    for xp in (np, jnp):
        e = np.asarray(quat.exp(xp, xp.asarray(r)))
        np.testing.assert_allclose(e, _exp_textbook(r), rtol=0, atol=4e-16 if largest <= 1 else 1e-15)
        np.testing.assert_allclose(np.linalg.norm(e, axis=-1), 1, rtol=0, atol=4e-16)
    assert quat.exp(np, np.zeros((2, 3))).tolist() == [[1.0, 0.0, 0.0, 0.0]] * 2  # exact at 0


def test_exponential_map_step_is_the_textbook_step_to_1e_14():
    """10^4 tumbling bodies, 50 compiled steps (the benchmark's loop) and the NumPy loop against the same
    steps written with libm's sin and cos: the series changed nothing beyond round-off."""
    import jax.numpy as jnp
    from steplab.integrators.rotation import angular_acceleration, compiled_steps

    rng = np.random.default_rng(3)
    n, dt, steps = 10_000, 1 / 60, 50
    inertia = np.sort(rng.uniform(1.0, 2.0, (n, 3)), axis=1)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    omega = rng.normal(size=(n, 3))
    model = RotationModel(inertia)
    qt, omegat = q, omega
    for _ in range(steps):  # the exponential map, textbook
        omegat = omegat + dt * angular_acceleration(np, model, 0.0, qt, omegat)
        qt = quat.normalize(np, quat.multiply(np, qt, _exp_textbook(dt * omegat)))
    method = get_rotation("exponential-map")
    q_loop, omega_loop = compiled_steps(method, model, dt, steps)(jnp.asarray(q), jnp.asarray(omega))
    _, q_numpy, omega_numpy = simulate_rotation(method, model, q, omega, dt, steps)
    for q1, omega1 in ((q_loop, omega_loop), (q_numpy[-1], omega_numpy[-1])):
        np.testing.assert_allclose(np.asarray(q1), qt, rtol=0, atol=1e-14)
        np.testing.assert_allclose(np.asarray(omega1), omegat, rtol=0, atol=1e-14)


def test_the_numba_kernel_is_the_numpy_step_bit_for_bit_and_the_textbook_step_beyond_the_series():
    """backend="numba" (the vectorised kernel the bench times): the same IEEE operations in the same order as
    NumPy's exponential-map, so the same bits; bodies beyond the series' radius take libm's sin and cos, one
    by one, so they are the textbook step, and the others differ from NumPy (which switches every body to
    libm then) by the series' round-off only."""
    from steplab.integrators.rotation_compiled import free_bodies, stream_pass

    rng = np.random.default_rng(11)
    n, dt = 1001, 1 / 60  # not a multiple of the vector width: the loop's remainder too
    inertia = np.sort(rng.uniform(1.0, 2.0, (n, 3)), axis=1)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    omega = rng.normal(size=(n, 3))
    method, model = get_rotation("exponential-map"), RotationModel(inertia)
    numpy = simulate_rotation(method, model, q, omega, dt, 40, save_every=15)
    numba = simulate_rotation(method, model, q, omega, dt, 40, save_every=15, backend="numba")
    for a, b in zip(numpy, numba):
        assert a.shape == b.shape and np.array_equal(a, b)
    bodies = free_bodies(q, omega, inertia)
    stream_pass(bodies)  # the bench's tighter bound moves the bytes and changes none
    assert np.array_equal(bodies.q, q.T) and np.array_equal(bodies.omega, omega.T)
    fast = omega.copy()
    fast[::9] *= 150  # h |omega| ~ 4 rad on every ninth body
    _, q_numpy, omega_numpy = simulate_rotation(method, model, q, fast, dt, 3)
    _, q_numba, omega_numba = simulate_rotation(method, model, q, fast, dt, 3, backend="numba")
    np.testing.assert_array_equal(omega_numba, omega_numpy)  # the omega update has no branch
    np.testing.assert_allclose(q_numba, q_numpy, rtol=0, atol=1e-15)
    assert not np.array_equal(q_numba, q_numpy)  # the slow bodies took the series here, libm there


def test_the_numba_backend_refuses_what_its_kernel_does_not_step():
    top = RotationModel(INERTIA[None], (ForceAtPoint(np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, -9.81])),))
    for method, model, message in ((get_rotation("dlm"), FREE, "not dlm: use backend numpy or jax"),
                                   (get_rotation("exponential-map"), top, "not exponential-map with torques")):
        with pytest.raises(ValueError, match=message):
            simulate_rotation(method, model, Q0[None], FLIP[None], 0.01, 2, backend="numba")


#: omega dt of the flip-period test, per declared order: inside each method's asymptotic range
PERIOD_OMEGA_DT = {1: [0.01, 0.005], 2: [0.1, 0.05], 4: [0.4, 0.2]}
#: the measured order of the flip period where it is not the method's order (the orientation's still is):
#: momentum-rescaled keeps |L| exactly, and the period depends on the run only through E and |L|
PERIOD_ORDER = {"momentum-rescaled": 2}


@pytest.mark.parametrize("name", METHODS)
def test_every_methods_flip_period_converges_to_the_closed_form_at_its_order(name):
    """The period of omega(t) on the Dzhanibekov flip (the study's measurement: the upward zero crossings of
    omega2, located by Hermite interpolation) against the closed form T = 4 K(m) / lambda, at two omega dt."""
    from steplab.studies import rotation as study

    method = get_rotation(name)
    grid = [w / 2 for w in PERIOD_OMEGA_DT[1]] if name in PERIOD_ORDER else PERIOD_OMEGA_DT[method.order]
    rows = study.flip(study.parameters(True) | {"flip_omega_dt": grid, "period_omega_dt_min": 0.0,
                                                "flip_periods": 2}, name)
    errors = np.array([r["period_error"] for r in rows])
    assert rows[0]["period_exact"] == pytest.approx(flip_period(INERTIA, FLIP * grid[0] * 60 / np.linalg.norm(FLIP)),
                                                    rel=1e-12)
    slope = np.log(errors[0] / errors[1]) / np.log(grid[0] / grid[1])
    expected = PERIOD_ORDER.get(name, method.order)
    assert slope == pytest.approx(expected, abs=0.2 if expected < 4 else 0.45), errors
    assert errors[1] < 5e-3  # near the closed form already


def test_simulate_rotation_refuses_what_simulate_refuses():
    # backend "torch" ran NumPy; dt < 0 ran backwards; n_steps 0 or -5 returned the start; a name was
    # "'str' object has no attribute 'step'"; a 1-D q0 an inhomogeneous-array error
    q0, omega0 = Q0[None], FLIP[None]
    bad = {"backend must be 'numpy', 'jax' or 'numba'": dict(backend="torch"),
           "dt must be a step > 0 s": dict(dt=-0.01), "n_steps must be a whole number": dict(n_steps=0),
           "save_every must be a whole number": dict(save_every=2.5),
           r"q0 must have shape \(R, 4\)": dict(q0=Q0)}
    for message, change in bad.items():
        arguments = dict(q0=q0, omega0=omega0, dt=0.01, n_steps=10) | change
        with pytest.raises(ValueError, match=message):
            simulate_rotation(get_rotation("exponential-map"), FREE, **arguments)
    with pytest.raises(TypeError, match=r"get_rotation\('exponential-map'\) for a name"):
        simulate_rotation("exponential-map", FREE, q0, omega0, 0.01, 10)
