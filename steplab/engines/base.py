"""What every engine adapter shares: the scene it is built from, its errors and its run loop.

An adapter turns a steplab scene (a :class:`steplab.physics.Model`, optionally a
:class:`steplab.physics.collision.CollisionWorld`) into the engine's own bodies, forces and
shapes, and is then a *system under test*: ``advance(y0, dt, n_steps)`` puts the bodies at
``y0`` (positions and velocities, shape (2, N, 3)), takes ``n_steps`` engine steps of
``dt`` and returns a steplab :class:`~steplab.integrators.Trajectory`, with a collision log
of the contacts the engine reports. The studies measure it by the same code as steplab's
own integrators (:mod:`steplab.studies.system`).

What a scene holds that an engine cannot express raises :class:`UnsupportedFeatureError`,
one line naming the feature and the engine, before anything is built.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import importlib.util
import inspect
import math
import time
from typing import ClassVar

import numpy as np

from steplab.integrators.base import check_count, check_real
from steplab.integrators.scene_rotation import RotationTrajectory
from steplab.integrators.simulate import (
    ANY_COUNT,
    MAX_STEPS,
    DivergenceError,
    Trajectory,
    divergence_limit,
    saved_steps,
)
from steplab.physics import Dampers, Gravity, Springs
from steplab.physics.collision import Box, Collision, CollisionLog, OrientedBox, Plane
from steplab.physics.rigid_body import RigidBodies, principal_inertia

#: approach speed recorded for a contact that began in a step, when the engine does not say
UNKNOWN = float("nan")


class UnsupportedFeatureError(ValueError):
    """A scene feature an engine has no counterpart for (one line: the feature and the engine)."""


class EngineNotInstalledError(ImportError):
    """The engine's Python package is not installed (the line says how to install it)."""


def require(package: str, engine: str):
    """Import ``package`` for ``engine``, or EngineNotInstalledError saying how to install it.

    File descriptors 1 and 2 go to /dev/null during the import: pybullet's C code prints
    its build time when it loads (on stderr, as of pybullet 3.2), which would land in the
    middle of a command's output. Python reports a failed import by exception, not there.
    """
    import ctypes
    import importlib
    import os
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in (1, 2)]
    try:
        with open(os.devnull, "wb") as null:
            for fd in (1, 2):
                os.dup2(null.fileno(), fd)
        return importlib.import_module(package)
    except ImportError:
        raise EngineNotInstalledError(
            f"{engine} needs the Python package {package!r}, which is not installed "
            '(pip install -e ".[engines]")') from None
    finally:
        ctypes.CDLL(None).fflush(None)  # what C's stdio buffered goes to /dev/null too, not out later
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


def version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


@dataclasses.dataclass(frozen=True)
class SceneParts:
    """A scene as an adapter reads it: bodies, the forces split by kind, static shapes.

    ``springs`` and ``dampers`` are lists of (i, j, stiffness, rest_length, damping):
    a spring and a damper on the same pair are one element (an engine's spring-damper).
    """

    masses: np.ndarray
    radii: np.ndarray
    pinned: np.ndarray
    names: tuple[str, ...]
    gravity: np.ndarray
    links: list[tuple[int, int, float, float | None, float]]
    collisions: object  # a CollisionWorld with a detector other than "none", or None

    @property
    def n(self) -> int:
        return len(self.masses)

    @property
    def shapes(self):
        return () if self.collisions is None else self.collisions.shapes

    def restitution(self, body: int, other) -> float:
        return self.collisions.properties(body, other)[0]

    def friction(self, body: int, other) -> float:
        return self.collisions.properties(body, other)[1]

    def against_shapes(self, body: int) -> tuple[float, float]:
        """(restitution, friction) of ``body`` against the static shapes (the first one's), or
        against another body where there are no shapes."""
        if self.collisions is None:
            return 0.0, 0.0
        other = self.shapes[0] if self.shapes else body
        return self.collisions.properties(body, other)


