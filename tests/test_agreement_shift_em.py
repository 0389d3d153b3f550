"""The agreement shift's EM (``fit_agreement_shift``) against the EM as first written.

The EM was rewritten for fewer numpy calls per iteration (a flat index into the posterior table,
``np.maximum`` / ``np.minimum`` for ``np.clip``, ``sum / n`` for ``mean``, the prior added to the
wrong-claim totals instead of tiled under them). Each rewrite keeps every floating-point operation
and its order, so the fitted shifts are equal to the last bit, not to a tolerance: a map refitted
with either holds the same beliefs. ``_em_as_first_written`` is the reference: the loop kept here
verbatim, over the claims as ``_fit_table`` prepares them (that part did not change).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import expit

from sgbelief.calibration.agreement_shift import _em_shifts, _fit_table, fit_agreement_shift


def _em_as_first_written(table, n_iter, tol, bound):
    """The EM loop as first written (verbatim but for reading its inputs from ``table``)."""
    t, lab, ci, m, x = table.tasks, table.labels, table.contexts, table.masses, table.offsets
    n_t, k, n_w = table.n_tasks, table.n_classes, len(table.codes)
    a = np.zeros(n_w)
    q = np.zeros((n_t, k))
    np.add.at(q, (t, lab), m)
    q /= q.sum(axis=1, keepdims=True)
    for _ in range(n_iter):
        y = q[t, lab]
        a = _intercepts_as_first_written(x, y, m, ci, n_w, a, bound)
        pi = q.mean(axis=0)
        p = expit(x + a[ci])
        p = np.clip(p, 1e-12, 1.0 - 1e-12)
        log_wrong = m * np.log((1.0 - p) / (k - 1))
        log_lik = np.tile(np.log(np.maximum(pi, 1e-300)), (n_t, 1))
        log_lik += np.bincount(t, weights=log_wrong, minlength=n_t)[:, None]
        np.add.at(log_lik, (t, lab), m * np.log(p) - log_wrong)
        log_lik -= log_lik.max(axis=1, keepdims=True)
        q_new = np.exp(log_lik)
        q_new /= q_new.sum(axis=1, keepdims=True)
        delta = float(np.max(np.abs(q_new - q)))
        q = q_new
        if delta <= tol:
            break
    return _intercepts_as_first_written(x, q[t, lab], m, ci, n_w, a, bound)


def _intercepts_as_first_written(x, y, m, ci, n_w, a0, bound, steps=50):
    a = np.clip(np.asarray(a0, dtype=np.float64).copy(), -bound, bound)
    target = np.bincount(ci, weights=m * y, minlength=n_w)
    for _ in range(steps):
        p = expit(x + a[ci])
        g = target - np.bincount(ci, weights=m * p, minlength=n_w)
        h = np.bincount(ci, weights=m * p * (1.0 - p), minlength=n_w)
        step = np.clip(g / np.maximum(h, 1e-12), -1.0, 1.0)
        a = np.clip(a + step, -bound, bound)
        if np.max(np.abs(step)) < 1e-10:
            break
    return a


@st.composite
def claim_tables(draw):
    """A claim table as the map consensus builds one: tasks with one to eight claims, up to six
    classes, two contexts, confidences including 0 and 1, masses from a split target or whole."""
    n_tasks = draw(st.integers(1, 12))
    per_task = draw(st.lists(st.integers(1, 8), min_size=n_tasks, max_size=n_tasks))
    tasks = np.repeat(np.arange(n_tasks) * 3, per_task)  # codes with gaps, as the consensus' node codes
    n = len(tasks)
    k = draw(st.integers(1, 6))
    labels = np.array(draw(st.lists(st.integers(0, k - 1), min_size=n, max_size=n)))
    conf = np.array(draw(st.lists(st.one_of(st.sampled_from([0.0, 0.5, 1.0]), st.floats(0.0, 1.0)),
                                  min_size=n, max_size=n)))
    contexts = np.array(draw(st.lists(st.sampled_from([0, 4]), min_size=n, max_size=n)))
    weights = draw(st.one_of(st.none(), st.lists(st.sampled_from([1.0, 0.5, 0.25, 0.7]), min_size=n, max_size=n)))
    order = draw(st.permutations(range(n)))
    idx = np.array(order, dtype=np.intp)
    w = None if weights is None else np.array(weights)[idx]
    return tasks[idx], labels[idx], conf[idx], contexts[idx], w


def _same_bits(a, b) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@settings(max_examples=300, deadline=None)
@given(claim_tables(), st.sampled_from([(), {0}, {4}, {0, 4}]), st.sampled_from([1, 3, 100]),
       st.sampled_from([1e-6, 0.0]))
def test_the_em_equals_the_em_as_first_written_to_the_last_bit(claims, level, n_iter, tol) -> None:
    tasks, labels, conf, ctx, w = claims
    table = _fit_table(tasks, labels, conf, ctx, w, level)
    if table is None or table.n_classes < 2:  # no EM runs
        return
    bound = math.log(1000.0)
    assert _same_bits(_em_shifts(table, n_iter, tol, bound), _em_as_first_written(table, n_iter, tol, bound))
    fit = fit_agreement_shift(tasks, labels, conf, ctx, weights=w, n_iter=n_iter, tol=tol, level_contexts=level)
    reference = _em_as_first_written(table, n_iter, tol, bound)
    assert fit == {int(c): (float(reference[j]), int(np.sum(table.contexts == j))) for j, c in enumerate(table.codes)}


def test_a_large_table_equals_the_em_as_first_written() -> None:
    """2,000 claims of 14 classes in three contexts, one read at one level (seeded)."""
    rng = np.random.default_rng(7)
    n = 2000
    table = _fit_table(rng.integers(0, 500, n), rng.integers(0, 14, n), rng.random(n), rng.integers(0, 3, n),
                       rng.choice([1.0, 0.5, 0.3], n), {1})
    assert table is not None and len(table.codes) == 3
    assert _same_bits(_em_shifts(table, 100, 1e-6, 5.0), _em_as_first_written(table, 100, 1e-6, 5.0))
