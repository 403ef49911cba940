"""Shared test setup: 64-bit JAX, importable project and helpers, common fixtures."""

from __future__ import annotations

import contextlib
import os
import shutil
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


@contextlib.contextmanager
def _locked(path: Path):
    """An exclusive lock on ``path`` among this run's processes (xdist's workers)."""
    import fcntl

    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def quick_records(tmp_path_factory):
    """``copy(out, names)``: the quick records and figures of the built-in studies ``names`` copied into
    ``out``, where runner.run_study then finds them cached (the same parameters and code). Each is run
    once per test run rather than once per test file that shows or compares it: by the first process
    to ask, into a folder that every xdist worker of the run shares, under a lock; a quick record is
    the same bytes whichever process computes it (less its provenance), as tests/test_dask.py checks."""
    from steplab.studies import STUDIES, runner

    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "quick-records"

    def copy(out: Path, names) -> Path:
        for name in names:
            folder = shared / name  # a folder each: run_study clears its folder's temporary files
            folder.mkdir(parents=True, exist_ok=True)
            with _locked(shared / f"{name}.lock"):
                record = runner.run_study(STUDIES[name], folder, quick=True)
                for file in (f"{name}.json", *record["figures"]):
                    shutil.copy2(folder / file, Path(out) / file)
        return Path(out)

    return copy


@pytest.fixture
def drawn(monkeypatch):
    """What ``steplab animate`` gives steplab.animate and draws: each call's runs and rotations, the
    energies of its energy panel and the view's axes that motion_view picks (helpers.spy_on_animate)."""
    return helpers.spy_on_animate(monkeypatch)


def pytest_terminal_summary(terminalreporter):
    """One line, not a buried skip reason, when the browser tests could not run."""
    skipped = terminalreporter.stats.get("skipped", [])
    if any(helpers.BROWSER_SKIP in str(report.longrepr) for report in skipped):
        terminalreporter.write_line(f"browser tests skipped: {helpers.BROWSER_SKIP}")
