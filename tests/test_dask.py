"""Studies on a Dask cluster: the serial records, a lost worker, resuming task by task, bad addresses."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import threading
import time

import pytest
from steplab.studies import STUDIES, distributed, runner
from steplab.studies.task_cache import FOLDER

from steplab import cluster as clusters
from steplab.cli import main

#: quick studies that do not time: their records must be the serial ones to the byte
STUDIES_COMPARED = ("frame_rate", "restitution")


def without_provenance(path) -> bytes:
    """A record's bytes as written, less the provenance (date, machine, cluster)."""
    record = json.loads(path.read_text())
    record.pop("provenance")
    return json.dumps(record, indent=2, sort_keys=True).encode()


@pytest.fixture(scope="module")
def serial(tmp_path_factory, quick_records):
    """The serial quick records of the compared studies (run in this test run's first process to ask)."""
    out = quick_records(tmp_path_factory.mktemp("serial"), STUDIES_COMPARED)
    for name in STUDIES_COMPARED:
        runner.run_study(STUDIES[name], out, quick=True)  # cached
    return out


@pytest.fixture(scope="module")
def client():
    with clusters.connect(workers=2) as client:
        yield client


def test_distributed_quick_run_writes_the_serial_records(serial, client, tmp_path):
    records = distributed.run_studies([STUDIES[name] for name in STUDIES_COMPARED], tmp_path, client, quick=True)
    for name, record in zip(STUDIES_COMPARED, records):
        assert without_provenance(tmp_path / f"{name}.json") == without_provenance(serial / f"{name}.json")
        assert record["provenance"]["cluster"]["workers"] == 2
    assert not (tmp_path / FOLDER).exists()  # the stored tasks go once the records are written


#: one setting of each engine: the engines study's quick record, serially and on the cluster
ENGINE_SETTINGS = ["mujoco-euler", "bullet-default", "box2d-default", "chipmunk"]
#: what a pit cost measures: wall time, which no two runs share
TIMINGS = ("per_step_seconds", "per_body_step_seconds", "real_time_factor")


def without_timings(path) -> tuple[bytes, list[float]]:
    """A record's bytes less the provenance and its pit costs' timings; and those timings."""
    record = json.loads(without_provenance(path))
    costs = [row["cost"] for row in record["rows"]] + list(record["steplab"]["cost"].values())
    timings = [pit.pop(name) for cost in costs for pit in cost.values() if "error" not in pit for name in TIMINGS]
    return json.dumps(record, indent=2, sort_keys=True).encode(), timings


def test_engines_study_on_the_cluster_writes_the_serial_record_but_its_timings(client, tmp_path):
    engines = STUDIES["engines"]
    if engines.unavailable():
        pytest.skip(engines.unavailable())
    # the quick parameters on one setting of each engine, without figures (the workers'
    # cache key is of the parameters the run sends them, so they run the same tasks)
    lean = dataclasses.replace(engines, parameters=lambda quick: engines.parameters(True) | {
        "settings": ENGINE_SETTINGS}, plot=lambda record, out: [])
    runner.run_study(lean, tmp_path / "serial", quick=True)
    [record] = distributed.run_studies([lean], tmp_path / "cluster", client, quick=True)
    serial, serial_timings = without_timings(tmp_path / "serial" / "engines.json")
    cluster, cluster_timings = without_timings(tmp_path / "cluster" / "engines.json")
    assert cluster == serial and [row["setting"] for row in record["rows"]] == ENGINE_SETTINGS
    # every engine timed its planar pit, steplab both pits with each of its systems
    pits = len(ENGINE_SETTINGS) + 2 * len(record["steplab"]["cost"])
    assert len(cluster_timings) == len(serial_timings) >= len(TIMINGS) * pits
    assert min(cluster_timings) > 0


