"""Start-up: a command's imports and work, each in a fresh interpreter, beside a bare NumPy import.

asv's ``timeraw_*`` benchmarks return code that asv runs with ``timeit`` in a new Python
process, so every import is paid again; the interpreter's own start is outside the
timing, and ``import numpy`` is the floor every command shares. The code and the targets
(issue 29: ``--help``, ``scenes``, ``integrators`` within 0.5 s, ``run projectile`` within
1.5 s) are ``steplab bench``'s (steplab/bench/startup.py).
"""

from __future__ import annotations

from steplab.bench.startup import COMMANDS, FLOOR, command_code


class Startup:
    params = (list(COMMANDS),)
    param_names = ["command"]
    number = 1
    repeat = 10
    warmup_time = 0

    def timeraw_command(self, command):
        return command_code(COMMANDS[command])


class Floor:
    number = 1
    repeat = 10
    warmup_time = 0

    def timeraw_import_numpy(self):
        return FLOOR
