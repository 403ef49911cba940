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
just enough to stop the sliding but at most mu |Lambda_s|; it never adds energy. On a sphere
that spins, the sliding velocity is the contact point's and the impulse turns the sphere too
(:mod:`.compiled_response`, "Spheres with spin": :func:`resolve_spinning`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..rules import number_problem, require, restitution_problem, short
from .compiled_response import impulse_rows, no_spin, resolve_rows
from .shapes import DEFAULT_MATERIAL


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
    v_rel = np.asarray(v_a, dtype=float) - v_b
    normal = np.asarray(normal, dtype=float)
    inverse_sum = np.asarray(inverse_mass_a, dtype=float) + inverse_mass_b
    shape = np.broadcast_shapes(v_rel.shape, normal.shape, inverse_sum.shape + (3,),
                                np.shape(restitution) + (3,), np.shape(friction) + (3,))

    def rows(x, tail=()):
        return np.ascontiguousarray(np.broadcast_to(x, shape[:-1] + tail).reshape((-1,) + tail), dtype=float)

    # the one definition, compiled (:func:`.compiled_response.impulse_of`), row by row
    return impulse_rows(rows(v_rel, (3,)), rows(inverse_sum), rows(normal, (3,)), rows(restitution),
                        rows(friction)).reshape(shape)


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

    def __post_init__(self):
        # the rules of a scene file's [collisions] restitution and friction (physics/scene.py)
        rules = [("", (self.restitution, self.friction))]
        if not isinstance(self.table, dict):
            raise TypeError(f"PairProperties: table must be a dict {{frozenset of materials: (restitution, "
                            f"friction)}}, got {short(self.table)}")
        for pair, value in self.table.items():
            if not isinstance(value, (tuple, list)) or len(value) != 2:
                raise TypeError(f"PairProperties: table[{short(pair)}] must be (restitution, friction), "
                                f"got {short(value)}")
            rules.append((f"table[{short(pair)}] ", value))
        for where, (restitution, friction) in rules:
            require(f"PairProperties: {where}restitution", restitution_problem(restitution))
            require(f"PairProperties: {where}friction", number_problem(friction, nonnegative=True))

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
    return resolve_spinning(y, (i, j), inverse_masses, (normal, depth), (restitution, friction), no_spin())


def resolve_spinning(y, pairs, inverse_masses, contact, material, spin):
    """:func:`resolve` for spheres that may spin: ``pairs`` = (i, j), ``contact`` = (normal, depth),
    ``material`` = (restitution, friction), ``spin`` a :class:`.compiled_response.Spin` whose
    ``omega`` the impulse's angular part changes in place (:mod:`.compiled_response`)."""
    i, j = pairs
    normal, depth = contact
    restitution, friction = material
    i = np.asarray(i, dtype=np.int64)
    j = np.full(len(i), -1, np.int64) if j is None else np.asarray(j, dtype=np.int64)

    def rows(x):
        return np.ascontiguousarray(np.broadcast_to(x, i.shape), dtype=float)

    # pair by pair with the compiled kernel (:func:`.compiled_response.respond`): the bodies are
    # distinct, so the order does not matter
    return resolve_rows(y, (i, j), np.asarray(inverse_masses, dtype=float),
                        np.ascontiguousarray(np.broadcast_to(normal, i.shape + (3,)), dtype=float), rows(depth),
                        (rows(restitution), rows(friction)), spin)
