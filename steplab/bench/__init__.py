"""``steplab bench``: steplab side by side with diffrax, scipy, Numba and the memory bound.

Each comparison runs the same method with the same dt and the same number of steps (the
accuracy-matched ones instead reach the same final error), in this one process. Every
contender is compiled and called once before timing; then the contenders are called in
turn, round after round, and each one's median is taken, so a burst of load from
elsewhere on the machine hits all of them alike. A ratio is steplab's median over the
peer's: below 1, steplab is faster. Each comparison also records how far apart the two
final states are, to show they computed the same thing.

The targets of issue 6 are reported as met or missed, never asserted: timings belong
in a benchmark, not in a unit test.

The package, one job a module: :mod:`.config` (sizes, targets), :mod:`.comparisons` (the
sections), :mod:`.systems` (the large models), :mod:`.profile` (loop kernels from the
compiled text), :mod:`.record` and :mod:`.report` (the JSON record and its tables);
:mod:`.collisions` (the ball pits, issue 13) with :mod:`.ball_pit_scene` (the scene) and
:mod:`.engines` (MuJoCo and pybullet, when installed); the timer is the studies'
(:mod:`steplab.core.timing`), run by :mod:`.timing` with one thread per side until the
minimums settle.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

from steplab.core.records import RECORD_ERRORS, make_folder, write_json
from steplab.core.timing import Times as Times
from steplab.core.timing import interleaved_medians as interleaved_medians
from steplab.core.timing import interleaved_samples as interleaved_samples
from steplab.core.timing import interleaved_times as interleaved_times

from .ball_pit_scene import ball_pit as ball_pit
from .ball_pit_scene import ball_pit_toml as ball_pit_toml
from .ball_pit_scene import mujoco_model as mujoco_model
from .comparisons import SECTIONS as SECTIONS
from .config import COMPILE_TARGET_SECONDS as COMPILE_TARGET_SECONDS
from .config import FULL as FULL
from .config import QUICK as QUICK
from .config import REAL_TIME_TARGETS as REAL_TIME_TARGETS
from .config import REQUIRED_RATIOS as REQUIRED_RATIOS
from .config import SEED as SEED
from .config import TARGETS as TARGETS
from .config import Config as Config
from .profile import loop_kernels as loop_kernels
from .record import Record as Record
from .report import format_markdown as format_markdown
from .report import format_table as format_table
from .report import rows as rows
from .systems import cloth_model as cloth_model
from .systems import particles_model as particles_model
from .systems import step_bytes as step_bytes
from .timing import pin_threads as pin_threads
from .timing import thread_settings as thread_settings


def section_name(section: Callable) -> str:
    """A section's name on the command line (``--only``): its function's, hyphenated (``xpbd-cloth``)."""
    return section.__name__.replace("_", "-")


def section_names() -> tuple[str, ...]:
    """The sections ``steplab bench --only`` takes, in the order a run takes them."""
    return tuple(section_name(section) for section in SECTIONS)


def run_bench(config: Config, quick: bool = False, progress: Callable[[str], None] | None = None,
              only: list[str] | None = None) -> dict:
    """Run every comparison, or only the sections named in ``only`` (:func:`section_names`); returns the
    record ``--json`` writes (its ``details["only"]``: the sections run, None for all)."""
    from steplab.studies.runner import provenance

    progress = progress or (lambda message: None)
    unknown = sorted(set(only or ()) - set(section_names()))
    if unknown:
        raise ValueError(f"bench: no section {', '.join(unknown)}; the sections: {', '.join(section_names())}")
    chosen = [section for section in SECTIONS if only is None or section_name(section) in only]
    record = Record(config, quick)
    record.data["details"]["only"] = None if only is None else [section_name(section) for section in chosen]
    start = time.perf_counter()
    for section in chosen:
        begin = time.perf_counter()
        section(config, record, progress)
        record.data["details"].setdefault("section_seconds", {})[section.__name__] = time.perf_counter() - begin
    record.data["details"]["total_seconds"] = time.perf_counter() - start
    # what Equinox actually runs with (it reads EQX_ON_ERROR once, when first imported)
    from equinox import _config as equinox_config

    record.data["details"]["EQX_ON_ERROR"] = getattr(equinox_config, "EQX_ON_ERROR", None)
    record.data["details"]["threads"] = thread_settings()
    record.data["provenance"] = provenance()
    return record.data


def fair_diffrax() -> None:
    """Turn off Equinox's run-time error checks for this process, as diffrax's FAQ asks.

    When comparing with other JAX code, the FAQ says to set ``EQX_ON_ERROR=nan`` before
    Equinox is imported: Equinox reads it once, at import, so this only acts before any
    diffrax use (the record says what Equinox actually ran with). Only ``steplab bench``, a process of its
    own, calls it: elsewhere diffrax must keep raising on a failed solve.
    """
    if "equinox" not in sys.modules:
        os.environ.setdefault("EQX_ON_ERROR", "nan")


#: the fields ``--from`` needs: a run's record (``--json``), or ``--repeat``'s
RECORD_FIELDS = (("order", "seconds", "ratios", "targets"), ("runs", "summary"))


def read_record(path: Path) -> dict:
    """The record ``steplab bench --json`` wrote to ``path`` (a run's or ``--repeat``'s), for ``--from``;
    any other file is refused in one line that says what it is not."""
    try:
        record = json.loads(path.read_text())
    except ValueError as err:  # not JSON, or not text
        raise ValueError(f"--from {path}: not JSON ({err})") from None
    if not (isinstance(record, dict) and any(all(k in record for k in keys) for keys in RECORD_FIELDS)):
        raise ValueError(f"--from {path}: not a record of `steplab bench --json` (a run's has the fields "
                         f"{', '.join(RECORD_FIELDS[0])}; --repeat's {', '.join(RECORD_FIELDS[1])})")
    for key, value in _ratios(record):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"--from {path}: {key} is {json.dumps(value)}, not a finite number (a ratio: "
                             "steplab's median seconds over the peer's)")
    return record


def _ratios(node, key: str = "", ratios: bool = False):
    """``(key, value)`` of every ratio in a bench record, keys dotted from the top: each value of a
    ``ratios`` table or list (``ratios.<name>``, --repeat's ``summary[0].ratios[2]``), each ``ratio``,
    each ``ratio_*`` but ``ratio_stable`` that is not null (``ratio_cpu`` is null where a side kept no
    CPU seconds), and --repeat's ``summary[i]`` min, median and max."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for name, value in items:
        here = f"{key}[{name}]" if isinstance(name, int) else f"{key}.{name}" if key else name
        if isinstance(value, (dict, list)):
            yield from _ratios(value, here, ratios=name == "ratios")
        elif ratios or name == "ratio" or (key.startswith("summary[") and name in ("min", "median", "max")):
            yield here, value
        elif isinstance(name, str) and name.startswith("ratio_") and name != "ratio_stable" and value is not None:
            yield here, value


def command(args) -> int:
    """``steplab bench``: run (or, with ``--from``, re-print) the comparisons, one thread per side."""
    from .repeat import format_summary, run_repeated

    if args.source is not None:  # what only a run takes: given with --from, it did nothing, silently
        running = [name for name, given in (("--repeat", args.repeat > 1), ("--json", args.json is not None),
                                            ("--only", args.only)) if given]
        if running:
            raise ValueError(f"{' and '.join(running)} {'is' if len(running) == 1 else 'are'} for a run of the bench "
                             "and --from prints a record without running: give one of them")
    log = (lambda message: print(f"[bench] {message}", file=sys.stderr, flush=True))
    writes = args.source is None and args.json is not None
    if writes:  # a path that cannot be written fails now, not after the runs
        if Path(args.json).is_dir():
            raise ValueError(f"--json {args.json}: a folder; give the record's file name")
        make_folder(Path(args.json).parent, "--json's folder")
    if args.source is not None:
        record = read_record(args.source)
    elif args.repeat > 1:  # the parent times nothing: its runs pin themselves, as a plain run does
        record = run_repeated(args.repeat, args.quick, args.only, log)
        if record is None:  # a run failed and said why on stderr
            return 1
    else:
        fair_diffrax()
        pin_threads()
        record = run_bench(QUICK if args.quick else FULL, quick=args.quick, progress=log, only=args.only)
    if writes:
        write_json(args.json, record)
    try:
        if "runs" in record and "summary" in record:  # a --repeat record
            text = format_summary(record, markdown=args.markdown)
        else:
            text = format_markdown(record) if args.markdown else format_table(record)
    except RECORD_ERRORS as err:
        if args.source is None:
            raise
        # a record cut short or edited, or written by a steplab whose records had other fields
        raise ValueError(f"--from {args.source}: a bench record without what its table needs "
                         f"({type(err).__name__}: {err})") from None
    print(text)
    return 0
