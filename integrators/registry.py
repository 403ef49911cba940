"""The integrator registry: every fixed-step method and reference solver steplab knows, by name.

:data:`INTEGRATORS` holds steplab's own methods and those of installed plugins (entry-point
group ``steplab.integrators``); :func:`register_integrator` adds one at run time, and
:func:`get_integrator` also imports ``"package.module:Name"``. It sits below
:mod:`.simulate`, which looks its integrator up here.
"""

from __future__ import annotations

from steplab.core.registry import PluginError, Registry, UnknownNameError, import_object

from .base import Integrator
from .euler import ExplicitEuler
from .exact import Exact
from .implicit_damping_euler import ImplicitDampingEuler
from .implicit_euler import ImplicitEuler
from .position_based import PBD, XPBD
from .position_first_euler import ExponentialDampingEuler, PositionFirstEuler
from .references import DiffraxDopri8, DiffraxKvaerno5, DiffraxTsit5, ScipyDOP853, ScipyRadau
from .runge_kutta import RK4, Heun, Midpoint
from .semi_implicit_euler import SemiImplicitEuler
from .verlet import PositionVerlet, VelocityVerlet
from .vertex_block_descent import VBD

#: the reference a study gets when it asks for "the reference"
DEFAULT_REFERENCE = "diffrax-dopri8"


class UnknownIntegratorError(UnknownNameError):
    """An integrator name or ``package.module:Name`` that names none: one line."""


def _as_integrator(obj) -> tuple[str, Integrator]:
    """A registry entry from what a plugin names: an Integrator instance, or a class made with no arguments."""
    if isinstance(obj, type) and issubclass(obj, Integrator):
        try:
            obj = obj()
        except TypeError as err:
            raise PluginError(f"integrator class {obj.__qualname__} cannot be made without arguments "
                              f"({err}); name an instance instead") from None
    if not isinstance(obj, Integrator):
        raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a steplab.integrators.Integrator "
                          "(a Stepper or a Solver)")
    name = getattr(obj, "name", None)
    if not isinstance(name, str) or not name or ":" in name:
        raise PluginError(f"{type(obj).__qualname__} needs a class attribute name = \"...\" "
                          f"(no colon), got {name!r}")
    return name, obj


#: every integrator steplab knows, by name: its own, then those of installed plugins (the
#: "steplab.integrators" entry points, loaded on first use; see steplab.core.registry)
INTEGRATORS: Registry = Registry("steplab.integrators", "integrator", [(method.name, method) for method in (
    ExplicitEuler(), SemiImplicitEuler(), VelocityVerlet(), PositionVerlet(), Heun(),
    Midpoint(), RK4(), ImplicitEuler(), ImplicitDampingEuler(), PositionFirstEuler(), ExponentialDampingEuler(),
    Exact(), DiffraxDopri8(), DiffraxTsit5(),
    DiffraxKvaerno5(), ScipyDOP853(), ScipyRadau(),
    # position-based: the springs as constraints (steplab.physics.constraints)
    PBD(), XPBD(), VBD(),
)], _as_integrator)


def register_integrator(integrator: Integrator | type[Integrator]) -> Integrator:
    """Add ``integrator`` (an instance, or a class made with no arguments) to :data:`INTEGRATORS`.

    From then on ``steplab run --integrator NAME``, ``steplab integrators`` and the studies
    (which take their stepper lists from the registry) see it.

    Raises
    ------
    steplab.core.registry.PluginError
        Not an integrator, or its name is taken by another one.
    """
    return INTEGRATORS.register(integrator, origin="register_integrator")


def get_integrator(method: str | Integrator) -> Integrator:
    """The integrator ``method``: a registry name, ``"package.module:Name"`` (an Integrator
    instance or class there, imported), or an Integrator itself.

    Raises
    ------
    UnknownIntegratorError
        One line: an unknown name (with the valid ones, and any plugin that failed to
        load), or a ``module:Name`` that cannot be imported or is not an integrator.
    """
    if isinstance(method, Integrator):  # an object of the caller's: checked as a plugin's is
        try:
            return _as_integrator(method)[1]
        except PluginError as err:
            raise UnknownIntegratorError(str(err)) from None
    if isinstance(method, str) and ":" in method:
        try:
            obj = import_object(method)
        except PluginError as err:
            raise UnknownIntegratorError(f"integrator {err}") from None
        try:
            return _as_integrator(obj)[1]
        except PluginError as err:
            raise UnknownIntegratorError(f"integrator {method!r}: {err}") from None
    try:
        return INTEGRATORS.lookup(method, hint=", or package.module:Name")
    except UnknownNameError as err:
        raise UnknownIntegratorError(str(err)) from None

