"""The rules a number of the model must meet, one copy each for scene files and the Python API.

A scene file's values are checked as they are read (:mod:`.scene_toml`, ``from_scene``);
the constructors (``Gravity(g)``, ``Model(masses, radii)``, ``Plane(normal)``, ...) check
the same values with the same rules. Each ``*_problem`` function returns what is wrong
("must be > 0, got -1"), or None when nothing is: the loader prefixes the file and key
path, a constructor its class and argument (:func:`require`), so one rule reads the same
in both.

Only concrete values are checked: JAX arrays (a model cast to ``jax.numpy``, tracers inside
``jit``) pass unchecked (:func:`skip_checks`), and nothing here converts or inspects them.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import sys

import numpy as np

#: inside :func:`trusted`: the values come from a model already checked, and are not checked again
_TRUSTED = contextvars.ContextVar("steplab_trusted", default=False)


@contextlib.contextmanager
def trusted():
    """Build models and forces from the parts of a checked one without checking them again: the
    attached springs' lever arms are rebuilt every step (:func:`.attachments.model_at`), where the
    checks took a third of the step."""
    token = _TRUSTED.set(True)
    try:
        yield
    finally:
        _TRUSTED.reset(token)


def skip_checks(*values) -> bool:
    """Whether the checks pass ``values`` by: any of them a JAX array or tracer (checked on NumPy
    values only), or inside :func:`trusted`.

    JAX is not imported for this: a value cannot be a JAX array before JAX is loaded."""
    if _TRUSTED.get():
        return True
    jax = sys.modules.get("jax")
    return jax is not None and any(isinstance(v, jax.Array) for v in values)


def require(where: str, problem: str | None, error: type[Exception] = ValueError) -> None:
    """Raise ``error("<where> <problem>")`` (one line) when a rule found a problem ("<where>:
    <problem>" for a problem that is a sentence of its own, not "must ...")."""
    if problem is not None:
        raise error(f"{where} {problem}" if problem.startswith("must") else f"{where}: {problem}")


def numeric(value) -> np.ndarray | None:
    """``value`` as a NumPy array of integers or floats (not booleans), or None when it is not one."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):  # ragged lists
        return None
    return arr if arr.dtype.kind in "iuf" else None


def number_problem(value, positive: bool = False, nonnegative: bool = False,
                   infinite: bool = False) -> str | None:
    """A number, or an array of them, finite (``infinite``: +inf allowed, never NaN), and
    ``positive`` (> 0) or ``nonnegative`` (>= 0); the message names the first bad element."""
    arr = numeric(value)
    if arr is None:
        return f"must be {'numbers' if np.ndim(value) else 'a number'}, got {short(value)}"
    arr = arr.astype(float, copy=False)
    finite = ~np.isnan(arr) & (arr != -np.inf) if infinite else np.isfinite(arr)
    for ok, rule in ((finite, "finite"), (arr > 0 if positive else True, "> 0"),
                     (arr >= 0 if nonnegative else True, ">= 0")):
        if not np.all(ok):
            k = int(np.argmin(np.broadcast_to(ok, arr.shape).ravel()))
            bad, where = float(arr.flat[k]), f" (element {k})" if arr.ndim else ""
            return f"must be {rule}, got {bad if rule == 'finite' else format(bad, 'g')}{where}"
    return None


def vector_problem(value, positive: bool = False, shown=None) -> str | None:
    """Three finite numbers [x, y, z] (``positive``: each > 0); ``shown``: the value as the user wrote it."""
    shown = value if shown is None else shown
    arr = numeric(value)
    if arr is None or arr.shape != (3,):
        return f"must be 3 numbers [x, y, z], got {short(shown)}"
    if not np.all(np.isfinite(arr)):
        return f"must be finite, got {short(shown)}"
    if positive and not np.all(arr > 0):
        return f"must be > 0 in every component, got {short(shown)}"
    return None


def unit_vector(vec) -> np.ndarray | None:
    """``vec`` (3 finite numbers) normalised, or None for a zero vector. Scaled by its largest
    component first, so that neither a huge ([1e200, 1e200, 0]) nor a subnormal vector over-
    or underflows to a zero direction."""
    vec = np.asarray(vec, dtype=float)
    scale = np.max(np.abs(vec))
    if not scale > 0:
        return None
    vec = vec / scale
    return vec / np.linalg.norm(vec)


#: a direction's message when it is the zero vector
ZERO_DIRECTION = "must be a non-zero vector"


def direction(where: str, vec):
    """A direction of the Python API: ``vec`` itself when it is a unit vector to round-off (so a
    scene's normalised one keeps its bytes), else normalised as a scene file's; ValueError for
    what is not 3 finite numbers or is zero."""
    require(where, vector_problem(vec))
    arr = np.asarray(vec)
    tol = 8 * np.finfo(arr.dtype if arr.dtype.kind == "f" else float).eps
    if abs(float(np.linalg.norm(arr.astype(float))) - 1.0) <= tol:
        return vec
    unit = unit_vector(arr)
    require(where, ZERO_DIRECTION if unit is None else None)
    return unit


def integer_problem(value, minimum: int, maximum: int) -> str | None:
    """An integer (not a boolean) between ``minimum`` and ``maximum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        return f"must be an integer, got {kind(value)}"
    if not minimum <= value <= maximum:
        return f"must be between {minimum} and {maximum}, got {value}"
    return None


def restitution_problem(value) -> str | None:
    """A coefficient of restitution: between 0 (the bodies stick) and 1 (elastic)."""
    problem = number_problem(value)
    if problem is None:
        arr = np.asarray(value, dtype=float)
        ok = (arr >= 0) & (arr <= 1)
        if not np.all(ok):
            k = int(np.argmin(ok.ravel()))
            where = f" (element {k})" if arr.ndim else ""
            problem = f"must be between 0 and 1 (a coefficient of restitution), got {float(arr.flat[k]):g}{where}"
    return problem


#: the smallest positive float64 whose inverse is finite (1 / x overflows below it: the subnormals)
SMALLEST_INVERTIBLE = 1 / np.finfo(float).max


def invertible(values) -> np.ndarray:
    """Where ``values`` (> 0) have a finite inverse: a subnormal mass or moment of inertia has none (a = F / m
    and I^-1 L overflow)."""
    with np.errstate(divide="ignore", over="ignore"):
        return np.float64(1.0) / np.asarray(values, dtype=float) < np.inf


def mass_problem(masses) -> str | None:
    """Masses, kg: finite, > 0, and with a finite inverse (a subnormal mass: a = F / m would overflow)."""
    problem = number_problem(masses, positive=True)
    if problem is None:
        arr = np.asarray(masses, dtype=float)
        ok = invertible(arr)
        if not np.all(ok):
            mass = float(arr.flat[int(np.argmin(ok.ravel()))])
            problem = (f"a body of mass {mass:.3g} kg has no finite inverse mass (the smallest mass is "
                       f"{SMALLEST_INVERTIBLE:.3g} kg)")
    return problem


def to_float(value) -> float:
    """A TOML number as a float; an integer too large for a float becomes inf (then refused)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def kind(value) -> str:
    """What a TOML value is, for messages: "a string", "a list", ..."""
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a table"}.get(type(value), type(value).__name__)


def short(value) -> str:
    """``repr(value)`` cut to 60 characters, for messages (on one line)."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def require_pairs(where: str, i, j, **params) -> None:
    """The pairs of a pair force (springs, dampers), as a scene file's ``bodies = ["a", "b"]``:
    ``i`` and ``j`` 1-D integer arrays of the same length P, indices >= 0 of two different
    bodies; each of ``params`` (name -> (values, rule keywords of :func:`number_problem`)) of
    shape (P,). Whether the indices name bodies of the model is the model's check
    (``Force.check_bodies``)."""
    arrays = {}
    for key, value in (("i", i), ("j", j)):
        arr = numeric(value)
        if arr is None or arr.dtype.kind not in "iu" or arr.ndim != 1:
            raise ValueError(f"{where}: {key} must be a 1-D array of body indices, got {short(value)}")
        arrays[key] = arr
    if arrays["i"].shape != arrays["j"].shape:
        raise ValueError(f"{where}: i and j must have the same length, got {arrays['i'].size} and {arrays['j'].size}")
    for key, arr in arrays.items():
        if arr.size and arr.min() < 0:
            raise ValueError(f"{where}: {key} must be body indices >= 0, got {int(arr.min())}")
    same = arrays["i"] == arrays["j"]
    if np.any(same):
        raise ValueError(f"{where}: a pair must join two different bodies, got body {int(arrays['i'][same][0])} "
                         f"twice (pair {int(np.argmax(same))})")
    for key, (value, rules) in params.items():
        require(f"{where}: {key}", number_problem(value, **rules))
        if np.shape(value) != arrays["i"].shape:
            raise ValueError(f"{where}: {key} must have one value per pair, shape {arrays['i'].shape}, "
                             f"got shape {np.shape(value)}")


def require_indices(where: str, indices, n_bodies: int) -> None:
    """Body indices ``indices`` (an integer array) name bodies of a model of ``n_bodies``."""
    arr = np.asarray(indices)
    if arr.size and arr.max() >= n_bodies:
        raise ValueError(f"{where}: body index {int(arr.max())} out of range for a model of {n_bodies} bodies "
                         f"(0..{n_bodies - 1})")


#: how far from orthonormal a rotation matrix may be: max |R^T R - I| over its entries. Building one in
#: float64 (Rodrigues' formula, a quaternion's matrix) leaves ~1e-16; 1e-9 turns a point 1 km out by
#: under 1 micrometre. A float32 matrix (which rounding alone leaves ~1e-7 off) gets 1e-5.
ORTHONORMAL_TOLERANCE = {8: 1e-9, 4: 1e-5}


def rotation_problem(value) -> str | None:
    """A rotation matrix: 3 x 3, finite, orthonormal (max |R^T R - I| within :data:`ORTHONORMAL_TOLERANCE`:
    1e-9 for float64 and integers, 1e-5 for float32) and proper (det +1: a reflection, det -1, turns
    nothing)."""
    arr = numeric(value)
    if arr is None or arr.shape != (3, 3):
        shown = f"shape {arr.shape}" if arr is not None else short(value)
        return f"must be a 3 x 3 rotation matrix, got {shown}"
    if not np.all(np.isfinite(arr)):
        return f"must be finite, got {short(arr.tolist())}"
    tol = ORTHONORMAL_TOLERANCE[4 if arr.dtype.kind == "f" and arr.dtype.itemsize <= 4 else 8]
    rot = arr.astype(float)
    off = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
    if not off <= tol:
        return f"must be orthonormal (max |R^T R - I| <= {tol:.2g}), got {off:.3g}"
    if np.linalg.det(rot) < 0:
        return "must be a rotation (det +1), got a reflection (det -1)"
    return None


def friction_problem(mu_static, mu_dynamic) -> str | None:
    """Coulomb friction: the sliding coefficient ``mu_dynamic`` at most the static one, ``mu_static``
    (both already numbers >= 0): sliding resisted harder than sticking can hold would chatter between
    the two. The message, of mu_dynamic, names both values."""
    s, d = np.asarray(mu_static, dtype=float), np.asarray(mu_dynamic, dtype=float)
    try:
        ok = d <= s
    except ValueError:  # shapes that do not broadcast
        return f"must have the shape of mu_static, {s.shape}, got {d.shape}"
    if np.all(ok):
        return None
    k = int(np.argmin(ok.ravel()))
    where = f" (element {k})" if ok.ndim else ""
    bad_s, bad_d = float(np.broadcast_to(s, ok.shape).flat[k]), float(np.broadcast_to(d, ok.shape).flat[k])
    return (f"must be <= mu_static (Coulomb friction: sliding cannot be resisted harder than sticking holds), "
            f"got mu_dynamic = {bad_d:g} > mu_static = {bad_s:g}{where}")
