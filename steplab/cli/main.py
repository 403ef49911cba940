"""The parser (one sub-parser per command module) and ``main``: status codes, never a traceback."""

from __future__ import annotations

import importlib
import os
import signal
import sys
import warnings
from pathlib import Path

from . import compile_notice
from .args import Parser
from .errors import BAD_INPUT, EXIT_BAD_INPUT, EXIT_DIVERGED, EXIT_INTERRUPTED, FAILED_RUN, fail, raised
from .interrupt import sticky_interrupt, stop_repeating

#: each command's module in this package, in the order ``steplab --help`` lists them; each has
#: ``add_parser(sub)`` (which imports nothing heavy) and ``command(args) -> status``
COMMANDS = {"integrators": "listing", "scenes": "listing", "run": "run", "check": "check", "animate": "animate",
            "paper": "paper", "report": "paper", "recommend": "recommend", "study": "study",
            "reproduce": "study", "export": "export", "bench": "bench"}


def _module(command: str):
    return importlib.import_module(f".{COMMANDS[command]}", __package__)


def build_parser() -> Parser:
    import steplab

    parser = Parser(prog="steplab", description="How wrong, how unstable and how slow is a "
                    "game-physics step? Integrators, scenes and studies.")
    parser.add_argument("--version", action="version", version=f"steplab {steplab.__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for command in COMMANDS:
        _module(command).add_parser(sub, command)
    return parser


def main(argv=None) -> int:
    try:
        with sticky_interrupt():  # Ctrl-C anywhere from here on: one line and status 130, never lost
            return _main(argv)
    finally:
        if argv is None:  # the command itself, not a call from Python: the work is done, so a Ctrl-C
            # now (during the interpreter's shutdown) would only print a traceback after the result
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _main(argv) -> int:
    # a name that is not UTF-8 (a surrogate escape from argv) prints escaped, never crashes
    if callable(getattr(sys.stdout, "reconfigure", None)):
        sys.stdout.reconfigure(errors="backslashreplace")
    command = None
    try:  # Ctrl-C anywhere from here on ends with one line and status 130, never a traceback
        args = build_parser().parse_args(argv)
        command = args.command
        compile_notice.arm()  # a line on a terminal when a first run compiles for long
        import numpy as np

        from steplab.core.registry import PluginWarning

        # runs detect non-finite states themselves: no floating-point warnings on stderr;
        # a skipped plugin is one warning line, not a warning with its source line
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.showwarning = _show_warning
            warnings.simplefilter("default", PluginWarning)
            return _run_command(args)
    except KeyboardInterrupt:
        stop_repeating()
        return fail(command, "interrupted", EXIT_INTERRUPTED)


def _run_command(args) -> int:
    # `--integrator package.module:Name` finds a module of the current folder, as `python -m`
    # would; appended, never first, so a folder there never shadows an installed package
    if str(Path.cwd()) not in sys.path:
        sys.path.append(str(Path.cwd()))
    try:
        return _module(args.command).command(args) or 0
    except BrokenPipeError:  # `steplab scenes | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 0
    except OSError as err:  # an unwritable --out or results folder, a full disk
        where = f"{err.filename}: " if err.filename else ""
        return fail(args.command, f"{where}{err.strerror or err}", EXIT_BAD_INPUT)
    except MemoryError:
        return fail(args.command, "out of memory (try a smaller scene, a shorter run or --save-every)",
                    EXIT_BAD_INPUT)
    except Exception as err:
        if raised(err, BAD_INPUT):
            return fail(args.command, str(err), EXIT_BAD_INPUT)
        if raised(err, FAILED_RUN):
            return fail(args.command, str(err), EXIT_DIVERGED)
        raise


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """A plugin warning as one line on stderr; any other warning as Python prints it."""
    from steplab.core.registry import PluginWarning

    if issubclass(category, PluginWarning):
        print(f"steplab: warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
