"""The overdispersed E-step's terms computed once per kind of cell (a distinct (worker, label)
column and count), against every cell computed on its own.

``_Groups`` computes :func:`dirichlet_multinomial_cells` once per kind and reads each cell's term
from its kind's row (docs/performance.md); the E-step is the one computing each cell on its own,
bit for bit, and so is the whole fit. Tables here have repeated kinds (whole and fractional
counts), workers with a finite and an infinite concentration, and independent workers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse

from sgbelief.calibration import dawid_skene
from sgbelief.calibration.dawid_skene import (CONCENTRATIONS, DawidSkene, _dirichlet_multinomial_by_column, _Groups,
                                             dirichlet_multinomial_cells)


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


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.sampled_from([1.0, 1.0, 2.0, 3.0, 0.5, 1.5, 0.25, 7.0])),
                min_size=1, max_size=40),
       st.lists(st.sampled_from(CONCENTRATIONS), min_size=6, max_size=6), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_the_terms_by_column_are_the_cells_terms(cells, s_of_col, k, seed) -> None:
    """lnG(s theta) once per column gives each cell's :func:`dirichlet_multinomial_cells` bit for bit."""
    col = np.array([c for c, _ in cells], dtype=np.intp)
    count = np.array([n for _, n in cells])
    s_of_col = np.array(s_of_col)
    rows = np.random.default_rng(seed).dirichlet(np.ones(k) * 0.3, size=6) + 1e-12
    want = dirichlet_multinomial_cells(count, s_of_col[col], rows[col])
    assert _same_bits(_dirichlet_multinomial_by_column(count, col, s_of_col, rows), want)


def _e_step_as_first_written(groups, theta, pi, conc):
    """Every cell's term on its own, summed per task by a (tasks x cells) sparse product."""
    n_w, k, n_l = theta.shape
    terms = dirichlet_multinomial_cells(groups.count, conc[groups.worker],
                                        theta.transpose(0, 2, 1).reshape(n_w * n_l, k)[groups.col])
    nnz = len(groups.count)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(groups.task, minlength=groups.n_tasks))])
    by_task = sparse.csr_matrix((np.ones(nnz), np.arange(nnz), indptr), shape=(groups.n_tasks, nnz))
    log_lik = np.asarray(by_task @ terms) + np.log(pi)
    log_lik -= log_lik.max(axis=1, keepdims=True)
    q = np.exp(log_lik)
    return q / q.sum(axis=1, keepdims=True)


@settings(max_examples=200, deadline=None)
@given(observations(), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_the_e_step_by_kind_is_the_e_step_cell_by_cell(obs, k, seed) -> None:
    *_, n_t, n_w, n_l = obs
    groups = _Groups(_cells(*obs), n_w, n_l)
    rng = np.random.default_rng(seed)
    theta = rng.dirichlet(np.ones(n_l), size=(n_w, k))
    pi = rng.dirichlet(np.ones(k))
    conc = rng.choice(np.array(CONCENTRATIONS), n_w)
    assert _same_bits(groups.e_step(theta, pi, conc), _e_step_as_first_written(groups, theta, pi, conc))


class _EveryCellItsOwn(_Groups):
    """The groups without kinds: every step as first written (each cell's term computed on its own)."""

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
