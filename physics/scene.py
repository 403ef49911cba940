"""Scenes: TOML files declaring bodies, forces and the simulation settings.

The schema (see README.md, "Scene files") is checked strictly: an unknown key, a
wrong type, a non-finite number or a non-positive mass is an error naming the file and
the key, so a typo never silently changes a study. Built-in scenes ship in
``physics/scenes/`` and can be named without a path (``projectile``).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

from . import soft_body
from .central_gravity import CentralGravity
from .dampers import Dampers
from .drag import AIR_DENSITY, Drag
from .friction import Friction
from .gravity import EARTH_GRAVITY, Gravity
from .model import Model
from .springs import Springs

DEFAULT_MATERIAL = "default"  # as physics.collision.shapes.DEFAULT_MATERIAL

#: largest scene the loader builds (bodies; all-pairs soft bodies count their pairs)
MAX_BODIES = 1_000_000
MAX_PAIRS = 5_000_000
#: largest scene file read (bytes): a hostile path such as /dev/zero is refused, not read forever
MAX_SCENE_BYTES = 16 * 2**20

DEFAULT_INTEGRATOR = "semi-implicit-euler"


class SceneError(ValueError):
    """A scene that cannot be loaded; the message is one line naming file and key."""


@dataclasses.dataclass(frozen=True)
class Scene:
    """A loaded scene: the model, the initial state and the simulation settings."""

    name: str
    model: Model
    y0: np.ndarray
    integrator: str
    dt: float
    t_start: float
    t_end: float
    description: str = ""
    #: the scene's [collisions] table (a physics.collision.CollisionWorld), or None
    collisions: object = None


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with steplab."""
    folder = resources.files("steplab.physics") / "scenes"
    return sorted(p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scene(scene: str | Path) -> Scene:
    """Load a scene by built-in name or by path to a TOML file."""
    path = Path(scene)
    if str(scene) in builtin_scenes():
        text = (resources.files("steplab.physics") / "scenes" / f"{scene}.toml").read_bytes()
        label = f"{scene} (built-in)"
    elif path.suffix == ".toml" or path.exists():
        try:
            with path.open("rb") as f:
                text = f.read(MAX_SCENE_BYTES + 1)
        except OSError as err:
            raise SceneError(f"{path}: cannot read: {err.strerror or err}") from None
        label = str(path)
    else:
        raise SceneError(f"unknown scene {str(scene)!r}: not a file, and the built-in scenes are "
                         f"{', '.join(builtin_scenes())}")
    # a file name that is not UTF-8 (surrogate escapes) must still print as a scene name
    name = path.stem.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return parse_scene(text, label, name=name)


def parse_scene(text: bytes | str, label: str = "<scene>", name: str = "scene") -> Scene:
    """Build a scene from TOML text; ``label`` names it in error messages."""
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(f"{label}: larger than the limit of {MAX_SCENE_BYTES} bytes for a scene file")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise SceneError(f"{label}: not UTF-8 text (byte {err.start})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{label}: malformed TOML: {err}") from None
    except RecursionError:  # tomllib recurses once per level of [[[...]]] or {a = {b = ...}}
        raise SceneError(f"{label}: malformed TOML: arrays or inline tables nested too deeply") from None
    with np.errstate(all="ignore"):  # every derived number is checked; no warnings on stderr
        return _SceneBuilder(label).build(data, name)


class _Table:
    """Typed, strict access to one TOML table, with the key path for error messages."""

    def __init__(self, data, where: str, label: str):
        self.label, self.where = label, where
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {_kind(data)}")
        self.data = data

    def fail(self, message: str, key: str | None = None):
        if key and key.startswith("["):  # a list element: "vertices[3]", not "vertices.[3]"
            where = f"{self.where}{key}"
        else:
            where = f"{self.where}.{key}" if key and self.where else (key or self.where)
        raise SceneError(f"{self.label}: {where}: {message}" if where else f"{self.label}: {message}")

    def allow(self, *keys: str):
        unknown = sorted(set(self.data) - set(keys))
        if unknown:
            self.fail(f"unknown key {unknown[0]!r}; allowed: {', '.join(keys)}")

    def _get(self, key, default):
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            self.fail("missing required key", key)
        return default

    def number(self, key, default=None, positive=False, nonnegative=False):
        value = self._get(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(f"must be a number, got {_kind(value)}", key)
        value = _float(value)
        if not math.isfinite(value):
            self.fail(f"must be finite, got {value}", key)
        if positive and not value > 0:
            self.fail(f"must be > 0, got {value:g}", key)
        if nonnegative and not value >= 0:
            self.fail(f"must be >= 0, got {value:g}", key)
        return value

    def integer(self, key, default=None, minimum=0, maximum=MAX_BODIES):
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(f"must be an integer, got {_kind(value)}", key)
        if not minimum <= value <= maximum:
            self.fail(f"must be between {minimum} and {maximum}, got {value}", key)
        return value

    def string(self, key, default=None, choices=None):
        value = self._get(key, default)
        if not isinstance(value, str):
            self.fail(f"must be a string, got {_kind(value)}", key)
        if choices is not None and value not in choices:
            self.fail(f"must be one of {', '.join(choices)}, got {value!r}", key)
        return value

    def boolean(self, key, default=False):
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.fail(f"must be true or false, got {_kind(value)}", key)
        return value

    def vector(self, key, default=None, positive=False):
        value = self._get(key, default)
        if value is None:
            return None
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)):
            self.fail(f"must be a list of 3 numbers [x, y, z], got {_short(value)}", key)
        vec = np.array([_float(x) for x in value])
        if not np.all(np.isfinite(vec)):
            self.fail(f"must be finite, got {_short(value)}", key)
        if positive and not np.all(vec > 0):
            self.fail(f"must be > 0 in every component, got {_short(value)}", key)
        return vec

    def vectors(self, key, maximum=MAX_BODIES):
        value = self._get(key, _REQUIRED)
        if not isinstance(value, list) or not value:
            self.fail(f"must be a non-empty list of [x, y, z], got {_kind(value)}", key)
        if len(value) > maximum:
            self.fail(f"has {len(value)} entries, more than the limit {maximum}", key)
        prefix = f"{self.where}.{key}" if self.where else key
        return np.array([_Table({f"[{k}]": v}, prefix, self.label).vector(f"[{k}]") for k, v in enumerate(value)])

    def tables(self, key):
        value = self.data.get(key, [])
        if not isinstance(value, list):
            self.fail(f"must be an array of tables ([[{key}]]), got {_kind(value)}", key)
        prefix = f"{self.where}.{key}" if self.where else key
        return [_Table(item, f"{prefix}[{k}]", self.label) for k, item in enumerate(value)]

    def table(self, key):
        if key not in self.data:
            return None
        prefix = f"{self.where}.{key}" if self.where else key
        return _Table(self.data[key], prefix, self.label)


