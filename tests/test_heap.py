"""The contact solver keeps the memory a step frees for the next one (physics/collision/heap.py)."""

import json
import platform
import subprocess
import sys

import pytest

glibc = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                           reason="glibc's malloc only")

# 40 MiB in five blocks, allocated, written and freed as a step of 10^4 boxes does (the narrow phase's
# slots, the contacts, the sweep order), five times; the minor page faults of each round.
_ROUNDS = """
import json, resource, sys
import numpy as np
from steplab.physics.collision.heap import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory() and keep_freed_memory()  # idempotent
faults = []
for _ in range(5):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    blocks = [np.ones(n) for n in (2 << 20, 1 << 20, 3 << 19, 1 << 18, 1 << 18)]
    del blocks
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(json.dumps(faults))
"""


def _faults(mode):
    # A fresh process, as the command line and the bench are: the setting is process-wide, and a
    # process that has once failed an allocation (a MemoryError) is moved by glibc to a secondary
    # arena, whose 64 MiB heaps are unmapped when they empty whatever the thresholds say (a test
    # worker that ran such a test first measured some 2,000 faults a round; see the module's docstring).
    out = subprocess.run([sys.executable, "-c", _ROUNDS, mode], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@glibc
def test_a_step_of_columns_is_not_faulted_in_again():
    # With glibc's defaults the freed top of the heap goes back to the system and every round faults
    # some 2,500 pages in again (measured); kept, the later rounds none.
    default, kept = _faults("default"), _faults("keep")
    assert min(default[1:]) > 1000, default
    assert max(kept[1:]) < 100, kept
