"""Exit statuses and the one-line error every failure ends with."""

from __future__ import annotations

import sys

EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 1
#: 128 + SIGINT, what a shell reports for a Ctrl-C
EXIT_INTERRUPTED = 130

#: (module, class) of the errors that are bad input, status 2 (ValueError: SceneError,
#: NotConstantForceError, PaperError, PluginError among them): named, not imported, because
#: an error class can only have been raised once its module is loaded (see :func:`raised`)
BAD_INPUT = (("steplab.integrators", "UnknownIntegratorError"), ("builtins", "ValueError"))
#: the errors of a run that failed on good input, status 1. FloatingPointError: the contact
#: solver's state became non-finite inside a step
FAILED_RUN = (("steplab.integrators.simulate", "DivergenceError"),
              ("steplab.integrators.references", "ReferenceFailedError"),
              ("steplab.studies.recommend", "NoFixedStepError"),
              ("steplab.physics.collision.impact_cap", "ImpactCapError"), ("builtins", "FloatingPointError"))


def raised(err: BaseException, classes) -> bool:
    """``err`` is one of ``classes`` ((module, name) pairs); modules never imported are skipped."""
    loaded = tuple(getattr(sys.modules[m], n) for m, n in classes if m in sys.modules)
    return isinstance(err, loaded)


def fail(command: str | None, message: str, status: int) -> int:
    """Print one line (a message's own line breaks escaped) and return ``status``."""
    message = str(message).replace("\r", "\\r").replace("\n", "\\n")
    print(f"steplab {command}: error: {message}" if command else f"steplab: error: {message}", file=sys.stderr)
    return status
