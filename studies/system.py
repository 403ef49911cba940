"""The system under test: whatever the measurements step, steplab's integrator or an engine.

The studies' measurements (the stability limit by bisection, the order fit, the energy
drift, the tunnelling shots, the drop height) take a ``method``: a steplab integrator's
name, which they run on their own compiled or NumPy paths, or a :class:`SystemUnderTest`,
which they run through one protocol,

    run = system.build(model, collisions, dt, y0)
    trajectory = run.advance(y0, dt, n_steps, t_start=0.0, save_every=1)

so an engine (:mod:`steplab.engines`) is measured by exactly the same code and criteria
as steplab's own methods. ``build`` sets the system up on a model (and its static
geometry); ``advance`` puts the bodies at ``y0`` and takes ``n_steps`` steps of ``dt``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import numpy as np


class Run(Protocol):
    """A system set up on one model: ``advance`` steps it from any state."""

    name: str

    def advance(self, y0, dt: float, n_steps: int, t_start: float = 0.0, save_every: int = 1): ...


@dataclasses.dataclass(frozen=True)
class SystemUnderTest:
    """A named factory of runs: ``build(model, collisions, dt, y0) -> Run``.

    ``precision`` is the float type the system computes in ("float32" engines cannot
    show differences below about 1e-7 relative); ``continuous`` whether it detects
    collisions continuously (None: no such switch).
    """

    name: str
    build: Callable
    precision: str = "float64"
    continuous: bool | None = None


def is_system(method) -> bool:
    return isinstance(method, SystemUnderTest)


def final_state(system: SystemUnderTest, model, y0, dt: float, n_steps: int, collisions=None) -> np.ndarray:
    """The state after ``n_steps`` steps of ``dt`` from ``y0`` (the run keeps only the ends)."""
    run = system.build(model, collisions, dt, y0)
    return run.advance(y0, dt, n_steps, save_every=n_steps).y[-1]


@dataclasses.dataclass
class SteplabRun:
    """steplab's own integrator (and collision world) behind the protocol: ``simulate``."""

    model: object
    integrator: object
    collisions: object = None

    @property
    def name(self) -> str:
        from steplab.integrators import get_integrator

        return get_integrator(self.integrator).name

    def advance(self, y0, dt: float, n_steps: int, t_start: float = 0.0, save_every: int = 1):
        from steplab.integrators import simulate

        return simulate(self.model, self.integrator, y0, t_start, dt=dt, n_steps=n_steps, save_every=save_every,
                        collisions=self.collisions)


def steplab_system(integrator: str, label: str | None = None, world_options: dict | None = None) -> SystemUnderTest:
    """steplab's ``integrator`` as a system under test; ``world_options`` replace fields of
    the collision world it is given (``{"detector": "overlap"}``)."""

    def build(model, collisions=None, dt=None, y0=None):
        if collisions is not None and world_options:
            collisions = dataclasses.replace(collisions, **world_options)
        return SteplabRun(model, integrator, collisions)

    continuous = None if not world_options or "detector" not in world_options else \
        world_options["detector"] == "swept"
    return SystemUnderTest(label or f"steplab {integrator}", build, "float64", continuous)


def engine_system(setting) -> SystemUnderTest:
    """An engine setting (:data:`steplab.engines.SETTINGS`) as a system under test, in its
    adapter's precision (Box2D computes in float32)."""
    return SystemUnderTest(setting.label, setting.build, setting.adapter.precision, setting.continuous)
