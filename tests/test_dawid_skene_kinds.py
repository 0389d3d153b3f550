"""The overdispersed E-step's terms computed once per kind of cell (a distinct (worker, label)
column and count), against every cell computed on its own.

``_Groups`` computes :func:`dirichlet_multinomial_cells` once per kind and gathers it to the cells
(docs/performance.md); the values are those of each cell computed on its own, bit for bit, so the
fit is the same to the last bit as well. Tables here have repeated kinds (whole and fractional
counts), workers with a finite and an infinite concentration, and independent workers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse

from sgbelief.calibration import dawid_skene
from sgbelief.calibration.dawid_skene import CONCENTRATIONS, DawidSkene, _Groups, dirichlet_multinomial_cells


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@st.composite
def observations(draw):
    """(tasks, workers, labels, weights, n_tasks, n_workers, n_labels): up to 60 observations."""
    n_t, n_w, n_l = draw(st.integers(1, 12)), draw(st.integers(1, 3)), draw(st.integers(1, 5))
    n = draw(st.integers(1, 60))
    ints = lambda hi: st.lists(st.integers(0, hi - 1), min_size=n, max_size=n)  # noqa: E731
    weights = draw(st.lists(st.sampled_from([1.0, 1.0, 0.5, 0.25, 0.7]), min_size=n, max_size=n))
    return (np.array(draw(ints(n_t))), np.array(draw(ints(n_w))), np.array(draw(ints(n_l))), np.array(weights),
            n_t, n_w, n_l)


def _cells(tasks, workers, labels, weights, n_t, n_w, n_l):
    return sparse.csr_matrix((weights, (tasks, workers * n_l + labels)), shape=(n_t, n_w * n_l))


@settings(max_examples=200, deadline=None)
@given(observations(), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_the_terms_by_kind_are_each_cells_own(obs, k, seed) -> None:
    *_, n_t, n_w, n_l = obs
    groups = _Groups(_cells(*obs), n_w, n_l)
    rng = np.random.default_rng(seed)
    theta = rng.dirichlet(np.ones(n_l), size=(n_w, k))
    conc = rng.choice(np.array(CONCENTRATIONS), n_w)
    rows = theta.transpose(0, 2, 1).reshape(n_w * n_l, k)
    own = dirichlet_multinomial_cells(groups.count, conc[groups.worker], rows[groups.col])
    assert _same_bits(groups._terms(groups.kinds, conc, theta), own)
    some = np.flatnonzero(groups.count != 1.0)
    for s in (np.inf, 32.0, 0.5):  # as the concentration search asks: one s for all
        want = dirichlet_multinomial_cells(groups.count[some], s, rows[groups.col[some]])
        assert _same_bits(groups._terms(groups.kinds.subset(some), np.full(n_w, s), theta), want)


class _EveryCellItsOwn(_Groups):
    def __init__(self, cells, n_workers, n_labels):
        super().__init__(cells, n_workers, n_labels, distinct=False)


@settings(max_examples=100, deadline=None)
@given(observations(), st.booleans())
def test_a_fit_by_kind_is_the_fit_cell_by_cell(obs, one_independent) -> None:
    tasks, workers, labels, weights, n_t, n_w, n_l = obs
    k = 3
    rng = np.random.default_rng(len(tasks))
    initial = rng.dirichlet(np.ones(k), size=n_t)
    independent = np.zeros(n_w, dtype=bool)
    independent[0] = one_independent

    def fit():
        ds = DawidSkene(n_iter=20, emission="dirichlet_multinomial", none_class=False)
        return ds.fit_coded(tasks, workers, labels, n_w, n_l, initial.copy(), weights, independent=independent)

    by_kind = fit()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dawid_skene, "_Groups", _EveryCellItsOwn)
        cell_by_cell = fit()
    for name in ("probas_", "errors_", "priors_", "concentrations_"):
        assert _same_bits(getattr(by_kind, name), getattr(cell_by_cell, name)), name
    assert by_kind.n_iter_ == cell_by_cell.n_iter_


def test_a_map_has_far_fewer_kinds_than_cells() -> None:
    """Two detectors' claims, mostly whole, on 200 elements: the kinds are the (detector, class,
    count) triples seen, not the cells."""
    rng = np.random.default_rng(3)
    n = 2000
    tasks, workers, labels = rng.integers(0, 200, n), rng.integers(0, 2, n), rng.integers(0, 10, n)
    groups = _Groups(_cells(tasks, workers, labels, np.ones(n), 200, 2, 10), 2, 10)
    assert groups.kinds.of_cell is not None
    assert len(groups.kinds.col) < len(groups.count) / 5
