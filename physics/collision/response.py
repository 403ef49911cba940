"""Collision response: the impulse with restitution (the lecture's equation 4), and friction.

Two bodies meet with velocities V1-, V2- and unit normal n pointing from body 1 to body 2.
The impulse Lambda acts on body 1 and -Lambda on body 2 (equation 1 and Newton's third
law): m1 V1+ = m1 V1- + Lambda, m2 V2+ = m2 V2- - Lambda. Frictionless, it is along the
normal, Lambda = Lambda_s n (equation 2), and the material closes the system (equation 3):

    (V1+ - V2+) . n = -eps (V1- - V2-) . n.

Substituting, Lambda_s (1/m1 + 1/m2) = -(1 + eps) (V1- - V2-) . n, which is equation 4:

    Lambda = -(m1 m2 (1 + eps) ((V1- - V2-) . n) / (m1 + m2)) n.

It is written here with inverse masses, Lambda_s = -(1 + eps) v_n / (1/m1 + 1/m2), so a
static shape or a pinned body is simply 1/m = 0 (infinite mass). Lambda is even in n:
flipping the normal flips both the dot product and the direction, so the formula does
not depend on which way n points, only on n being a unit vector along the contact.

The kinetic energy changes by -(1 - eps^2) v_n^2 / (2 (1/m1 + 1/m2)) <= 0 for eps in
[0, 1]: unchanged at eps = 1, the most lost at eps = 0 (the bodies stick along n).

Coulomb friction (optional) adds a tangential impulse against the sliding velocity v_t,
just enough to stop the sliding but at most mu |Lambda_s|; it never adds energy.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .shapes import DEFAULT_MATERIAL


def _dot(x, y):
    return (x * y).sum(axis=-1)


def normal_speed(v_a, v_b, normal):
    """Approach speed (V_a - V_b) . n: positive when the bodies move towards each other."""
    return _dot(np.asarray(v_a) - v_b, normal)


def impulse(v_a, v_b, inverse_mass_a, inverse_mass_b, normal, restitution, friction=0.0):
    """The impulse Lambda on body A (body B gets -Lambda), vectorised over pairs.

    Parameters
    ----------
    v_a, v_b : array, shape (K, 3) or (3,)
        Velocities just before the collision, m/s.
    inverse_mass_a, inverse_mass_b : array, shape (K,) or ()
        1/m, 1/kg; 0 for a static or pinned body.
    normal : array, shape (K, 3) or (3,)
        Unit normal from A to B.
    restitution : array or float
        eps in [0, 1].
    friction : array or float
        Coulomb coefficient mu >= 0 (0: frictionless, the lecture's case).

    Returns
    -------
    Lambda : array, shape (K, 3) or (3,)
        N s. Zero for pairs that are not approaching.
    """
    v_rel = v_a - v_b
    v_n = _dot(v_rel, normal)
    inverse_sum = np.asarray(inverse_mass_a) + inverse_mass_b
    approaching = (v_n > 0) & (inverse_sum > 0)
    safe_sum = np.where(inverse_sum > 0, inverse_sum, 1.0)
    lambda_s = np.where(approaching, -(1 + np.asarray(restitution)) * v_n / safe_sum, 0.0)
    total = lambda_s[..., None] * normal
    if np.any(np.asarray(friction) > 0):
        v_t = v_rel - v_n[..., None] * normal
        speed_t = np.sqrt(_dot(v_t, v_t))
        stop = speed_t / safe_sum  # the tangential impulse that ends the sliding
        j_t = np.where(approaching, np.minimum(stop, np.asarray(friction) * np.abs(lambda_s)), 0.0)
        total = total - (j_t / np.where(speed_t > 0, speed_t, 1.0))[..., None] * v_t
    return total


@dataclasses.dataclass(frozen=True)
class PairProperties:
    """Restitution and friction per pair of materials (a collision's property, not an object's).

    The lecture notes that the coefficient of restitution belongs to the *pair*: a ball
    bounces differently off a floor and off another ball. Pairs not in ``table`` use the
    defaults. ``table`` maps ``frozenset({material_a, material_b})`` (one element for a
    material against itself) to ``(restitution, friction)``.
    """

    restitution: float = 1.0
    friction: float = 0.0
    table: dict = dataclasses.field(default_factory=dict)

    def lookup(self, material_a: str = DEFAULT_MATERIAL, material_b: str = DEFAULT_MATERIAL) -> tuple[float, float]:
        return self.table.get(frozenset((material_a, material_b)), (self.restitution, self.friction))


def resolve(y, i, j, inverse_masses, normal, depth, restitution, friction=0.0):
    """The lecture's collision step for pairs (i, j) in place: move apart, then new velocities.

    Bodies overlapping by ``depth`` > 0 are moved apart along the normal, each in
    proportion to its inverse mass (a static shape, ``j = None``, does not move); then the
    impulse is applied, V_i += Lambda / m_i and V_j -= Lambda / m_j (equation 1). The
    bodies of one call must be distinct. Returns Lambda, shape (K, 3).

    Parameters
    ----------
    y : ndarray, shape (2, N, 3)
        State, changed in place.
    i, j : int array, shape (K,); ``j`` may be None for a static shape
    normal : array, shape (K, 3)
        Unit normal from i towards j.
    depth : array, shape (K,)
    """
    inv_a = inverse_masses[i]
    inv_b = inverse_masses[j] if j is not None else np.zeros_like(inv_a)
    inv_sum = inv_a + inv_b
    push = np.where((depth > 0) & (inv_sum > 0), depth, 0.0) / np.where(inv_sum > 0, inv_sum, 1.0)
    y[0, i] -= normal * (push * inv_a)[:, None]
    v_b = y[1, j] if j is not None else np.zeros_like(y[1, i])
    lam = impulse(y[1, i], v_b, inv_a, inv_b, normal, restitution, friction)
    y[1, i] += lam * inv_a[:, None]
    if j is not None:
        y[0, j] += normal * (push * inv_b)[:, None]
        y[1, j] -= lam * inv_b[:, None]
    return lam
