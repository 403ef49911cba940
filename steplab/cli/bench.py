"""``steplab bench``: steplab timed against diffrax, scipy, Numba and the memory bound (steplab/bench/)."""

from __future__ import annotations

import argparse

from .args import Deferred, count, pathname

#: the most runs ``--repeat`` takes: each is a whole bench in a process of its own, one after another (about
#: a minute with --quick, 4 without), so 100 is hours, while a ratio's median settles in 10 (docs/performance.md)
MAX_REPEAT = 100


def _sections():
    from steplab.bench import section_names

    return section_names()


def repeat_count(text: str) -> int:
    """``--repeat``: a positive integer, at most MAX_REPEAT."""
    value = count(text)
    if value > MAX_REPEAT:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_REPEAT} (each run is a whole bench in a process of "
                                         f"its own, one after another), got {value}")
    return value


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="time steplab against diffrax, scipy, Numba and the memory bound")
    p.add_argument("--quick", action="store_true", help="fewer repeats and batches (under about a minute)")
    p.add_argument("--json", type=pathname, metavar="FILE", help="write every ratio and the medians behind it to FILE")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown (docs/performance.md's)")
    p.add_argument("--from", dest="source", type=pathname, metavar="FILE",
                   help="print the table of a record written by --json instead of running")
    p.add_argument("--only", action="append", choices=Deferred(_sections), metavar="SECTION",
                   help="run only this section (repeat for more), e.g. xpbd-cloth or ball-pits (a wrong name "
                        "lists them); a ratio that moves between runs, such as xpbd-cloth's, is judged over several")
    p.add_argument("--repeat", type=repeat_count, default=1, metavar="N",
                   help=f"run the bench N times (at most {MAX_REPEAT}), each in a process of its own, and print each "
                        "ratio's least, median and largest value and how many runs met its target (--json: every "
                        "run's record)")


def command(args) -> int:
    from steplab.bench import command

    return command(args)
