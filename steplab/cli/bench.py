"""``steplab bench``: steplab timed against diffrax, scipy, Numba and the memory bound (steplab/bench/)."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub, name: str) -> None:
    p = sub.add_parser(name, help="time steplab against diffrax, scipy, Numba and the memory bound")
    p.add_argument("--quick", action="store_true", help="fewer repeats and batches (under about a minute)")
    p.add_argument("--json", type=Path, metavar="FILE", help="write every ratio and the medians behind it to FILE")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown (docs/performance.md's)")
    p.add_argument("--from", dest="source", type=Path, metavar="FILE",
                   help="print the table of a record written by --json instead of running")


def command(args) -> int:
    from steplab.bench import command

    return command(args)
