"""The child process of :func:`.stacking.on_cores`: steplab's box pit timed on several cores.

``python -m steplab.bench.pit_child BOXES STEPS REPEATS CORES`` prints one line of JSON, the
record of :func:`timed_on_cores`. A module of its own, not ``-m steplab.bench.stacking``: the
package imports that one, and running an imported module as ``__main__`` runs it twice (Python
warns so on stderr).
"""

from __future__ import annotations

import json
import os
import sys

from steplab.core.timing import Times, interleaved_samples

from .stacking import box_pit, contenders


def timed_on_cores(boxes: int, steps: int, repeats: int, cores: int) -> dict:
    """The child of :func:`.stacking.on_cores`: widen to ``cores`` cores, time, return the record."""
    if hasattr(os, "sched_setaffinity"):  # the bench process gave it its one core
        try:
            os.sched_setaffinity(0, set(sorted(range(os.cpu_count() or 1))[:cores]))
        except OSError:
            pass
    import numba

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    runs, settings, _ = contenders(box_pit(boxes, threads=cores), {})
    samples = interleaved_samples({"steplab": lambda: runs["steplab"](steps)}, repeats)["steplab"]
    times = Times.of(samples)
    per_step = {"median": times.median / steps, "minimum": times.minimum / steps}
    if times.cpu is not None:
        per_step |= {"cpu_median": times.cpu.median / steps, "cpu_minimum": times.cpu.minimum / steps}
    return {"seconds_per_step": per_step, "steps": steps, "rounds": times.rounds, "settings": settings["steplab"],
            "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
            "solver_threads": cores, "numba_threads": int(numba.get_num_threads()),
            "threading_layer": numba.threading_layer(),
            "cpu_per_wall": times.threads,
            "load_average": [load, os.getloadavg()[0] if hasattr(os, "getloadavg") else None]}


if __name__ == "__main__":
    print(json.dumps(timed_on_cores(*(int(x) for x in sys.argv[1:5]))))
