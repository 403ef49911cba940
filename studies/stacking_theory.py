"""The stacking study's analytic answers: rolling, the incline, and a stack's static deflection.

Each is derived here from the mechanics alone, never from a run:

- **sliding to rolling** (a solid sphere launched at v0 without spin on a floor of friction
  mu): kinetic friction mu m g decelerates the centre and its torque mu m g r spins the ball
  up, v = v0 - mu g t and omega = 5 mu g t / (2 r) (I = 2/5 m r^2), until v = omega r at
  t = 2 v0 / (7 mu g); from then on it rolls at v = 5/7 v0. (Equivalently: friction acts at the
  contact point, so the angular momentum about it, m v r + I omega, is kept.)
- **the incline** of angle theta: a box at rest sticks while the static friction needed,
  m g sin theta, is at most mu m g cos theta (tan theta <= mu); otherwise it slides at
  a = g (sin theta - mu cos theta).
- **static deflection of a stack on soft contacts**: the solver's soft contact (Catto 2011,
  :mod:`steplab.physics.collision.solver_settings`) acts at each contact point as a spring of
  stiffness k = m_eff omega^2, omega = 2 pi contact_hertz, m_eff = 1 / (J M^-1 J^T) that
  point's effective mass. At rest the solver's fixed point is the equilibrium of those springs:
  its increment vanishes when m_eff (a2 / (1 + a2)) (omega / a1) s = -lambda / (1 + a2), and
  with a2 = h omega a1 that is lambda / h = -m_eff omega^2 s for the substep h: a linear spring
  whatever h, zeta or the number of iterations. :func:`static_deflection` solves the linear
  elastic problem K u = f of those springs for the boxes' heights and tilts. For a column of
  n equal cubes (4 corner points per face, each of effective mass m / 4 on the floor and m / 8
  between boxes, so the face pairs are springs m omega^2 and m omega^2 / 2) the top sinks
  n^2 g / omega^2.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np

G = 9.81
#: faces closer than this (m) touch: the boxes of a stack meet to round-off
TOUCHING = 1e-9


def sliding_to_rolling(v0: float, mu: float, radius: float, g: float = G) -> dict:
    """When and where a solid sphere launched at v0 without spin starts to roll, and how fast.

    Returns t_roll = 2 v0 / (7 mu g) (s), v_roll = 5/7 v0 (m/s) and x_roll = 12 v0^2 / (49 mu g)
    (m, the distance slid), and omega_roll = v_roll / radius (rad/s).
    """
    t = 2 * v0 / (7 * mu * g)
    return {"t_roll": t, "v_roll": v0 - mu * g * t, "x_roll": v0 * t - 0.5 * mu * g * t * t,
            "omega_roll": (v0 - mu * g * t) / radius}


def rolling_speed(v0: float, mu: float, radius: float, t, g: float = G) -> tuple[np.ndarray, np.ndarray]:
    """The centre's speed v(t) and the spin omega(t) r of the sphere of :func:`sliding_to_rolling`."""
    t = np.minimum(np.asarray(t, float), sliding_to_rolling(v0, mu, radius, g)["t_roll"])
    return v0 - mu * g * t, 2.5 * mu * g * t


def incline_acceleration(theta: float, mu: float, g: float = G) -> float:
    """Acceleration down an incline of ``theta`` rad of a body at rest with friction mu, m/s^2:
    0 while tan theta <= mu (it sticks), else g (sin theta - mu cos theta)."""
    if math.tan(theta) <= mu:
        return 0.0
    return g * (math.sin(theta) - mu * math.cos(theta))


class StackContacts(NamedTuple):
    """The contact points of a stack of axis-aligned boxes at rest, normal +z.

    upper, lower : int ndarray, shape (P,)
        The box above and the box below (-1: the floor) of each point.
    points : ndarray, shape (P, 3)
        The corners of each face-to-face overlap rectangle (4 per touching pair), m.
    """

    upper: np.ndarray
    lower: np.ndarray
    points: np.ndarray


