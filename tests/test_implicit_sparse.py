"""Implicit Euler at scale: the sparse Jacobian, the CG Newton step, and what they must agree with.

References: the dense Jacobian and dense Newton solve (small systems, same step to 1e-10),
JAX's forward-mode derivative of the acceleration, the analytic one-step map
(I - h A)^-1 of implicit Euler on the linear damped oscillator, and implicit Euler's own
equations v1 = v + h a(q + h v1, v1), checked on the step it returns.
"""

from __future__ import annotations

import math
import warnings

import helpers
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.testing import assert_allclose
from steplab.integrators import ImplicitEuler, simulate
from steplab.integrators import conjugate_gradients as cg
from steplab.integrators.implicit_euler import DENSE_MAX_BODIES
from steplab.physics import CentralGravity, Dampers, Drag, Gravity, Model, Springs, sparse_jacobian
from steplab.physics.soft_body import connect, grid
from steplab.physics.sparse_jacobian import newton_matrix

TIGHT = 1e-12  # Newton's rtol where the sparse and dense steps are compared to 1e-10


def network(seed: int = 0, n: int = 9, squeeze: float = 0.15, speed: float = 0.5):
    """Bodies on springs and dampers (some pairs twice, in both orders), gravity, drag; body 4 pinned.

    Rest lengths within ``squeeze`` of the initial lengths, so some springs start
    compressed (negative transverse stiffness), some stretched.
    """
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, (n, 3))
    i = np.array([0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 2, 1])
    j = np.array([1, 2, 3, 4, 5, 6, 7, 8, 0, 3, 0, 0])  # (1, 0) repeats (0, 1) the other way round
    length = np.linalg.norm(q[j] - q[i], axis=1)
    springs = Springs(i, j, rng.uniform(5.0, 20.0, i.size), length * rng.uniform(1 - squeeze, 1 + squeeze, i.size))
    dampers = Dampers(i[:7], j[:7], rng.uniform(0.1, 0.5, 7))
    pinned = np.zeros(n, bool)
    pinned[4] = True
    model = Model(rng.uniform(0.5, 2.0, n), np.full(n, 0.1),
                  [Gravity(), springs, dampers, Drag.from_coefficients(np.full(n, 0.3))], pinned=pinned)
    v = rng.normal(0.0, speed, (n, 3)) * ~pinned[:, None]
    return model, np.stack([q, v])


def sparse(rtol=TIGHT, **kwargs):
    return ImplicitEuler(rtol=rtol, linear_solver="cg", cg_rtol=1e-10, **kwargs)


# --- the sparse Jacobian -----------------------------------------------------------------------


def test_sparse_jacobian_is_the_derivative_of_the_acceleration():
    model, y = network()
    model = Model(model.masses, model.radii, [*model.forces, CentralGravity(3.0)], pinned=model.pinned)
    y[1, 4] = 0.1  # every body moving: drag's |v| has no derivative at v = 0
    dq, dv = model.sparse_jacobian(0.0, y[0], y[1])
    n3 = 3 * model.n_bodies
    # independent reference: forward-mode autodiff of the acceleration itself
    jacobians = jax.jit(jax.jacfwd(model.cast(jnp).acceleration, argnums=(1, 2)))
    jq, jv = jacobians(0.0, jnp.asarray(y[0]), jnp.asarray(y[1]))
    for sparse_part, exact in ((dq, np.asarray(jq).reshape(n3, n3)), (dv, np.asarray(jv).reshape(n3, n3))):
        assert_allclose(sparse_part.toarray(), exact, rtol=0, atol=1e-12 * np.abs(exact).max())
    dense_q, dense_v = model.jacobian(0.0, y[0], y[1])
    assert_allclose(dq.toarray(), dense_q, rtol=0, atol=1e-13 * np.abs(dense_q).max())
    assert_allclose(dv.toarray(), dense_v, rtol=0, atol=1e-13 * np.abs(dense_v).max())


