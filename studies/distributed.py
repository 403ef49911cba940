"""Studies on a Dask cluster: the same tasks as the serial runner, spread over workers.

A study given as tasks (:class:`studies.runner.Study`: ``tasks``, ``task``, ``reduce``) has
each task submitted to the cluster (``dask.distributed``). Results come back to the process
that started the run, which stores each one as it arrives (studies/task_cache.py), reduces a
study the moment its last task is in, draws its figures and writes its record, exactly as
the serial runner does: the same results, through JSON, into the same reduction, give the
same bytes. Only the provenance differs: it names the cluster (``provenance.cluster``).

Losing a worker loses nothing: the scheduler hands its tasks to the others (a
``LocalCluster``'s nanny restarts it), and what had finished is already on disk. An
interrupted run resumes from the stored tasks.

Timing. A study that measures run time (work-precision, broadphase, the contact solver's)
must not time while other tasks load the machine, nor must a task that does
(``Study.timed``: the tunnelling study's cost rows, the engines study's pit costs). Such
tasks, and every study not given as tasks, run after every other task has finished, one at
a time, in the process that started the run, with the workers idle: their numbers mean what
they mean in a serial run, on the machine the run was started from. (The bench, ``steplab
bench``, is a command of its own and never runs on a cluster.)

Every worker must run the same steplab source as that process: a task checks the cache key
it was sent against its own and fails with one line when they differ. Connecting to a
cluster is the command line's part (steplab/cluster.py): here, any ``distributed.Client``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import socket
from collections.abc import Callable
from pathlib import Path

import numpy as np

from steplab.core.records import make_folder, remove_temporary_files

from .runner import Study, cache_key, finish, is_cached, run_study
from .task_cache import TaskCache, as_json, item_key


class WorkerSourceError(ValueError):
    """A worker runs other steplab source than the process that started the run."""


def describe(client) -> dict:
    """What a record's provenance says about the cluster its tasks ran on."""
    threads = client.nthreads()
    return {"scheduler": client.scheduler.address, "workers": len(threads), "threads": int(sum(threads.values())),
            "client_host": socket.gethostname()}


# --- on a worker ------------------------------------------------------------------------


@functools.cache
def _worker_key(study_name: str, parameters_json: str) -> str:
    """This worker's cache key for a study (once per process: the source it imported)."""
    return cache_key(_study(study_name), json.loads(parameters_json))


def _study(name: str) -> Study:
    from steplab.studies import STUDIES

    if name not in STUDIES:
        raise WorkerSourceError(f"study {name!r} is not installed on worker {socket.gethostname()}")
    return STUDIES[name]


def _check_source(study_name: str, parameters: dict, key: str) -> Study:
    if _worker_key(study_name, json.dumps(parameters, sort_keys=True)) != key:
        raise WorkerSourceError(f"worker {socket.gethostname()} runs other steplab source than the run's client "
                           f"(study {study_name}): install the same steplab on every machine")
    return _study(study_name)


def run_task(study_name: str, parameters: dict, item, key: str):
    """One task of a study, on a worker: its result as JSON gives it back."""
    study = _check_source(study_name, parameters, key)
    with np.errstate(all="ignore"):  # as the command line runs them: non-finite states are detected, not warned
        return as_json(study.task(parameters, item))


# --- in the process that started the run --------------------------------------------------


@dataclasses.dataclass
class _Run:
    """One study computed on the cluster: its tasks, their results so far, and what is left."""

    study: Study
    parameters: dict
    key: str
    items: list
    cache: TaskCache
    results: list
    waiting: int = 0  # tasks submitted to the cluster and not back yet
    timed: list = dataclasses.field(default_factory=list)  # indices of tasks for the timing phase


def run_studies(studies: list[Study], out: str | Path, client, quick: bool = False,
                force: bool = False, finished: Callable[[dict], None] | None = None) -> list[dict]:
    """Run ``studies`` on the cluster of ``client`` into ``out`` (each unless cached); their records, in order.

    The untimed tasks of every study given as tasks go to the cluster at once; the timed
    tasks and the other studies run afterwards here, one at a time (see the module's docstring).
    ``finished(record)`` is called as each study's record is written (or found cached).
    """
    from distributed import as_completed
    from tqdm import tqdm

    out = make_folder(out, "results folder")
    remove_temporary_files(out)  # what a run killed by SIGKILL left half-written
    records, runs, alone, futures, cluster = _Records(finished), [], [], {}, describe(client)
    for study in studies:
        if not force and is_cached(study, out, quick):
            records[study.name] = run_study(study, out, quick)
        elif study.tasks is None:
            alone.append(study)
        else:
            runs.append(_plan(study, out, quick, force))
    for run in runs:
        for index, item in enumerate(run.items):
            found, result = run.cache.load(item)
            if found:
                run.results[index] = result
            elif run.study.timed(item):
                run.timed.append(index)
            else:
                futures[client.submit(run_task, run.study.name, run.parameters, item, run.key, pure=False,
                                      key=f"{run.study.name}-{item_key(run.key, item)}")] = (run, index)
                run.waiting += 1
    total = len(futures) + sum(len(run.timed) for run in runs) + len(alone)
    with tqdm(total=total, desc="cluster", unit="task", disable=None) as bar:
        for run in runs:
            if run.waiting == 0 and not run.timed:  # every task stored by an earlier run
                records[run.study.name] = _finish(run, out, cluster)
        for future in as_completed(list(futures)):
            run, index = futures.pop(future)  # drop the future: the cluster may forget its result
            result = future.result()  # a task's exception is raised here, as in a serial run
            run.results[index] = run.cache.store(run.items[index], result)
            run.waiting -= 1
            bar.set_postfix_str(run.study.name)
            bar.update()
            if run.waiting == 0 and not run.timed:
                records[run.study.name] = _finish(run, out, cluster)
        # the timing phase: every other task has finished, the workers are idle
        for run in runs:
            for index in run.timed:
                bar.set_postfix_str(f"{run.study.name} (timed, alone)")
                with np.errstate(all="ignore"):
                    result = run.study.task(run.parameters, run.items[index])
                run.results[index] = run.cache.store(run.items[index], result)
                bar.update()
            if run.timed:
                records[run.study.name] = _finish(run, out, cluster)
        for study in alone:
            bar.set_postfix_str(f"{study.name} (alone)")
            records[study.name] = run_study(study, out, quick, force)
            bar.update()
    return [records[study.name] for study in studies]


class _Records(dict):
    """The records by study name; each one stored is passed to ``finished`` as it comes."""

    def __init__(self, finished: Callable[[dict], None] | None):
        super().__init__()
        self.finished = finished

    def __setitem__(self, name: str, record: dict) -> None:
        super().__setitem__(name, record)
        if self.finished is not None:
            self.finished(record)


def _plan(study: Study, out: Path, quick: bool, force: bool) -> _Run:
    parameters = study.parameters(quick)
    key = cache_key(study, parameters)  # of the source as the run starts, as in run_study
    items = study.tasks(parameters)
    return _Run(study, parameters, key, items, TaskCache(out, study.name, key, fresh=force), [None] * len(items))


def _finish(run: _Run, out: Path, cluster: dict) -> dict:
    """Reduce a study whose tasks are all in, draw and write its record, drop its stored tasks."""
    record = finish(run.study, run.parameters, run.key, run.study.reduce(run.parameters, run.results), out, cluster)
    run.cache.clear()
    return record