def scene_parts(model, collisions, engine: str, forces=(Gravity, Springs, Dampers),
                shapes=(Plane, Box, OrientedBox)) -> SceneParts:
    """Read ``model`` and ``collisions`` for ``engine``: UnsupportedFeatureError for a force
    class outside ``forces``, a shape outside ``shapes``, a trigger shape."""
    gravity = np.zeros(3)
    links: dict[tuple[int, int], list] = {}
    for force in model._source_forces:
        if not isinstance(force, forces):
            raise UnsupportedFeatureError(f"the {force.name} force has no counterpart in {engine} "
                                          f"(it expresses: {', '.join(f.name for f in forces)})")
        if isinstance(force, Gravity):
            gravity = gravity + np.asarray(force.g, dtype=float)
        elif isinstance(force, Springs):
            for i, j, k, rest in zip(force.i, force.j, force.stiffness, force.rest_length):
                entry = links.setdefault((int(i), int(j)), [0.0, None, 0.0])
                if entry[1] is not None:
                    raise UnsupportedFeatureError(f"two springs on one pair of bodies ({model.names[i]}, "
                                                  f"{model.names[j]}): {engine} gets one spring-damper per pair")
                if not np.isfinite(k):
                    raise UnsupportedFeatureError(f"the inextensible spring (stiffness = inf) between "
                                                  f"{model.names[i]} and {model.names[j]}: {engine} gets springs "
                                                  "of finite stiffness (the position-based integrators take it)")
                entry[0], entry[1] = float(k), float(rest)
        else:
            for i, j, c in zip(force.i, force.j, force.damping):
                links.setdefault((int(i), int(j)), [0.0, None, 0.0])[2] += float(c)
    if collisions is not None and collisions.detector == "none":
        collisions = None
    if collisions is not None:
        for shape in collisions.shapes:
            if shape.trigger:
                raise UnsupportedFeatureError(f"trigger shape {shape.name!r}: the {engine} adapter has no "
                                              "trigger volumes")
            if not isinstance(shape, shapes):
                raise UnsupportedFeatureError(f"shape {shape.name!r} ({shape.kind}) has no counterpart in {engine}")
    pinned = np.asarray(model.pinned, bool)
    return SceneParts(np.asarray(model.masses, float), np.asarray(model.radii, float), pinned,
                      tuple(model.names), gravity, [(i, j, *v) for (i, j), v in links.items()], collisions)


def plane_axes(parts: SceneParts, y0, engine: str) -> tuple[int, int]:
    """The two world axes a 2-D engine simulates in, for a scene that stays in a plane.

    The dropped axis is the first of z, y, x along which every body starts at the same
    coordinate at rest and gravity is zero (the drop test, in x-z; the oscillator, in x-y);
    a plane's normal and an oriented box's turn must then lie in the other two.
    UnsupportedFeatureError for a 3-D scene.
    """
    q, v = np.asarray(y0[0], float), np.asarray(y0[1], float)
    for drop in (2, 1, 0):
        if np.ptp(q[:, drop]) == 0 and not np.any(v[:, drop]) and parts.gravity[drop] == 0:
            break
    else:
        raise UnsupportedFeatureError(f"a 3-D scene: {engine} simulates bodies in a plane, and these bodies "
                                      "do not start in one plane at rest across it")
    axes = tuple(k for k in range(3) if k != drop)
    for shape in parts.shapes:
        if isinstance(shape, Plane) and shape.normal[drop] != 0:
            raise UnsupportedFeatureError(f"plane {shape.name!r} is tilted out of the bodies' plane: {engine} is 2-D")
        if isinstance(shape, OrientedBox) and (abs(abs(shape.rotation[drop, drop]) - 1) > 1e-12):
            raise UnsupportedFeatureError(f"oriented box {shape.name!r} is turned out of the bodies' plane: "
                                          f"{engine} is 2-D")
        if isinstance(shape, Box) and not shape.lo[drop] <= q[0, drop] <= shape.hi[drop]:
            raise UnsupportedFeatureError(f"box {shape.name!r} does not reach the bodies' plane")
    return axes