_REQUIRED = object()


def _unit(t: _Table, key: str, vec: np.ndarray) -> np.ndarray:
    """``vec`` normalised; scaled by its largest component first, so that neither a huge
    ([1e200, 1e200, 0]) nor a subnormal vector over- or underflows to a zero direction."""
    scale = np.max(np.abs(vec))
    if not scale > 0:
        t.fail("must be a non-zero vector", key)
    vec = vec / scale
    return vec / np.linalg.norm(vec)


def _float(value) -> float:
    """A TOML number as a float; an integer too large for a float becomes inf (then refused)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _kind(value) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a table"}.get(type(value), type(value).__name__)


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class _SceneBuilder:
    def __init__(self, label: str):
        self.label = label
        self.names: list[str] = []
        self.index: dict[str, int] = {}  # body name -> index (a list lookup would be O(n^2) in total)
        self.masses: list[float] = []
        self.radii: list[float] = []
        self.positions: list[np.ndarray] = []
        self.velocities: list[np.ndarray] = []
        self.pinned: list[bool] = []
        self.forces: list = []
        self.materials: list[str] = []

    def build(self, data, name: str) -> Scene:
        root = _Table(data, "", self.label)
        root.allow("name", "description", "simulation", "bodies", "soft_bodies", "particles", "forces",
                   "collisions")
        sim = root.table("simulation")
        if sim is None:
            root.fail("missing required table [simulation]")
        for body in root.tables("bodies"):
            self.add_body(body)
            self._material(body)
        for soft in root.tables("soft_bodies"):
            self.add_soft_body(soft)
            self._material(soft)
        for group in root.tables("particles"):
            self.add_particles(group)
            self._material(group)
        if not self.names:
            root.fail("declares no bodies: add [[bodies]], [[soft_bodies]] or [[particles]]")
        forces = root.table("forces")
        if forces is not None:
            self.add_forces(forces)

        sim.allow("integrator", "dt", "t_start", "t_end")
        integrator = sim.string("integrator", DEFAULT_INTEGRATOR)
        dt = sim.number("dt", _REQUIRED, positive=True)
        t_start = sim.number("t_start", 0.0)
        t_end = sim.number("t_end", _REQUIRED)
        if not t_end > t_start:
            sim.fail(f"must be later than t_start = {t_start:g}, got {t_end:g}", "t_end")

        model = Model(np.array(self.masses), np.array(self.radii), self.forces,
                      pinned=np.array(self.pinned), names=self.names)
        y0 = np.stack([np.array(self.positions), np.array(self.velocities)])
        table = root.table("collisions")
        collisions = self.add_collisions(table) if table is not None else None
        return Scene(root.string("name", name), model, y0, integrator, dt, t_start, t_end,
                     root.string("description", ""), collisions)

    def _append(self, table, name, mass, radius, position, velocity, pinned=False):
        if name in self.index:
            table.fail(f"duplicate body name {name!r}", "name")
        if len(self.names) >= MAX_BODIES:
            table.fail(f"more than {MAX_BODIES} bodies")
        if not np.float64(1.0) / mass < np.inf:  # a subnormal mass: a = F / m would overflow
            table.fail(f"a body of mass {mass:.3g} kg has no finite inverse mass (the smallest mass is "
                       f"{1 / np.finfo(float).max:.3g} kg)", "mass")
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
            table.fail(f"body {name!r} would be placed at a non-finite position or velocity (the numbers "
                       "overflow)")
        self.index[name] = len(self.names)
        self.names.append(name)
        self.masses.append(mass)
        self.radii.append(radius)
        self.positions.append(position)
        self.velocities.append(velocity)
        self.pinned.append(pinned)

    def add_body(self, t: _Table):
        t.allow("name", "mass", "radius", "position", "velocity", "pinned", "material")
        velocity, pinned = t.vector("velocity", [0, 0, 0]), t.boolean("pinned")
        if pinned and np.any(velocity != 0):
            t.fail("a pinned body never moves, so it cannot have a velocity", "velocity")
        self._append(t, t.string("name", _REQUIRED), t.number("mass", _REQUIRED, positive=True),
                     t.number("radius", _REQUIRED, positive=True), t.vector("position", _REQUIRED),
                     velocity, pinned)

    def add_soft_body(self, t: _Table):
        t.allow("name", "shape", "size", "center", "rows", "cols", "spacing", "origin", "shear",
                "vertices", "edges", "connect", "mass", "radius", "stiffness", "damping",
                "velocity", "pinned", "material")
        name = t.string("name", _REQUIRED)
        shape = t.string("shape", _REQUIRED, choices=("box", "grid", "mesh"))
        if shape == "box":
            mesh = soft_body.box(t.vector("size", [1, 1, 1], positive=True), t.vector("center", [0, 0, 0]))
        elif shape == "grid":
            rows, cols = t.integer("rows", _REQUIRED, 1, 1000), t.integer("cols", _REQUIRED, 1, 1000)
            mesh = soft_body.grid(rows, cols, t.number("spacing", _REQUIRED, positive=True),
                                  t.vector("origin", [0, 0, 0]), t.boolean("shear", True))
        else:
            vertices = t.vectors("vertices")
            mesh = soft_body.Mesh(vertices, self._edges(t, len(vertices)))
        default_connect = "edges" if shape == "grid" else "all-pairs"
        connect = t.string("connect", default_connect, choices=("all-pairs", "edges"))
        n = len(mesh.vertices)
        if connect == "all-pairs":
            if n * (n - 1) // 2 > MAX_PAIRS:
                t.fail(f"{n} vertices give more than {MAX_PAIRS} all-pairs springs; use connect = \"edges\"")
            pairs = soft_body.all_pairs(n)
        else:
            if len(mesh.edges) == 0:
                t.fail("connect = \"edges\" needs edges", "edges")
            pairs = mesh.edges
        mass = t.number("mass", _REQUIRED, positive=True)
        radius = t.number("radius", 0.01, positive=True)
        velocity = t.vector("velocity", [0, 0, 0])
        pinned = set(self._indices(t, "pinned", n))
        offset = len(self.names)
        for k, vertex in enumerate(mesh.vertices):  # pinned vertices stay put: no velocity
            self._append(t, f"{name}[{k}]", mass / n, radius, vertex, 0 * velocity if k in pinned else velocity,
                         k in pinned)
        springs, dampers = soft_body.connect(mesh.vertices, pairs, t.number("stiffness", _REQUIRED, positive=True),
                                             t.number("damping", 0.0, nonnegative=True), offset)
        if not np.all(np.isfinite(springs.rest_length)):
            t.fail("vertices so far apart that a spring's rest length overflows")
        self.forces += [f for f in (springs, dampers) if f is not None]

    def _indices(self, t: _Table, key: str, n: int) -> list[int]:
        value = t.data.get(key, [])
        if not isinstance(value, list) or any(isinstance(k, bool) or not isinstance(k, int) for k in value):
            t.fail(f"must be a list of vertex indices, got {_short(value)}", key)
        bad = [k for k in value if not 0 <= k < n]
        if bad:
            t.fail(f"vertex index {bad[0]} out of range 0..{n - 1}", key)
        return value

    def _edges(self, t: _Table, n: int) -> np.ndarray:
        value = t.data.get("edges", [])
        if not isinstance(value, list) or any(
                not isinstance(e, list) or len(e) != 2 or any(isinstance(k, bool) or not isinstance(k, int) for k in e)
                for e in value):
            t.fail(f"must be a list of [i, j] vertex index pairs, got {_short(value)}", "edges")
        edges = np.array(value, dtype=np.int64).reshape(-1, 2)
        if edges.size and (edges.min() < 0 or edges.max() >= n):
            t.fail(f"vertex index out of range 0..{n - 1}", "edges")
        if np.any(edges[:, 0] == edges[:, 1]):
            t.fail("an edge joins a vertex to itself", "edges")
        return edges

    def add_particles(self, t: _Table):
        t.allow("name", "count", "seed", "mass", "radius", "box_min", "box_max", "speed", "material")
        name, count = t.string("name", _REQUIRED), t.integer("count", _REQUIRED, 1, MAX_BODIES)
        lo, hi = t.vector("box_min", _REQUIRED), t.vector("box_max", _REQUIRED)
        if not np.all(hi > lo):
            t.fail("must exceed box_min in every component", "box_max")
        if not np.all(np.isfinite(hi - lo)):  # the generator cannot draw from an infinitely wide box
            t.fail("box_max - box_min overflows: the box is wider than the largest float", "box_max")
        rng = np.random.default_rng(t.integer("seed", 0, 0, 2**63 - 1))
        mass, radius = t.number("mass", _REQUIRED, positive=True), t.number("radius", _REQUIRED, positive=True)
        speed = t.number("speed", 0.0, nonnegative=True)
        positions = rng.uniform(lo, hi, size=(count, 3))
        directions = rng.normal(size=(count, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        velocities = directions * speed * rng.uniform(size=(count, 1))
        for k in range(count):
            self._append(t, f"{name}[{k}]", mass, radius, positions[k], velocities[k])

    def _body_indices(self, t: _Table, key: str, required=True) -> list[int] | None:
        if key not in t.data and not required:
            return None
        value = t._get(key, _REQUIRED)
        if not isinstance(value, list) or any(not isinstance(b, str) for b in value):
            t.fail(f"must be a list of body names, got {_short(value)}", key)
        index = self.index
        unknown = [b for b in value if b not in index]
        if unknown:
            t.fail(f"names unknown body {unknown[0]!r}", key)
        return [index[b] for b in value]

    def _pair(self, t: _Table) -> tuple[int, int]:
        pair = self._body_indices(t, "bodies")
        if len(pair) != 2 or pair[0] == pair[1]:
            t.fail("must name two different bodies", "bodies")
        return pair[0], pair[1]

    def add_forces(self, forces: _Table):
        forces.allow("gravity", "central_gravity", "springs", "dampers", "drag", "friction")
        gravity = forces.table("gravity")
        if gravity is not None:
            gravity.allow("g")
            self.forces.append(Gravity(gravity.vector("g", list(EARTH_GRAVITY))))
        central = forces.table("central_gravity")
        if central is not None:
            central.allow("mu", "center")
            self.forces.append(CentralGravity(central.number("mu", _REQUIRED, positive=True),
                                              central.vector("center", [0.0, 0.0, 0.0])))
        springs = forces.tables("springs")
        if springs:
            q = np.array(self.positions)
            i, j, k, rest = [], [], [], []
            for s in springs:
                s.allow("bodies", "stiffness", "rest_length")
                a, b = self._pair(s)
                i.append(a)
                j.append(b)
                k.append(s.number("stiffness", _REQUIRED, positive=True))
                rest.append(s.number("rest_length", float(np.linalg.norm(q[b] - q[a])), nonnegative=True))
            self.forces.append(Springs(np.array(i), np.array(j), np.array(k), np.array(rest)))
        dampers = forces.tables("dampers")
        if dampers:
            i, j, c = [], [], []
            for d in dampers:
                d.allow("bodies", "damping")
                a, b = self._pair(d)
                i.append(a)
                j.append(b)
                c.append(d.number("damping", _REQUIRED, nonnegative=True))
            self.forces.append(Dampers(np.array(i), np.array(j), np.array(c)))
        drag = forces.table("drag")
        if drag is not None:
            drag.allow("density", "drag_coefficient", "bodies")
            chosen = self._body_indices(drag, "bodies", required=False)
            mask = None
            if chosen is not None:
                mask = np.zeros(len(self.names), bool)
                mask[chosen] = True
            self.forces.append(Drag.from_coefficients(
                self.radii, drag.number("density", AIR_DENSITY, positive=True),
                drag.number("drag_coefficient", 0.4, nonnegative=True), mask))
        friction = forces.table("friction")
        if friction is not None:
            friction.allow("mu_static", "mu_dynamic", "height", "normal")
            normal = _unit(friction, "normal", friction.vector("normal", [0, 0, 1]))
            mu_s = friction.number("mu_static", _REQUIRED, nonnegative=True)
            mu_d = friction.number("mu_dynamic", _REQUIRED, nonnegative=True)
            self.forces.append(Friction(mu_s, mu_d, normal, friction.number("height", 0.0),
                                        np.array(self.radii)))

    # --- collisions ----------------------------------------------------------------------

    def _material(self, t: _Table):
        """The collision material of the bodies a table just added."""
        material = t.string("material", DEFAULT_MATERIAL)
        self.materials += [material] * (len(self.names) - len(self.materials))

    def add_collisions(self, c: _Table):
        """The [collisions] table: detector, materials and static geometry (a CollisionWorld)."""
        from .broadphase import METHODS
        from .collision import world as collision_world
        from .collision.pairs import DEFAULT_BROADPHASE
        from .collision.response import PairProperties
        from .collision.shapes import Box, OrientedBox, Plane, rotation_matrix

        c.allow("detector", "restitution", "friction", "bisection_iterations", "max_impacts_per_step",
                "broadphase", "rest_speed", "materials", "planes", "boxes")
        detector = c.string("detector", "swept", choices=collision_world.DETECTOR_NAMES)
        restitution = self._restitution(c, "restitution", 1.0)
        friction = c.number("friction", 0.0, nonnegative=True)
        iterations = c.integer("bisection_iterations", collision_world.DEFAULT_BISECTION_ITERATIONS, 0, 60)
        max_impacts = c.integer("max_impacts_per_step", collision_world.DEFAULT_MAX_IMPACTS_PER_STEP, 1, 10**6)
        broadphase = c.string("broadphase", DEFAULT_BROADPHASE, choices=tuple(METHODS))
        rest_speed = c.number("rest_speed", collision_world.DEFAULT_REST_SPEED, nonnegative=True)

        shapes = []
        for p in c.tables("planes"):
            p.allow("name", "normal", "offset", "material", "trigger")
            normal = _unit(p, "normal", p.vector("normal", _REQUIRED))  # [1e200, 1e200, 0] too
            shapes.append((p, Plane(normal, p.number("offset", 0.0), p.string("name", f"plane[{len(shapes)}]"),
                                    p.string("material", DEFAULT_MATERIAL), p.boolean("trigger"))))
        for b in c.tables("boxes"):
            b.allow("name", "center", "size", "axis", "angle", "material", "trigger")
            center, size = b.vector("center", _REQUIRED), b.vector("size", _REQUIRED, positive=True)
            common = {"name": b.string("name", f"box[{len(shapes)}]"),
                      "material": b.string("material", DEFAULT_MATERIAL), "trigger": b.boolean("trigger")}
            angle = b.number("angle", 0.0)
            axis = _unit(b, "axis", b.vector("axis", [0, 0, 1]))
            if angle == 0.0:
                shapes.append((b, Box.from_center(center, size, **common)))
            else:
                shapes.append((b, OrientedBox(center, 0.5 * size, rotation_matrix(axis, angle), **common)))
        seen = set()
        for t, shape in shapes:
            if shape.name in seen:
                t.fail(f"duplicate shape name {shape.name!r}", "name")
            seen.add(shape.name)

        used = set(self.materials) | {shape.material for _, shape in shapes} | {DEFAULT_MATERIAL}
        table = {}
        for m in c.tables("materials"):
            m.allow("pair", "restitution", "friction")
            pair = m.data.get("pair")
            if (not isinstance(pair, list) or len(pair) != 2 or not all(isinstance(x, str) for x in pair)):
                m.fail(f"must be two material names [\"a\", \"b\"], got {_short(pair)}", "pair")
            unknown = [x for x in pair if x not in used]
            if unknown:
                m.fail(f"names material {unknown[0]!r}, which no body or shape has; materials: "
                       f"{', '.join(sorted(used))}", "pair")
            key = frozenset(pair)
            if key in table:
                m.fail(f"the pair {pair} is listed twice", "pair")
            table[key] = (self._restitution(m, "restitution", _REQUIRED),
                          m.number("friction", friction, nonnegative=True))
        materials = tuple(self.materials) if set(self.materials) != {DEFAULT_MATERIAL} else ()
        return collision_world.CollisionWorld(
            detector=detector, shapes=tuple(shape for _, shape in shapes), materials=materials,
            pair_properties=PairProperties(restitution, friction, table), bisection_iterations=iterations,
            max_impacts_per_step=max_impacts, broadphase=broadphase, rest_speed=rest_speed)

    @staticmethod
    def _restitution(t: _Table, key: str, default):
        value = t.number(key, default)
        if not 0 <= value <= 1:
            t.fail(f"must be between 0 and 1 (a coefficient of restitution), got {value:g}", key)
        return value
