"""Cloth under XPBD (issue 28): one step of steplab's ``xpbd``, of a plain Numba loop and of NVIDIA Newton.

``time_step`` times one step (one substep, one iteration, dt = 1/600 s) of the bench's cloth
(:func:`steplab.bench.systems.cloth_model`) by each contender; Newton's is skipped without the
extra ``steplab[newton]``. ``track_ratio`` is ``steplab bench``'s ratios on the 160 x 160 cloth
(25,600 particles, 101,442 springs): one step over one pass of the memory-traffic bound, both
from cold caches (target 1.5; ``steplab.bench.cold``), the same step over a tighter bound, the
same bytes in one compiled pass (``compiled_stream``), and the marginal step over the Numba
loop's and over Newton's SolverXPBD's (target 0.5), in the same rounds.
"""

from __future__ import annotations

from steplab.bench.timing import pin_threads

# one thread per side, as ``steplab bench`` runs its ratios: before JAX or Numba is imported
pin_threads()


class XPBDClothStep:
    """One xpbd step of a side x side cloth with dampers, gravity and two pinned corners."""

    params = (["steplab", "numba", "newton"], [40, 160])
    param_names = ["contender", "side"]
    timeout = 300

    def setup(self, contender, side):
        from steplab.integrators.position_based import cloth_benchmark_step

        from steplab.bench.cloth import CLOTH_DT, newton_run, numba_xpbd_step
        from steplab.bench.systems import cloth_model

        model, y0, _ = cloth_model(side)
        dt = CLOTH_DT
        if contender == "steplab":
            self.call = cloth_benchmark_step(model, y0, dt).advance
        elif contender == "numba":
            self.call = numba_xpbd_step(model, y0, dt).advance
        else:
            newton = newton_run(model, dt, y0, solver="xpbd", iterations=1)
            if newton is None:
                raise NotImplementedError("newton is not installed (pip install steplab[newton])")
            self.call = lambda: newton.run(1, dt)
        self.call()  # compile (Numba, Warp)

    def time_step(self, contender, side):
        self.call()


class XPBDClothRatios:
    """``steplab bench``'s cloth (XPBD) comparisons, measured once in ``setup_cache``."""

    params = ["memory_bound", "compiled_stream", "numba", "newton"]
    param_names = ["peer"]
    unit = "ratio"
    timeout = 900

    def setup_cache(self):
        from steplab.bench import QUICK, Record
        from steplab.bench.cloth import xpbd_cloth

        record = Record(QUICK, quick=True)
        xpbd_cloth(QUICK, record, lambda message: None)
        tighter = record.data["seconds"]["vs_memory_bound_xpbd_cloth"]["compiled_stream"]["ratio"]
        return record.data["ratios"] | {"vs_compiled_stream_xpbd_cloth": tighter}

    def setup(self, ratios, peer):
        if f"vs_{peer}_xpbd_cloth" not in ratios:
            raise NotImplementedError(f"{peer} did not run (newton: pip install steplab[newton])")

    def track_ratio(self, ratios, peer):
        return ratios[f"vs_{peer}_xpbd_cloth"]
