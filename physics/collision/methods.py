"""Collision methods: how a physics step resolves the contacts it finds, one class per method.

A scene picks one by name, ``[collisions] method = "event"`` (``steplab run --method``), and
the collision world builds each run's step from the class it finds in
:data:`COLLISION_METHODS`. A method is a subclass of :class:`CollisionMethod` with

- ``name``: its key, which also names its settings table ``[collisions.<name>]``;
- ``from_scene(table)``: the :class:`.world.CollisionWorld` fields that table sets (``{}``
  without settings; ``table`` is None where the scene has no such table);
- ``step(world, model, integrator)``: the physics step of one run, called as
  ``step(t, y, dt, carry) -> (y, carry)`` with a collision log in ``step.log``.

steplab's two: the lecture's event loop (:class:`EventLoop`, exact: every impact resolved at
its time of impact) and the engines' contact solver (:class:`ContactSolverMethod`, every
contact of a step solved together by sequential impulses). Others come from
``COLLISION_METHODS.register(cls)`` or the ``steplab.collision_methods`` entry points.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from steplab.core.registry import PluginError, Registry

from .solver_settings import CORRECTIONS, MAX_SWEEPS, ContactSolver, is_thread_count, sweeps_refusal, threads_allowed


class CollisionMethod:
    """A way of resolving a step's contacts: its scene key, its settings table and its step."""

    name: ClassVar[str] = ""

    @classmethod
    def from_scene(cls, table) -> dict:
        """The world fields the scene's ``[collisions.<name>]`` table sets; this method has none."""
        if table is not None:
            table.fail(f"the collision method {cls.name!r} takes no settings")
        return {}

    @classmethod
    def step(cls, world, model, integrator):
        raise NotImplementedError(f"collision method {cls.__qualname__} has no step")


class EventLoop(CollisionMethod):
    """The lecture's event loop: each impact found at its time of impact and resolved there,
    the step then continued from it (:mod:`.step`); the exact reference. Spheres that spin, where
    friction can turn them, carry their omega and orientation (:mod:`.spin_step`)."""

    name: ClassVar[str] = "event"

    @classmethod
    def step(cls, world, model, integrator):
        if world.rigid is not None and world.rigid.has_corners:
            raise ValueError('the event loop steps spheres only: boxes and capsules need [collisions] method = '
                             '"solver" (the event loop has no time of impact under rotation)')
        if world.rigid is not None:  # spheres that rotate: spin only where friction can change it
            from .spin_step import SpinningCollisionStep, has_friction

            if has_friction(world):
                return SpinningCollisionStep(world, model, integrator)
        from .step import CollisionStep

        return CollisionStep(world, model, integrator)


class ContactSolverMethod(CollisionMethod):
    """The engines' contact solver: every contact of the step gathered once and solved together
    by sequential impulses, in substeps (:mod:`.solver_step`); ``[collisions.solver]`` holds
    its :class:`.solver_settings.ContactSolver` settings."""

    name: ClassVar[str] = "solver"

    @classmethod
    def from_scene(cls, table) -> dict:
        d = ContactSolver()
        if table is None:
            return {"solver": d}
        table.allow(*(f.name for f in dataclasses.fields(ContactSolver)))
        baumgarte = table.number("baumgarte", d.baumgarte, positive=True)
        if baumgarte > 1:
            table.fail(f"must be in (0, 1] (the fraction of the penetration undone per substep), got {baumgarte:g}",
                       "baumgarte")
        threads = table.raw("threads", d.threads)
        if not is_thread_count(threads):
            table.fail(f"must be {threads_allowed()}, got {threads!r}", "threads")
        iterations = table.integer("iterations", d.iterations, 1, MAX_SWEEPS)
        substeps = table.integer("substeps", d.substeps, 1, MAX_SWEEPS)
        if iterations * substeps > MAX_SWEEPS:
            table.fail(sweeps_refusal(iterations, substeps).removeprefix("contact solver: "), "iterations")
        return {"solver": ContactSolver(
            iterations=iterations, substeps=substeps,
            correction=table.string("correction", d.correction, choices=CORRECTIONS),
            contact_hertz=table.number("contact_hertz", d.contact_hertz, positive=True),
            damping_ratio=table.number("damping_ratio", d.damping_ratio, nonnegative=True),
            baumgarte=baumgarte, slop=table.number("slop", d.slop, nonnegative=True),
            push_speed=table.number("push_speed", d.push_speed, positive=True),
            rolling_resistance=table.number("rolling_resistance", d.rolling_resistance, nonnegative=True),
            threads=threads)}

    @classmethod
    def step(cls, world, model, integrator):
        """The sphere solver (:mod:`.solver_step`), or the rigid one (:mod:`.rigid_solver_step`) when
        some body rotates."""
        if world.rigid is not None:
            from .rigid_solver_step import RigidSolverStep

            return RigidSolverStep(world, model, integrator)
        from .solver_step import SolverStep

        return SolverStep(world, model, integrator)


def _as_collision_method(obj) -> tuple[str, type[CollisionMethod]]:
    """A registry entry from what a plugin names: a CollisionMethod subclass with a name."""
    if not (isinstance(obj, type) and issubclass(obj, CollisionMethod)):
        raise PluginError(f"{obj!r} is not a subclass of steplab.physics.collision.methods.CollisionMethod")
    if not isinstance(obj.name, str) or not obj.name.replace("-", "_").isidentifier():
        raise PluginError(f"collision method {obj.__qualname__} needs a class attribute name = \"...\" "
                          f"(letters, digits, _ and -), got {obj.name!r}")
    return obj.name, obj


#: every collision method, by scene key: steplab's two, then registered ones and those of the
#: "steplab.collision_methods" entry points (loaded on first use)
COLLISION_METHODS: Registry = Registry("steplab.collision_methods", "collision method",
                                       [(m.name, m) for m in (EventLoop, ContactSolverMethod)],
                                       _as_collision_method)
