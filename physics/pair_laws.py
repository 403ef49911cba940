"""The spring and damper laws of one pair, defined once for every path that evaluates them.

A pair acts along ``d``, the unit vector from its first body to its second, at length ``l``
(``inverse_length`` is 1 / l, and 0 at l = 0, where there is no direction); ``approach`` is
the relative velocity along it, d . (v_j - v_i). Each law below is a scalar function of
those and of the pair's constants, in plain arithmetic without branches, so that one Python
function serves both kinds of caller:

- NumPy and JAX evaluate it on whole (P,) columns of pairs, elementwise (:mod:`.springs`,
  :mod:`.dampers`: the forces, potentials and Jacobian blocks of every integrator);
- Numba compiles it (:func:`compiled`) into the sparse Newton kernel's loop over pairs
  (:mod:`.sparse_kernels`), which needs forces and blocks at once for implicit Euler.

Compiled without ``fastmath``, the kernel performs the operations in the order written, so a
force is the same bits on every path; the kernel then adds a spring's and a damper's
tensions before multiplying by d, which the NumPy path does after (equal to round-off).
``tests/test_one_definition.py`` fails when a module writes one of these laws again.
(``steplab/peers.py`` keeps an intentionally independent copy, the bench's reference.)

The Jacobian blocks are written in the basis the kernel assembles them in, d d^T, I and the
symmetrised d w^T (w = u - (d . u) d, the relative velocity across the pair), each law
returning the coefficients of its terms already multiplied by the Newton matrix's
``coefficient`` (-h^2 or -h; 1 for the Jacobian itself).
"""

from __future__ import annotations


def spring_tension(stiffness, length, rest_length):
    """Hooke's law: k (l - L), N, the pull along d on the first body (> 0: stretched)."""
    return stiffness * (length - rest_length)


def spring_potential(stiffness, length, rest_length):
    """1/2 k (l - L)^2, J: the energy stored in the spring."""
    return 0.5 * stiffness * (length - rest_length) ** 2


def spring_transverse(rest_length, inverse_length):
    """t = 1 - L / l, the geometric stiffness across the pair relative to k (negative when compressed).

    At l = 0 (inverse_length 0) t = 1: the block is k I, the limit of a spring with no direction.
    """
    return 1.0 - rest_length * inverse_length


def spring_block(stiffness, transverse, coefficient):
    """coefficient * d f_i / d q_j = a d d^T + b I, as ``(a, b)``: the axial k (1 - t) and the transverse k t.

    The block k [d d^T + t (I - d d^T)] of f_i = k (l - L) d, d = (q_j - q_i) / l: the axial
    stiffness along d and the geometric stiffness k (1 - L / l) across it.
    """
    k = coefficient * stiffness
    return k * (1.0 - transverse), k * transverse


def damper_tension(damping, approach):
    """The dashpot's law: c (d . u), N, along d on the first body (> 0: the bodies separate)."""
    return damping * approach


def damper_velocity_block(damping, coefficient):
    """coefficient * d f_i / d v_j = a d d^T, as ``a``: c d d^T, the dashpot resists only the axial speed."""
    return coefficient * damping


def damper_position_block(damping, inverse_length, approach, coefficient):
    """coefficient * d f_i / d q_j = b (I - d d^T) + e d w^T, as ``(e, b)``: e = c / l and b = e (d . u).

    The damping force turns with the pair: d d / d q_j = (I - d d^T) / l, so
    d [c (d . u) d] / d q_j = c [(d . u) (I - d d^T) + d w^T] / l with w = (I - d d^T) u. Not
    symmetric; the Newton matrix takes its symmetric part, (d w^T + w d^T) / 2 for the last term.
    """
    e = coefficient * damping * inverse_length
    return e, e * approach


def compiled(law):
    """``law`` compiled by Numba for the kernels' loops over pairs (inlined where it is called).

    Numba is imported here, by the kernels, not by the forces: a command that only reads a scene
    stays light (tests/test_startup.py).
    """
    from numba import njit

    return njit(cache=True, inline="always")(law)
