"""``steplab study`` and ``steplab reproduce``: studies into records, with progress as they run.

In a terminal a bar (on stderr) counts the tasks of the study running; one line per study
goes to stdout the moment it finishes, so ``steplab reproduce > log`` shows its progress as
it goes. The summary table of every study follows at the end, as before.
"""

from __future__ import annotations

import time
from pathlib import Path

from .args import study_arguments
from .table import table


def add_parser(sub, name: str) -> None:
    if name == "study":
        p = sub.add_parser(name, help="run one study (see --list)")
        p.add_argument("name", nargs="?", help="study name")
        p.add_argument("--list", action="store_true", help="list the studies")
    else:
        p = sub.add_parser(name, help="run every study and write the results")
    study_arguments(p)


def command(args) -> int:
    from steplab.studies import STUDIES, builtin_studies

    if args.command == "study":
        if args.list or args.name is None:
            print(table([(name, study.title + ("" if STUDIES.origin(name) == "steplab"
                                               else f" [plugin: {STUDIES.origin(name)}]"))
                         for name, study in STUDIES.items()]))
            return 0
        if args.name not in STUDIES:
            raise ValueError(f"unknown study {args.name!r}; valid: {', '.join(STUDIES)}")
        reason = STUDIES[args.name].unavailable()
        if reason:  # an optional package missing: the line says how to install it
            raise ValueError(reason)
        studies = [STUDIES[args.name]]
    else:  # steplab's own studies, the paper's records; a plugin's study runs by name
        studies = []
        for study in builtin_studies():
            reason = study.unavailable()
            if reason:
                print(f"{study.name}: skipped: {reason}", flush=True)
            else:
                studies.append(study)
    finished = _Finished(len(studies))
    if args.workers or args.scheduler:
        from steplab.cluster import connect
        from steplab.studies.distributed import run_studies

        with connect(args.workers, args.scheduler) as client:
            records = run_studies(studies, args.out, client, quick=args.quick, force=args.force, finished=finished)
    else:
        records = [_run(study, args, finished) for study in studies]
    print_summary(records, args.out)
    return 0


class _Finished:
    """Called with each record as its study finishes: one line on stdout, flushed, with the
    study's own wall and CPU seconds where it ran in this process (the CPU seconds hardly move
    with the machine's load, the wall seconds do)."""

    def __init__(self, total: int):
        self.total, self.done, self.start = total, 0, time.perf_counter()

    def __call__(self, record: dict, seconds: tuple[float, float] | None = None) -> None:
        self.done += 1
        state = "cached" if record.get("cached") else "computed"
        own = "" if seconds is None else f" in {seconds[0]:.1f} s ({seconds[1]:.1f} s CPU)"
        print(f"[{self.done}/{self.total}] {record['study']}: {state}{own}, {time.perf_counter() - self.start:.0f} s "
              "since the start", flush=True)


def _run(study, args, finished) -> dict:
    """One study in this process, with a bar over its tasks (or its compute's steps) in a terminal."""
    from tqdm import tqdm

    from steplab.core.timing import cpu_seconds
    from steplab.studies import run_study

    total = len(study.tasks(study.parameters(args.quick))) if study.tasks is not None else None
    wall, cpu = time.perf_counter(), cpu_seconds()
    with tqdm(total=total, desc=f"{study.name} ({finished.done + 1}/{finished.total})", unit="task",
              disable=None, leave=False) as bar:
        record = run_study(study, args.out, quick=args.quick, force=args.force, progress=bar.update)
    finished(record, (time.perf_counter() - wall, cpu_seconds() - cpu))
    return record


def print_summary(records, out: Path) -> None:
    from steplab.studies import STUDIES

    for record in records:
        state = "cached" if record.get("cached") else "computed"
        print(f"{record['study']} ({state}): {record['title']}")
        rows = STUDIES[record["study"]].summary(record)
        if rows:
            print(table(rows, indent="  "))
        for figure in record.get("figures", []):
            print(f"  figure: {figure}")
        print(f"  record: {Path(out) / (record['study'] + '.json')}")
