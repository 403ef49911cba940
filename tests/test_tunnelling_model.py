"""The tunnelling study's miss-rate model against its measurements, up to v dt / (w + 2r) = 50.

Overlap testing stops a sphere only if it is resolved in the front half of the band w + 2r
wide (past the wall's middle the nearest face is the far one and the push-out goes forward),
so the miss rate depends on where the detector resolves the collision: at the first
overlapping sample without bisection, at the first grid point m dt / 2^k inside the band with
k bisections.
"""

from __future__ import annotations

import numpy as np
import pytest
from steplab.studies.tunnelling import (
    Shot,
    analytic_miss_rate,
    bisection_miss_rate,
    nearest_face_miss_rate,
    shoot,
)

#: phases at the midpoints of n equal parts of a step: the stopped shots are those whose
#: phase lies in at most two intervals, so their count is within 2 of n P(stop)
TRIALS = 400
TOLERANCE = 2.0 / TRIALS + 1e-12
RADIUS = 0.05


def stop_probability(rho: float, k: int | None) -> float:
    """P(stopped), typed from the piecewise closed forms (``k=None``: no bisection)."""
    if k is None or k == 0:
        return min(1.0, 1.0 / (2 * rho))
    n = 2.0**k
    if rho <= n / 2:
        return min(1.0, 1.0 / rho)
    if rho < n:
        return 3.0 / (2 * rho) - 1.0 / n
    return 1.0 / (2 * rho)


@pytest.mark.parametrize("k", [0, 1, 2, 5, 8])
def test_the_models_are_the_piecewise_closed_forms(k):
    for rho in np.geomspace(0.05, 600.0, 301):
        assert bisection_miss_rate(rho, k) == pytest.approx(1 - stop_probability(rho, k), abs=1e-14)
        assert nearest_face_miss_rate(rho) == pytest.approx(1 - stop_probability(rho, None), abs=1e-14)
    # below 2^(k-1) bisection is as good as stopping at every overlapping sample
    assert bisection_miss_rate(2.0 ** (k - 1), k) == pytest.approx(analytic_miss_rate(2.0 ** (k - 1)), abs=1e-14)


@pytest.mark.parametrize(("iterations", "ratios", "wall"), [
    (5, [0.8, 1.5, 8.0, 16.0, 20.0, 24.0, 28.0, 40.0, 50.0], (0.01, 0.01)),
    (5, [24.0, 50.0], (0.1, 0.002)),
    (2, [1.5, 3.0, 6.0], (0.01, 0.01)),
    (0, [0.4, 0.6, 0.9, 3.0, 50.0], (0.002, 0.02)),
])
def test_measured_miss_rate_follows_the_model(iterations, ratios, wall):
    w, dt = wall
    phases = (np.arange(TRIALS) + 0.5) / TRIALS
    for rho in ratios:
        shot = shoot(Shot(rho, w, dt, RADIUS), phases, "overlap", iterations)
        measured = shot["misses"] / TRIALS
        model = bisection_miss_rate(rho, iterations)
        assert abs(measured - model) <= TOLERANCE, (iterations, rho, measured, model)
        if iterations == 0:
            assert model == nearest_face_miss_rate(rho)
        if rho > 2.0 ** (iterations - 1) + 1.0:  # where the model parts from 1 - 1/rho, the measurement does too
            assert abs(measured - analytic_miss_rate(rho)) > TOLERANCE, (iterations, rho, measured)
