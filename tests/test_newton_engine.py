"""NVIDIA Newton as a peer (steplab.engines.newton_engine): its solvers against steplab's methods,
and one-line errors for what the adapter cannot express.

The solver tests need the extra ``pip install -e ".[newton]"`` and are skipped without it
(CI's default install leaves it out: Warp compiles its kernels on first use, about a
minute, then runs them from ~/.cache/warp).
"""

import numpy as np
import pytest
from steplab.integrators import simulate
from steplab.integrators.position_based import XPBD
from steplab.physics import Drag, Gravity, Model
from steplab.physics.scene import load_scene
from steplab.studies.problems import oscillator_problem

from steplab.engines import ENGINES, EngineNotInstalledError, UnsupportedFeatureError, build

SETTINGS = {s.key: s for s in ENGINES["newton"].study_settings}
#: steps of the comparisons: long enough for the methods to part (by 1e-3 and more), short
#: enough that float32 round-off stays near its own size
STEPS = 40


def needs_newton():
    pytest.importorskip("newton", reason="needs the extra steplab[newton]")


@pytest.fixture(scope="module")
def cloth():
    from steplab.bench.cloth import swinging_cloth

    return swinging_cloth()


def relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_semi_implicit_cloth_equals_steplab_semi_implicit_euler_to_float32_round_off(cloth):
    """Newton's SolverSemiImplicit is steplab's semi-implicit Euler: it differs from it by what
    steplab's own float32 run differs by (round-off), and from the nearest other method by 100x more."""
    needs_newton()
    model, y0, dt = cloth
    ours = simulate(model, "semi-implicit-euler", y0, 0.0, dt=dt, n_steps=STEPS).y
    round_off = relative(simulate(model, "semi-implicit-euler", y0, 0.0, dt=dt, n_steps=STEPS, dtype=np.float32).y,
                         ours)
    theirs = SETTINGS["newton-semi-implicit"].build(model, None, dt, y0).advance(y0, dt, STEPS).y
    assert relative(theirs, ours) <= 4 * round_off
    nearest_other = min(relative(simulate(model, m, y0, 0.0, dt=dt, n_steps=STEPS).y, ours)
                        for m in ("velocity-verlet", "position-first-euler", "euler"))
    assert relative(theirs, ours) < 0.01 * nearest_other


def test_xpbd_is_steplabs_on_one_spring_and_a_jacobi_sweep_on_the_cloth(cloth):
    """Newton's SolverXPBD takes steplab's compliance 1 / (k dt^2) and damping kd / (k dt): on one
    damped spring (where a Jacobi sweep is a Gauss-Seidel one) it is steplab's xpbd to float32
    round-off; on the cloth its Jacobi sweep is another method, 1e-3 and more away."""
    needs_newton()
    problem = oscillator_problem(0.1)
    dt = 0.1 / problem.omega
    ours = simulate(problem.model, XPBD(iterations=1), problem.y0, 0.0, dt=dt, n_steps=100).y
    theirs = SETTINGS["newton-xpbd"].build(problem.model, None, dt, problem.y0).advance(problem.y0, dt, 100).y
    assert relative(theirs, ours) < 2e-5
    model, y0, dt = cloth
    ours = simulate(model, XPBD(iterations=1), y0, 0.0, dt=dt, n_steps=STEPS).y
    theirs = SETTINGS["newton-xpbd"].build(model, None, dt, y0).advance(y0, dt, STEPS).y
    assert relative(theirs, ours) > 1e-3


