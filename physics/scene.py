"""Scenes: TOML files declaring bodies, forces and the simulation settings.

The schema (see the documentation, docs/scenes.md) is checked strictly: an unknown key, a
wrong type, a non-finite number or a non-positive mass is an error naming the file and
the key, so a typo never silently changes a study. Built-in scenes ship in
``physics/scenes/`` and can be named without a path (``projectile``).

This module is the scene *builder*: bodies, soft bodies, particles and collisions, in
the order a reader meets them in a file. Reading the TOML strictly is
:mod:`.scene_toml`'s job; each force reads its own table (``Force.from_scene``), found
by its key in the registry :data:`.forces.FORCES`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from steplab.core.registry import BUILTIN

from . import constraints, rigid_body, soft_body, stacks
from .forces import FORCES
from .model import Model
from .rules import mass_problem, restitution_problem, short
from .scene_library import SCENES
from .scene_toml import MAX_BODIES as MAX_BODIES
from .scene_toml import MAX_PAIRS as MAX_PAIRS
from .scene_toml import MAX_SCENE_BYTES as MAX_SCENE_BYTES
from .scene_toml import REQUIRED, Table, read_toml
from .scene_toml import SceneError as SceneError

DEFAULT_MATERIAL = "default"  # as physics.collision.shapes.DEFAULT_MATERIAL

DEFAULT_INTEGRATOR = "semi-implicit-euler"


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
    #: the bodies that rotate (a physics.rigid_body.RigidBodies), or None: all point masses
    rigid_bodies: rigid_body.RigidBodies | None = None
    #: [simulation] rotation, the rotation method's name (None: steplab.integrators.DEFAULT_ROTATION)
    rotation: str | None = None
    #: the settings of ``integrator`` from its table [simulation.<integrator>] (``substeps = 4``),
    #: as read; the integrator checks them (:func:`steplab.integrators.settings.scene_integrator`)
    integrator_settings: dict = dataclasses.field(default_factory=dict)


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with steplab and with installed plugins (:data:`.scene_library.SCENES`)."""
    return sorted(SCENES)


def load_scene(scene: str | Path, collisions: bool = True) -> Scene:
    """Load a scene by name (steplab's or a plugin's) or by path to a TOML file.

    ``collisions=False`` leaves its [collisions] table unread (``Scene.collisions`` None): what
    a listing of scenes needs, without importing the compiled collision kernels."""
    path = Path(scene)
    if str(scene) in SCENES:
        text = SCENES[str(scene)].read_bytes()
        origin = SCENES.origin(str(scene))
        label = f"{scene} (built-in)" if origin == BUILTIN else f"{scene} (from {origin})"
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
    return parse_scene(text, label, name=name, collisions=collisions)


def parse_scene(text: bytes | str, label: str = "<scene>", name: str = "scene", collisions: bool = True) -> Scene:
    """Build a scene from TOML text; ``label`` names it in error messages (``collisions``: see load_scene)."""
    data = read_toml(text, label)
    with np.errstate(all="ignore"):  # every derived number is checked; no warnings on stderr
        return _SceneBuilder(label).build(data, name, collisions)


#: the keys that describe each shape of [[soft_bodies]] (the others are common to all)
SOFT_SHAPE_KEYS = {"box": ("size", "center"), "grid": ("rows", "cols", "spacing", "origin", "shear"),
                   "mesh": ("vertices", "edges")}


def _check_energy(root: Table, tables: list[Table], model: Model, y0: np.ndarray, rigid) -> None:
    """Refuse a start whose energy overflows float64: each number of the scene is finite, but a run
    would report its energy as inf J and the change as NaN (a mass of 1e300 kg at 1e5 m/s). The
    refusal names the body whose own term overflows, at its table (``tables``, one per body), or the
    force whose potential does; else (a sum of finite terms) only the file."""
    parts = {"kinetic energy, sum of m |v|^2 / 2,": model.kinetic_energy(y0[1]),
             "potential energy of the forces": model.potential_energy(y0[0])}
    if rigid is not None:
        parts["rotational kinetic energy, sum of omega . I omega / 2,"] = rigid.kinetic_energy()
    for what, value in [*parts.items(), ("mechanical energy", sum(parts.values()))]:
        if not np.isfinite(value):
            table, alone, key = _overflowing_term(what, root, tables, model, y0, rigid)
            table.fail(f"the initial {what} is {value} J, beyond float64{alone}: masses, speeds, spins or forces too "
                       "large (their product overflows)", key)


