"""The asv suite's structure beyond what ``asv check`` checks (benchmarks/benchmarks/).

asv runs a ``setup_cache`` once per key, the module and line where the function is defined, and
hands its result to every benchmark whose ``setup_cache`` has that key. So two classes that
measure different things must not share one: five of the ratio classes once inherited one
``setup_cache`` and tracked the first class's dictionary, in which their own names were missing
(n/a in every asv run).
"""

import json
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"

# In a child: importing a benchmark module pins its process to one thread (steplab.bench.timing.pin_threads)
SETUP_CACHE_KEYS = """
import importlib, inspect, json, pkgutil, sys
from asv_runner.benchmarks._base import get_setup_cache_key
sys.path.insert(0, sys.argv[1])
import benchmarks
keys = {}
for module in pkgutil.iter_modules(benchmarks.__path__):
    module = importlib.import_module(f"benchmarks.{module.name}")
    for name, cls in inspect.getmembers(module, inspect.isclass):
        if cls.__module__ == module.__name__ and not name.startswith("_") and hasattr(cls, "setup_cache"):
            keys.setdefault(get_setup_cache_key(cls.setup_cache), []).append(f"{module.__name__}.{name}")
print(json.dumps(keys))
"""


def test_each_benchmark_class_has_a_setup_cache_of_its_own():
    child = subprocess.run([sys.executable, "-c", SETUP_CACHE_KEYS, str(BENCHMARKS)], capture_output=True,
                           text=True, check=True)
    keys = json.loads(child.stdout)
    shared = {key: classes for key, classes in keys.items() if len(classes) > 1}
    assert not shared, f"classes that would share one asv setup_cache: {shared}"
    assert len(keys) >= 10 and "benchmarks.ratios.BenchRatio" in sum(keys.values(), [])
