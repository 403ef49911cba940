"""The contact solver keeps the memory a step frees for the next one (physics/collision/heap.py)."""

import platform
import resource

import numpy as np
import pytest
from steplab.physics.collision.heap import keep_freed_memory

glibc = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                           reason="glibc's malloc only")


@glibc
def test_a_step_of_columns_is_not_faulted_in_again():
    # 40 MiB in five blocks, allocated, written and freed as a step of 10^4 boxes does (the narrow phase's
    # slots, the contacts, the sweep order). With glibc's defaults the freed top of the heap goes back to
    # the system and every round faults some 2,500 pages in again (measured); kept, the later rounds none.
    assert keep_freed_memory() and keep_freed_memory()  # idempotent
    faults = []
    for _ in range(5):
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        blocks = [np.ones(n) for n in (2 << 20, 1 << 20, 3 << 19, 1 << 18, 1 << 18)]
        del blocks
        faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    assert max(faults[1:]) < 100, faults
