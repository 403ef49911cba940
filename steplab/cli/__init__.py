"""The ``steplab`` command line: one module per command, a parser that imports none of them.

Bad input (an unknown integrator, a malformed scene, a non-positive dt...) ends with
one line on stderr and exit status 2; a simulation that diverges, or whose step holds
more impacts than the cap, and a ``recommend`` that finds nothing meeting the tolerance
end with one line and status 1. Never a traceback.

Start-up: building the parser imports no command; a command imports what it uses when it
runs, so ``steplab --help``, ``scenes``, ``integrators`` and a NumPy ``run`` never load JAX,
matplotlib, the studies or the compiled collision kernels.
"""

from __future__ import annotations

from .errors import EXIT_BAD_INPUT as EXIT_BAD_INPUT
from .errors import EXIT_DIVERGED as EXIT_DIVERGED
from .errors import EXIT_INTERRUPTED as EXIT_INTERRUPTED
from .main import build_parser as build_parser
from .main import main as main
