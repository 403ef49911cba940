"""Pair forces on JAX: the incidence table's gather against a plain scatter-add, and the shared gathers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from steplab.physics import Dampers, Model, Springs
from steplab.physics._array import scatter_pairs
from steplab.physics.incidence import incidence, shared_indices, take_rows


def _scatter_reference(n, i, j, f):
    # the sums in pair order, first bodies then second bodies, one pair at a time
    out = np.zeros((n, 3))
    for p in range(len(i)):
        out[i[p]] += f[p]
    for p in range(len(i)):
        out[j[p]] -= f[p]
    return out


def _random_pairs(rng, n, p):
    i = rng.integers(0, n, p)
    j = (i + rng.integers(1, n, p)) % n  # never a body paired with itself
    return i, j


def test_pair_sums_by_gather_equal_the_scatter_add_bit_for_bit():
    rng = np.random.default_rng(3)
    n, p = 40, 90
    i, j = _random_pairs(rng, n - 1, p)  # body 39 in no pair
    i[:4], j[:4] = 0, 1  # a repeated pair
    f = rng.normal(size=(p, 3))
    table = incidence(jnp.asarray(i), jnp.asarray(j), n, np.float64)
    assert table is not None and table.slots == np.bincount(np.concatenate([i, j]), minlength=n).max()
    out = jax.jit(lambda f: scatter_pairs(jnp, n, jnp.asarray(i), jnp.asarray(j), f))(jnp.asarray(f))
    assert np.array_equal(np.asarray(out), _scatter_reference(n, i, j, f))


def test_a_hub_keeps_the_scatter_add():
    n = 200
    i, j = np.zeros(n - 1, int), np.arange(1, n)  # a star: body 0 in every pair
    f = np.random.default_rng(4).normal(size=(n - 1, 3))
    assert incidence(jnp.asarray(i), jnp.asarray(j), n, np.float64) is None
    out = scatter_pairs(jnp, n, jnp.asarray(i), jnp.asarray(j), jnp.asarray(f))
    np.testing.assert_allclose(np.asarray(out), _scatter_reference(n, i, j, f), rtol=0, atol=1e-12)


def test_take_rows_is_indexing():
    x = jnp.asarray(np.random.default_rng(5).normal(size=(7, 3)))
    index = np.array([6, 0, 0, 3])
    assert np.array_equal(np.asarray(jax.jit(lambda x: take_rows(x, jnp.asarray(index)))(x)), np.asarray(x)[index])
    assert np.array_equal(np.asarray(take_rows(x, jnp.asarray([-1, 2]))), np.asarray(x)[[-1, 2]])  # wraps


def test_forces_on_the_same_pairs_share_their_index_arrays():
    i, j = np.array([0, 1, 2]), np.array([1, 2, 3])
    springs = Springs(i, j, np.full(3, 10.0), np.ones(3))
    model = Model(np.ones(4), np.full(4, 0.1), [springs, Dampers(i.copy(), j.copy(), np.full(3, 0.5))], xp=jnp)
    s, d = model.forces
    assert s.i is d.i and s.j is d.j and s.i is not s.j
    assert shared_indices(jnp, i[::-1]) is not s.i  # equal contents only


@pytest.mark.parametrize("damping", [0.0, 0.3])
def test_cloth_force_on_jax_matches_numpy(damping):
    # a grid with structural and shear springs (and dampers): the gathers on JAX give
    # the NumPy force to round-off
    from steplab.physics.soft_body import connect, grid

    mesh = grid(6, 5, 0.2)
    springs, dampers = connect(mesh.vertices, mesh.edges, stiffness=50.0, damping=damping)
    rng = np.random.default_rng(6)
    q = mesh.vertices + rng.normal(0.0, 0.02, mesh.vertices.shape)
    v = rng.normal(0.0, 0.1, q.shape)
    model = Model(np.full(30, 1e-3), np.full(30, 0.01), [f for f in (springs, dampers) if f is not None])
    a_numpy = model.acceleration(0.0, q, v)
    a_jax = jax.jit(model.cast(jnp).acceleration)(0.0, jnp.asarray(q), jnp.asarray(v))
    np.testing.assert_allclose(np.asarray(a_jax), a_numpy, rtol=1e-13, atol=1e-9)