#: m, the least half extent of a rotating body's engine shape (MuJoCo and Bullet need sizes > 0)
SMALLEST_EXTENT = 1e-6


@dataclasses.dataclass(frozen=True)
class RigidShape:
    """One rotating body as an engine builds it: its shape, mass, principal moments and extent.

    ``half_extents`` are the box's half edges; for a capsule or cylinder (r, r, half its
    length along the body z axis: the capsule's cylindrical part, as MuJoCo and Bullet
    define it); for a sphere (r, r, r). ``body`` is its index among the scene's bodies.
    """

    body: int
    shape: str
    mass: float
    inertia: np.ndarray
    half_extents: np.ndarray

    @property
    def radius(self) -> float:
        return float(self.half_extents[0])


def rigid_shapes(model, bodies: RigidBodies | None, collisions=None) -> tuple[RigidShape, ...]:
    """The rotating bodies of a scene with their extents, for the engines' collision shapes.

    A scene with collisions keeps each box's half edges and each capsule's half length
    (``collisions.rigid``, the contact solver's :class:`RigidScene`); otherwise they follow from
    the principal moments: a box's edges are those of the uniform box with these moments,
    inverted from m/12 (b^2 + c^2, ...), a^2 = 6 (I2 + I3 - I1) / m; a cylinder's length from
    I1 = m/12 (3 r^2 + l^2); a capsule's by bisection on its (monotone) I1(l). (The engine gets
    the moments themselves either way.) An extent that comes out zero (a thin plate's edge) is
    :data:`SMALLEST_EXTENT`: the engines refuse a shape of size 0.
    """
    if bodies is None:
        return ()
    given = getattr(collisions, "rigid", None)
    out = []
    for k, (i, shape) in enumerate(zip(bodies.index, bodies.shapes or ("sphere",) * bodies.n)):
        m, r, inertia = float(model.masses[i]), float(model.radii[i]), np.asarray(bodies.inertia[k], float)
        known = None if given is None else np.asarray(given.half[i], float)
        if shape == "box":
            half = known if known is not None and np.all(known > 0) else \
                0.5 * np.sqrt(np.maximum(6.0 * (inertia.sum() - 2 * inertia) / m, 0.0))
        elif shape in ("cylinder", "capsule"):
            if known is not None and known[2] > 0:
                length = 2 * known[2]
            elif shape == "cylinder":
                length = math.sqrt(max(12.0 * inertia[0] / m - 3 * r * r, 0.0))
            else:
                length = _capsule_length(m, r, inertia[0])
            half = np.array([r, r, 0.5 * length])
        else:
            half = np.full(3, r)
        if not np.all(np.isfinite(half)):
            raise UnsupportedFeatureError(f"body {model.names[i]!r}: the {shape} of mass {m:g} kg with moments "
                                          f"{inertia.tolist()} kg m^2 has edges beyond float64 (the engines get "
                                          "its extents from its moments)")
        out.append(RigidShape(int(i), shape, m, inertia, np.maximum(half, SMALLEST_EXTENT)))
    return tuple(out)


def _capsule_length(mass: float, radius: float, across: float) -> float:
    """The cylindrical length l of a capsule of ``mass`` and ``radius`` whose I1 is ``across``."""
    from scipy.optimize import brentq

    def excess(length):
        return principal_inertia("capsule", mass, radius, length=length)[0] - across

    if excess(0.0) >= 0:
        return 0.0
    hi = 1.0 + radius
    while excess(hi) < 0:
        hi *= 2
    return float(brentq(excess, 0.0, hi, xtol=1e-15 * hi, rtol=4 * np.finfo(float).eps))


