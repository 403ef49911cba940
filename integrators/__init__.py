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

from steplab.core.registry import PluginError as PluginError

from .base import Integrator as Integrator
from .base import Solver as Solver
from .base import Stepper as Stepper
from .euler import ExplicitEuler as ExplicitEuler
from .exact import Exact as Exact
from .exact import NotConstantForceError as NotConstantForceError
from .game_loop import GameLoop as GameLoop
from .implicit_damping_euler import ImplicitDampingEuler as ImplicitDampingEuler
from .implicit_euler import ImplicitEuler as ImplicitEuler
from .position_based import PBD as PBD
from .position_based import XPBD as XPBD
from .position_first_euler import ExponentialDampingEuler as ExponentialDampingEuler
from .position_first_euler import PositionFirstEuler as PositionFirstEuler
from .references import DiffraxDopri8 as DiffraxDopri8
from .references import DiffraxKvaerno5 as DiffraxKvaerno5
from .references import DiffraxTsit5 as DiffraxTsit5
from .references import ReferenceFailedError as ReferenceFailedError
from .references import ScipyDOP853 as ScipyDOP853
from .references import ScipyRadau as ScipyRadau
from .registry import DEFAULT_REFERENCE as DEFAULT_REFERENCE
from .registry import INTEGRATORS as INTEGRATORS
from .registry import UnknownIntegratorError as UnknownIntegratorError
from .registry import get_integrator as get_integrator
from .registry import register_integrator as register_integrator
from .rotation import RotationMethod as RotationMethod
from .rotation_registry import DEFAULT_ROTATION as DEFAULT_ROTATION
from .rotation_registry import ROTATIONS as ROTATIONS
from .rotation_registry import get_rotation as get_rotation
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
from .vertex_block_descent import VBD as VBD
