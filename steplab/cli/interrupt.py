"""A Ctrl-C that cannot be lost: raised again every 0.1 s until the command has stopped.

Python raises a signal's KeyboardInterrupt in whatever Python code the main thread runs next.
When that code is a garbage-collection callback or a ``__del__``, the exception is printed as
"ignored" and dropped, and the command runs on to status 0. JAX runs such a callback at every
collection (``jax._src.lib._xla_gc_callback``, which frees XLA's buffers), and a command that is
tracing and compiling collects often, so under load a single Ctrl-C was lost now and then
(tests/test_reliability.py's interrupted runs). Here the first Ctrl-C also starts a 0.1 s timer
whose SIGALRM raises KeyboardInterrupt again, until ``main`` has caught one and stopped it; a
dropped one is not printed (it is not lost: the timer raises it again).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

#: how often a Ctrl-C is raised again until it has been caught (s)
REPEAT = 0.1


def _raise(signum, frame):
    if signum == signal.SIGINT:
        signal.setitimer(signal.ITIMER_REAL, REPEAT, REPEAT)
    # the timer's tick while ``main`` is already handling the interrupt (its except clause, before
    # it stops the timer): nothing more to raise
    elif isinstance(sys.exception(), KeyboardInterrupt):
        return
    raise KeyboardInterrupt


def stop_repeating():
    """The interrupt has been caught: no more ticks."""
    if threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, 0)


@contextlib.contextmanager
def sticky_interrupt():
    """Within: a Ctrl-C is raised again every :data:`REPEAT` s until caught (:func:`stop_repeating`).
    Only in the main thread of a system with interval timers; elsewhere Python's own handling."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        yield
        return
    before = signal.signal(signal.SIGINT, _raise), signal.signal(signal.SIGALRM, _raise), sys.unraisablehook

    def unraisable(info):
        if not issubclass(info.exc_type, KeyboardInterrupt):
            before[2](info)

    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        stop_repeating()
        signal.signal(signal.SIGINT, before[0])
        signal.signal(signal.SIGALRM, before[1])
        sys.unraisablehook = before[2]