def _overflowing_term(what: str, root: Table, tables: list[Table], model: Model, y0: np.ndarray, rigid):
    """Where :func:`_check_energy` refuses the energy ``what``: (table, what to say of the culprit, key). The
    first body whose own term is not finite, at its table, or the force whose potential is not; else (a sum
    of finite terms) the file."""
    q, v = y0
    if what.startswith("potential"):  # the energy's forces: inextensible springs count 0 (as Model's)
        potentials = [(f, f.potential(np, q, model.masses)) for f in constraints.without_inextensible(model.forces)]
        bad = [f for f, u in potentials if u is not None and not np.isfinite(u)]
        return root, f" (forces.{bad[0].name}'s alone is)" if bad else "", None
    if what.startswith("kinetic"):
        key, terms, index = "velocity", 0.5 * np.asarray(model.masses) * np.sum(v * v, axis=1), None
    elif what.startswith("rotational"):
        key, index = "angular_velocity", rigid.index
        terms = rigid_body.rotational_energy(np, rigid.inertia, rigid.body_angular_velocities())
    else:
        return root, "", None
    bad = np.flatnonzero(~np.isfinite(terms))
    if not len(bad):
        return root, "", None
    k = int(bad[0] if index is None else index[bad[0]])
    # a group's bodies ([[particles]], a soft body, a stack) have no key of their own: the group's table
    return tables[k], f" (the term of body {model.names[k]!r} alone is)", key if key in tables[k].data else None


