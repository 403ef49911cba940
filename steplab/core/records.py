"""Writing records and figures atomically: the one writer every result file goes through.

A file is written to a temporary name beside its destination and renamed into place
(``os.replace`` is atomic on POSIX), so a reader never sees a half-written file even if
the process is killed mid-write. The studies' runner, the plots, the paper, the bench,
the animations and ``steplab run``'s trajectories all write through here.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

#: the names the writer gives its temporary files: ``.<name>.<random>.tmp``, and
#: ``.<name>.<random>.tmp.<ext>`` for writers that pick the format from the name (animations)
TEMPORARY_PATTERNS = (".*.*.tmp", ".*.*.tmp.*")
#: what reading a record's fields raises when one is missing or not what the reader expects (a record cut
#: short or edited, or written by a steplab whose records had other fields; "abc" where a number is
#: formatted): the readers catch these to say so in one line naming the record
RECORD_ERRORS = (KeyError, IndexError, TypeError, AttributeError, ValueError)


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that ``path`` is either the old file or the whole new one."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())


def write_json(path: str | Path, record) -> None:
    """A record as sorted, indented JSON (the same record gives the same bytes), atomically."""
    write_atomic(path, (json.dumps(record, indent=2, sort_keys=True) + "\n").encode())


def write_with(path: str | Path, save: Callable[[Path], object]) -> None:
    """Let ``save(tmp)`` write a file itself (matplotlib's animation writers need a real
    file, not bytes), then move it onto ``path`` atomically."""
    with atomic_path(path, keep_suffix=True) as tmp:
        save(tmp)


def make_folder(folder: str | Path, what: str) -> Path:
    """Make ``folder`` and its parents before the work whose results go there, so that a path
    that cannot hold them fails first (one line naming ``what``), not after the computing."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{what} {folder}: a file, not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@contextlib.contextmanager
def atomic_path(path: str | Path, keep_suffix: bool = False) -> Iterator[Path]:
    """A fresh temporary file beside ``path`` to write into; renamed onto ``path`` when the
    block ends, deleted if it raises.

    ``keep_suffix`` ends the temporary name with ``path``'s suffix
    (``.<name>.<random>.tmp.gif``), for writers that choose the format by extension.
    """
    path = Path(path)
    if path.is_dir():  # else the rename's error, after the work, names the temporary file
        raise IsADirectoryError(errno.EISDIR, "a folder, not a file: give a file name", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = ".tmp" + (path.suffix if keep_suffix else "")
    try:
        fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    except OSError as err:
        raise _naming(err, path, f"cannot create a file in {path.parent}") from None
    os.close(fd)
    tmp = Path(name)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are for everyone to read
        yield tmp
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(err, OSError) and str(tmp) in (str(err.filename), str(err.filename2)):
            raise _naming(err, path) from None  # the user's path, never the temporary name
        raise


def _naming(err: OSError, path: Path, what: str = "") -> OSError:
    """``err`` as the same kind of OSError about ``path`` (what an error line names), with ``what`` before
    its reason."""
    reason = err.strerror or str(err)
    return type(err)(err.errno, f"{what} ({reason})" if what else reason, str(path))


def _umask() -> int:
    """The process's umask (reading it means setting it: set it straight back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def remove_temporary_files(folder: str | Path) -> list[Path]:
    """Delete the temporary files a killed writer left in ``folder`` (SIGKILL skips clean-up).

    Call it when a run starts, not while another process writes into the same folder.
    Returns what was deleted.
    """
    removed = []
    for path in sorted({p for pattern in TEMPORARY_PATTERNS for p in Path(folder).glob(pattern)}):
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, PermissionError):
            if path.is_file():
                path.unlink()
                removed.append(path)
    return removed
