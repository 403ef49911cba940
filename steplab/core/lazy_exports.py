"""A package's public names imported on first use (PEP 562), so ``import steplab`` stays cheap.

``steplab``, ``steplab.physics``, ``steplab.integrators`` and ``steplab.studies`` re-export
names from their submodules. Imported eagerly, they would load JAX, Numba, SciPy and every
study for a command that needs none of them (``steplab --help`` paid 3 s). Each package
instead lists where every name lives; the first ``package.Name`` imports that module, and
the value is then stored in the package, so later reads cost nothing.

A name that is also a submodule's name (``steplab.physics.projectile``, the function and
its module) must stay eager in the package: the first import of the submodule would
otherwise set the package attribute to the module.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> tuple[Callable[[str], object], Callable[[], list]]:
    """``(__getattr__, __dir__)`` for ``package``, whose name ``N`` is ``exports[N]``'s ``N``.

    ``exports`` maps each public name to the module that defines it (absolute, or relative
    to ``package`` with a leading dot). Any other name that is a submodule's is that
    submodule, imported, as it was when the package imported its submodules eagerly.
    """
    def __getattr__(name: str):
        if name in exports:
            value = getattr(importlib.import_module(exports[name], package), name)
        elif not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
            value = importlib.import_module(f"{package}.{name}")  # a submodule, as the eager imports made it
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        setattr(importlib.import_module(package), name, value)
        return value

    def __dir__() -> list:
        return sorted(set(vars(importlib.import_module(package))) | set(exports))

    return __getattr__, __dir__
