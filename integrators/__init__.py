"""Fixed-step integrators and reference solvers, looked up by name in one registry.

>>> from steplab.integrators import get_integrator, simulate
>>> get_integrator("rk4").order
4
"""

from __future__ import annotations

from .base import Integrator as Integrator
from .base import Solver as Solver
from .base import Stepper as Stepper
from .euler import ExplicitEuler as ExplicitEuler
from .exact import Exact as Exact
from .exact import NotConstantForceError as NotConstantForceError
from .game_loop import GameLoop as GameLoop
from .implicit_euler import ImplicitEuler as ImplicitEuler
from .references import DiffraxDopri8 as DiffraxDopri8
from .references import DiffraxKvaerno5 as DiffraxKvaerno5
from .references import DiffraxTsit5 as DiffraxTsit5
from .references import ReferenceFailedError as ReferenceFailedError
from .references import ScipyDOP853 as ScipyDOP853
from .references import ScipyRadau as ScipyRadau
from .runge_kutta import RK4 as RK4
from .runge_kutta import ButcherTableau as ButcherTableau
from .runge_kutta import ExplicitRungeKutta as ExplicitRungeKutta
from .runge_kutta import Heun as Heun
from .runge_kutta import Midpoint as Midpoint
from .runge_kutta import rk_step as rk_step
from .semi_implicit_euler import SemiImplicitEuler as SemiImplicitEuler
from .simulate import DivergenceError as DivergenceError
from .simulate import Trajectory as Trajectory
from .simulate import simulate as simulate
from .verlet import PositionVerlet as PositionVerlet
from .verlet import VelocityVerlet as VelocityVerlet

#: every integrator steplab knows, by name
INTEGRATORS: dict[str, Integrator] = {
    method.name: method
    for method in (
        ExplicitEuler(), SemiImplicitEuler(), VelocityVerlet(), PositionVerlet(), Heun(),
        Midpoint(), RK4(), ImplicitEuler(), Exact(), DiffraxDopri8(), DiffraxTsit5(),
        DiffraxKvaerno5(), ScipyDOP853(), ScipyRadau(),
    )
}

#: the reference a study gets when it asks for "the reference"
DEFAULT_REFERENCE = "diffrax-dopri8"


class UnknownIntegratorError(KeyError):
    def __str__(self):
        return self.args[0]


def get_integrator(method: str | Integrator) -> Integrator:
    """The integrator named ``method``, or ``method`` itself if it already is one."""
    if isinstance(method, Integrator):
        return method
    try:
        return INTEGRATORS[method]
    except (KeyError, TypeError):
        raise UnknownIntegratorError(
            f"unknown integrator {method!r}; valid: {', '.join(INTEGRATORS)}") from None
