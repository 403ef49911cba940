"""Shared test setup: 64-bit JAX, importable project and helpers, common fixtures."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

_TESTS = Path(__file__).resolve().parent
_ROOT = _TESTS.parent
# The project root (physics, integrators) and tests/ (helpers) must be importable whether
# or not steplab is installed and whichever pytest import mode is configured.
for _path in (_ROOT, _TESTS):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

import jax  # noqa: E402

# Importing physics turns on float64 in JAX; do it here as well, before any test module
# creates a JAX array, so no test depends on import order.
jax.config.update("jax_enable_x64", True)
import helpers  # noqa: E402
import steplab.physics  # noqa: E402, F401


def pytest_configure(config):
    assert jax.config.jax_enable_x64, "tests need jax_enable_x64 (float64 JAX arrays)"


# Hypothesis (fuzz and property tests): the default profile "ci" is derandomised (the same
# examples on every run and machine), has no per-example deadline (no wall-clock asserts)
# and keeps no example database. HYPOTHESIS_PROFILE=explore draws fresh random examples;
# STEPLAB_FUZZ_SCALE=10 multiplies every test's example budget (tests/test_fuzz.py).
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("ci", derandomize=True, deadline=None, database=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.register_profile("explore", deadline=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def rng():
    """A seeded generator: every random test case is reproducible."""
    import numpy as np

    return np.random.default_rng(20240611)


@pytest.fixture
def oscillator():
    """Undamped body on a spring to a pinned anchor; period 1 s, exact solution attached."""
    return helpers.oscillator()


@pytest.fixture
def damped_oscillator():
    """The same oscillator with a damper (zeta = 0.1); exact solution attached."""
    import math

    return helpers.oscillator(damping=0.2 * 2 * math.pi, velocity=0.3, direction=(2.0, -1.0, 2.0))


@pytest.fixture
def lecture_projectile():
    """The lecture's projectile: m = 2.5 kg, p = (10, 0, 2), V = (7.68, 0, 29), t0 = 5 s."""
    return helpers.lecture_projectile()


@pytest.fixture
def drawn(monkeypatch):
    """What ``steplab animate`` gives steplab.animate and draws: each call's runs and rotations, the
    energies of its energy panel and the view's axes that motion_view picks."""
    import steplab.animate

    seen = {"calls": [], "energies": [], "views": []}
    animate, changes, view = steplab.animate.animate, steplab.animate.energy_changes, steplab.animate.motion_view

    def animate_(runs, model, out, **kw):
        seen["calls"].append((runs, kw.get("rotations")))
        return animate(runs, model, out, **kw)

    def changes_(energies):
        seen["energies"].append(energies)
        return changes(energies)

    def view_(tracks):
        seen["views"].append(view(tracks))
        return seen["views"][-1]

    monkeypatch.setattr(steplab.animate, "animate", animate_)
    monkeypatch.setattr(steplab.animate, "energy_changes", changes_)
    monkeypatch.setattr(steplab.animate, "motion_view", view_)
    return seen


def pytest_terminal_summary(terminalreporter):
    """One line, not a buried skip reason, when the browser tests could not run."""
    skipped = terminalreporter.stats.get("skipped", [])
    if any(helpers.BROWSER_SKIP in str(report.longrepr) for report in skipped):
        terminalreporter.write_line(f"browser tests skipped: {helpers.BROWSER_SKIP}")
