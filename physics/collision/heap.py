"""Keeping the memory a step frees for the next step (glibc's malloc), so that it is not faulted in again.

A step of the contact solver on 10^4 boxes allocates and frees some 40 MB of columns (the narrow
phase's slots, the contacts, the sweep order). glibc gives the top of its heap back to the system
whenever more than its trim threshold lies free there, and the next step's first touch of those
pages faults each of them in again: 300 to 650 minor page faults a step, 1 to 4.7 ms of system time
on this project's 2-core machine, 10 to 20 % of the step's wall time and much of its spread
(docs/performance.md). Raising the trim threshold keeps the freed memory in the heap; fixing the
mmap threshold at its largest (32 MiB) keeps the columns in the heap at all (a threshold set by hand
is no longer raised by glibc as blocks are freed). The step then faults no pages in.

:func:`keep_freed_memory` is process-wide and idempotent; on another C library it does nothing.
It keeps the main arena's memory, the one a process's main thread allocates from. A thread whose
allocation once failed (a MemoryError caught and survived) is moved by glibc to a secondary arena;
there memory comes in heaps of 64 MiB, and a heap that empties is unmapped whatever the thresholds
say, so a step whose columns spill into a second heap faults them in again (some 1,500 to 2,000 pages
a step, measured in a process that had survived one MemoryError).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import platform

#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: free memory the heap keeps at its top, bytes
TRIM_THRESHOLD = 1 << 30
#: blocks from this size on are mapped on their own, not taken from the heap: glibc's largest (64-bit)
MMAP_THRESHOLD = 32 << 20

_done = False


def keep_freed_memory() -> bool:
    """Set glibc's trim and mmap thresholds (:data:`TRIM_THRESHOLD`, :data:`MMAP_THRESHOLD`) once;
    whether they are set (False on a C library other than glibc)."""
    global _done
    if _done:
        return True
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _done = bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
            libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False
    return _done