def test_newton_matrix_is_the_symmetric_part_and_the_definite_one_is_positive_definite():
    model, y = network(squeeze=0.5, speed=3.0)
    h = 0.5
    free = np.repeat(~model.pinned, 3)
    dq, dv = model.jacobian(0.0, y[0], y[1])
    weighted = np.repeat(np.asarray(model.masses), 3)[:, None] * (np.eye(dq.shape[0]) - h * h * dq - h * dv)
    expected = (0.5 * (weighted + weighted.T))[np.ix_(free, free)]
    symmetric, _ = newton_matrix(model, 0.0, y[0], y[1], h)
    assert_allclose(symmetric.toarray(), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    # strongly compressed springs at this h make the symmetric part indefinite; the definite part never is
    assert np.linalg.eigvalsh(symmetric.toarray()).min() < 0
    definite, _ = newton_matrix(model, 0.0, y[0], y[1], h, definite=True)
    a = definite.toarray()
    assert_allclose(a, a.T, rtol=0, atol=1e-15 * np.abs(a).max())
    assert np.linalg.eigvalsh(a).min() >= np.min(model.masses) * (1 - 1e-12)
    # the springs' and dampers' compiled kernels add the same blocks as their jacobian_blocks
    for flag, compiled in ((False, symmetric), (True, definite)):
        generic = newton_matrix(model, 0.0, y[0], y[1], h, definite=flag, compiled=False)[0].toarray()
        assert_allclose(compiled.toarray(), generic, rtol=0, atol=1e-14 * np.abs(generic).max())


def test_the_compiled_forces_and_blocks_are_the_models():
    # springs with dampers on the same pairs (one kernel pass), dampers on pairs of their own,
    # drag and gravity (NumPy), and a pair of coincident bodies (no direction: no force, a
    # spring block k I)
    model, y = network()
    springs = model.forces[1]
    q = y[0].copy()
    q[6] = q[5]  # bodies 5 and 6 coincide: the pair (5, 6) has zero length
    on_springs = Dampers(springs.i, springs.j, np.linspace(0.1, 0.3, springs.i.size))
    model = Model(model.masses, model.radii, [*model.forces, on_springs], pinned=model.pinned)
    a, matrix, pattern = sparse_jacobian.newton_system(model, 0.0, q, y[1], 0.1)
    expected = model.acceleration(0.0, q, y[1])
    assert_allclose(a, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    assert_allclose(sparse_jacobian.acceleration(model, 0.0, q, y[1]), expected, rtol=0,
                    atol=1e-14 * np.abs(expected).max())
    generic = newton_matrix(model, 0.0, q, y[1], 0.1, compiled=False)[0].toarray()
    assert_allclose(matrix.toarray(), generic, rtol=0, atol=1e-14 * np.abs(generic).max())
    assert_allclose(pattern.kept, np.flatnonzero(~model.pinned))


# --- the CG step against the dense step and the equations of implicit Euler ---------------------


@pytest.mark.parametrize("seed, dt", [(0, 0.01), (1, 0.05), (2, 0.2)])
def test_cg_step_equals_the_dense_step(seed, dt):
    model, y = network(seed)
    dense = ImplicitEuler(rtol=TIGHT, linear_solver="dense").step(model, 0.0, y, dt, None)[0]
    step = sparse().step(model, 0.0, y, dt, None)[0]
    assert_allclose(step, dense, rtol=0, atol=1e-10)
    assert_allclose(step[:, 4], y[:, 4], rtol=0, atol=0)  # the pinned body never moves


@pytest.mark.parametrize("seed, squeeze, speed, dt", [(0, 0.15, 0.5, 0.05), (7, 0.3, 1.0, 0.5)])
def test_cg_step_solves_the_implicit_euler_equations(seed, squeeze, speed, dt):
    model, y = network(seed, squeeze=squeeze, speed=speed)
    indefinite = np.linalg.eigvalsh(newton_matrix(model, 0.0, y[0], y[1], dt)[0].toarray()).min() < 0
    assert indefinite == (dt == 0.5)  # there the step falls back to the definite Newton matrix
    y1 = sparse().step(model, 0.0, y, dt, None)[0]
    q1, v1 = y1
    assert_allclose(q1, y[0] + dt * v1, rtol=0, atol=1e-15)
    residual = v1 - y[1] - dt * model.acceleration(dt, q1, v1)
    assert np.max(np.abs(residual)) <= 1e-10 * (1 + np.max(np.abs(v1)))
    dense = ImplicitEuler(rtol=TIGHT, linear_solver="dense").step(model, 0.0, y, dt, None)[0]
    assert_allclose(y1, dense, rtol=0, atol=1e-10)


def test_cloth_step_equals_the_dense_step_and_auto_picks_the_solver():
    mesh = grid(8, 8, 0.1, origin=(0.0, 0.0, 2.0))
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=100.0, damping=0.05)
    pinned = np.zeros(64, bool)
    pinned[[0, 7]] = True
    model = Model(np.full(64, 0.01), np.full(64, 0.01), [Gravity(), springs, dampers], pinned=pinned)
    y = np.stack([mesh.vertices, np.zeros_like(mesh.vertices)])
    for _ in range(3):
        dense = ImplicitEuler(rtol=TIGHT).step(model, 0.0, y, 0.02, None)[0]  # auto: dense at 64 bodies
        step = sparse().step(model, 0.0, y, 0.02, None)[0]
        assert_allclose(step, dense, rtol=0, atol=1e-10)
        y = dense
    assert not ImplicitEuler().uses_cg(model) and sparse().uses_cg(model)
    big = Model(np.ones(DENSE_MAX_BODIES + 1), np.ones(DENSE_MAX_BODIES + 1), [Gravity()])
    assert ImplicitEuler().uses_cg(big) and not ImplicitEuler().uses_cg(big.cast(jnp))


def test_one_newton_iteration_is_the_linearised_step():
    # Baraff and Witkin's step: one Newton iteration from v1 = v, A delta = -M G(v)
    model, y = network(4)
    dt = 0.05
    y1 = ImplicitEuler(linear_solver="cg", cg_rtol=1e-12, newton_iterations=1).step(model, 0.0, y, dt, None)[0]
    dense = ImplicitEuler(linear_solver="dense", newton_iterations=1).step(model, 0.0, y, dt, None)[0]
    q, v = y
    g = -dt * model.acceleration(dt, q + dt * v, v)  # G(v) = v - v - dt a(q + dt v, v)
    dq, dv = model.jacobian(dt, q + dt * v, v)
    n3 = dq.shape[0]
    weighted = np.repeat(np.asarray(model.masses), 3)[:, None] * (np.eye(n3) - dt * dt * dq - dt * dv)
    free = np.repeat(~model.pinned, 3)
    delta = np.zeros(n3)
    # the CG step solves with the symmetric part of the mass-weighted matrix (no damper dq asymmetry left)
    sym = 0.5 * (weighted + weighted.T)
    rhs = -(np.repeat(np.asarray(model.masses), 3) * g.ravel())
    delta[free] = np.linalg.solve(sym[np.ix_(free, free)], rhs[free])
    assert_allclose(y1[1], v + delta.reshape(v.shape), rtol=0, atol=1e-11)
    # the dense step solves the unsymmetrised system: the two differ by O(dt^2 |dF/dq of the dampers|)
    assert np.max(np.abs(y1[1] - dense[1])) < 1e-2 * np.max(np.abs(dense[1] - v))


# --- damped-spring invariants -----------------------------------------------------------------


def linear_oscillator(omega=2 * math.pi, zeta=0.1, amplitude=0.3, velocity=1.0):
    k, m = omega**2, 1.0
    return helpers.oscillator(stiffness=k, mass=m, damping=2 * zeta * omega * m, amplitude=amplitude,
                              velocity=velocity, direction=(1.0, 2.0, -2.0), with_exact=False)


@pytest.mark.parametrize("omega_dt", [0.1, 1.0, 10.0])
def test_one_step_is_the_analytic_map_on_the_linear_oscillator(omega_dt):
    # s'' = -omega^2 s - 2 zeta omega s' along the spring: y1 = (I - h A)^-1 y0 exactly
    omega, zeta = 2 * math.pi, 0.1
    problem = linear_oscillator(omega, zeta)
    h = omega_dt / omega
    a = np.array([[0.0, 1.0], [-omega**2, -2 * zeta * omega]])
    expected = np.linalg.solve(np.eye(2) - h * a, [0.3, 1.0])
    y1 = sparse().step(problem.model, 0.0, problem.y0, h, None)[0]
    u = np.array([1.0, 2.0, -2.0]) / 3.0
    s = np.linalg.norm(y1[0, 1] - y1[0, 0]) - 1.0
    assert_allclose([s, y1[1, 1] @ u], expected, rtol=1e-12, atol=1e-13)
    assert_allclose(np.cross(y1[1, 1], u), 0.0, atol=1e-13)  # stays on the spring's line


def test_implicit_euler_never_gains_energy_on_a_damped_spring():
    problem = linear_oscillator(zeta=0.05, amplitude=0.2, velocity=0.5)
    k, m = (2 * math.pi) ** 2, 1.0
    stepper = sparse(rtol=None)
    for dt in (0.01, 0.3, 3.0):
        y, energy = problem.y0, [helpers.oscillator_energy(problem.y0, k, m)]
        for _ in range(30):
            y = stepper.step(problem.model, 0.0, y, dt, None)[0]
            energy.append(helpers.oscillator_energy(y, k, m))
        assert np.all(np.diff(energy) <= 1e-12 * energy[0])
        assert energy[-1] < energy[0]


# --- conjugate gradients: converged, or told why not ----------------------------------------------


def spd(n=30, seed=0):
    from scipy.sparse import csr_array

    x = np.random.default_rng(seed).normal(size=(n, n))
    return csr_array(x @ x.T + n * np.eye(n)), np.random.default_rng(seed + 1).normal(size=n)


def block_parts(a):
    """D (the 3x3 diagonal blocks) and L (the blocks below them) of a dense matrix."""
    d = np.zeros_like(a)
    for r in range(0, a.shape[0], 3):
        d[r:r + 3, r:r + 3] = a[r:r + 3, r:r + 3]
    rows, cols = np.indices(a.shape) // 3
    return d, np.where(rows > cols, a, 0.0)


@pytest.mark.parametrize("preconditioner", cg.PRECONDITIONERS)
def test_cg_reports_its_residual_and_iterations(preconditioner):
    from scipy.sparse.linalg import cg as scipy_cg

    a, b = spd()
    result = cg.solve(a, b, rtol=1e-10, preconditioner=preconditioner)
    assert result.converged and 0 < result.iterations <= 30
    assert result.residual <= 2e-10
    assert_allclose(result.x, np.linalg.solve(a.toarray(), b), rtol=1e-8)
    # the same iteration as scipy's cg preconditioned by block Jacobi, M = D, or by symmetric
    # Gauss-Seidel, M = (D + L) D^-1 (D + L)^T (run here through Eisenstat's congruent system):
    # the same iterates
    d, lower = block_parts(a.toarray())
    w = d + lower
    inverse = np.linalg.inv(d) if preconditioner == "block-jacobi" else np.linalg.inv(w @ np.linalg.inv(d) @ w.T)
    for steps in (1, 4):
        ours = cg.solve(a, b, rtol=1e-300, maxiter=steps, preconditioner=preconditioner)
        theirs, _ = scipy_cg(a, b, rtol=1e-300, maxiter=steps, M=inverse)
        assert not ours.converged and ours.iterations == steps
        assert_allclose(ours.x, theirs, rtol=1e-10, atol=1e-14)
        assert_allclose(ours.residual, np.linalg.norm(b - a @ theirs) / np.linalg.norm(b), rtol=1e-8)


def test_gauss_seidel_cg_solves_a_cloth_newton_system_as_a_direct_solver_does():
    from scipy.sparse.linalg import spsolve

    mesh = grid(12, 12, 0.1, origin=(0.0, 0.0, 2.0))
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=100.0, damping=0.05)
    model = Model(np.full(144, 0.01), np.full(144, 0.01), [Gravity(), springs, dampers])
    q = mesh.vertices + np.random.default_rng(3).normal(0.0, 0.01, mesh.vertices.shape)
    v = np.random.default_rng(4).normal(0.0, 0.1, q.shape)
    matrix, _ = newton_matrix(model, 0.0, q, v, 0.02, definite=True)  # h^2 k / m = 4: some springs buckle
    b = np.random.default_rng(5).normal(size=matrix.shape[0])
    exact = spsolve(matrix.tobsr().tocsc(), b)
    iterations = {}
    for preconditioner in cg.PRECONDITIONERS:
        result = cg.solve(matrix, b, rtol=1e-10, preconditioner=preconditioner)
        assert result.converged
        assert_allclose(result.x, exact, rtol=0, atol=1e-8 * np.abs(exact).max())
        iterations[preconditioner] = result.iterations
    assert iterations["gauss-seidel"] < iterations["block-jacobi"]


