"""``steplab run``'s output: a trajectory as NPZ or CSV, written atomically.

The files go through :func:`steplab.core.records.write_atomic`, the one writer of
every result file, so a reader never sees a half-written trajectory.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from steplab.core.records import write_atomic

TRAJECTORY_FORMATS = (".npz", ".csv")


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


def save_trajectory(path: str | Path, trajectory, model, metadata: dict, extra: dict | None = None) -> None:
    """Write a trajectory as NPZ (arrays plus metadata JSON) or CSV (one row per body and time).

    ``extra``: more NPZ arrays by name (the rotating bodies' ``orientations`` and
    ``angular_velocities``); the CSV holds the translation only.

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
                 metadata=np.array(json.dumps(metadata, sort_keys=True)), **(extra or {}))
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
