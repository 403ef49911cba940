"""The command line's line on stderr while Numba compiles for long (steplab/cli/compile_notice.py)."""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap
import time

from steplab.cli import compile_notice
from steplab.cli.compile_notice import MESSAGE, CompileNotice


class Terminal(io.StringIO):
    def isatty(self):
        return True


def wait_for(predicate, seconds=10.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end and not predicate():
        time.sleep(0.01)
    return predicate()


def test_a_long_compile_is_announced_once_on_the_terminal():
    stream = Terminal()
    notice = CompileNotice(stream, after=0.05)
    for _ in range(2):  # two long compiles: one line
        notice.on_start(None)
        assert wait_for(lambda: MESSAGE in stream.getvalue())
        notice.on_end(None)
    time.sleep(0.2)
    assert stream.getvalue() == MESSAGE + "\n"


def test_compiles_shorter_than_the_wait_say_nothing_and_a_later_long_one_is_announced():
    stream = Terminal()
    notice = CompileNotice(stream, after=0.5)
    notice.on_start(None)
    notice.on_end(None)  # done before the timer fires
    time.sleep(1.0)
    assert stream.getvalue() == ""
    notice.on_start(None)  # the timer is armed again
    assert wait_for(lambda: stream.getvalue() == MESSAGE + "\n")
    notice.on_end(None)


def test_nothing_is_watched_where_stderr_is_not_a_terminal():
    before = list(sys.meta_path)
    assert compile_notice.arm(io.StringIO()) is None
    assert sys.meta_path == before


def test_the_watch_waits_for_numbas_import_and_then_hears_its_compiles():
    """In a fresh process: arming imports no Numba (the commands that never compile start as fast);
    importing it registers the listener, and a compile that outlasts the wait prints the line."""
    code = textwrap.dedent("""
        import io, sys, time
        from steplab.cli import compile_notice
        class Terminal(io.StringIO):
            def isatty(self):
                return True
        stream = Terminal()
        compile_notice.AFTER = 0.0  # any compile is long enough
        notice = compile_notice.arm(stream)
        assert notice is not None and "numba" not in sys.modules
        from numba import njit
        njit(lambda x: x + 1)(1)  # not cached: compiled now
        end = time.monotonic() + 10
        while time.monotonic() < end and not stream.getvalue():
            time.sleep(0.01)
        print(repr(stream.getvalue()))
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == repr(MESSAGE + "\n")


def test_arming_again_watches_with_the_first_notice(monkeypatch):
    """``main`` called twice from Python, on a terminal: one notice, one listener."""
    import numba  # noqa: F401  (imported: the notice registers at once, no import hook is left behind)

    monkeypatch.setattr(compile_notice, "_armed", [])
    registered = []
    monkeypatch.setattr(CompileNotice, "register", lambda self: registered.append(self) or self)
    first, second = compile_notice.arm(Terminal()), compile_notice.arm(Terminal())
    assert first is second and registered == [first]  # Numba is imported here: registered at once