def test_symmetric_block_matrix_is_the_matrix_it_stores():
    from steplab.physics.symmetric_blocks import SymmetricBlockMatrix

    a, _ = spd()
    stored = SymmetricBlockMatrix.from_sparse(a)
    assert stored.pairs.n_pairs == 45  # 10 block rows, all coupled: 10 * 9 / 2 blocks above the diagonal
    assert_allclose(stored.toarray(), a.toarray(), rtol=0, atol=0)
    x = np.random.default_rng(2).normal(size=30)
    assert_allclose(stored @ x, a.toarray() @ x, rtol=1e-13)
    with pytest.raises(ValueError, match="not symmetric"):
        SymmetricBlockMatrix.from_sparse(np.triu(a.toarray()))
    with pytest.raises(ValueError, match="3n rows"):
        SymmetricBlockMatrix.from_sparse(np.eye(4))


def test_cg_refuses_what_it_cannot_solve():
    from scipy.sparse import csr_array

    a, b = spd()
    nan = cg.solve(a, np.full_like(b, np.nan))
    assert not nan.converged and np.isnan(nan.residual) and np.all(np.isnan(nan.x))
    with pytest.raises(cg.NotPositiveDefiniteError, match="diagonal block"):
        cg.solve(-a, b)
    # positive definite diagonal blocks, an indefinite matrix (eigenvalues 1 - 2 and 1 + 2)
    indefinite = csr_array(np.kron([[1.0, 2.0], [2.0, 1.0]], np.eye(3)))
    for preconditioner in cg.PRECONDITIONERS:
        with pytest.raises(cg.NotPositiveDefiniteError, match="p\\^T A p <= 0"):
            cg.solve(indefinite, np.array([1.0, 0, 0, -1.0, 0, 0]), preconditioner=preconditioner)
    with pytest.raises(ValueError, match="preconditioner must be one of block-jacobi, gauss-seidel"):
        cg.solve(a, b, preconditioner="ilu")


