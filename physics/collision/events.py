"""Collision events: the prologue, the record of every collision, and the epilogue.

The lecture resolves a collision in three parts. The *prologue* learns that a collision
occurred and may decide to ignore it (a character walks through an invisible wall: only
a sound plays); the *collision* places the objects at the point of impact and gives them
new velocities; the *epilogue* propagates the effects (destroy the rocket, play the
"clink", inflict damage).

Here a prologue is a callable ``prologue(event, log) -> bool``: returning False cancels
the collision (no push, no impulse; the pair is left alone until the shapes separate, so
a body crossing a ghost wall is reported once).
An epilogue is ``epilogue(event, log) -> None``, called after the response with the
impulse filled in. Every collision, resolved or cancelled, is one :class:`Collision`
in the run's :class:`CollisionLog`, which ``steplab run --out`` writes beside the
trajectory.
"""

from __future__ import annotations

import csv
import dataclasses
import io

import numpy as np

#: CSV columns of a collision log
CSV_COLUMNS = ("t", "kind", "body", "other", "nx", "ny", "nz", "impact_speed", "impulse",
               "restitution", "t_lo", "t_hi")


@dataclasses.dataclass
class Collision:
    """One collision between body ``body`` and ``other`` (a body name or a static shape's name).

    Attributes
    ----------
    t : float
        Time of the collision, s (for overlap testing: the end of the bisection bracket).
    kind : str
        ``"impact"`` (resolved), ``"trigger"`` (entered a trigger volume) or
        ``"cancelled"`` (a prologue said no).
    normal : ndarray, shape (3,)
        Unit normal from ``body`` towards ``other``.
    impact_speed : float
        Approach speed along the normal just before, m/s.
    impulse : float
        |Lambda| given to ``body``, N s (0 until resolved).
    bracket : (float, float)
        The time interval known to contain the first touch: the bisection bracket for
        overlap testing, (t, t) for intersection testing.
    """

    t: float
    body: int
    other: int | str
    body_name: str
    other_name: str
    normal: np.ndarray
    impact_speed: float
    restitution: float
    friction: float
    bracket: tuple[float, float]
    kind: str = "impact"
    impulse: float = 0.0
    #: whether ``other`` is a trigger shape
    trigger: bool = False

    def as_row(self) -> list:
        return [repr(self.t), self.kind, self.body_name, self.other_name,
                *(repr(float(x)) for x in self.normal), repr(self.impact_speed), repr(self.impulse),
                repr(self.restitution), repr(self.bracket[0]), repr(self.bracket[1])]


@dataclasses.dataclass(frozen=True)
class ImpactBlock:
    """Collisions of one step as columns, made into :class:`Collision` objects only when read.

    The contact solver has hundreds of impacts per step in a big pile; when no prologue or
    epilogue needs to see them one by one, building a Python object for each (3 us, a
    fifth of a 10^4-ball step) is deferred until someone reads ``log.events``.
    """

    t: np.ndarray
    body: np.ndarray
    other: np.ndarray  # the other body, or -1 - (index of the static shape)
    normal: np.ndarray  # (k, 3)
    impact_speed: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray
    impulse: np.ndarray
    bracket: tuple[float, float]
    body_names: tuple  # the model's names
    shapes: tuple  # the world's static shapes

    def __len__(self) -> int:
        return len(self.t)

    def collisions(self) -> list[Collision]:
        events = []
        for t, body, other, normal, speed, e, mu, impulse in zip(
                self.t.tolist(), self.body.tolist(), self.other.tolist(), self.normal, self.impact_speed.tolist(),
                self.restitution.tolist(), self.friction.tolist(), self.impulse.tolist()):
            shape = self.shapes[-1 - other] if other < 0 else None
            events.append(Collision(t=t, body=body, other=shape.name if shape else other,
                                    body_name=self.body_names[body],
                                    other_name=shape.name if shape else self.body_names[other], normal=normal,
                                    impact_speed=speed, restitution=e, friction=mu, bracket=self.bracket,
                                    impulse=impulse, trigger=shape is not None and shape.trigger))
        return events