def stack_contacts(centres, sizes, floor: float = 0.0) -> StackContacts:
    """Brute force over all pairs: where the bottom face of one box lies on the top face of
    another (or on the floor z = ``floor``) with an overlap of positive area, the overlap
    rectangle's four corners. ``centres`` and ``sizes`` are (n, 3), m."""
    centres, half = np.asarray(centres, float), 0.5 * np.asarray(sizes, float)
    lo, hi = centres - half, centres + half
    upper, lower, points = [], [], []

    def add(i, j, x0, x1, y0, y1, z):
        for x, y in itertools.product((x0, x1), (y0, y1)):
            upper.append(i)
            lower.append(j)
            points.append((x, y, z))

    for i in range(len(centres)):
        if abs(lo[i, 2] - floor) < TOUCHING:
            add(i, -1, lo[i, 0], hi[i, 0], lo[i, 1], hi[i, 1], lo[i, 2])
    for i, j in itertools.permutations(range(len(centres)), 2):
        if abs(lo[i, 2] - hi[j, 2]) < TOUCHING:
            x0, x1 = max(lo[i, 0], lo[j, 0]), min(hi[i, 0], hi[j, 0])
            y0, y1 = max(lo[i, 1], lo[j, 1]), min(hi[i, 1], hi[j, 1])
            if x1 - x0 > TOUCHING and y1 - y0 > TOUCHING:
                add(i, j, x0, x1, y0, y1, lo[i, 2])
    return StackContacts(np.array(upper, int), np.array(lower, int), np.array(points, float).reshape(-1, 3))


def static_deflection(centres, sizes, masses, contact_hertz: float, g: float = G,
                      sticking: bool = False) -> np.ndarray:
    """Each box's sink (m, > 0 downwards) at the equilibrium of the soft contacts' springs.

    Parameters
    ----------
    centres, sizes : ndarray, shape (n, 3)
        Axis-aligned boxes at rest, touching (as :func:`stack_contacts` finds them), m.
    masses : ndarray, shape (n,)
        kg.
    contact_hertz : float
        The soft contact's natural frequency, Hz.
    sticking : bool
        Whether friction holds every contact point: no slip across the normal (see Notes).

    Notes
    -----
    Unknowns per box: its sink w and small tilts (phi_x, phi_y); a point r from the centre
    then moves down by w - phi_x r_y + phi_y r_x, and a contact point's spring shortens by the
    upper box's move less the lower's. Each point's spring is k = m_eff omega^2 with
    1 / m_eff = sum over its two bodies of 1 / m + r_y^2 / I_x + r_x^2 / I_y (the normal's
    angular part (r x n) I^-1 (r x n) for n = z; a box's principal moments). The stiffness
    matrix K = sum k a a^T (a the point's row of the compatibility map) and the weights f give
    K u = f, solved densely (3 n unknowns).

    With ``sticking``, each box has all 6 small displacements (u, phi; a point moves by
    u + phi x r), and friction holds each contact point: the two bodies' points do not slip
    along x or y. The solver's friction is a rigid constraint (it drives the tangential
    velocity to 0 while |P_t| <= mu P, with no softness), so this is the rigid limit of
    tangential springs: K restricted to the displacements C u = 0 that keep every point
    stuck (u = N z with N a basis of the null space of C, N^T K N z = N^T f; computed as its
    limit, :func:`_sticking_deflection`). In a pyramid it
    matters: a box on two others would tilt their tops apart (the normal springs alone let
    them turn and slide under it), and the stuck points forbid that shear, so the pyramid is
    stiffer. In a column nothing tilts and both give n^2 g / omega^2. (The springs enter
    with the weights along -z here, and the sink is returned > 0 down, as without it.)
    """
    centres, sizes, masses = (np.asarray(x, float) for x in (centres, sizes, masses))
    n, omega = len(masses), 2 * math.pi * contact_hertz
    contacts = stack_contacts(centres, sizes)
    a2, b2, c2 = (sizes**2).T
    ix, iy = masses / 12 * (b2 + c2), masses / 12 * (a2 + c2)
    if sticking:
        return _sticking_deflection(centres, masses, np.stack([ix, iy, masses / 12 * (a2 + b2)], axis=1),
                                    contacts, omega, g)
    rows = np.zeros((len(contacts.points), 3 * n))
    inverse_mass = np.zeros(len(contacts.points))
    for sign, body in ((1.0, contacts.upper), (-1.0, contacts.lower)):
        box = body >= 0
        k, r = body[box], contacts.points[box] - centres[body[box]]
        p = np.nonzero(box)[0]
        rows[p, 3 * k] = sign
        rows[p, 3 * k + 1] = -sign * r[:, 1]
        rows[p, 3 * k + 2] = sign * r[:, 0]
        inverse_mass[p] += 1 / masses[k] + r[:, 1] ** 2 / ix[k] + r[:, 0] ** 2 / iy[k]
    stiffness = omega**2 / inverse_mass
    K = rows.T @ (stiffness[:, None] * rows)
    f = np.zeros(3 * n)
    f[0::3] = masses * g
    return np.linalg.solve(K, f)[0::3]


