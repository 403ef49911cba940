"""Fixed-step integrators and reference solvers, looked up by name in one registry.

The registry :data:`INTEGRATORS` holds steplab's own methods and those of installed
plugins (entry-point group ``steplab.integrators``); :func:`register_integrator` adds one
at run time, and :func:`get_integrator` also imports ``"package.module:Name"``.

>>> from steplab.integrators import get_integrator, simulate
>>> get_integrator("rk4").order
4
"""

from __future__ import annotations

# Only the installed name: run from the repository root, ``import integrators`` would find this
# folder too, and a Numba kernel cached under that foreign name fails to load elsewhere.
if __name__ != "steplab.integrators":
    raise ImportError(f"{__name__} is steplab's integrators/ folder imported under the wrong name: "
                      "import steplab.integrators instead")

from steplab.physics.plugins import PluginError as PluginError
from steplab.physics.plugins import Registry, import_object

from .base import Integrator as Integrator
from .base import Solver as Solver
from .base import Stepper as Stepper
from .euler import ExplicitEuler as ExplicitEuler
from .exact import Exact as Exact
from .exact import NotConstantForceError as NotConstantForceError
from .game_loop import GameLoop as GameLoop
from .implicit_damping_euler import ImplicitDampingEuler as ImplicitDampingEuler
from .implicit_euler import ImplicitEuler as ImplicitEuler
from .position_first_euler import ExponentialDampingEuler as ExponentialDampingEuler
from .position_first_euler import PositionFirstEuler as PositionFirstEuler
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

#: the reference a study gets when it asks for "the reference"
DEFAULT_REFERENCE = "diffrax-dopri8"


class UnknownIntegratorError(KeyError):
    def __str__(self):
        return self.args[0]


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
#: "steplab.integrators" entry points, loaded on first use; see steplab.physics.plugins)
INTEGRATORS: Registry = Registry("steplab.integrators", "integrator", [(method.name, method) for method in (
    ExplicitEuler(), SemiImplicitEuler(), VelocityVerlet(), PositionVerlet(), Heun(),
    Midpoint(), RK4(), ImplicitEuler(), ImplicitDampingEuler(), PositionFirstEuler(), ExponentialDampingEuler(),
    Exact(), DiffraxDopri8(), DiffraxTsit5(),
    DiffraxKvaerno5(), ScipyDOP853(), ScipyRadau(),
)], _as_integrator)


def register_integrator(integrator: Integrator | type[Integrator]) -> Integrator:
    """Add ``integrator`` (an instance, or a class made with no arguments) to :data:`INTEGRATORS`.

    From then on ``steplab run --integrator NAME``, ``steplab integrators`` and the studies
    (which take their stepper lists from the registry) see it.

    Raises
    ------
    steplab.physics.plugins.PluginError
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
    if isinstance(method, Integrator):
        return method
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
        return INTEGRATORS[method]
    except (KeyError, TypeError):
        if isinstance(method, str) and method in INTEGRATORS.errors:  # a plugin that failed to load
            raise UnknownIntegratorError(f"integrator {method!r} is unavailable: "
                                         f"{INTEGRATORS.errors[method]}") from None
        raise UnknownIntegratorError(
            f"unknown integrator {method!r}; valid: {', '.join(INTEGRATORS)}, or package.module:Name") from None


# --- rotation methods (kind "rotation"): their own registry, since their names ("rk4") are
# those of the translation methods they pair with; a scene's [simulation] rotation = "NAME"
# and --rotation NAME look them up here, "steplab.rotations" entry points add more
from .rotation import DEFAULT_ROTATION as DEFAULT_ROTATION  # noqa: E402
from .rotation import METHODS as _ROTATION_METHODS  # noqa: E402
from .rotation import RotationMethod as RotationMethod  # noqa: E402


def _as_rotation(obj) -> tuple[str, RotationMethod]:
    """A registry entry from what a plugin names: a RotationMethod instance, or a class made with no arguments."""
    if isinstance(obj, type) and issubclass(obj, RotationMethod):
        obj = obj()
    if not isinstance(obj, RotationMethod):
        raise PluginError(f"{obj!r} is a {type(obj).__name__}, not a steplab.integrators.RotationMethod")
    return _as_integrator(obj)


#: every rotation method by name: steplab's own, then the "steplab.rotations" entry points
ROTATIONS: Registry = Registry("steplab.rotations", "rotation method",
                               [(method.name, method) for method in _ROTATION_METHODS], _as_rotation)


def get_rotation(method: str | RotationMethod) -> RotationMethod:
    """The rotation method ``method`` (a name in :data:`ROTATIONS`, or a RotationMethod).

    Raises
    ------
    UnknownIntegratorError
        One line naming the valid methods.
    """
    if isinstance(method, RotationMethod):
        return method
    try:
        return ROTATIONS[method]
    except (KeyError, TypeError):
        raise UnknownIntegratorError(f"unknown rotation method {method!r}; valid: {', '.join(ROTATIONS)}") from None
