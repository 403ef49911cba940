"""One line on stderr while Numba compiles for long, so that a machine's first run does not look hung.

steplab's kernels are compiled on their first use and cached beside the sources. On a fresh
install the first run of a box scene compiles the contact solver and the narrow phase for about
70 s (2 cores), the event loop's first run about 12 s, and nothing says why the progress bar
stands still. The command line therefore watches Numba's compile events (``numba:compile``, which
fire on a cache miss only) and, once compiling has gone on for :data:`AFTER` seconds, says so
once: what is happening, that it happens once, and where the result is kept.

Only where stderr is a terminal (a log, a pipe and the tests get no such line), and without
importing Numba: the watch is set when Numba is first imported (:func:`arm`), so commands that
never compile (``--help``, ``scenes``, a run without collisions) start as fast as before.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
import threading

#: seconds of compiling before the line is printed: shorter compiles pass unannounced
AFTER = 2.0
MESSAGE = ("steplab: compiling its Numba kernels (the first run on this machine, or after an update: up to "
           "two minutes; cached beside the sources afterwards)")


class CompileNotice:
    """A listener of Numba's ``numba:compile`` events that writes :data:`MESSAGE` to ``stream`` once, when a
    compile has been under way for ``after`` seconds (a timer armed at the first compile after a quiet spell)."""

    def __init__(self, stream, after: float = AFTER):
        self.stream, self.after = stream, after
        self.depth, self.timer, self.said = 0, None, False
        self.lock = threading.Lock()

    def on_start(self, event) -> None:
        with self.lock:
            self.depth += 1
            if self.timer is None and not self.said:
                self.timer = threading.Timer(self.after, self._say)
                self.timer.daemon = True
                self.timer.start()

    def on_end(self, event) -> None:
        with self.lock:
            self.depth -= 1

    def _say(self) -> None:
        with self.lock:
            self.timer = None  # a quiet spell: the next compile arms it again
            if self.depth <= 0 or self.said:
                return
            self.said = True
        from tqdm import tqdm

        tqdm.write(MESSAGE, file=self.stream)  # above a progress bar, if one is drawn

    def register(self) -> CompileNotice:
        """Listen to Numba's compile events from now on (imports Numba's event module)."""
        from numba.core import event

        class Listener(event.Listener):
            def on_start(_, ev):
                self.on_start(ev)

            def on_end(_, ev):
                self.on_end(ev)

        event.register("numba:compile", Listener())
        return self


class _AfterNumba(importlib.abc.MetaPathFinder):
    """Registers ``notice`` as soon as ``numba`` itself has been imported (and only then)."""

    def __init__(self, notice: CompileNotice):
        self.notice = notice

    def find_spec(self, name, path, target=None):
        if name != "numba":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        execute, notice = spec.loader.exec_module, self.notice

        def exec_module(module):
            execute(module)
            notice.register()

        spec.loader.exec_module = exec_module
        return spec


#: the process's notice, once armed (``main`` called again from Python arms nothing more)
_armed: list = []


def arm(stream=None) -> CompileNotice | None:
    """Watch Numba's compiles when ``stream`` (default stderr) is a terminal: the notice, or None."""
    stream = sys.stderr if stream is None else stream
    if not getattr(stream, "isatty", lambda: False)():
        return None
    if _armed:
        return _armed[0]
    notice = CompileNotice(stream, AFTER)
    _armed.append(notice)
    if "numba" in sys.modules:
        return notice.register()
    sys.meta_path.insert(0, _AfterNumba(notice))
    return notice