@dataclasses.dataclass(frozen=True)
class ImpactRows:
    """The event loop's impacts of one step as rows (:data:`.compiled_loop.LOGGED`), made into
    :class:`Collision` objects only when read: what the Python loop logs, field for field."""

    rows: np.ndarray
    body_names: tuple  # the model's names
    shapes: tuple  # the world's static shapes
    properties: object  # (body, other body or shape) -> (restitution, friction), the world's

    def __len__(self) -> int:
        return len(self.rows)

    def collisions(self) -> list[Collision]:
        events = []
        for r in self.rows:
            body, other = int(r["body"]), int(r["other"])
            shape = self.shapes[-1 - other] if other < 0 else None
            restitution, friction = self.properties(body, other if shape is None else shape)
            impulse = float(np.linalg.norm(np.array([r["lx"], r["ly"], r["lz"]])))  # as the Python loop's
            events.append(Collision(t=float(r["t"]), body=body, other=shape.name if shape else other,
                                    body_name=self.body_names[body],
                                    other_name=shape.name if shape else self.body_names[other],
                                    normal=np.array([r["nx"], r["ny"], r["nz"]]), impact_speed=float(r["speed"]),
                                    restitution=restitution, friction=friction,
                                    bracket=(float(r["t_lo"]), float(r["t_hi"])), impulse=impulse))
        return events


@dataclasses.dataclass
class CollisionLog:
    """Everything the collision stage did during one run."""

    _events: list[Collision] = dataclasses.field(default_factory=list, repr=False)
    #: impacts not yet made into Collision objects, in order, after ``_events``
    _blocks: list[ImpactBlock | ImpactRows] = dataclasses.field(default_factory=list, repr=False)
    #: bodies an epilogue removed from collision detection (they fly on untouched)
    removed: set[int] = dataclasses.field(default_factory=set)
    #: the most impacts resolved in one step
    most_impacts_in_a_step: int = 0
    #: resting-contact corrections (a body put back on a surface it was pressed into)
    resting_corrections: int = 0
    #: pairs whose collision a prologue cancelled, left alone until they separate
    cancelled_pairs: set = dataclasses.field(default_factory=set)
    #: the contact solver's largest complementarity residual at the end of a step, m/s
    #: (None for the event loop, which resolves every impact exactly)
    largest_residual: float | None = None

    @property
    def events(self) -> list[Collision]:
        """Every collision of the run, in order (resolved, trigger or cancelled)."""
        for block in self._blocks:
            self._events += block.collisions()
        self._blocks.clear()
        return self._events

    def add_impacts(self, block: ImpactBlock | ImpactRows) -> None:
        """Append a step's impacts as columns (see :class:`ImpactBlock`)."""
        if len(block):
            self._blocks.append(block)

    def remove(self, body: int) -> None:
        self.removed.add(int(body))

    def count(self, kind: str = "impact") -> int:
        pending = sum(len(block) for block in self._blocks) if kind == "impact" else 0
        return pending + sum(1 for e in self._events if e.kind == kind)

    def summary(self) -> dict:
        return {"impacts": self.count("impact"), "triggers": self.count("trigger"),
                "cancelled": self.count("cancelled"),
                "most_impacts_in_a_step": self.most_impacts_in_a_step,
                "resting_corrections": self.resting_corrections,
                **({} if self.largest_residual is None else {"largest_residual": self.largest_residual})}

    def to_csv(self) -> str:
        text = io.StringIO()
        writer = csv.writer(text, lineterminator="\n")
        writer.writerow(CSV_COLUMNS)
        writer.writerows(e.as_row() for e in self.events)
        return text.getvalue()


def cancel_triggers(event: Collision, log: CollisionLog) -> bool:
    """The built-in prologue: a collision with a trigger shape is recorded, never resolved."""
    return not event.trigger


def remove_on_impact(shape_name: str):
    """An epilogue: a body that hits ``shape_name`` is removed (the rocket that slams into a wall)."""

    def epilogue(event: Collision, log: CollisionLog) -> None:
        if event.other_name == shape_name:
            log.remove(event.body)

    return epilogue
