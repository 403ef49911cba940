"""Each finished task of a study's sweep, kept on disk until the study's record is written.

A study given as tasks (:class:`studies.runner.Study`: ``tasks``, ``task``, ``reduce``) has
its results stored one file per task, ``<out>/.tasks/<study>/<key>.json``, where the key
hashes the study's cache key (its parameters and the source it runs) with the task's item.
A run that is interrupted, or loses a worker, keeps every task that finished; the next run
with the same parameters and code computes only the missing ones. The folder goes once
the record is written: from then on the record is the cache.

Every result passes through JSON on its way to the reduction, whether it was just computed
here, on a worker, or read back from disk, so the reduction always sees the same values
(tuples as lists, NumPy scalars as Python numbers) and writes the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np

from steplab.core.records import remove_temporary_files, write_atomic

#: the folder under a results folder that holds the tasks of studies not yet complete
FOLDER = ".tasks"


def as_json(value):
    """``value`` as JSON gives it back: the one form every result reaches a reduction in."""
    return json.loads(json.dumps(value, default=_plain))


def _plain(value):
    """NumPy scalars and arrays as Python numbers and lists (json.dumps calls this for what it cannot write)."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"a task result holds a {type(value).__name__}, which JSON cannot hold")


def item_key(study_key: str, item) -> str:
    """The file name of one task: the study's cache key and the task's item, hashed."""
    text = json.dumps(item, sort_keys=True, default=_plain)
    return hashlib.sha256(f"{study_key}\n{text}".encode()).hexdigest()[:32]


class TaskCache:
    """The finished tasks of one study run, under ``out/.tasks/<study>/``.

    ``fresh`` (``--force``) ignores what is there: every task is computed again.
    """

    def __init__(self, out: str | Path, study: str, study_key: str, fresh: bool = False):
        self.folder = Path(out) / FOLDER / study
        self.study_key, self.fresh = study_key, fresh
        if self.folder.is_dir():  # what a writer killed by SIGKILL left half-written
            remove_temporary_files(self.folder)

    def path(self, item) -> Path:
        return self.folder / f"{item_key(self.study_key, item)}.json"

    def load(self, item) -> tuple[bool, object]:
        """(True, result) for a task finished before with the same key; (False, None) otherwise."""
        if self.fresh:
            return False, None
        try:
            stored = json.loads(self.path(item).read_text())
        except (OSError, ValueError):
            return False, None
        # the item itself is stored too: a hash collision or a stray file is not taken for a result
        if not isinstance(stored, dict) or stored.get("item") != as_json(item) or "result" not in stored:
            return False, None
        return True, stored["result"]

    def store(self, item, result):
        """Write one finished task (atomically) and return its result as the reduction will see it."""
        result = as_json(result)
        write_atomic(self.path(item), json.dumps({"item": item, "result": result}, default=_plain).encode())
        return result

    def clear(self) -> None:
        """Remove the study's task folder (its record now holds everything), and ``.tasks`` if empty."""
        shutil.rmtree(self.folder, ignore_errors=True)
        try:
            self.folder.parent.rmdir()
        except OSError:
            pass