def planar_rotation(axes: tuple[int, int], shape: RigidShape, q, omega, engine: str) -> tuple[float, float, float]:
    """(angle, spin, moment) of a body of a 2-D engine: a turn and a spin about the dropped axis.

    The engine's counter-clockwise angle turns its x (steplab's ``axes[0]``) towards its y
    (``axes[1]``): about +e_d when (axes[0], axes[1], d) is right-handed (d = 2 or 0),
    about -e_d otherwise (d = 1). UnsupportedFeatureError for an orientation or an angular
    velocity off that axis (a 3-D tumble).
    """
    drop = 3 - sum(axes)
    sign = -1.0 if drop == 1 else 1.0
    q, omega = np.asarray(q, float), np.asarray(omega, float)
    if np.any(q[[1 + k for k in axes]] != 0) or np.any(omega[list(axes)] != 0):
        raise UnsupportedFeatureError(f"body {shape.body}: a 3-D orientation or spin; {engine} turns bodies "
                                      f"only about the axis out of its plane ({'xyz'[drop]})")
    return sign * 2.0 * math.atan2(q[1 + drop], q[0]), sign * float(omega[drop]), float(shape.inertia[drop])


def planar_orientation(axes: tuple[int, int], angle: float, spin: float) -> tuple[np.ndarray, np.ndarray]:
    """The quaternion [w, x, y, z] and world angular velocity of a 2-D engine's (angle, spin)."""
    drop = 3 - sum(axes)
    sign = -1.0 if drop == 1 else 1.0
    q, omega = np.zeros(4), np.zeros(3)
    q[0], q[1 + drop] = math.cos(0.5 * angle), sign * math.sin(0.5 * angle)
    omega[drop] = sign * spin
    return q, omega


@dataclasses.dataclass(frozen=True)
class Setting:
    """One engine in one configuration, as the engines study measures it.

    ``options`` are the adapter's keyword arguments; ``continuous`` whether the setting
    detects collisions continuously (None: the engine has no such switch); ``equals`` the
    steplab method it is expected to step (the identification's finding, which
    tests/test_engines.py checks, and by which it knows the free-fall lead); ``deviation`` why its bounce in the
    drop test is not the lecture's eps^2. ``engine`` and ``adapter`` are filled in by the
    adapter class that lists the setting.
    """

    key: str
    label: str
    options: dict = dataclasses.field(default_factory=dict)
    continuous: bool | None = None
    equals: str | None = None
    deviation: str | None = None
    engine: str = ""
    adapter: type | None = None

    def build(self, model, collisions=None, dt: float = 0.01, y0=None, bodies=None) -> EngineRun:
        return build_adapter(self.adapter, model, collisions, dt, y0, bodies=bodies, **self.options)

    @property
    def available(self) -> bool:
        return self.adapter.available()


