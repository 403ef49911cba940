"""Writing results: trajectories (NPZ or CSV) and JSON records, always atomically.

A file is written to a temporary name beside its destination and renamed into place
(``os.replace`` is atomic on POSIX), so a reader never sees a half-written file even if
the process is killed mid-write.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np

TRAJECTORY_FORMATS = (".npz", ".csv")
#: the names write_atomic gives its temporary files: ``.<name>.<random>.tmp``
TEMPORARY_PATTERN = ".*.*.tmp"


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that ``path`` is either the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are for everyone to read
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def remove_temporary_files(folder: str | Path) -> list[Path]:
    """Delete the temporary files a killed writer left in ``folder`` (SIGKILL skips clean-up).

    Call it when a run starts, not while another process writes into the same folder.
    Returns what was deleted.
    """
    removed = []
    for path in sorted(Path(folder).glob(TEMPORARY_PATTERN)):
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, PermissionError):
            if path.is_file():
                path.unlink()
                removed.append(path)
    return removed


def write_json(path: str | Path, record) -> None:
    write_atomic(path, (json.dumps(record, indent=2, sort_keys=True) + "\n").encode())


def check_trajectory_path(path: str | Path) -> Path:
    """The output path, or ValueError if its extension is not a trajectory format."""
    path = Path(path)
    if path.suffix.lower() not in TRAJECTORY_FORMATS:
        raise ValueError(f"--out {path}: unknown trajectory format {path.suffix or '(none)'!r}; "
                         f"use {' or '.join(TRAJECTORY_FORMATS)}")
    if path.is_dir():
        raise ValueError(f"--out {path}: is a folder, not a file")
    folder = next((p for p in path.parents if p.exists()), None)  # the deepest existing ancestor
    if folder is not None and not folder.is_dir():
        raise ValueError(f"--out {path}: {folder} is a file, not a folder")
    return path


def save_trajectory(path: str | Path, trajectory, model, metadata: dict) -> None:
    """Write a trajectory as NPZ (arrays plus metadata JSON) or CSV (one row per body and time).

    CSV columns: ``t, body, x, y, z, vx, vy, vz``. Numbers are written with ``repr``
    precision (17 significant digits), so the same run gives byte-identical files.
    """
    path = check_trajectory_path(path)
    names = np.array(model.names)
    if path.suffix.lower() == ".npz":
        buffer = io.BytesIO()
        np.savez(buffer, t=trajectory.t, positions=trajectory.positions,
                 velocities=trajectory.velocities, masses=np.asarray(model.masses),
                 radii=np.asarray(model.radii), names=names,
                 metadata=np.array(json.dumps(metadata, sort_keys=True)))
        write_atomic(path, buffer.getvalue())
        return
    k, n = trajectory.positions.shape[:2]
    table = np.concatenate([trajectory.positions, trajectory.velocities], axis=2).reshape(k * n, 6)
    times = np.repeat(trajectory.t, n)
    bodies = np.tile(names, k)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["t", "body", "x", "y", "z", "vx", "vy", "vz"])
    writer.writerows([repr(float(t)), b] + [repr(float(x)) for x in row]
                     for t, b, row in zip(times, bodies, table))
    write_atomic(path, text.getvalue().encode())
