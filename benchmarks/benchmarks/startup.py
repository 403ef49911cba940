"""Start-up: a command's imports and work, each in a fresh interpreter, beside a bare NumPy import.

asv's ``timeraw_*`` benchmarks return code that asv runs with ``timeit`` in a new Python
process, so every import is paid again; the interpreter's own start (about 20 ms) is
outside the timing, the floor every command shares is ``import numpy``. Targets (issue 29):
``--help``, ``scenes`` and ``integrators`` within 0.5 s, ``run projectile`` within 1.5 s.
The command's output goes to a buffer: asv reads the timing from the process's stdout.
"""

from __future__ import annotations

#: the commands timed, as argv lists
COMMANDS = {"help": ["--help"], "scenes": ["scenes"], "integrators": ["integrators"],
            "run_projectile": ["run", "projectile"]}


def command_code(argv: list[str]) -> str:
    """Python that runs ``steplab ARGV`` with its output discarded."""
    return ("import contextlib, io\nfrom steplab.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
            f"    try:\n        main({argv!r})\n    except SystemExit:\n        pass\n")


class Startup:
    params = (list(COMMANDS),)
    param_names = ["command"]
    number = 1
    repeat = 10
    warmup_time = 0

    def timeraw_command(self, command):
        return command_code(COMMANDS[command])


class Floor:
    """The floor under every command: NumPy's import in a fresh interpreter."""

    number = 1
    repeat = 10
    warmup_time = 0

    def timeraw_import_numpy(self):
        return "import numpy"
