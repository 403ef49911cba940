"""The exact torque-free motion of a rigid body: omega(t) by Jacobi elliptic functions, q(t) by quadrature.

Landau and Lifshitz, Mechanics, section 37. With principal moments I1 < I2 < I3, the
energy 2E = sum I_i omega_i^2 and L^2 = sum (I_i omega_i)^2, let D = 2E I3 - L^2 > 0 and
G = L^2 - 2E I1 > 0. When L^2 > 2E I2 the body precesses about its axis 3 ("polar" axis
p = 3, the other c = 1):

    omega1 = A1 cn(u, m),  omega2 = A2 sn(u, m),  omega3 = A3 dn(u, m),  u = lambda t + u0,
    lambda^2 = (I3 - I2) G / (I1 I2 I3),  m = k^2 = (I2 - I1) D / ((I3 - I2) G),
    A1^2 = D / (I1 (I3 - I1)),  A2^2 = D / (I2 (I3 - I2)),  A3^2 = G / (I3 (I3 - I1));

when L^2 < 2E I2, about axis 1: swap the roles of 1 and 3 (and of D and G), so omega1 is
the dn and omega3 the cn. omega(t) has the period T = 4 K(m) / lambda, in the first case

    T = 4 K(m) sqrt(I1 I2 I3 / ((I3 - I2) (L^2 - 2E I1))),

the formula of issue 25, and in the second T = 4 K(m) sqrt(I1 I2 I3 / ((I2 - I1) (2E I3 - L^2))).
Over one period the intermediate axis reverses twice (omega2 ~ sn): a Dzhanibekov flip
takes T/2.

The orientation: with L along the z axis of an inertial frame, the body's Euler angles
(z-x-z, body to world R = Rz(phi) Rx(theta) Rz(psi), polar axis as the body z) follow from
omega alone, cos theta = I_p omega_p / L and tan psi = I_a omega_a / (I_b omega_b), except
the angle phi about L, whose rate

    dphi/dt = L (I_a omega_a^2 + I_b omega_b^2) / (I_a^2 omega_a^2 + I_b^2 omega_b^2)

is integrated here by composite Gauss-Legendre quadrature (:data:`PANELS` panels of
:data:`NODES` nodes per period; the integrand is analytic and T-periodic, so the result is
accurate to round-off, and phi(t) = floor(t/T) phi(T) + phi(t mod T)). The elliptic
integral of the third kind gives the same phi in closed form; the quadrature is simpler to
check and as accurate.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc
from steplab.physics import quaternion as quat

#: quadrature of dphi/dt: panels per period and Gauss-Legendre nodes per panel; 20 nodes
#: integrate a polynomial of degree 39 exactly, and T/256 is far inside the radius where
#: the analytic integrand is that smooth, so the error is round-off (checked against diffrax)
PANELS, NODES = 256, 20
#: the body frame relabelled (2, 3, 1) so that axis 1 becomes the polar z axis: the
#: rotation by -120 degrees about (1, 1, 1), which takes e1 to e3, e2 to e1 and e3 to e2
_AXIS_1_AS_POLAR = np.array([0.5, -0.5, -0.5, -0.5])


class TorqueFreeMotion:
    """The exact motion of one free rigid body from (q0, omega0), omega in the body frame.

    Parameters
    ----------
    inertia : array, shape (3,)
        Principal moments, strictly increasing I1 < I2 < I3 (kg m^2).
    q0 : array, shape (4,)
        Unit quaternion, body to world.
    omega0 : array, shape (3,)
        rad/s, body frame; neither on the separatrix L^2 = 2E I2 nor a steady spin about
        axis 1 or 3 (where the Euler angles used here are singular).
    """

    def __init__(self, inertia, q0, omega0):
        inertia, omega0 = np.asarray(inertia, float), np.asarray(omega0, float)
        i1, i2, i3 = inertia
        if not 0 < i1 < i2 < i3:
            raise ValueError(f"the exact torque-free motion needs 0 < I1 < I2 < I3, got {inertia.tolist()}")
        self.inertia, self.q0, self.omega0 = inertia, np.asarray(q0, float), omega0
        two_e, l2 = float(np.sum(inertia * omega0**2)), float(np.sum((inertia * omega0) ** 2))
        self.momentum = np.sqrt(l2)
        d, g = two_e * i3 - l2, l2 - two_e * i1
        self.energy = 0.5 * two_e
        if not (d > 0 and g > 0):
            raise ValueError("the exact torque-free motion needs a body that precesses (2E I1 < L^2 < 2E I3); "
                             f"omega0 = {omega0.tolist()} is a steady spin about a principal axis")
        if l2 > two_e * i2:  # precession about axis 3
            self.polar, self.cn_axis = 2, 0
            lam2, m = (i3 - i2) * g / (i1 * i2 * i3), (i2 - i1) * d / ((i3 - i2) * g)
            amplitude = np.sqrt([d / (i1 * (i3 - i1)), d / (i2 * (i3 - i2)), g / (i3 * (i3 - i1))])
        elif l2 < two_e * i2:  # about axis 1
            self.polar, self.cn_axis = 0, 2
            lam2, m = (i2 - i1) * d / (i1 * i2 * i3), (i3 - i2) * g / ((i2 - i1) * d)
            amplitude = np.sqrt([d / (i1 * (i3 - i1)), g / (i2 * (i2 - i1)), g / (i3 * (i3 - i1))])
        else:
            raise ValueError(f"omega0 = {omega0.tolist()} lies on the separatrix L^2 = 2E I2: "
                             "the flip period is infinite")
        self.rate, self.m = float(np.sqrt(lam2)), float(m)
        # signs: dn > 0 fixes sigma_p; Euler's equations need sigma1 sigma2 sigma3 = 1, so
        # with sigma_c = +1 the sn component has the polar sign
        sigma = np.ones(3)
        sigma[self.polar] = sigma[1] = np.sign(omega0[self.polar])
        self.amplitude = sigma * amplitude
        sn0 = np.clip(omega0[1] / self.amplitude[1], -1, 1)
        cn0 = np.clip(omega0[self.cn_axis] / self.amplitude[self.cn_axis], -1, 1)
        self.u0 = float(ellipkinc(np.arctan2(sn0, cn0), self.m))
        #: the period of omega(t), s: two flips of the intermediate axis
        self.period = 4 * float(ellipk(self.m)) / self.rate
        nodes, weights = np.polynomial.legendre.leggauss(NODES)
        self._nodes, self._weights = 0.5 * (nodes + 1), 0.5 * weights
        edges = np.linspace(0.0, self.period, PANELS + 1)
        self._panel_width = edges[1]
        self._phi_at_edges = np.concatenate([[0.0], np.cumsum(self._integral(edges[:-1], edges[1:]))])
        self._frame0 = self._frame(np.zeros(1), np.zeros(1))[0]

    # --- omega(t) -----------------------------------------------------------------------

    def angular_velocity(self, t) -> np.ndarray:
        """omega(t) in the body frame, shape (K, 3)."""
        sn, cn, dn, _ = ellipj(self.rate * np.asarray(t, float) + self.u0, self.m)
        parts = [None, sn, None]
        parts[self.cn_axis], parts[self.polar] = cn, dn
        return np.stack(parts, axis=-1) * self.amplitude

    # --- q(t) ---------------------------------------------------------------------------

    def _phi_rate(self, t):
        """dphi/dt at times t (any shape)."""
        omega = self.angular_velocity(t.reshape(-1))
        a, b = np.delete(np.arange(3), self.polar)
        inertia = self.inertia
        energy_across = inertia[a] * omega[:, a] ** 2 + inertia[b] * omega[:, b] ** 2
        momentum_across = (inertia[a] * omega[:, a]) ** 2 + (inertia[b] * omega[:, b]) ** 2
        return (self.momentum * energy_across / momentum_across).reshape(t.shape)

    def _integral(self, lo, hi):
        """int_lo^hi dphi/dt dt, elementwise, by one Gauss-Legendre panel each."""
        width = (hi - lo)[:, None]
        return np.sum(self._weights * self._phi_rate(lo[:, None] + width * self._nodes), axis=1) * width[:, 0]

    def precession_angle(self, t) -> np.ndarray:
        """phi(t) - phi(0), the angle turned about L, rad, shape (K,)."""
        t = np.asarray(t, float)
        periods, s = np.divmod(t, self.period)
        panel = np.minimum((s // self._panel_width).astype(int), PANELS - 1)
        lo = panel * self._panel_width
        return periods * self._phi_at_edges[-1] + self._phi_at_edges[panel] + self._integral(lo, s)

    def _frame(self, t, phi):
        """The body-to-L-frame orientation Rz(phi) Rx(theta) Rz(psi), shape (K, 4)."""
        body_l = self.inertia * self.angular_velocity(t)
        # the two other axes in right-handed order after the polar one: (1, 2) for polar 3, and
        # (2, 3) for polar 1, the frame relabelled (2, 3, 1)
        a, b = np.delete(np.arange(3), self.polar)
        theta = np.arctan2(np.hypot(body_l[:, a], body_l[:, b]), body_l[:, self.polar])
        psi = np.arctan2(body_l[:, a], body_l[:, b])
        ez, ex = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
        q = quat.multiply(np, quat.from_axis_angle(np, ez, phi), quat.from_axis_angle(np, ex, theta))
        q = quat.multiply(np, q, quat.from_axis_angle(np, ez, psi))
        return quat.multiply(np, q, np.broadcast_to(_AXIS_1_AS_POLAR, q.shape)) if self.polar == 0 else q

    def orientation(self, t) -> np.ndarray:
        """q(t), body to world, shape (K, 4): q0 (frame(0))* frame(t)."""
        t = np.atleast_1d(np.asarray(t, float))
        start = quat.multiply(np, self.q0, quat.conjugate(np, self._frame0))
        return quat.multiply(np, np.broadcast_to(start, (len(t), 4)), self._frame(t, self.precession_angle(t)))


def flip_period(inertia, omega0) -> float:
    """The period T = 4 K(m) / lambda of omega(t) for a free body (see the module docstring), s."""
    return TorqueFreeMotion(inertia, quat.IDENTITY, omega0).period
