"""Where the position-based sweep keeps each body (integrators/arrangement.py): a relabelling that moves
the blocks of the sweep into runs and leaves every byte of the result as it was."""

import numpy as np
import pytest
from steplab.integrators import PBD, XPBD, arrangement, simulate
from steplab.integrators.arrangement import arranged, chain_rows
from steplab.integrators.constraint_projection import RUN, layouts, ordered, wavefront


def test_a_chain_is_laid_out_even_places_first():
    # bodies 0-1-2-3-4 joined neighbour to neighbour, 5 alone, 6-7 a chain of two: evens of a chain, then its odds
    i, j = np.array([0, 1, 2, 3, 6]), np.array([1, 2, 3, 4, 7])
    assert chain_rows(i, j, 8).tolist() == [0, 3, 1, 4, 2, 5, 6, 7]
    assert chain_rows(j, i, 8).tolist() == [0, 3, 1, 4, 2, 5, 6, 7]  # either end first
    # cut into pieces of at most 4: (0 1 2 3) -> 0 2 1 3, then (4) alone
    assert chain_rows(i, j, 8, longest=4).tolist() == [0, 2, 1, 3, 4, 5, 6, 7]
    # a constraint between bodies two apart joins no chain
    assert chain_rows(np.array([0, 2]), np.array([2, 4]), 5).tolist() == [0, 1, 2, 3, 4]


def test_a_grids_rows_laid_out_put_its_horizontal_springs_in_runs():
    # the cloth's horizontal springs of one colour are (0, 1), (2, 3), ...: in the grid numbering their ends
    # advance by 2 (blocks by index), laid out by rows as runs by 1, as the vertical and shear springs already are
    from steplab.bench.systems import cloth_model

    model, _, _ = cloth_model(40)
    c, colours = ordered(XPBD(1, 1).constraints(model)[0], model.n_bodies)
    rows, swept, segments = arranged(c, colours, model.n_bodies)
    assert np.array_equal(np.sort(rows), np.arange(model.n_bodies)) and not np.array_equal(rows, np.sort(rows))
    numbered, numbered_segments = wavefront(c, colours)
    horizontal = lambda a: np.abs(a.i.astype(int) - a.j.astype(int)) == 1
    assert horizontal(numbered).sum() == 40 * 39  # the grid's rows: 39 springs each
    before = layouts(numbered.i, numbered.j, numbered_segments)
    kinds = layouts(swept.i, swept.j, segments)
    # rows of 40: runs of 20 and 19, each cut into halves of 4 and a rest by index
    assert np.count_nonzero(kinds == RUN) >= 0.85 * len(kinds)  # 90 %
    assert np.count_nonzero(before == RUN) <= 0.5 * len(kinds)  # 46 %: the vertical and shear springs
    # the same constraints, relabelled
    pairs = lambda a, b: set(zip(a.tolist(), b.tolist()))
    assert pairs(swept.i, swept.j) == pairs(rows[c.i], rows[c.j])


def test_a_numbering_without_chains_is_kept():
    # springs only between bodies two apart in number: no chains, the model's numbering stays
    from steplab.physics import Model, Springs

    n = 40
    i = np.arange(n - 2)
    model = Model(np.ones(n), np.full(n, 0.05), [Springs(i, i + 2, np.full(n - 2, 100.0), np.ones(n - 2))])
    c, colours = ordered(XPBD(1, 1).constraints(model)[0], n)
    rows, _, _ = arranged(c, colours, n)
    assert np.array_equal(rows, np.arange(n))


@pytest.mark.parametrize("method", [XPBD(1, 1), XPBD(2, 3), PBD(1, 4)], ids=["xpbd-1x1", "xpbd-2x3", "pbd-1x4"])
def test_the_rows_change_no_byte_of_the_result(method, monkeypatch):
    # the same run with the bodies in the grid numbering and laid out by chains: the same bytes
    from steplab.bench.systems import cloth_model

    model, y0, _ = cloth_model(24)
    rows = method.init(model, 0.0, y0).rows
    assert not np.array_equal(rows, np.arange(model.n_bodies))  # the rows are laid out by chains
    laid_out = simulate(model, method, y0, 0.0, n_steps=20, dt=1 / 600).y[-1]
    monkeypatch.setattr(arrangement, "chain_rows", lambda i, j, n: np.arange(n))
    numbered = simulate(model, method, y0, 0.0, n_steps=20, dt=1 / 600).y[-1]
    assert laid_out.tobytes() == numbered.tobytes() and not np.array_equal(laid_out, y0)
