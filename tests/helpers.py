"""Test problems with known solutions, and the integrator lists the tests parametrise over.

Every exact solution here is written out independently of steplab's own code (the
closed forms are typed from the textbook formulas, not taken from ``physics``), so a
test that compares a run against them compares against an independent reference.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import steplab.physics  # noqa: F401  (turns on jax_enable_x64 before any JAX array exists)
from steplab.integrators import INTEGRATORS, Solver, Stepper
from steplab.physics import Dampers, Drag, Gravity, Model, Springs
from steplab.physics.soft_body import all_pairs, connect

# --- integrator lists, read from the registry so a new integrator is tested automatically --

#: names of the fixed-step integrators (Steppers)
FIXED_STEP = [name for name, method in INTEGRATORS.items() if isinstance(method, Stepper)]
#: names of the adaptive reference solvers
REFERENCES = [name for name, method in INTEGRATORS.items()
              if isinstance(method, Solver) and method.kind == "reference"]
#: names of the closed-form solvers
EXACT = [name for name, method in INTEGRATORS.items()
         if isinstance(method, Solver) and method.kind == "exact"]
#: every registered name
ALL = list(INTEGRATORS)
#: fixed-step integrators of order 1 / of order >= 2
FIRST_ORDER = [name for name in FIXED_STEP if INTEGRATORS[name].order == 1]
SECOND_ORDER_OR_HIGHER = [name for name in FIXED_STEP if (INTEGRATORS[name].order or 0) >= 2]
#: fixed-step integrators that declare themselves symplectic
SYMPLECTIC = [name for name in FIXED_STEP if INTEGRATORS[name].symplectic]


@dataclasses.dataclass(frozen=True)
class Problem:
    """A model, its initial state, and (when known) the exact solution ``exact(t) -> y``."""

    name: str
    model: Model
    y0: np.ndarray
    t0: float = 0.0
    exact: Callable | None = None  # t (scalar or (K,)) -> y of shape (2, N, 3) or (K, 2, N, 3)


def _stack_solution(s, ds, anchor, direction):
    """States of :func:`oscillator` for the 1-D motion s(t) along unit ``direction``:
    the anchor fixed, the mass at anchor + s u with velocity ds u. Shape (..., 2, 2, 3)."""
    s, ds = np.asarray(s, float)[..., None], np.asarray(ds, float)[..., None]
    q_mass = anchor + s * direction
    v_mass = ds * direction
    q_anchor = np.broadcast_to(anchor, q_mass.shape)
    positions = np.stack([q_anchor, q_mass], axis=-2)
    velocities = np.stack([np.zeros_like(v_mass), v_mass], axis=-2)
    return np.stack([positions, velocities], axis=-3)


def oscillator(stiffness=4 * math.pi**2, mass=1.0, rest_length=1.0, amplitude=0.5, velocity=0.0,
               damping=0.0, direction=(1.0, 0.0, 0.0), anchor=(0.0, 0.0, 0.0),
               with_exact=True) -> Problem:
    """A body on a spring to a pinned anchor (body 0), moving along ``direction``.

    The mass starts at anchor + (rest_length + amplitude) u with velocity ``velocity`` u.
    With s = l - rest_length the motion is m s'' = -k s - c s' as long as the spring does
    not pass through zero length (the exact solution below assumes that).
    Defaults: k = 4 pi^2 N/m, m = 1 kg, so omega = 2 pi rad/s and the period is 1 s.
    """
    u = np.asarray(direction, float)
    u = u / np.linalg.norm(u)
    anchor = np.asarray(anchor, float)
    forces = [Springs(np.array([0]), np.array([1]), np.array([float(stiffness)]),
                      np.array([float(rest_length)]))]
    if damping:
        forces.append(Dampers(np.array([0]), np.array([1]), np.array([float(damping)])))
    model = Model([1.0, mass], [0.05, 0.05], forces, pinned=[True, False])
    y0 = np.array([[anchor, anchor + (rest_length + amplitude) * u],
                   [np.zeros(3), velocity * u]])

    w0 = math.sqrt(stiffness / mass)
    zeta = damping / (2 * math.sqrt(stiffness * mass))
    if zeta >= 1:
        with_exact = False  # only the underdamped closed form is written out

    def exact(t):
        t = np.asarray(t, float)
        if zeta == 0:
            s = amplitude * np.cos(w0 * t) + velocity / w0 * np.sin(w0 * t)
            ds = -amplitude * w0 * np.sin(w0 * t) + velocity * np.cos(w0 * t)
        else:
            # s = e^{-zeta w0 t} (A cos wd t + B sin wd t), B = (v0 + zeta w0 A) / wd
            wd = w0 * math.sqrt(1 - zeta**2)
            a, b = amplitude, (velocity + zeta * w0 * amplitude) / wd
            decay = np.exp(-zeta * w0 * t)
            cos, sin = np.cos(wd * t), np.sin(wd * t)
            s = decay * (a * cos + b * sin)
            ds = decay * ((b * wd - zeta * w0 * a) * cos - (a * wd + zeta * w0 * b) * sin)
        return _stack_solution(rest_length + s, ds, anchor, u)

    name = "damped-oscillator" if damping else "oscillator"
    return Problem(name, model, y0, 0.0, exact if with_exact else None)


def oscillator_energy(y, stiffness=4 * math.pi**2, mass=1.0, rest_length=1.0):
    """1/2 m |v|^2 + 1/2 k (l - l_rest)^2 of :func:`oscillator` states y (..., 2, 2, 3)."""
    y = np.asarray(y, float)
    length = np.linalg.norm(y[..., 0, 1, :] - y[..., 0, 0, :], axis=-1)
    return 0.5 * mass * np.sum(y[..., 1, 1, :] ** 2, axis=-1) + 0.5 * stiffness * (length - rest_length) ** 2


# The lecture's projectile (slides "Explicit Euler Integration Example").
LECTURE_MASS = 2.5
LECTURE_P0 = (10.0, 0.0, 2.0)
LECTURE_V0 = (7.68, 0.0, 29.0)
LECTURE_G = (0.0, 0.0, -9.81)
LECTURE_T0 = 5.0


def projectile_solution(t, p0, v0, g, t0):
    """p0 + v0 (t - t0) + g (t - t0)^2 / 2 and v0 + g (t - t0), as (K, 2, 1, 3)."""
    tau = np.asarray(t, float)[..., None] - t0
    p0, v0, g = (np.asarray(x, float) for x in (p0, v0, g))
    p = p0 + v0 * tau + 0.5 * g * tau**2
    v = v0 + g * tau
    return np.stack([p, v], axis=-2)[..., :, None, :]


def lecture_projectile() -> Problem:
    """m = 2.5 kg, p = (10, 0, 2) m, V = (7.68, 0, 29) m/s, g = (0, 0, -9.81), t0 = 5 s."""
    model = Model([LECTURE_MASS], [0.1], [Gravity(np.array(LECTURE_G))])
    y0 = np.array([[LECTURE_P0], [LECTURE_V0]], dtype=float)

    def exact(t):
        return projectile_solution(t, LECTURE_P0, LECTURE_V0, LECTURE_G, LECTURE_T0)

    return Problem("projectile", model, y0, LECTURE_T0, exact)


def tetrahedron(scale=1.0):
    """The 4 vertices of a regular-ish tetrahedron (not all edges equal, on purpose)."""
    return scale * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.9, 0.0], [0.4, 0.3, 0.8]])


def soft_tetrahedron(stiffness=50.0, damping=0.5, mass=0.25, gravity=True, deform=0.1,
                     speed=0.5, seed=0, offset=0, pinned=None):
    """An all-pairs soft body of 4 vertices, deformed and moving (forces, y0, masses).

    Rest lengths are the undeformed distances; the initial state is displaced by up to
    ``deform`` m and given random velocities of up to ``speed`` m/s.
    """
    rng = np.random.default_rng(seed)
    rest = tetrahedron() + np.array([0.0, 0.0, 1.0])
    springs, dampers = connect(rest, all_pairs(4), stiffness, damping, offset)
    forces = [springs] + ([dampers] if dampers is not None else [])
    if gravity:
        forces.append(Gravity())
    q0 = rest + rng.uniform(-deform, deform, size=(4, 3))
    v0 = rng.uniform(-speed, speed, size=(4, 3))
    return forces, np.stack([q0, v0]), np.full(4, mass)


def mixed_problem() -> Problem:
    """Three independent systems in one model, every applied force kind on the way:

    bodies 0-1 a spring oscillator with a damper to a pinned anchor, body 2 a projectile
    with quadratic drag, bodies 3-6 a deformed moving all-pairs soft body with dampers;
    gravity on all of them.
    """
    rng = np.random.default_rng(7)
    k = 40.0
    soft_forces, soft_y0, soft_masses = soft_tetrahedron(offset=3, gravity=False, seed=3)
    masses = np.concatenate([[1.0, 0.8, 0.43], soft_masses])
    radii = np.concatenate([[0.05, 0.05, 0.11], np.full(4, 0.05)])
    forces = [
        Gravity(),
        Springs(np.array([0]), np.array([1]), np.array([k]), np.array([0.7])),
        Dampers(np.array([0]), np.array([1]), np.array([0.3])),
        Drag.from_coefficients(radii, mask=np.arange(7) >= 2),
        *soft_forces,
    ]
    pinned = np.zeros(7, bool)
    pinned[0] = True
    model = Model(masses, radii, forces, pinned=pinned)
    q0 = np.concatenate([[[0.0, 0.0, 3.0], [0.6, 0.2, 2.4], [0.0, 0.0, 0.0]], soft_y0[0]])
    v0 = np.concatenate([[[0.0, 0.0, 0.0], [0.3, -0.2, 0.0], [19.8, 0.0, 19.8]], soft_y0[1]])
    v0 = v0 + np.concatenate([np.zeros((3, 3)), rng.uniform(-0.1, 0.1, (4, 3))])
    return Problem("mixed", model, np.stack([q0, v0]))


def max_error(y, y_ref) -> float:
    return float(np.max(np.abs(np.asarray(y) - np.asarray(y_ref))))


def fit_order(dts, errors) -> float:
    """Least-squares slope of log(error) against log(dt)."""
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


#: the smallest valid scene, and the same with a second body 1 m away (for springs and errors)
ONE_BODY_SCENE = """
[simulation]
dt = 0.01
t_end = 1.0
[[bodies]]
name = "a"
mass = 1.0
radius = 0.1
position = [0.0, 0.0, 0.0]
"""
TWO_BODY_SCENE = ONE_BODY_SCENE + '[[bodies]]\nname = "b"\nmass = 1.0\nradius = 0.1\nposition = [1.0, 0.0, 0.0]\n'


#: why a browser test skips, in one line that says how to enable it
BROWSER_SKIP = ("headless Chromium not found: `apt-get install chromium chromium-driver` runs the browser tests "
                "(CI=true requires them)")


def browser_missing():
    """Called by a browser test that finds no Chromium: a skip on a fresh machine (the README's
    test command must pass there), a failure in CI, which installs Debian's ``chromium``."""
    import os

    import pytest

    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("CI=true requires the browser tests, and no Chromium was found (.ci/run installs it)")
    pytest.skip(BROWSER_SKIP)