@pytest.mark.slow  # 30 s on a loaded 2-core machine: pytest tests/test_newton_engine.py -m slow -n 0
def test_vbd_is_implicit_euler_but_for_float32_positions(cloth):
    """Newton's SolverVBD, iterated, stays about 5e-4 from implicit Euler on the cloth: not a
    different fixed point but float32 positions. It solves for x and takes v = (x - x_prev) / h,
    so its round-off is eps32 |x| / h: the same cloth 20 m from the origin is many times further
    from implicit Euler (which moves with it to 1e-13), 1 m nearer it is closer, and more
    iterations change nothing."""
    needs_newton()
    from steplab.integrators import ImplicitEuler

    model, y0, dt = cloth
    # the velocities of implicit Euler, which a shift of the cloth leaves unchanged (uniform gravity)
    ours = simulate(model, ImplicitEuler(rtol=1e-12), y0, 0.0, dt=dt, n_steps=STEPS).y[:, 1]
    gaps = {}
    for shift, iterations in ((0.0, 8), (0.0, 32), (-1.0, 8), (20.0, 8)):
        y = y0.copy()
        y[0, :, 2] += shift
        theirs = build("newton", model, None, dt, y, solver="vbd", iterations=iterations).advance(y, dt, STEPS).y
        gaps[shift, iterations] = float(np.max(np.abs(theirs[:, 1] - ours)))  # m/s
    assert 1e-4 < gaps[0.0, 8] < 5e-3  # 9e-4 m/s measured; eps32 x 2 m / 2 ms = 1.2e-4 m/s a step
    assert 0.5 < gaps[0.0, 32] / gaps[0.0, 8] < 2  # converged: iterations do not close the gap
    assert gaps[-1.0, 8] < gaps[0.0, 8] < gaps[20.0, 8] / 5  # it grows with |x|


@pytest.mark.parametrize("solver", ["SolverSemiImplicit", "SolverXPBD", "SolverFeatherstone"])
def test_rigid_solvers_step_the_tumbling_box_as_the_first_order_quaternion_update(solver):
    """Each Newton rigid solver turns the dzhanibekov box as steplab's first-order-quaternion
    method (explicit gyroscopic omega first, then q += h/2 q (0, omega1), normalised): within float32
    round-off over 20 frames, where every other steplab method is 2.5e-4 and more away."""
    needs_newton()
    from steplab.integrators import ROTATIONS, get_rotation
    from steplab.integrators.rotation import simulate_rotation
    from steplab.physics import quaternion as quat
    from steplab.physics.rigid_body import RotationModel

    from steplab.bench.newton_rotation import rotation_apart, tumbling_box
    from steplab.engines.newton_engine import free_body_rotation

    inertia, omega0, dt = tumbling_box()
    q, omega = free_body_rotation(inertia, omega0, dt, 20, solver)
    apart = {}
    for name in ROTATIONS:
        _, q_ref, omega_ref = simulate_rotation(get_rotation(name), RotationModel(inertia[None, :]),
                                                quat.IDENTITY[None, :], omega0[None, :], dt, 20)
        apart[name] = rotation_apart(q, omega, q_ref[:, 0], omega_ref[:, 0])
    assert apart.pop("first-order-quaternion") < 1e-5
    assert min(apart.values()) > 2e-4


def test_what_the_adapter_cannot_express_is_one_line():
    model = Model([1.0], [0.1], [Gravity(), Drag.from_coefficients(np.array([0.1]))])
    with pytest.raises(UnsupportedFeatureError) as err:
        build("newton", model)
    assert "\n" not in str(err.value) and "drag" in str(err.value) and "Newton" in str(err.value)
    drop = load_scene("drop")
    with pytest.raises(UnsupportedFeatureError, match="^collisions: the Newton adapter") as err:
        build("newton", drop.model, drop.collisions, drop.dt, drop.y0)
    with pytest.raises(ValueError, match="unknown solver 'pbd'; valid: semi-implicit, xpbd, vbd"):
        build("newton", Model([1.0], [0.1], [Gravity()]), solver="pbd")


def test_without_newton_the_error_says_how_to_install_it(monkeypatch):
    monkeypatch.setattr(ENGINES["newton"], "available", classmethod(lambda cls: False))
    with pytest.raises(EngineNotInstalledError, match=r"\(pip install steplab\[newton\]\)$"):
        build("newton", Model([1.0], [0.1], [Gravity()]))