class EngineRun:
    """One engine set up on one scene: a system under test.

    An adapter declares its engine's facts as class data: ``engine`` (its registry key),
    ``display_name`` (for figures), ``colour`` (its figures' colour), ``planar`` (a 2-D
    engine, bodies in a plane), ``precision`` (its float type, "float64" or "float32"),
    ``package`` and ``distribution`` (the Python package it imports and its name on PyPI;
    None: it needs none), ``contacts`` (whether it expresses collisions), ``study_settings``
    (the :class:`Setting` tuple the engines study measures), ``rotation_settings`` (those the
    rotation study measures on a free rigid body: ``equals`` is the steplab *rotation* method
    each is expected to step, None for none, and ``deviation`` says what the engine does to the
    rotation) and ``stack_settings`` (:mod:`.stacks`: the engine's defaults first, then its
    documented tuned settings, each ``deviation`` saying what it changes and why).
    Instances set ``settings`` (a line saying how the run is set up) and
    implement ``set_state(y)``, ``step(dt)``, ``state() -> y`` and, where the engine reports
    contacts, ``touching() -> {(body, other): normal}`` (``other`` a body index or a shape's name).
    """

    engine: ClassVar[str] = "engine"
    display_name: ClassVar[str] = ""
    colour: ClassVar[str] = "tab:gray"
    planar: ClassVar[bool] = False
    precision: ClassVar[str] = "float64"
    package: ClassVar[str | None] = None
    distribution: ClassVar[str | None] = None
    study_settings: ClassVar[tuple[Setting, ...]] = ()
    rotation_settings: ClassVar[tuple[Setting, ...]] = ()
    stack_settings: ClassVar[tuple[Setting, ...]] = ()
    #: whether the adapter expresses a scene's collisions; the engines study, whose measurements
    #: are contacts (drops, tunnelling, ball pits), measures only those that do
    contacts: ClassVar[bool] = True
    settings: str = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        # each setting names its adapter: one table of facts per engine, kept in its adapter
        for kind in ("study_settings", "rotation_settings", "stack_settings"):
            setattr(cls, kind, tuple(dataclasses.replace(s, engine=cls.engine, adapter=cls)
                                     for s in cls.__dict__.get(kind, ())))

    @classmethod
    def available(cls) -> bool:
        """Whether the engine's Python package is installed (without importing it)."""
        return cls.package is None or importlib.util.find_spec(cls.package) is not None

    def __init__(self, parts: SceneParts, model=None, bodies: RigidBodies | None = None):
        self.parts = parts
        self._pinned_y = None
        self.rigid_bodies = bodies
        self.rigid = rigid_shapes(model, bodies, parts.collisions)

    @property
    def name(self) -> str:
        return self.settings or self.engine

    def set_state(self, y) -> None:
        raise NotImplementedError

    def step(self, dt: float) -> None:
        raise NotImplementedError

    def state(self) -> np.ndarray:
        raise NotImplementedError

    def touching(self) -> dict:
        return {}

    def set_rotation(self, orientations, angular_velocities) -> None:
        raise NotImplementedError

    def rotation(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def close(self) -> None:
        """Release what the engine holds outside Python (a pybullet connection)."""

    def _rebuild(self) -> None:
        """Set the engine up again from the scene (:func:`steplab.engines.build` records how)."""
        rebuild = getattr(self, "rebuild", None)
        if rebuild is not None:
            self.close()
            rebuild(self)

    def advance(self, y0, dt: float, n_steps: int, t_start: float = 0.0, save_every: int = 1,
                log_contacts: bool | None = None) -> Trajectory:
        """Put the bodies at ``y0``, take ``n_steps`` steps of ``dt``, return the trajectory.

        The trajectory keeps every ``save_every``-th state (and the last); its collision log
        holds one ``"contact"`` event per pair that began to touch in a step, at the step's
        end (``log_contacts``: default, when the scene has collisions). DivergenceError when
        the state becomes non-finite or absurdly large, as for steplab's own integrators.
        The rotating bodies start from their ``bodies`` state (:meth:`advance_rotating`
        returns their trajectory too).
        """
        return self.advance_rotating(y0, dt, n_steps, t_start, save_every, log_contacts)[0]

    def advance_rotating(self, y0, dt: float, n_steps: int, t_start: float = 0.0, save_every: int = 1,
                         log_contacts: bool | None = None) -> tuple[Trajectory, RotationTrajectory | None]:
        """:meth:`advance`, and the rotating bodies at the same saved times (None: the adapter was
        built without ``bodies``): orientations and world-frame angular velocities as the engine
        reports them. DivergenceError also when an angular velocity becomes non-finite or absurd."""
        y0 = np.asarray(y0, dtype=float)
        if y0.shape != (2, self.parts.n, 3):
            raise ValueError(f"{self.name}: y0 must have shape (2, {self.parts.n}, 3) (positions and velocities "
                             f"of the scene's bodies), got {y0.shape}")
        check_count(self.name, "n_steps", n_steps, MAX_STEPS, "steplab.integrators.simulate.MAX_STEPS")
        check_count(self.name, "save_every", save_every, ANY_COUNT, "a 64-bit integer")
        check_real(self.name, "dt", dt, lambda h: h > 0, "a step > 0 s")
        log_contacts = self.parts.collisions is not None if log_contacts is None else log_contacts
        saves = saved_steps(n_steps, save_every)
        out = np.empty((len(saves),) + y0.shape)
        out[0] = y0
        saved, limit = 1, divergence_limit(y0, np.float64)
        log = CollisionLog() if log_contacts else None
        touching: dict = {}
        self.set_state(y0)
        bodies = self.rigid_bodies if self.rigid else None
        if bodies is not None:
            self.set_rotation(bodies.orientations, bodies.angular_velocities)
            turns = np.empty((len(saves), bodies.n, 4))
            spins = np.empty((len(saves), bodies.n, 3))
            turns[0], spins[0] = bodies.orientations, bodies.angular_velocities
            spin_limit = divergence_limit(bodies.angular_velocities, np.float64)
        start = time.perf_counter()
        y = y0
        for k in range(n_steps):
            self.step(dt)
            if log is not None:
                touching = self._log_contacts(log, touching, y, t_start + (k + 1) * dt, dt)
            if saved < len(saves) and saves[saved] == k + 1 or log is not None or k + 1 == n_steps:
                y = self.state()
                rotation = self.rotation() if bodies is not None else None
                if not np.abs(y).max() <= limit or rotation is not None and not np.abs(rotation[1]).max() <= spin_limit:
                    self._rebuild()  # a non-finite state can stay in the engine's caches
                    raise DivergenceError(self.name, dt, k + 1, t_start + (k + 1) * dt)
                if saved < len(saves) and saves[saved] == k + 1:
                    out[saved] = y
                    if rotation is not None:
                        turns[saved], spins[saved] = rotation
                    saved += 1
        wall = time.perf_counter() - start
        t = t_start + saves * dt
        trajectory = Trajectory(t, out, self.name, dt, n_steps, self.engine, wall, collisions=log)
        return trajectory, (RotationTrajectory(t, turns, spins, self.name, bodies) if bodies is not None else None)

    def _log_contacts(self, log, before: dict, y_before, t: float, dt: float) -> dict:
        """Record the pairs that began touching in the step that ended at ``t``."""
        now = self.touching()
        names = self.parts.names
        for (body, other), normal in now.items():
            if (body, other) in before:
                continue
            v = y_before[1, body] - (y_before[1, other] if isinstance(other, int) else 0.0)
            speed = float(np.dot(v, normal)) if normal is not None else UNKNOWN
            other_name = names[other] if isinstance(other, int) else other
            e, mu = self.parts.collisions.properties(body, other if isinstance(other, int) else
                                                     _shape(self.parts, other))
            log.events.append(Collision(t, body, other, names[body], other_name,
                                        np.zeros(3) if normal is None else np.asarray(normal, float),
                                        speed, e, mu, (t - dt, t), kind="contact"))
        return now


class PlanarRun(EngineRun):
    """An engine of bodies in a plane (Box2D, Chipmunk): steplab's axes ``self.axes`` are its x and y.

    Subclasses set ``self.bodies`` and ``self.moving`` and name the engine's body attributes.
    """

    planar = True
    #: the engine's names of a body's linear velocity and of its spin
    velocity_attribute = "velocity"
    spin_attribute = "angular_velocity"

    def __init__(self, model, collisions, engine: str, y0=None, bodies: RigidBodies | None = None):
        """The scene's parts an engine in a plane takes (gravity, springs, dampers; planes and
        boxes), the plane's two axes from the state ``y0`` (default: all at the origin, at rest);
        each rotating body's (angle, spin, moment) about the axis out of the plane
        (``self.turns``; UnsupportedFeatureError for a 3-D tumble)."""
        super().__init__(scene_parts(model, collisions, engine, forces=(Gravity, Springs, Dampers),
                                     shapes=(Plane, Box, OrientedBox)), model, bodies)
        y0 = np.zeros((2, self.parts.n, 3)) if y0 is None else np.asarray(y0, float)
        self.axes = plane_axes(self.parts, y0, engine)
        self._y = y0.copy()
        self.turns = {shape.body: planar_rotation(self.axes, shape, bodies.orientations[k],
                                                  bodies.angular_velocities[k], engine)
                      for k, shape in enumerate(self.rigid)}

    def outline(self, shape: RigidShape) -> tuple:
        """A rotating body's section by the plane, in the engine's body frame (its x, y along
        steplab's ``axes``): ``("circle", r)``, ``("box", (hx, hy))`` or ``("segment", hl, r)``,
        a capsule from (0, -hl) to (0, hl) of radius r. A capsule or cylinder (axis: body z)
        whose axis is out of the plane is its circle."""
        a, b = self.axes
        if shape.shape == "box":
            return ("box", (float(shape.half_extents[a]), float(shape.half_extents[b])))
        if shape.shape == "sphere" or b != 2:  # body z out of the plane: a circle
            return ("circle", shape.radius)
        half = float(shape.half_extents[2])  # body z is the engine's y
        return ("box", (shape.radius, half)) if shape.shape == "cylinder" else ("segment", half, shape.radius)

    def moment(self, i: int, default: float) -> float:
        """Body ``i``'s moment of inertia about the axis out of the plane (``default``: a point mass's disc)."""
        return self.turns[i][2] if i in self.turns else default

    def set_rotation(self, orientations, angular_velocities) -> None:
        for k, shape in enumerate(self.rigid):
            if self.parts.pinned[shape.body]:
                continue
            body = self.bodies[shape.body]
            body.angle, spin, _ = planar_rotation(self.axes, shape, orientations[k], angular_velocities[k],
                                                  self.engine)
            setattr(body, self.spin_attribute, spin)

    def rotation(self) -> tuple[np.ndarray, np.ndarray]:
        turns = [planar_orientation(self.axes, self.bodies[s.body].angle,
                                    getattr(self.bodies[s.body], self.spin_attribute)) for s in self.rigid]
        return np.array([q for q, _ in turns]), np.array([w for _, w in turns])

    def set_state(self, y) -> None:
        a, b = self.axes
        self._y = np.array(y, dtype=float)
        for i in self.moving:
            body = self.bodies[i]
            body.position = (float(self._y[0, i, a]), float(self._y[0, i, b]))
            setattr(body, self.velocity_attribute, (float(self._y[1, i, a]), float(self._y[1, i, b])))
            body.angle = 0.0
            setattr(body, self.spin_attribute, 0.0)

    def state(self) -> np.ndarray:
        a, b = self.axes
        for i in self.moving:
            body = self.bodies[i]
            self._y[0, i, a], self._y[0, i, b] = body.position
            self._y[1, i, a], self._y[1, i, b] = getattr(body, self.velocity_attribute)
        return self._y.copy()

    def _enter_contact(self, out: dict, u, w, normal_in_plane) -> None:
        """Enter a contact of owners ``u`` and ``w`` (a body index or a shape name), its normal
        in the plane from u to w, into ``out`` as (body, other) -> the normal in 3-D from the body."""
        a, b = self.axes
        normal = np.zeros(3)
        normal[a], normal[b] = normal_in_plane
        if isinstance(u, int):
            out[(u, w)] = normal
        elif isinstance(w, int):
            out[(w, u)] = -normal


def _shape(parts: SceneParts, name: str):
    return next(s for s in parts.shapes if s.name == name)


def body_indices(parts: SceneParts) -> np.ndarray:
    """The bodies that move (the engine's dynamic bodies), in scene order."""
    return np.flatnonzero(~parts.pinned)


def build_adapter(cls: type[EngineRun], model, collisions=None, dt: float = 0.01, y0=None, bodies=None,
                  **options) -> EngineRun:
    """The adapter ``cls`` built on a model, its collisions and its rotating ``bodies`` (see
    :func:`steplab.engines.build`). UnsupportedFeatureError for rotating bodies in an adapter
    that does not take them."""
    if bodies is not None:
        if "bodies" not in inspect.signature(cls).parameters:
            raise UnsupportedFeatureError(f"rotating bodies: the {cls.engine} adapter builds point masses only")
        options["bodies"] = bodies
    try:
        run = cls(model, collisions, dt, y0=y0, **options)
    except TypeError as err:
        if "unexpected keyword" in str(err):
            raise ValueError(f"{cls.engine}: {err}") from None
        raise
    # after a divergence the run sets itself up again this way: NaN can stay in an engine's caches
    run.rebuild = lambda self: cls.__init__(self, model, collisions, dt, y0=y0, **options)
    return run