#: the no-slip constraints' springs, as a multiple of each point's normal spring: the rigid limit
#: to 1e-6 relative (the sink converges as 1 / STUCK; an exact null-space solve agrees, tested)
STUCK = 1e6


def _sticking_deflection(centres, masses, inertia, contacts, omega, g) -> np.ndarray:
    """:func:`static_deflection` with every contact point held by friction (6 unknowns a box, u and phi).

    The no-slip constraints C u = 0 enter as springs :data:`STUCK` times each point's normal
    spring: one dense solve, where the exact null-space basis of C (an SVD of 2 P x 6 n) takes
    a minute for the 210-box pyramid."""
    n, count = len(masses), len(contacts.points)
    move = sticking_moves(centres, contacts, n)
    inverse_mass = np.zeros(count)
    for body in (contacts.upper, contacts.lower):
        box = body >= 0
        k, r = body[box], contacts.points[box] - centres[body[box]]
        inverse_mass[np.nonzero(box)[0]] += 1 / masses[k] + r[:, 1] ** 2 / inertia[k, 0] + r[:, 0] ** 2 / inertia[k, 1]
    spring = omega**2 / inverse_mass
    K = sum(move[:, d, :].T @ ((spring * (1.0 if d == 2 else STUCK))[:, None] * move[:, d, :]) for d in range(3))
    f = np.zeros(6 * n)
    f[2::6] = -masses * g  # the weights, along -z
    return -np.linalg.solve(K, f)[2::6]


def sticking_moves(centres, contacts, n: int) -> np.ndarray:
    """(P, 3, 6 n): each contact point's relative displacement (the upper box's point less the
    lower's) along x, y, z per unknown, u = (u_x, u_y, u_z, phi_x, phi_y, phi_z) per box, a
    point r from a centre moving by u + phi x r."""
    move = np.zeros((len(contacts.points), 3, 6 * n))
    for sign, body in ((1.0, contacts.upper), (-1.0, contacts.lower)):
        box = body >= 0
        k, r = body[box], contacts.points[box] - centres[body[box]]
        p = np.nonzero(box)[0]
        for d in range(3):
            move[p, d, 6 * k + d] = sign
        # phi x r = (phi_y r_z - phi_z r_y, phi_z r_x - phi_x r_z, phi_x r_y - phi_y r_x)
        move[p, 0, 6 * k + 4], move[p, 0, 6 * k + 5] = sign * r[:, 2], -sign * r[:, 1]
        move[p, 1, 6 * k + 5], move[p, 1, 6 * k + 3] = sign * r[:, 0], -sign * r[:, 2]
        move[p, 2, 6 * k + 3], move[p, 2, 6 * k + 4] = sign * r[:, 1], -sign * r[:, 0]
    return move
