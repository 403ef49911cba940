"""Running studies: parameters -> record (JSON) -> figures, cached, resumable, atomic.

A :class:`Study` is three plain functions: ``parameters(quick)`` gives the parameters,
``compute(parameters, progress)`` turns them into a JSON-able record (all the numbers),
and ``plot(record, out)`` draws figures from the record alone; its ``tables`` are the
tables ``steplab paper`` prints from the record (studies/tables.py). The runner adds
provenance, writes the figures and then the JSON (each atomically, through
steplab/core/records.py, JSON last), and skips a study whose JSON carries the same cache
key: a hash of its parameters and of the source code it runs (physics, integrators and the study modules it uses). So an
interrupted ``steplab reproduce`` resumes where it stopped, and a change to the code or
the parameters re-runs what it affects.

A study may instead give its sweep as independent tasks and a reduction (``tasks``,
``task``, ``reduce``): then ``compute`` is those run in turn, each finished task is kept on
disk until the record is written (studies/task_cache.py), so an interrupted study resumes
task by task, and studies/distributed.py spreads the same tasks over a Dask cluster.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import platform
import subprocess
import sys
import types
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from steplab.core.records import RECORD_ERRORS, make_folder, remove_temporary_files, write_json

from .tables import Table
from .task_cache import TaskCache, as_json

#: packages whose source is part of the cache keys (of studies: the modules a study uses)
SOURCE_PACKAGES = ("physics", "integrators", "studies")


@dataclasses.dataclass(frozen=True)
class Study:
    name: str
    title: str
    parameters: Callable[[bool], dict]
    compute: Callable[..., dict]
    plot: Callable[[dict, Path], list[str]]
    #: ``summary(record) -> [(label, value), ...]`` for the table ``reproduce`` prints
    summary: Callable[[dict], list[tuple[str, str]]] = lambda record: []
    #: the tables ``steplab paper`` prints from this study's record (studies/tables.py)
    tables: tuple[Table, ...] = ()
    #: ``unavailable() -> str | None``: why the study cannot run here (an optional package
    #: missing, with how to install it); ``steplab reproduce`` skips it with that line
    unavailable: Callable[[], str | None] = lambda: None
    #: the sweep as independent tasks, which the serial runner (:func:`run_tasks`) and the
    #: distributed one (studies/distributed.py) share: ``tasks(parameters) -> [item, ...]``
    #: (JSON values), ``task(parameters, item) -> result`` (a JSON value, and a pure function
    #: of its arguments: the same bytes on any worker) and ``reduce(parameters, results) ->
    #: record`` (the results in the items' order). Without them the study runs ``compute`` whole.
    tasks: Callable[[dict], list] | None = None
    task: Callable[[dict, Any], Any] | None = None
    reduce: Callable[[dict, list], dict] | None = None
    #: ``timed(item)``: True for a task that measures run time; on a cluster it runs alone,
    #: after every other task, in the process that started the run. (A study not given as
    #: tasks, such as the timing studies work-precision and broadphase, runs that way whole.)
    timed: Callable[[Any], bool] = lambda item: False


def source_hash(root: Path | None = None, studies: Iterable[str] | None = None) -> str:
    """SHA-256 of the source files of steplab's model and integrators, and of ``studies``
    (module names such as ``steplab.studies.stability``; default: the whole studies package), under
    ``root`` (default: this checkout)."""
    root = Path(root) if root is not None else Path(__file__).resolve().parent.parent
    files = []
    for package in SOURCE_PACKAGES if studies is None else ("physics", "integrators"):
        files += sorted(p for p in (root / package).rglob("*")
                        if p.suffix in (".py", ".toml") and "__pycache__" not in p.parts)
    if studies is not None:
        files += [root / "studies" / f"{name.split('.')[-1]}.py" for name in sorted(studies)]
    digest = hashlib.sha256()
    for path in files:
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def study_modules(study: Study) -> set[str]:
    """The modules of the studies package a study's code uses: its own and, through their
    imports, every one they reach (found from the imported names, so nothing is listed by hand)."""
    seen, todo = set(), [study.compute.__module__]
    while todo:
        name = todo.pop()
        if name in seen or name not in sys.modules:
            continue
        seen.add(name)
        for value in vars(sys.modules[name]).values():
            used = value.__name__ if isinstance(value, types.ModuleType) else getattr(value, "__module__", None)
            if isinstance(used, str) and used.startswith("steplab.studies."):
                todo.append(used)
    return {name for name in seen if name.startswith("steplab.studies.")}


def cache_key(study: Study, parameters: dict) -> str:
    """Hash of the parameters and of the code the study runs: physics, integrators and the
    study modules it uses, so an edit to one study does not invalidate the others."""
    text = json.dumps({"study": study.name, "parameters": parameters}, sort_keys=True)
    return hashlib.sha256((text + source_hash(studies=study_modules(study))).encode()).hexdigest()


def is_cached(study: Study, out: Path, quick: bool) -> bool:
    """True when ``out/<name>.json`` and its figures are from the same parameters and code."""
    path = out / f"{study.name}.json"
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(record, dict) or record.get("cache_key") != cache_key(study, study.parameters(quick)):
        return False
    figures = record.get("figures", [])
    if not (isinstance(figures, list) and all(isinstance(f, str) and (out / f).is_file() for f in figures)):
        return False
    try:  # a record whose fields were cut or edited is no cache: its summary would be a traceback
        study.summary(record)
    except RECORD_ERRORS:
        return False
    return True


def run_study(study: Study, out: Path, quick: bool = False, force: bool = False, progress=None) -> dict:
    """Run one study into ``out`` (unless cached) and return its record."""
    out = make_folder(out, "results folder")
    remove_temporary_files(out)  # what a run killed by SIGKILL left half-written
    if not force and is_cached(study, out, quick):
        record = json.loads((out / f"{study.name}.json").read_text())
        record["cached"] = True
        return record
    parameters = study.parameters(quick)
    key = cache_key(study, parameters)  # of the source as the study starts: an edit meanwhile re-runs it
    if study.tasks is None:
        return finish(study, parameters, key, study.compute(parameters, progress=progress), out)
    cache = TaskCache(out, study.name, key, fresh=force)  # each finished task, until the record is written
    record = finish(study, parameters, key, run_tasks(study, parameters, progress, cache), out)
    cache.clear()
    return record


def run_tasks(study: Study, parameters: dict, progress=None, cache: TaskCache | None = None) -> dict:
    """A study given as tasks, in this process: each task in turn (or its result from ``cache``),
    then the reduction into the record."""
    results = []
    for item in study.tasks(parameters):
        found, result = cache.load(item) if cache is not None else (False, None)
        if not found:
            result = study.task(parameters, item)
            result = cache.store(item, result) if cache is not None else as_json(result)
        results.append(result)
        if progress is not None:
            progress()
    return study.reduce(parameters, results)


def finish(study: Study, parameters: dict, key: str, record: dict, out: Path, cluster: dict | None = None) -> dict:
    """Add what a record says about itself, draw its figures and write it (last: its presence
    means "complete"). ``cluster``: where its tasks ran, when not in this process alone."""
    record.update(study=study.name, title=study.title, parameters=parameters,
                  provenance=provenance(cluster), cache_key=key)
    record["figures"] = study.plot(record, out)
    write_json(out / f"{study.name}.json", record)
    record["cached"] = False
    return record


def provenance(cluster: dict | None = None) -> dict:
    """Where a record came from: versions, commit, machine, date (and the cluster, if one ran it)."""
    from importlib.metadata import PackageNotFoundError, version

    def ver(package):
        try:
            return version(package)
        except PackageNotFoundError:
            return None

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                                cwd=Path(__file__).parent).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {
        "steplab": ver("steplab"), "git_commit": commit,
        "packages": {p: ver(p) for p in ("numpy", "scipy", "jax", "diffrax", "matplotlib")},
        "python": platform.python_version(), "cpu": _cpu_name(), "machine": platform.machine(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    } | ({} if cluster is None else {"cluster": cluster})


def _cpu_name(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The CPU's model name, with its family and model numbers and widest vector extension where
    /proc/cpuinfo gives them: a virtual machine may call two generations alike ("AMD EPYC"),
    and the compiled kernels' speed depends on which (AVX-512 or AVX2: docs/performance.md)."""
    try:
        first = cpuinfo.read_text().split("\n\n", 1)[0]  # the first processor's block
    except OSError:
        first = ""
    fields = {name.strip(): value.strip() for name, _, value in (line.partition(":") for line in first.splitlines())}
    if "model name" not in fields:
        return platform.processor() or platform.machine()
    flags = fields.get("flags", "").split()
    known = {"cpu family", "model"} <= fields.keys()
    about = [f"family {fields['cpu family']} model {fields['model']}"] if known else []
    about += [v for f, v in (("avx512f", "AVX-512"), ("avx2", "AVX2")) if f in flags][:1]
    return fields["model name"] + (f" ({', '.join(about)})" if about else "")