def spring_net(seed, n=8, p=16):
    """A seeded random spring net for the position-based methods' tests: n bodies in the unit cube,
    p springs of 10-1000 N/m, pre-stretched +-20 %, random velocities."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.0, 1.0, (n, 3))
    pairs = set()
    while len(pairs) < p:
        a, b = sorted(rng.choice(n, 2, replace=False).tolist())
        pairs.add((a, b))
    i, j = np.array(sorted(pairs)).T
    rest = np.linalg.norm(q[j] - q[i], axis=1) * rng.uniform(0.8, 1.2, p)
    model = Model(rng.uniform(0.5, 2.0, n), np.full(n, 0.01), [Springs(i, j, rng.uniform(10.0, 1000.0, p), rest)])
    return model, np.stack([q, rng.normal(0.0, 1.0, (n, 3))])


def spy_on_animate(patch) -> dict:
    """What ``steplab animate`` gives steplab.animate and draws, while ``patch`` (a pytest.MonkeyPatch) holds:
    each call's runs and rotations, the energies of its energy panel and the view's axes that motion_view
    picks (the ``drawn`` fixture of tests/conftest.py)."""
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

    patch.setattr(steplab.animate, "animate", animate_)
    patch.setattr(steplab.animate, "energy_changes", changes_)
    patch.setattr(steplab.animate, "motion_view", view_)
    return seen


def run_main(capsys, argv) -> tuple[int, str, str]:
    """``steplab *argv`` in this process: (status, stdout, stderr); argparse's refusals, which exit, caught."""
    from steplab.cli import main

    try:
        status = main(list(argv))
    except SystemExit as exit_:
        status = exit_.code
    out, err = capsys.readouterr()
    return status, out, err


def refused(capsys, argv) -> str:
    """stderr of ``steplab *argv`` in this process, checked to be one line with status 2 and no traceback."""
    status, _, err = run_main(capsys, argv)
    assert status == 2, err
    assert "Traceback" not in err and err.count("\n") == 1, err
    return err


#: the built-in oscillator scene (a pinned anchor and a mass on a spring), as a file
OSCILLATOR_SCENE = Path(__file__).resolve().parent.parent / "physics" / "scenes" / "oscillator.toml"


def oscillator_scene(integrator: str | None = None, table: str = "") -> str:
    """The oscillator scene's TOML, stepped by ``integrator`` (default: its own), with ``table`` appended
    (a ``[simulation.<integrator>]`` table of settings, say)."""
    text = OSCILLATOR_SCENE.read_text()
    if integrator is not None:
        text = text.replace('integrator = "semi-implicit-euler"', f'integrator = "{integrator}"')
    return text + table

