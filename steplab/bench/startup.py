"""Start-up: each light command in a fresh interpreter, beside a bare ``import numpy`` (issue 29).

A command's time here is its imports and its work, run with ``timeit`` in a new Python
process, without the interpreter's own start (about 20 ms); ``import numpy``, the floor
every command shares, is timed the same way. The processes run interleaved, round after
round, and each one's minimum is kept: a fresh process is cheap, and its noise is all
upward. asv times the same code (benchmarks/benchmarks/startup.py).
"""

from __future__ import annotations

import subprocess
import sys

#: the commands timed, as argv lists, and their targets (s)
COMMANDS = {"--help": ["--help"], "scenes": ["scenes"], "integrators": ["integrators"],
            "run projectile": ["run", "projectile"]}
TARGETS = {"--help": 0.5, "scenes": 0.5, "integrators": 0.5, "run projectile": 1.5}
#: the floor under every command
FLOOR = "import numpy"


def command_code(argv: list[str]) -> str:
    """Python that runs ``steplab ARGV`` with its output discarded (asv reads stdout for its timing)."""
    return ("import contextlib, io\nfrom steplab.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
            f"    try:\n        main({argv!r})\n    except SystemExit:\n        pass\n")


def fresh_process_seconds(code: str) -> float:
    """Seconds ``code`` takes in a new interpreter (its start excluded)."""
    timed = f"import time\n_start = time.perf_counter()\n{code}\nprint(time.perf_counter() - _start)\n"
    done = subprocess.run([sys.executable, "-c", timed], capture_output=True, text=True, check=True)
    return float(done.stdout.split()[-1])


def startup(config, record, progress) -> None:
    """The minimum over 2 x ``config.repeats`` interleaved rounds of each command and of the floor."""
    codes = {FLOOR: FLOOR} | {name: command_code(argv) for name, argv in COMMANDS.items()}
    best = dict.fromkeys(codes, float("inf"))
    for _ in range(2 * config.repeats):
        for name, code in codes.items():
            best[name] = min(best[name], fresh_process_seconds(code))
    record.data["startup_seconds"] = best
    for name, target in TARGETS.items():
        record.data["targets"][f"startup {name}"] = {"target": target, "seconds": best[name],
                                                      "met": best[name] <= target}
    progress("start-up: done")


def footer(record: dict) -> list[str]:
    """The report's line: each command's time, its target, and the floor."""
    seconds = record.get("startup_seconds")
    if not seconds:
        return []
    timed = ", ".join(f"{name} {seconds[name]:.2f} s (≤ {target:g}: "
                      f"{'met' if seconds[name] <= target else 'missed'})" for name, target in TARGETS.items())
    return [f"start-up, fresh process, min of {2 * record['config']['repeats']}: {timed}; "
            f"{FLOOR} {seconds[FLOOR]:.2f} s"]
