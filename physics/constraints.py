"""The model's springs as distance constraints, the view position-based integrators step.

A Hooke spring of stiffness k between bodies i and j is the distance constraint
C(q) = |q_j - q_i| - l_rest with compliance alpha = 1 / k: its potential
k C^2 / 2 = C^2 / (2 alpha) is the constraint's energy in XPBD (Macklin, Mueller and
Chentanez, "XPBD: position-based simulation of compliant constrained dynamics", MIG 2016,
eq. 2-4). A spring of stiffness ``inf`` is an inextensible constraint, alpha = 0, which
only a position-based method can step: as a force it is inf * 0. A damper on a spring's
pair is the constraint's damping coefficient beta (N s/m, Macklin 2016 section 3.5).

What a position-based method can express: these constraints, plus forces that are one
constant acceleration field (gravity, constant forces), which enter its predict step as
external accelerations. Anything else (drag, central gravity, ground contact, a damper
without a spring on its pair) is refused with one line.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .dampers import Dampers
from .modes import NonFiniteModelError
from .springs import Springs


class DistanceConstraints(NamedTuple):
    """Distance constraints C = |q_j - q_i| - rest_length, one per spring (float64 NumPy).

    i, j : int64 ndarray, shape (P,)
    rest_length : ndarray, shape (P,), m
    compliance : ndarray, shape (P,), m/N; alpha = 1 / k, 0 for an inextensible one
    damping : ndarray, shape (P,), N s/m; beta, the damper on the same pair (0 without)
    """

    i: np.ndarray
    j: np.ndarray
    rest_length: np.ndarray
    compliance: np.ndarray
    damping: np.ndarray


class InextensibleSpringError(NonFiniteModelError):
    """A force evaluation on springs of infinite stiffness: one line (they are constraints)."""


class NotConstraintsError(ValueError):
    """A model a position-based method cannot express: one line naming the force."""


def has_inextensible(forces) -> bool:
    """Whether some spring has stiffness = inf (an inextensible constraint)."""
    return any(isinstance(f, Springs) and np.any(np.isinf(np.asarray(f.stiffness))) for f in forces)


def without_inextensible(forces) -> tuple:
    """The forces with infinitely stiff springs at stiffness 0, for the energy.

    An enforced constraint's potential is 0 on the constraint (C = 0) and undefined off it;
    its energy is the rest of the system's.
    """
    return tuple(dataclasses.replace(f, stiffness=np.where(np.isinf(f.stiffness), 0.0, f.stiffness))
                 if isinstance(f, Springs) else f for f in forces)


def inextensible_error() -> InextensibleSpringError:
    return InextensibleSpringError(
        "springs of stiffness = inf are inextensible constraints, not forces: only the position-based "
        "integrators (pbd, xpbd) can step them; give the springs a finite stiffness for this integrator")


def distance_constraints(forces) -> DistanceConstraints:
    """The springs of ``forces`` as distance constraints, each with the damper on its pair.

    Raises
    ------
    NotConstraintsError
        A force that is neither a spring, a damper on a spring's pair nor constant.
    """
    springs = [f for f in forces if isinstance(f, Springs)]
    for f in forces:
        if not (isinstance(f, (Springs, Dampers)) or f.constant):
            raise NotConstraintsError(
                f"position-based integrators step springs (with dampers on their pairs) and constant forces "
                f"(gravity, constant forces) only; this model also has {f.name!r}")
    if not springs:
        return DistanceConstraints(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0),
                                   np.zeros(0))
    i = np.concatenate([np.asarray(s.i, np.int64) for s in springs])
    j = np.concatenate([np.asarray(s.j, np.int64) for s in springs])
    k = np.concatenate([np.asarray(s.stiffness, float) for s in springs])
    rest = np.concatenate([np.asarray(s.rest_length, float) for s in springs])
    with np.errstate(divide="ignore", over="ignore"):
        compliance = np.where(np.isinf(k), 0.0, 1.0 / k)
    if not np.all(np.isfinite(compliance)):  # a subnormal stiffness: alpha = 1 / k overflows
        raise NotConstraintsError(
            f"a spring of stiffness {k[~np.isfinite(compliance)][0]:.3g} N/m has no finite compliance 1 / k; the "
            f"position-based integrators take stiffnesses from {1 / np.finfo(float).max:.3g} N/m (and inf)")
    # a damper joins the constraint on its (unordered) pair
    slot = {(min(a, b), max(a, b)): p for p, (a, b) in enumerate(zip(i.tolist(), j.tolist()))}
    damping = np.zeros(len(i))
    for d in (f for f in forces if isinstance(f, Dampers)):
        for a, b, c in zip(np.asarray(d.i).tolist(), np.asarray(d.j).tolist(), np.asarray(d.damping).tolist()):
            p = slot.get((min(a, b), max(a, b)))
            if p is None:
                raise NotConstraintsError(f"a damper between bodies {a} and {b} has no spring on its pair: "
                                          "position-based integrators damp constraints only")
            damping[p] += c
    return DistanceConstraints(i, j, rest, compliance, damping)
