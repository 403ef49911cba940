"""The stacking study's analytic answers against independent derivations and scipy."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from steplab.physics.stacks import stack_layout
from steplab.studies import stacking_theory as theory
from steplab.studies.stacking_theory import G, stack_contacts, static_deflection


@pytest.mark.parametrize("v0,mu,r", [(2.0, 0.2, 0.1), (5.0, 0.6, 0.3), (0.5, 0.05, 1.0)])
def test_sliding_to_rolling_against_the_equations_of_motion(v0, mu, r):
    """m dv/dt = -mu m g, I domega/dt = mu m g r (I = 2/5 m r^2) integrated by scipy until the
    slip v - omega r vanishes; and the angular momentum about the contact point kept."""
    answer = theory.sliding_to_rolling(v0, mu, r)

    def slip(t, y):
        return y[0] - y[1] * r

    slip.terminal = True
    sol = solve_ivp(lambda t, y: [-mu * G, mu * G * r / (0.4 * r * r), y[0]], (0, 10), [v0, 0.0, 0.0],
                    events=slip, rtol=1e-12, atol=1e-14)
    t, (v, omega, x) = sol.t_events[0][0], sol.y_events[0][0]
    assert answer["t_roll"] == pytest.approx(t, rel=1e-9)
    assert answer["v_roll"] == pytest.approx(v, rel=1e-9) == pytest.approx(5 / 7 * v0)
    assert answer["x_roll"] == pytest.approx(x, rel=1e-9)
    assert answer["omega_roll"] == pytest.approx(omega, rel=1e-9)
    # m v r + I omega about the contact point: m v0 r at the start
    assert v * r + 0.4 * r * r * omega == pytest.approx(v0 * r, rel=1e-9)
    vs, spin = theory.rolling_speed(v0, mu, r, [0.0, 0.5 * t, 2 * t])
    np.testing.assert_allclose(vs, [v0, v0 - 0.5 * mu * G * t, 5 / 7 * v0], rtol=1e-12)
    np.testing.assert_allclose(spin, [0.0, 1.25 * mu * G * t, 5 / 7 * v0], rtol=1e-12)


def test_incline_sticks_up_to_the_friction_angle_and_then_slides():
    mu = 0.4
    assert theory.incline_acceleration(math.atan(mu) * (1 - 1e-9), mu) == 0.0
    assert theory.incline_acceleration(math.atan(mu), mu) == pytest.approx(0.0, abs=1e-12)
    # just past the friction angle the acceleration starts from 0, continuously
    assert 0 < theory.incline_acceleration(math.atan(mu) + 1e-6, mu) < 1e-4
    # frictionless: the whole downhill component of gravity; vertical: free fall
    assert theory.incline_acceleration(0.3, 0.0) == pytest.approx(G * math.sin(0.3))
    assert theory.incline_acceleration(math.pi / 2, 0.9) == pytest.approx(G)


def cubes(kind, rows, masses=None):
    c, row = stack_layout(kind, rows, [1.0, 1.0, 1.0], 0.0, [0.0, 0.0, 0.0])
    m = np.ones(len(c)) if masses is None else np.asarray(masses, float)[row]
    return c, np.ones((len(c), 3)), m


@pytest.mark.parametrize("n", [1, 2, 10, 20])
def test_column_of_cubes_sinks_n_squared_g_over_omega_squared(n):
    """Contact i (0: the floor) carries (n - i) m g on face springs of m omega^2 (floor) and
    m omega^2 / 2 (two boxes in series); the top sinks by the sum: n^2 g / omega^2."""
    omega = 2 * math.pi * 30.0
    sink = static_deflection(*cubes("column", n), 30.0)
    expected = np.cumsum([n] + [2 * (n - i) for i in range(1, n)]) * G / omega**2
    np.testing.assert_allclose(sink, expected, rtol=1e-10)
    assert sink[-1] == pytest.approx(n * n * G / omega**2, rel=1e-10)


def test_mass_ratio_column_is_springs_in_series():
    omega = 2 * math.pi * 30.0
    masses = [1.0, 1.0, 1.0, 100.0]
    sink = static_deflection(*cubes("column", 4, masses), 30.0)
    carried = np.cumsum(masses[::-1])[::-1]  # weight above each contact, kg
    effective = [masses[0]] + [a * b / (a + b) for a, b in zip(masses, masses[1:])]
    np.testing.assert_allclose(sink, np.cumsum(carried / effective) * G / omega**2, rtol=1e-10)


def test_pyramid_springs_carry_its_weight_symmetrically():
    """Brute force from the solution: every box's springs balance its weight and the loads from
    above (the floor carries all 210 boxes), and the pyramid sinks mirror-symmetrically."""
    centres, sizes, masses = cubes("pyramid", 20)
    hertz = 30.0
    sink = static_deflection(centres, sizes, masses, hertz)
    contacts = stack_contacts(centres, sizes)
    assert len(contacts.points) == 4 * (20 + 2 * (210 - 20))  # floor faces, and two half faces per box
    # the sinks of mirror-image boxes (x -> -x, same row) agree
    for z in np.unique(centres[:, 2]):
        row = np.nonzero(centres[:, 2] == z)[0]
        np.testing.assert_allclose(sink[row], sink[row[::-1]], rtol=1e-9)
    assert np.all(np.diff(sink[[0, 20, 39, 57]]) > 0)  # higher rows sink further
    # the floor points' spring forces sum to the weight of the whole pyramid (a box's four
    # corners sink by w +- its tilt terms, equally stiff on cubes, so the tilts cancel in the sum)
    omega = 2 * math.pi * hertz
    floor = contacts.lower == -1
    r = contacts.points[floor] - centres[contacts.upper[floor]]
    inverse_mass = 1 + 6 * (r[:, 0] ** 2 + r[:, 1] ** 2)  # cubes: 1/m + r_y^2 / I_x + r_x^2 / I_y, I = 1/6
    force = omega**2 / inverse_mass * sink[contacts.upper[floor]]
    assert force.sum() == pytest.approx(210 * G, rel=1e-9)


@pytest.mark.parametrize("n", [1, 4])
def test_friction_does_not_stiffen_a_column(n):
    """Nothing in a column tilts or shears: held by friction it still sinks n^2 g / omega^2."""
    omega = 2 * math.pi * 30.0
    sink = static_deflection(*cubes("column", n), 30.0, sticking=True)
    assert sink[-1] == pytest.approx(n * n * G / omega**2, rel=1e-8)


def test_sticking_pyramid_is_the_rigid_limit_of_its_constraints():
    """The stuck points' springs (STUCK times the normal ones) against the exact constrained
    equilibrium, solved on the null space of the no-slip constraints by scipy's SVD; and
    friction makes the pyramid stiffer than its normal springs alone."""
    from scipy.linalg import null_space

    centres, sizes, masses = cubes("pyramid", 4)
    omega = 2 * math.pi * 30.0
    sink = static_deflection(centres, sizes, masses, 30.0, sticking=True)
    contacts = stack_contacts(centres, sizes)
    n, count = len(masses), len(contacts.points)
    move = theory.sticking_moves(centres, contacts, n)
    inverse_mass = np.zeros(count)  # cubes of 1 m: I = m / 6 about every axis
    for body in (contacts.upper, contacts.lower):
        box = body >= 0
        r = contacts.points[box] - centres[body[box]]
        inverse_mass[box] += 1 / masses[body[box]] + (r[:, 0] ** 2 + r[:, 1] ** 2) * 6 / masses[body[box]]
    K = move[:, 2, :].T @ ((omega**2 / inverse_mass)[:, None] * move[:, 2, :])
    basis = null_space(move[:, :2, :].reshape(2 * count, 6 * n))
    f = np.zeros(6 * n)
    f[2::6] = -masses * G
    exact = -(basis @ np.linalg.solve(basis.T @ K @ basis, basis.T @ f))[2::6]
    np.testing.assert_allclose(sink, exact, rtol=1e-5)
    assert np.all(sink[-1] < static_deflection(centres, sizes, masses, 30.0)[-1])