def test_a_worker_killed_mid_run_loses_nothing(serial, client, tmp_path):
    pids = set(client.run(os.getpid).values())
    stored = tmp_path / FOLDER / "restitution"
    seen = {}

    def kill_one_worker_once_tasks_come_back():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(list(stored.glob("*.json"))) < 2:
            time.sleep(0.005)
        seen["record_before_kill"] = (tmp_path / "restitution.json").exists()
        os.kill(min(pids), signal.SIGKILL)

    killer = threading.Thread(target=kill_one_worker_once_tasks_come_back)
    killer.start()
    distributed.run_studies([STUDIES["restitution"]], tmp_path, client, quick=True)
    killer.join()
    assert seen == {"record_before_kill": False}  # the worker died while the study was running
    assert without_provenance(tmp_path / "restitution.json") == without_provenance(serial / "restitution.json")
    assert min(pids) not in set(client.run(os.getpid).values())


def _counting_study(calls: list, fail_at: int | None = None) -> runner.Study:
    """Five tasks squaring their item (one raising KeyboardInterrupt, like a Ctrl-C, if asked)."""
    def task(parameters, item):
        if item == fail_at:
            raise KeyboardInterrupt
        calls.append(item)
        return {"square": item * item}

    return runner.Study("counting", "five squares", lambda quick: {"n": 5}, lambda p, progress=None: {},
                        lambda record, out: [], tasks=lambda p: list(range(p["n"])), task=task,
                        reduce=lambda p, results: {"squares": [r["square"] for r in results]})


def test_an_interrupted_run_resumes_task_by_task(tmp_path):
    calls = []
    with pytest.raises(KeyboardInterrupt):
        runner.run_study(_counting_study(calls, fail_at=3), tmp_path)
    assert calls == [0, 1, 2] and len(list((tmp_path / FOLDER / "counting").glob("*.json"))) == 3
    record = runner.run_study(_counting_study(calls), tmp_path)
    assert calls == [0, 1, 2, 3, 4]  # only the missing tasks ran
    assert record["squares"] == [0, 1, 4, 9, 16] and not (tmp_path / FOLDER).exists()


@pytest.mark.parametrize("address", ["nonsense", "tcp://127.0.0.1:1"])
def test_bad_scheduler_address_is_one_line_and_status_2(address, capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(clusters, "CONNECT_TIMEOUT_S", 0.5)
    status = main(["study", "frame_rate", "--quick", "--out", str(tmp_path), "--scheduler", address])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert len(err.splitlines()) == 1 and address in err and "dask scheduler" in err
    with pytest.raises(SystemExit) as exit_:
        main(["reproduce", "--workers", "0"])
    assert exit_.value.code == 2 and len(capsys.readouterr().err.splitlines()) == 1


@pytest.mark.parametrize("reply", [b"HTTP/1.1 400 Bad Request\r\n\r\n", b"\x01" + bytes(7) + b"\x02"])
def test_a_server_that_is_not_dask_is_named_in_one_line(reply, capsys, monkeypatch, tmp_path):
    # a web server where the scheduler was expected: Dask reads "HTTP/1.1" as a message of 3 EiB and
    # asks NumPy for it (a MemoryError, which reached the user as "out of memory"); a reply shorter
    # than a length, a struct.error traceback
    import socket

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def answer():
        with server:
            connection, _ = server.accept()
            with connection:
                connection.sendall(reply)
                connection.recv(1024)

    threading.Thread(target=answer, daemon=True).start()
    monkeypatch.setattr(clusters, "CONNECT_TIMEOUT_S", 5.0)
    address = f"tcp://127.0.0.1:{port}"
    status = main(["study", "frame_rate", "--quick", "--out", str(tmp_path), "--scheduler", address])
    out, err = capsys.readouterr()
    assert status == 2 and out == "" and len(err.splitlines()) == 1
    assert f"what answers at {address!r} is not a Dask scheduler" in err


def test_more_local_workers_than_a_few_a_core_are_refused(capsys, tmp_path):
    from steplab.cli.args import MAX_WORKERS_PER_CORE

    too_many = MAX_WORKERS_PER_CORE * (os.cpu_count() or 1) + 1
    with pytest.raises(SystemExit) as exit_:
        main(["study", "frame_rate", "--quick", "--out", str(tmp_path), "--workers", str(too_many)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and len(err.splitlines()) == 1
    assert f"--workers: must be at most {too_many - 1}" in err and not any(tmp_path.iterdir())
