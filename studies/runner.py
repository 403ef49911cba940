"""Running studies: parameters -> record (JSON) -> figures, cached, resumable, atomic.

A :class:`Study` is three plain functions: ``parameters(quick)`` gives the parameters,
``compute(parameters, progress)`` turns them into a JSON-able record (all the numbers),
and ``plot(record, out)`` draws figures from the record alone. The runner adds
provenance, writes the figures and then the JSON (each atomically, JSON last), and
skips a study whose JSON carries the same cache key: a hash of its parameters and of
steplab's source code. So an interrupted ``steplab reproduce`` resumes where it
stopped, and a change to the code or the parameters re-runs what it affects.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import platform
import subprocess
from collections.abc import Callable
from pathlib import Path

from steplab.io import remove_temporary_files, write_json

#: packages whose source is part of every study's cache key
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


def source_hash(root: Path | None = None) -> str:
    """SHA-256 of the source files of steplab's model, integrators and studies (under ``root``,
    default: this checkout)."""
    root = Path(root) if root is not None else Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for package in SOURCE_PACKAGES:
        for path in sorted((root / package).rglob("*")):
            if path.suffix in (".py", ".toml") and "__pycache__" not in path.parts:
                digest.update(str(path.relative_to(root)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_key(name: str, parameters: dict) -> str:
    text = json.dumps({"study": name, "parameters": parameters}, sort_keys=True)
    return hashlib.sha256((text + source_hash()).encode()).hexdigest()


def is_cached(study: Study, out: Path, quick: bool) -> bool:
    """True when ``out/<name>.json`` and its figures are from the same parameters and code."""
    path = out / f"{study.name}.json"
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(record, dict) or record.get("cache_key") != cache_key(study.name, study.parameters(quick)):
        return False
    figures = record.get("figures", [])
    return isinstance(figures, list) and all(isinstance(f, str) and (out / f).is_file() for f in figures)


def run_study(study: Study, out: Path, quick: bool = False, force: bool = False, progress=None) -> dict:
    """Run one study into ``out`` (unless cached) and return its record."""
    out = Path(out)
    if out.is_dir():  # what a run killed by SIGKILL left half-written
        remove_temporary_files(out)
    if not force and is_cached(study, out, quick):
        record = json.loads((out / f"{study.name}.json").read_text())
        record["cached"] = True
        return record
    parameters = study.parameters(quick)
    record = study.compute(parameters, progress=progress)
    record.update(study=study.name, title=study.title, parameters=parameters,
                  provenance=provenance(), cache_key=cache_key(study.name, parameters))
    record["figures"] = study.plot(record, out)
    write_json(out / f"{study.name}.json", record)  # last: its presence means "complete"
    record["cached"] = False
    return record


def provenance() -> dict:
    """Where a record came from: versions, commit, machine, date."""
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
    }


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
