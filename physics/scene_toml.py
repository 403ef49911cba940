"""The strict TOML layer of scene files: bounded reading and typed, checked access to tables.

Nothing here knows what a body or a force is. :func:`read_toml` turns the bytes of a
scene file into nested dicts, refusing what is too large, not UTF-8 or malformed;
:class:`Table` reads one table of them with a type, a range and finiteness checked per
key. Every refusal is a :class:`SceneError` of one line naming the file and the key path
(``s.toml: forces.springs[0].stiffness: must be > 0, got -1``), so a typo never silently
changes a study. The scene builder (:mod:`.scene`) and each force's ``from_scene``
(:mod:`.forces`) read their tables through it.
"""

from __future__ import annotations

import tomllib

import numpy as np

from .rules import ZERO_DIRECTION, integer_problem, kind, number_problem, short, to_float, unit_vector, vector_problem

#: largest scene the loader builds (bodies; all-pairs soft bodies count their pairs)
MAX_BODIES = 1_000_000
MAX_PAIRS = 5_000_000
#: largest scene file read (bytes): a hostile path such as /dev/zero is refused, not read forever
MAX_SCENE_BYTES = 16 * 2**20

#: the default of a key that must be present: ``t.number("mass", REQUIRED)``
REQUIRED = object()


class SceneError(ValueError):
    """A scene that cannot be loaded; the message is one line naming file and key."""


def read_toml(text: bytes | str, label: str) -> dict:
    """The TOML document ``text`` as nested dicts; ``label`` names it in error messages.

    Raises
    ------
    SceneError
        Larger than :data:`MAX_SCENE_BYTES`, not UTF-8, or malformed TOML.
    """
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(f"{label}: larger than the limit of {MAX_SCENE_BYTES} bytes for a scene file")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise SceneError(f"{label}: not UTF-8 text (byte {err.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{label}: malformed TOML: {err}") from None
    except RecursionError:  # tomllib recurses once per level of [[[...]]] or {a = {b = ...}}
        raise SceneError(f"{label}: malformed TOML: arrays or inline tables nested too deeply") from None


class Table:
    """Typed, strict access to one TOML table, with the key path for error messages.

    Parameters
    ----------
    data : dict
        The table as :mod:`tomllib` read it (anything else is refused: "must be a table").
    where : str
        Its key path, ``"forces.springs[0]"`` (``""`` for the document itself).
    label : str
        The file, as error messages name it.
    """

    def __init__(self, data, where: str, label: str):
        self.label, self.where = label, where
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {kind(data)}")
        self.data = data

    def fail(self, message: str, key: str | None = None):
        """Raise the one-line :class:`SceneError` ``"<file>: <where>.<key>: <message>"``."""
        if key and key.startswith("["):  # a list element: "vertices[3]", not "vertices.[3]"
            where = f"{self.where}{key}"
        else:
            where = f"{self.where}.{key}" if key and self.where else (key or self.where)
        raise SceneError(f"{self.label}: {where}: {message}" if where else f"{self.label}: {message}")

    def allow(self, *keys: str):
        """Refuse any key but ``keys`` (the message lists them)."""
        unknown = sorted(set(self.data) - set(keys))
        if unknown:
            self.fail(f"unknown key {unknown[0]!r}; allowed: {', '.join(keys)}")

    def raw(self, key: str, default=REQUIRED):
        """The value of ``key`` unchecked (``default`` when absent; a missing REQUIRED key fails)."""
        if key in self.data:
            return self.data[key]
        if default is REQUIRED:
            self.fail("missing required key", key)
        return default

    def number(self, key, default=None, positive=False, nonnegative=False):
        value = self.raw(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(f"must be a number, got {kind(value)}", key)
        value = to_float(value)
        problem = number_problem(value, positive, nonnegative)
        if problem:
            self.fail(problem, key)
        return value

    def integer(self, key, default=None, minimum=0, maximum=MAX_BODIES):
        value = self.raw(key, default)
        if not isinstance(value, int):  # a TOML integer, not a NumPy one
            self.fail(f"must be an integer, got {kind(value)}", key)
        problem = integer_problem(value, minimum, maximum)
        if problem:
            self.fail(problem, key)
        return value

    def string(self, key, default=None, choices=None):
        value = self.raw(key, default)
        if not isinstance(value, str):
            self.fail(f"must be a string, got {kind(value)}", key)
        if choices is not None and value not in choices:
            self.fail(f"must be one of {', '.join(choices)}, got {value!r}", key)
        return value

    def name(self, key="name", default=None):
        """A name (a body's, a group's, a shape's, the scene's): a non-empty string of printable
        characters, as the tables, logs and CSV rows that print it on one line need."""
        value = self.string(key, default)
        if not value or not value.isprintable():
            self.fail(f"must be a non-empty name of printable characters, got {value!r}", key)
        return value

    def boolean(self, key, default=False):
        value = self.raw(key, default)
        if not isinstance(value, bool):
            self.fail(f"must be true or false, got {kind(value)}", key)
        return value

    def vector(self, key, default=None, positive=False):
        value = self.raw(key, default)
        if value is None:
            return None
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)):
            self.fail(f"must be a list of 3 numbers [x, y, z], got {short(value)}", key)
        vec = np.array([to_float(x) for x in value])
        problem = vector_problem(vec, positive, shown=value)
        if problem:
            self.fail(problem, key)
        return vec

    def direction(self, key, default=None) -> np.ndarray:
        """A vector normalised to unit length (a zero vector is refused)."""
        return unit(self, key, self.vector(key, default))

    def vectors(self, key, maximum=MAX_BODIES):
        value = self.raw(key, REQUIRED)
        if not isinstance(value, list) or not value:
            self.fail(f"must be a non-empty list of [x, y, z], got {kind(value)}", key)
        if len(value) > maximum:
            self.fail(f"has {len(value)} entries, more than the limit {maximum}", key)
        prefix = f"{self.where}.{key}" if self.where else key
        return np.array([Table({f"[{k}]": v}, prefix, self.label).vector(f"[{k}]") for k, v in enumerate(value)])

    def tables(self, key) -> list[Table]:
        """The array of tables ``[[key]]`` (empty when absent)."""
        value = self.data.get(key, [])
        if not isinstance(value, list):
            self.fail(f"must be an array of tables ([[{key}]]), got {kind(value)}", key)
        prefix = f"{self.where}.{key}" if self.where else key
        return [Table(item, f"{prefix}[{k}]", self.label) for k, item in enumerate(value)]

    def table(self, key) -> Table | None:
        """The sub-table ``[key]``, or None when absent."""
        if key not in self.data:
            return None
        prefix = f"{self.where}.{key}" if self.where else key
        return Table(self.data[key], prefix, self.label)


def unit(t: Table, key: str, vec: np.ndarray) -> np.ndarray:
    """``vec`` normalised (:func:`.rules.unit_vector`); a zero vector fails."""
    direction = unit_vector(vec)
    if direction is None:
        t.fail(ZERO_DIRECTION, key)
    return direction
