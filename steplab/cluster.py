"""Where ``steplab study`` and ``steplab reproduce`` run their sweeps: a Dask cluster.

``--workers N`` starts a ``LocalCluster`` of N worker processes on this machine (one thread
each: the tasks are NumPy and JAX loops); ``--scheduler ADDRESS`` joins a cluster already
running (``dask scheduler`` on one machine, ``dask worker ADDRESS`` on each; see
docs/cluster.md). What runs on it, and how the records come back, is studies/distributed.py.

The workers of a local cluster are asked to import the studies as soon as they are up, so
that their imports (a second or more each: JAX, Numba, matplotlib) happen while this
process plans the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
from collections.abc import Iterator

#: how long to try to reach a scheduler given by address before giving up (dask retries within it)
CONNECT_TIMEOUT_S = 10.0


class ClusterError(ValueError):
    """No cluster at the address given."""


@contextlib.contextmanager
def connect(workers: int | None = None, scheduler: str | None = None) -> Iterator[object]:
    """A ``distributed.Client`` of a new ``LocalCluster`` of ``workers`` processes, or of the
    scheduler at ``scheduler``."""
    from distributed import Client, LocalCluster, fire_and_forget

    logging.getLogger("distributed").setLevel(logging.CRITICAL)  # a lost worker is handled, not news
    if scheduler is not None:
        _probe(scheduler)
        with Client(scheduler, timeout=CONNECT_TIMEOUT_S) as client:
            yield client
        return
    try:
        local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                             silence_logs=logging.CRITICAL)
    except (OSError, RuntimeError) as err:
        raise ClusterError(f"cannot start a local Dask cluster of {workers} workers: {err}") from None
    with local, Client(local) as client:
        # the workers import the studies meanwhile (each once: a task it will not have to wait for)
        fire_and_forget([client.submit(_import_studies, workers=[worker], pure=False)
                         for worker in client.nthreads()])
        yield client


def _import_studies() -> None:
    importlib.import_module("steplab.studies")


def _probe(address: str) -> None:
    """Fail with one line if nothing answers at ``address`` (before a Client, whose failed
    construction leaves a client that prints a traceback when it is collected)."""
    from distributed.comm import connect as open_comm

    async def knock():
        comm = await open_comm(address, timeout=CONNECT_TIMEOUT_S)
        await comm.close()

    try:
        asyncio.run(knock())
    except (OSError, ValueError, TypeError) as err:
        raise ClusterError(f"cannot reach a Dask scheduler at {address!r}: {err} "
                           "(start one with `dask scheduler`, workers with `dask worker ADDRESS`)") from None
    except Exception:  # something else answered (a web server): Dask read its bytes as a message's lengths
        raise ClusterError(f"what answers at {address!r} is not a Dask scheduler (its reply is not Dask's "
                           "protocol; start one with `dask scheduler`)") from None
