"""steplab's physical model: state, forces, scenes.

Importing steplab turns on 64-bit floats in JAX (``jax_enable_x64``, set in
``steplab/__init__.py`` before JAX loads): float64 is the default everywhere, float32 is
asked for explicitly.
"""

from __future__ import annotations

# Only the installed name: run from the repository root, ``import physics`` would find this
# folder too, and a Numba kernel cached under that foreign name fails to load elsewhere.
if __name__ != "steplab.physics":
    raise ImportError(f"{__name__} is steplab's physics/ folder imported under the wrong name: "
                      "import steplab.physics instead")

from steplab.core.lazy_exports import lazy_exports  # noqa: E402

from .projectile import projectile as projectile  # noqa: E402  (eager: also a submodule's name)

#: the public names, each imported from its module on first use (steplab/core/lazy_exports.py):
#: ``import steplab.physics`` loads neither JAX nor the Numba kernels
_EXPORTS = {
    "find_pairs": ".broadphase",
    "CentralGravity": ".central_gravity",
    "kepler_orbit": ".central_gravity",
    "ConstantForce": ".constant_force",
    "Dampers": ".dampers",
    "Drag": ".drag",
    "Force": ".force",
    "FORCES": ".forces",
    "register_force": ".forces",
    "Friction": ".friction",
    "Gravity": ".gravity",
    "Model": ".model",
    "Springs": ".springs",
    "State": ".state",
    "from_lecture_state": ".state",
    "lecture_derivative": ".state",
    "lecture_state": ".state",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = [*_EXPORTS, "projectile"]