def test_a_cg_solve_short_of_its_tolerance_warns_with_the_residual():
    model, y = network(5)
    with pytest.warns(cg.CGConvergenceWarning, match=r"relative residual [0-9.e+-]+ \(> cg_rtol = 1e-300\)"):
        ImplicitEuler(linear_solver="cg", cg_rtol=1e-300).step(model, 0.0, y, 0.01, None)


def test_a_failed_sparse_step_is_reported_not_silent():
    # Newton cannot converge within its iterations at rtol 1e-300: NaN, which simulate reports
    model, y = network(6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cg.CGConvergenceWarning)
        step = ImplicitEuler(rtol=1e-300, linear_solver="cg").step(model, 0.0, y, 0.01, None)[0]
        assert np.all(np.isnan(step))
        with pytest.raises(ArithmeticError, match="diverged"):
            simulate(model, ImplicitEuler(rtol=1e-300, linear_solver="cg"), y, 0.0, dt=0.01, n_steps=2)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="linear_solver must be one of auto, dense, cg"):
        ImplicitEuler(linear_solver="lu")
    with pytest.raises(ValueError, match="newton_iterations"):
        ImplicitEuler(newton_iterations=0)
    model, y = network()
    with pytest.raises(ValueError, match="NumPy backend"):
        ImplicitEuler(linear_solver="cg").step(model.cast(jnp), 0.0, jnp.asarray(y), 0.01, None)
    # the dense solve refuses what would not fit (the bench's cloth: 44 GiB a matrix), before allocating
    big = Model(np.ones(4_000), np.ones(4_000), [Gravity()])
    with pytest.raises(ValueError, match=r"implicit-euler: the dense Jacobian of 4,000 bodies needs \(3N\)\^2 "
                                         r"matrices of .* GiB each"):
        ImplicitEuler(linear_solver="dense").step(big, 0.0, np.zeros((2, 4_000, 3)), 0.01, None)


