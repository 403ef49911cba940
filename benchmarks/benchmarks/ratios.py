"""``steplab bench``'s ratios as ``track_`` benchmarks, so a regression against a peer shows in asv's history.

A ratio is steplab's median time over the peer's on the same work (lower is better). Only
the bench's small system is run here (one oscillator, 10^5 steps, at the quick bench's
sizes, against diffrax, Numba and a Python loop): a few seconds, where the large systems,
the accuracy match and the ball pits take minutes (``steplab bench`` runs them all).
"""

from __future__ import annotations

from steplab.bench.timing import pin_threads

# one thread per side, as ``steplab bench`` runs: before this module imports JAX (asv times
# each benchmark in a process of its own)
pin_threads()

from steplab.peers import DIFFRAX_METHODS  # noqa: E402

#: the small system's ratios, named as in the bench's record (one per diffrax method, then Numba and Python)
SMALL_SYSTEM_RATIOS = [f"vs_diffrax_{method.replace('-', '_')}" for method in DIFFRAX_METHODS] + [
    "vs_numba_semi_implicit_euler", "vs_python_loop_semi_implicit_euler"]


class BenchRatio:
    """The quick bench's small-system ratios, steplab / peer, measured once in ``setup_cache``."""

    params = SMALL_SYSTEM_RATIOS
    param_names = ["ratio"]
    unit = "ratio"
    timeout = 300

    def setup_cache(self):
        from steplab.bench import QUICK, Record, fair_diffrax

        fair_diffrax()  # Equinox's run-time checks off, as in ``steplab bench`` (before diffrax is imported)
        from steplab.bench.comparisons import small_system

        record = Record(QUICK, quick=True)
        small_system(QUICK, record, lambda message: None)
        return record.data["ratios"]

    def track_ratio(self, ratios, ratio):
        # a name this commit's bench does not record (an older steplab) shows as n/a
        return ratios.get(ratio, float("nan"))