@dataclasses.dataclass(frozen=True)
class SceneBodies:
    """The bodies a scene declared, as the forces' ``from_scene`` reads them.

    Parameters
    ----------
    names : tuple of str
    masses, radii : ndarray, shape (N,)
        kg, m.
    positions : ndarray, shape (N, 3)
        Initial positions, m.
    pinned : bool ndarray, shape (N,)
    rotating : bool ndarray, shape (N,), optional
        The bodies that rotate (:mod:`.rigid_body`; None: none of them).
    orientations : ndarray, shape (N, 4), optional
        Initial orientations [w, x, y, z], the identity for a point mass.
    angular_velocities : ndarray, shape (N, 3), optional
        Initial angular velocities, world frame, rad/s (zero for a point mass).
    """

    names: tuple[str, ...]
    masses: np.ndarray
    radii: np.ndarray
    positions: np.ndarray
    pinned: np.ndarray
    #: body name -> index (a list lookup would be O(n^2) in total)
    index: dict[str, int] = dataclasses.field(repr=False, default_factory=dict)
    rotating: np.ndarray | None = None
    orientations: np.ndarray | None = None
    angular_velocities: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.names)

    def indices(self, t: Table, key: str, required: bool = True) -> list[int] | None:
        """The bodies a list of names ``key`` picks (None when absent and not required)."""
        if key not in t.data and not required:
            return None
        value = t.raw(key, REQUIRED)
        if not isinstance(value, list) or any(not isinstance(b, str) for b in value):
            t.fail(f"must be a list of body names, got {short(value)}", key)
        index = self.index
        unknown = [b for b in value if b not in index]
        if unknown:
            t.fail(f"names unknown body {unknown[0]!r}", key)
        return [index[b] for b in value]

    def pair(self, t: Table, key: str = "bodies") -> tuple[int, int]:
        """The two different bodies a list of two names ``key`` picks."""
        pair = self.indices(t, key)
        if len(pair) != 2 or pair[0] == pair[1]:
            t.fail("must name two different bodies", key)
        return pair[0], pair[1]

    def mask(self, t: Table, key: str) -> np.ndarray | None:
        """The bodies a list of names ``key`` picks as a bool mask (None, all bodies, when absent)."""
        chosen = self.indices(t, key, required=False)
        if chosen is None:
            return None
        mask = np.zeros(self.n, bool)
        mask[chosen] = True
        return mask


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
        self.tables: list = []  # each body's table (a soft body's or a stack's for theirs): where its keys are
        self.forces: list = []
        self.materials: list[str] = []
        self.rotating: list[tuple] = []  # (body index, shape, inertia, orientation, angular velocity)
        self.half: dict[int, np.ndarray] = {}  # body index -> a box's half edges, a capsule's (0, 0, l / 2)

    def build(self, data, name: str, collisions: bool = True) -> Scene:
        root = Table(data, "", self.label)
        root.allow("name", "description", "simulation", "bodies", "soft_bodies", "particles", "stacks", "forces",
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
        for stack in root.tables("stacks"):
            self.add_stack(stack)
            self._material(stack)
        if not self.names:
            root.fail("declares no bodies: add [[bodies]], [[soft_bodies]], [[particles]] or [[stacks]]")
        forces = root.table("forces")
        if forces is not None:
            self.add_forces(forces)

        integrator = sim.string("integrator", DEFAULT_INTEGRATOR)
        keys = ("integrator", "dt", "t_start", "t_end", "rotation")
        sim.allow(*keys, integrator)  # [simulation.<integrator>]: its settings
        settings = sim.table(integrator) if integrator not in keys else None
        rotation = sim.string("rotation") if "rotation" in sim.data else None
        dt = sim.number("dt", REQUIRED, positive=True)
        t_start = sim.number("t_start", 0.0)
        t_end = sim.number("t_end", REQUIRED)
        if not t_end > t_start:
            sim.fail(f"must be later than t_start = {t_start:g}, got {t_end:g}", "t_end")

        model = Model(np.array(self.masses), np.array(self.radii), self.forces,
                      pinned=np.array(self.pinned), names=self.names)
        y0 = np.stack([np.array(self.positions), np.array(self.velocities)])
        rigid = self.rigid_bodies()
        _check_energy(root, self.tables, model, y0, rigid)
        table = root.table("collisions") if collisions else None
        collisions = self.add_collisions(table, rotation) if table is not None else None
        return Scene(root.name("name", name), model, y0, integrator, dt, t_start, t_end,
                     root.string("description", ""), collisions, rigid, rotation,
                     {} if settings is None else dict(settings.data))

    def rigid_bodies(self) -> rigid_body.RigidBodies | None:
        if not self.rotating:
            return None
        index, shapes, inertia, orientations, angular_velocities = zip(*self.rotating)
        return rigid_body.RigidBodies(np.array(index), np.array(inertia), np.array(orientations),
                                      np.array(angular_velocities), shapes)

    def _append(self, table, name, mass, radius, position, velocity, pinned=False):
        if name in self.index:
            table.fail(f"duplicate body name {name!r}", "name")
        if len(self.names) >= MAX_BODIES:
            table.fail(f"more than {MAX_BODIES} bodies")
        problem = mass_problem(mass)  # a subnormal mass: a = F / m would overflow
        if problem:
            table.fail(problem, "mass")
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
            table.fail(f"body {name!r} would be placed at a non-finite position or velocity (the numbers "
                       "overflow)")
        self.index[name] = len(self.names)
        self.tables.append(table)
        self.names.append(name)
        self.masses.append(mass)
        self.radii.append(radius)
        self.positions.append(position)
        self.velocities.append(velocity)
        self.pinned.append(pinned)

    def add_body(self, t: Table):
        t.allow("name", "mass", "radius", "position", "velocity", "pinned", "material", *rigid_body.SCENE_KEYS)
        velocity, pinned = t.vector("velocity", [0, 0, 0]), t.boolean("pinned")
        if pinned and np.any(velocity != 0):
            t.fail("a pinned body never moves, so it cannot have a velocity", "velocity")
        name = t.name("name", REQUIRED)
        mass, radius = t.number("mass", REQUIRED, positive=True), t.number("radius", REQUIRED, positive=True)
        self._append(t, name, mass, radius, t.vector("position", REQUIRED), velocity, pinned)
        rotation = rigid_body.from_scene_body(t, mass, radius)
        if rotation is not None:
            self.rotating.append((len(self.names) - 1, *rotation))
            if rotation[0] == "box":
                self.half[len(self.names) - 1] = 0.5 * t.vector("size", REQUIRED)
            elif rotation[0] in ("capsule", "cylinder"):
                self.half[len(self.names) - 1] = np.array([0.0, 0.0, 0.5 * t.number("length", REQUIRED)])

    def add_soft_body(self, t: Table):
        t.allow("name", "shape", *(key for keys in SOFT_SHAPE_KEYS.values() for key in keys), "connect", "mass",
                "radius", "stiffness", "damping", "velocity", "pinned", "material")
        name = t.name("name", REQUIRED)
        shape = t.string("shape", REQUIRED, choices=tuple(SOFT_SHAPE_KEYS))
        for other, keys in SOFT_SHAPE_KEYS.items():  # a key of another shape would be ignored: refused
            for key in keys:
                if key in t.data and other != shape:
                    t.fail(f'belongs to a soft body of shape "{other}"; this one\'s shape is "{shape}" '
                           f"(its keys: {', '.join(SOFT_SHAPE_KEYS[shape])})", key)
        if shape == "box":
            mesh = soft_body.box(t.vector("size", [1, 1, 1], positive=True), t.vector("center", [0, 0, 0]))
        elif shape == "grid":
            rows, cols = t.integer("rows", REQUIRED, 1, 1000), t.integer("cols", REQUIRED, 1, 1000)
            mesh = soft_body.grid(rows, cols, t.number("spacing", REQUIRED, positive=True),
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
        mass = t.number("mass", REQUIRED, positive=True)
        radius = t.number("radius", 0.01, positive=True)
        velocity = t.vector("velocity", [0, 0, 0])
        pinned = set(self._indices(t, "pinned", n))
        offset = len(self.names)
        for k, vertex in enumerate(mesh.vertices):  # pinned vertices stay put: no velocity
            self._append(t, f"{name}[{k}]", mass / n, radius, vertex, 0 * velocity if k in pinned else velocity,
                         k in pinned)
        stiffness, damping = self._stiffness(t), t.number("damping", 0.0, nonnegative=True)
        try:  # Springs refuses a non-finite rest length: vertices so far apart that it overflows
            springs, dampers = soft_body.connect(mesh.vertices, pairs, stiffness, damping, offset)
        except ValueError as err:
            if "rest_length must be finite" not in str(err):
                raise
            t.fail("vertices so far apart that a spring's rest length overflows")
        self.forces += [f for f in (springs, dampers) if f is not None]

    @staticmethod
    def _stiffness(t: Table) -> float:
        """k, N/m, > 0; ``inf``: inextensible springs, which only position-based integrators step."""
        if t.data.get("stiffness") == float("inf"):
            return float("inf")
        return t.number("stiffness", REQUIRED, positive=True)

    def _indices(self, t: Table, key: str, n: int) -> list[int]:
        value = t.data.get(key, [])
        if not isinstance(value, list) or any(isinstance(k, bool) or not isinstance(k, int) for k in value):
            t.fail(f"must be a list of vertex indices, got {short(value)}", key)
        bad = [k for k in value if not 0 <= k < n]
        if bad:
            t.fail(f"vertex index {bad[0]} out of range 0..{n - 1}", key)
        return value

    def _edges(self, t: Table, n: int) -> np.ndarray:
        value = t.data.get("edges", [])
        if not isinstance(value, list) or any(
                not isinstance(e, list) or len(e) != 2 or any(isinstance(k, bool) or not isinstance(k, int) for k in e)
                for e in value):
            t.fail(f"must be a list of [i, j] vertex index pairs, got {short(value)}", "edges")
        bad = [k for e in value for k in e if not 0 <= k < n]  # in Python: an index past int64 is one line too
        if bad:
            t.fail(f"vertex index {bad[0]} out of range 0..{n - 1}", "edges")
        edges = np.array(value, dtype=np.int64).reshape(-1, 2)
        if np.any(edges[:, 0] == edges[:, 1]):
            t.fail("an edge joins a vertex to itself", "edges")
        return edges

    def add_particles(self, t: Table):
        t.allow("name", "count", "seed", "mass", "radius", "box_min", "box_max", "speed", "material")
        name, count = t.name("name", REQUIRED), t.integer("count", REQUIRED, 1, MAX_BODIES)
        lo, hi = t.vector("box_min", REQUIRED), t.vector("box_max", REQUIRED)
        if not np.all(hi > lo):
            t.fail("must exceed box_min in every component", "box_max")
        if not np.all(np.isfinite(hi - lo)):  # the generator cannot draw from an infinitely wide box
            t.fail("box_max - box_min overflows: the box is wider than the largest float", "box_max")
        rng = np.random.default_rng(t.integer("seed", 0, 0, 2**63 - 1))
        mass, radius = t.number("mass", REQUIRED, positive=True), t.number("radius", REQUIRED, positive=True)
        speed = t.number("speed", 0.0, nonnegative=True)
        positions = rng.uniform(lo, hi, size=(count, 3))
        directions = rng.normal(size=(count, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        velocities = directions * speed * rng.uniform(size=(count, 1))
        for k in range(count):
            self._append(t, f"{name}[{k}]", mass, radius, positions[k], velocities[k])

    def add_stack(self, t: Table):
        """A column or pyramid of boxes "name[0]", "name[1]", ... bottom row first (:mod:`.stacks`):
        each a rotating box of ``size``, at rest, its radius the half diagonal (the sphere
        that bounds it), its mass ``mass`` or, row by row from the bottom, ``masses``."""
        t.allow("name", "kind", "rows", "size", "mass", "masses", "gap", "base", "material")
        name, kind = t.name("name", REQUIRED), t.string("kind", REQUIRED, choices=stacks.KINDS)
        rows = t.integer("rows", REQUIRED, 1, 1000)
        size = t.vector("size", REQUIRED, positive=True)
        if ("mass" in t.data) == ("masses" in t.data):
            t.fail("needs either mass (every box) or masses (one per row, bottom up), not both" if "mass" in t.data
                   else "missing required key mass (every box) or masses (one per row, bottom up)")
        if "mass" in t.data:
            row_masses = [t.number("mass", REQUIRED, positive=True)] * rows
        else:
            value = t.raw("masses")
            if not isinstance(value, list) or len(value) != rows:
                t.fail(f"must be a list of {rows} masses, one per row bottom up, got {short(value)}", "masses")
            row_masses = [Table({f"[{k}]": m}, f"{t.where}.masses", self.label).number(f"[{k}]", positive=True)
                          for k, m in enumerate(value)]
        gap, base = t.number("gap", 0.0, nonnegative=True), t.vector("base", [0, 0, 0])
        centres, row = stacks.stack_layout(kind, rows, size, gap, base)
        radius = 0.5 * float(np.hypot(np.hypot(size[0], size[1]), size[2]))  # hypot: no overflow on the way
        if not np.isfinite(radius):
            t.fail(f"a box of edges {size.tolist()} m has no finite half diagonal (the numbers overflow)", "size")
        for k, (centre, r) in enumerate(zip(centres, row)):
            mass = row_masses[r]
            self._append(t, f"{name}[{k}]", mass, radius, centre, np.zeros(3))
            inertia = rigid_body.principal_inertia("box", mass, radius, size)
            problem = rigid_body.shape_inertia_problem("box", inertia)
            if problem:
                t.fail(problem, "size")
            self.rotating.append((len(self.names) - 1, "box", inertia, np.array([1.0, 0, 0, 0]), np.zeros(3)))
            self.half[len(self.names) - 1] = 0.5 * size

    def bodies(self) -> SceneBodies:
        """The bodies declared so far, for the forces' tables."""
        n = len(self.names)
        rotating, orientations, angular_velocities = np.zeros(n, bool), np.zeros((n, 4)), np.zeros((n, 3))
        orientations[:, 0] = 1.0  # a point mass keeps the identity
        for k, _, _, orientation, angular_velocity in self.rotating:
            rotating[k], orientations[k], angular_velocities[k] = True, orientation, angular_velocity
        return SceneBodies(tuple(self.names), np.array(self.masses), np.array(self.radii),
                           np.array(self.positions).reshape(-1, 3), np.array(self.pinned), self.index,
                           rotating, orientations, angular_velocities)

    def add_forces(self, forces: Table):
        """The [forces] table: each key is a registered force, which reads its own table.

        Forces are added in the file's order (the model sums them in that order).
        """
        forces.allow(*sorted(FORCES))
        bodies = self.bodies()
        for key in forces.data:
            cls = FORCES[key]
            if cls.array_of_tables:
                table = forces.tables(key)
                if not table:  # an empty array declares nothing
                    continue
            else:
                table = forces.table(key)
            self.forces.append(cls.from_scene(table, bodies))

    # --- collisions ----------------------------------------------------------------------

    def _material(self, t: Table):
        """The collision material of the bodies a table just added."""
        material = t.string("material", DEFAULT_MATERIAL)
        self.materials += [material] * (len(self.names) - len(self.materials))

    def rigid_scene(self, c: Table, method: str, rotation: str | None):
        """The rotating bodies' shapes and state for the contact solver (None: all point masses)."""
        bodies = self.rigid_bodies()
        if bodies is None:
            return None
        from .collision.rigid_solver_step import DEFAULT_ROTATION, KINDS, RigidScene

        if method == "solver" and "cylinder" in bodies.shapes:
            c.fail('the contact solver has no manifold for a cylinder; give the body shape = "capsule"', "method")
        kind = np.zeros(len(self.names), np.int8)
        kind[bodies.index] = [KINDS.get(shape, -1) for shape in bodies.shapes]
        half = np.zeros((len(self.names), 3))
        for body, extent in self.half.items():
            half[body] = extent
        radius = np.where(kind == KINDS["box"], 0.0, np.array(self.radii))  # a box is its half edges
        return RigidScene(kind, radius, half, bodies, rotation or DEFAULT_ROTATION)

    def add_collisions(self, c: Table, rotation: str | None = None):
        """The [collisions] table: detector, materials and static geometry (a CollisionWorld)."""
        from .broadphase import METHODS
        from .broadphase.common import MAX_COORDINATE
        from .collision import world as collision_world
        from .collision.detectors import DETECTORS
        from .collision.methods import COLLISION_METHODS
        from .collision.pairs import DEFAULT_BROADPHASE
        from .collision.response import PairProperties
        from .collision.shapes import Box, OrientedBox, Plane, rotation_matrix

        # each collision method reads its own settings table, [collisions.<method>]
        c.allow("detector", "restitution", "friction", "bisection_iterations", "max_impacts_per_step",
                "broadphase", "rest_speed", "materials", "planes", "boxes", "method", *COLLISION_METHODS)
        detector = c.string("detector", "swept", choices=tuple(DETECTORS))
        method = c.string("method", "event", choices=tuple(COLLISION_METHODS))
        for other in COLLISION_METHODS:
            if other != method and other in c.data:
                c.table(other).fail(f'sets the collision method {other!r}, but the method is not "{other}" '
                                    f'(add method = "{other}")')
        method_fields = COLLISION_METHODS[method].from_scene(c.table(method))
        restitution = self._restitution(c, "restitution", 1.0)
        friction = c.number("friction", 0.0, nonnegative=True)
        iterations = c.integer("bisection_iterations", collision_world.DEFAULT_BISECTION_ITERATIONS, 0,
                               collision_world.MAX_BISECTION_ITERATIONS)
        max_impacts = (c.integer("max_impacts_per_step", None, 1, collision_world.MAX_IMPACTS_PER_STEP)
                       if "max_impacts_per_step" in c.data
                       else collision_world.DEFAULT_MAX_IMPACTS_PER_STEP)  # None: scaled with the bodies
        broadphase = c.string("broadphase", DEFAULT_BROADPHASE, choices=tuple(METHODS))
        rest_speed = c.number("rest_speed", collision_world.DEFAULT_REST_SPEED, nonnegative=True)

        for k, (radius, position) in enumerate(zip(self.radii, self.positions)):
            # the broadphase squares distances: beyond MAX_COORDINATE they overflow (it would refuse mid-run,
            # naming no file, or a run would "diverge" at its first step)
            for key, size in (("radius", radius), ("position", float(np.max(np.abs(position))))):
                if size > MAX_COORDINATE:  # the key where the body's table has it (a group's bodies: the group's)
                    self.tables[k].fail(f"body {self.names[k]!r}: a {key} of {size:g} m in a scene with [collisions]; "
                                        f"at most {MAX_COORDINATE:g} m (squared distances would overflow)",
                                        key if key in self.tables[k].data else None)
        shapes = []
        for p in c.tables("planes"):
            p.allow("name", "normal", "offset", "material", "trigger")
            normal = p.direction("normal", REQUIRED)  # [1e200, 1e200, 0] too
            shapes.append((p, Plane(normal, p.number("offset", 0.0), p.name("name", f"plane[{len(shapes)}]"),
                                    p.string("material", DEFAULT_MATERIAL), p.boolean("trigger"))))
        for b in c.tables("boxes"):
            b.allow("name", "center", "size", "axis", "angle", "material", "trigger")
            center, size = b.vector("center", REQUIRED), b.vector("size", REQUIRED, positive=True)
            common = {"name": b.name("name", f"box[{len(shapes)}]"),
                      "material": b.string("material", DEFAULT_MATERIAL), "trigger": b.boolean("trigger")}
            angle = b.number("angle", 0.0)
            axis = b.direction("axis", [0, 0, 1])
            # what Box (lo < hi, finite) and OrientedBox (size / 2 > 0) refuse, said of this file's key
            lo, hi = center - 0.5 * size, center + 0.5 * size
            if not (np.all(0.5 * size > 0) if angle != 0.0 else np.all(np.isfinite(lo) & np.isfinite(hi) & (hi > lo))):
                b.fail(f"gives a box float64 cannot represent at center {short(center.tolist())}: its faces, "
                       f"center -/+ size / 2, are {short(lo.tolist())} and {short(hi.tolist())}", "size")
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
                m.fail(f"must be two material names [\"a\", \"b\"], got {short(pair)}", "pair")
            unknown = [x for x in pair if x not in used]
            if unknown:
                m.fail(f"names material {unknown[0]!r}, which no body or shape has; materials: "
                       f"{', '.join(sorted(used))}", "pair")
            key = frozenset(pair)
            if key in table:
                m.fail(f"the pair {pair} is listed twice", "pair")
            table[key] = (self._restitution(m, "restitution", REQUIRED),
                          m.number("friction", friction, nonnegative=True))
        materials = tuple(self.materials) if set(self.materials) != {DEFAULT_MATERIAL} else ()
        return collision_world.CollisionWorld(
            detector=detector, shapes=tuple(shape for _, shape in shapes), materials=materials,
            pair_properties=PairProperties(restitution, friction, table), bisection_iterations=iterations,
            max_impacts_per_step=max_impacts, broadphase=broadphase, rest_speed=rest_speed, method=method,
            rigid=self.rigid_scene(c, method, rotation), **method_fields)

    @staticmethod
    def _restitution(t: Table, key: str, default):
        value = t.number(key, default)
        problem = restitution_problem(value)
        if problem:
            t.fail(problem, key)
        return value