def test_stiffest_mode_from_the_sparse_jacobian(monkeypatch):
    # steplab check's mode: from the sparse Jacobian (large models) as from differences of the forces
    from steplab.physics import modes
    from steplab.physics.scene import load_scene

    scene = load_scene("cloth")
    assert sparse_jacobian.is_complete(scene.model)
    reference = modes.stiffest_mode(scene.model, scene.y0[0], derivative="difference")
    monkeypatch.setattr(modes, "SPARSE_SIZE", 0)
    mode = modes.stiffest_mode(scene.model, scene.y0[0], derivative="difference")
    assert mode.omega == pytest.approx(reference.omega, rel=1e-8)
    assert mode.damping_ratio == pytest.approx(reference.damping_ratio, rel=1e-6)


def test_a_heavily_damped_cloth_steps_as_the_dense_solve_does():
    # dampers of 100 N s/m on the built-in cloth at a frame's step: the dampers' dependence on positions,
    # left out of CG's symmetric and definite matrices, outweighs the masses, and that iteration stopped
    # contracting (the run diverged at step 3); the step falls back to Newton on the exact sparse Jacobian
    from steplab.studies.soft_bodies import FRAME, cloth_scene

    scene = cloth_scene(damping=100.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cg.CGConvergenceWarning)
        step = simulate(scene.model, sparse(), scene.y0, 0.0, dt=FRAME, n_steps=6).y[-1]
    dense = simulate(scene.model, ImplicitEuler(rtol=TIGHT, linear_solver="dense"), scene.y0, 0.0, dt=FRAME,
                     n_steps=6).y[-1]
    assert_allclose(step, dense, rtol=0, atol=1e-9)
