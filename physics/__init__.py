"""steplab's physical model: state, forces, scenes.

Importing steplab turns on 64-bit floats in JAX (``jax_enable_x64``): float64 is the
default everywhere, float32 is asked for explicitly.
"""

from __future__ import annotations

# Only the installed name: run from the repository root, ``import physics`` would find this
# folder too, and a Numba kernel cached under that foreign name fails to load elsewhere.
if __name__ != "steplab.physics":
    raise ImportError(f"{__name__} is steplab's physics/ folder imported under the wrong name: "
                      "import steplab.physics instead")

import jax

jax.config.update("jax_enable_x64", True)

from .broadphase import find_pairs as find_pairs  # noqa: E402
from .central_gravity import CentralGravity as CentralGravity  # noqa: E402
from .central_gravity import kepler_orbit as kepler_orbit  # noqa: E402
from .constant_force import ConstantForce as ConstantForce  # noqa: E402
from .dampers import Dampers as Dampers  # noqa: E402
from .drag import Drag as Drag  # noqa: E402
from .force import Force as Force  # noqa: E402
from .forces import FORCES as FORCES  # noqa: E402
from .forces import register_force as register_force  # noqa: E402
from .friction import Friction as Friction  # noqa: E402
from .gravity import Gravity as Gravity  # noqa: E402
from .model import Model as Model  # noqa: E402
from .projectile import projectile as projectile  # noqa: E402
from .springs import Springs as Springs  # noqa: E402
from .state import State as State  # noqa: E402
from .state import from_lecture_state as from_lecture_state  # noqa: E402
from .state import lecture_derivative as lecture_derivative  # noqa: E402
from .state import lecture_state as lecture_state  # noqa: E402
