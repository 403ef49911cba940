"""A collision world: the static geometry, the detector and the materials of one scene."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..rules import integer_problem, number_problem, require, short
from .detectors import DETECTORS
from .events import cancel_triggers
from .impact_cap import default_cap
from .methods import COLLISION_METHODS
from .pairs import DEFAULT_BROADPHASE
from .response import PairProperties
from .shapes import DEFAULT_MATERIAL, Shape
from .solver_settings import ContactSolver

#: bisection iterations of overlap testing (the lecture: "usually 5 iterations is pretty close")
DEFAULT_BISECTION_ITERATIONS = 5
#: the most bisection iterations a world takes (a scene file's bound too): 60 halvings resolve
#: the collision time of any step to float64 round-off, and more would only spin
MAX_BISECTION_ITERATIONS = 60
#: the largest bound on the impacts of one step a world takes (a scene file's bound too)
MAX_IMPACTS_PER_STEP = 10**9
#: collisions resolved per step at most when a scene names no bound: None, scaled with the
#: bodies (:func:`.impact_cap.default_cap`); a step that holds more raises ImpactCapError
DEFAULT_MAX_IMPACTS_PER_STEP = None
#: how the step finds its impacts after each one (:mod:`.step`): "incremental" re-tests the
#: pairs of the bodies the impact moved, "full" re-integrates and re-tests everything, "auto"
#: is "incremental" where the two agree to round-off (semi-implicit Euler, constant forces)
EVENT_LOOPS = ("auto", "incremental", "full")
#: approach speeds at or below this never bounce, m/s (Box2D's "restitution threshold" is
#: 1 m/s; 1 mm/s only stops round-off-sized speeds from rattling through touching bodies)
DEFAULT_REST_SPEED = 1e-3


@dataclasses.dataclass(frozen=True)
class CollisionWorld:
    """Everything collision handling needs besides the bodies (which are the model's spheres).

    Parameters
    ----------
    detector : str
        One of :data:`.detectors.DETECTORS`: "none", "overlap" or "swept" (or a registered one).
    shapes : tuple of Shape
        Static geometry: planes, boxes, oriented boxes (triggers among them).
    materials : tuple of str
        One material name per body; empty for all ``"default"``.
    pair_properties : PairProperties
        Restitution and friction per pair of materials.
    bisection_iterations : int
        Overlap testing: halvings of the step bracketing each collision time.
    max_impacts_per_step : int or None
        Collisions resolved per step at most (None: :func:`.impact_cap.default_cap` of the
        bodies); a step holding more raises :class:`.impact_cap.ImpactCapError`.
    broadphase : str
        Pair-finding method (see ``physics.broadphase``).
    rest_speed : float
        m/s; slower approaches are resting contacts (eps = 0), see :func:`.step.rest_speed`.
    prologues, epilogues : tuples of callables
        See :mod:`.events`. The default prologue makes trigger shapes report, not collide.
    event_loop : str
        One of :data:`EVENT_LOOPS`: ``"auto"`` (default: ``"incremental"`` where it gives the
        full loop's results to round-off, else ``"full"``), ``"incremental"`` or ``"full"``,
        the reference that re-tests everything after every impact (see :mod:`.step`).
    compiled_loop : bool
        The incremental loop's impacts in one compiled call per step where the scene allows it
        (:func:`.compiled_loop.applies`; the same numbers bit for bit); False: the Python loop,
        kept as the reference the compiled one is tested and timed against.
    method : str
        One of :data:`.methods.COLLISION_METHODS`: ``"event"`` (default), the lecture's event
        loop, exact, every impact at its time (:mod:`.step`); ``"solver"``, the engines' way,
        every contact of the step solved together by sequential impulses (:mod:`.solver_step`);
        or a registered one. The solver finds its own (speculative) contacts: of the detectors
        it only heeds "none".
    solver : ContactSolver
        The contact solver's settings (iterations, substeps, position correction).
    rigid : physics.collision.rigid_solver_step.RigidScene or None
        The bodies' shapes and rotational state when some of them rotate (boxes, capsules,
        spinning spheres): the contact solver then steps them as rigid bodies
        (:mod:`.rigid_solver_step`); None, the default, for point masses.
    """

    detector: str = "swept"
    shapes: tuple[Shape, ...] = ()
    materials: tuple[str, ...] = ()
    pair_properties: PairProperties = dataclasses.field(default_factory=PairProperties)
    bisection_iterations: int = DEFAULT_BISECTION_ITERATIONS
    max_impacts_per_step: int | None = DEFAULT_MAX_IMPACTS_PER_STEP
    broadphase: str = DEFAULT_BROADPHASE
    rest_speed: float = DEFAULT_REST_SPEED
    prologues: tuple[Callable, ...] = (cancel_triggers,)
    epilogues: tuple[Callable, ...] = ()
    event_loop: str = "auto"
    compiled_loop: bool = True
    method: str = "event"
    solver: ContactSolver = dataclasses.field(default_factory=ContactSolver)
    rigid: object = None

    def __post_init__(self):
        DETECTORS.lookup(self.detector)
        # the same bounds as a scene file's [collisions] table (physics/scene.py), by the same rules
        require("CollisionWorld: bisection_iterations",
                integer_problem(self.bisection_iterations, 0, MAX_BISECTION_ITERATIONS))
        require("CollisionWorld: rest_speed", number_problem(self.rest_speed, nonnegative=True))
        if self.max_impacts_per_step is not None:
            require("CollisionWorld: max_impacts_per_step",
                    integer_problem(self.max_impacts_per_step, 1, MAX_IMPACTS_PER_STEP))
        # a list is taken as the tuple it stands for; anything else is refused here, not at run time
        for key, kind, what in (("shapes", Shape, "static shapes (Plane, Box, ...)"),
                                ("materials", str, "material names, one per body")):
            value = getattr(self, key)
            if not isinstance(value, (tuple, list)) or not all(isinstance(x, kind) for x in value):
                raise TypeError(f"CollisionWorld: {key} must be a tuple of {what}, got {short(value)}")
            object.__setattr__(self, key, tuple(value))
        if not isinstance(self.pair_properties, PairProperties):
            raise TypeError(f"CollisionWorld: pair_properties must be a PairProperties, "
                            f"got {short(self.pair_properties)}")
        if self.event_loop not in EVENT_LOOPS:
            raise ValueError(f"unknown event loop {self.event_loop!r}; valid: {', '.join(EVENT_LOOPS)}")
        COLLISION_METHODS.lookup(self.method)

    def check_bodies(self, n_bodies: int) -> None:
        """Refuse (ValueError, one line) materials that are not one per body of a model of ``n_bodies``."""
        if self.materials and len(self.materials) != n_bodies:
            raise ValueError(f"CollisionWorld: materials must name one material per body, or none (all "
                             f"{DEFAULT_MATERIAL!r}): got {len(self.materials)} for {n_bodies} bodies")

    def impact_cap(self, n_bodies: int) -> int:
        """Impacts resolved per step at most, for a scene of ``n_bodies``."""
        if self.max_impacts_per_step is not None:
            return self.max_impacts_per_step
        return default_cap(n_bodies)

    def material(self, body: int) -> str:
        return self.materials[body] if self.materials else DEFAULT_MATERIAL

    def properties(self, body: int, other) -> tuple[float, float]:
        """(restitution, friction) of ``body`` against another body (an index) or a static shape."""
        other_material = other.material if isinstance(other, Shape) else self.material(other)
        return self.pair_properties.lookup(self.material(body), other_material)

    def with_detector(self, detector: str) -> CollisionWorld:
        return dataclasses.replace(self, detector=detector)

    def with_rotation(self, rotation: str) -> CollisionWorld:
        """The world whose rigid bodies turn by the rotation method ``rotation`` (itself without rigid bodies)."""
        if self.rigid is None:
            return self
        return dataclasses.replace(self, rigid=dataclasses.replace(self.rigid, rotation=rotation))

    def check_solver(self, integrator=None) -> None:
        """What the contact solver refuses before any step, each in its one line (ValueError): its rigid
        bodies' rotation method where it does not compose with the substeps
        (:func:`.rigid_solver_step.rotation_codes`), and ``integrator``, when given, other than the one its
        substeps are (:func:`.solver_step.check_solver_integrator`); nothing for the event loop. ``run``,
        ``check`` and ``recommend`` call it, so that they refuse alike."""
        if self.method != "solver":
            return
        if self.rigid is not None:
            from .rigid_solver_step import rotation_codes

            rotation_codes(self.rigid.rotation)
        if integrator is not None:
            from .solver_step import check_solver_integrator

            check_solver_integrator(integrator, self)

    def check_attachments(self, model) -> None:
        """Springs or dampers at body-frame points (``offsets``) run with collisions in the contact solver
        on rigid bodies only (method "solver" with ``rigid``), which turns their lever arms at every
        substep; the event loop and the sphere solver would keep them where they started: ValueError."""
        from ..attachments import attached_forces

        if attached_forces(model) and not (self.method == "solver" and self.rigid is not None):
            raise ValueError("springs and dampers at body-frame points (offsets) run with collisions in the contact "
                             "solver on rigid bodies only, not the event loop; use [collisions] method = \"solver\", "
                             "or --detector none")

    def stepper(self, model, integrator):
        """The physics step of one run, ``step(t, y, dt, carry)``, holding its collision log.

        ``simulate(..., collisions=world)`` calls this once before its loop. None for the
        detector "none": the integrator's own step, on any backend. ValueError for what
        collision handling cannot serve: a solver, or a model on another backend than NumPy.
        """
        self.check_bodies(model.n_bodies)
        if self.detector == "none":
            return None
        self.check_attachments(model)
        if not hasattr(integrator, "step"):  # a solver: it has no steps to put collisions between
            raise ValueError(f"collisions need a fixed-step integrator, not the {integrator.kind} solver "
                             f"'{integrator.name}' (use the detector 'none')")
        if model.xp is not np:
            backend = model.xp.__name__.split(".")[0]
            raise ValueError(f"collision detection runs on the NumPy backend only, not {backend!r} "
                             "(use backend 'numpy', or the detector 'none')")
        return COLLISION_METHODS[self.method].step(self, model, integrator)
