"""Dawid–Skene EM (sgbelief.calibration.dawid_skene): hand-computed steps, crowd-kit's reference,
systematic confusions learned without ground truth, and the "none of these" class."""

from __future__ import annotations

import numpy as np
import pytest

from sgbelief.calibration.dawid_skene import NONE_CLASS, DawidSkene


def _stream(seed: int, n_tasks: int = 300, k: int = 4, n_workers: int = 5, per_task: int = 3):
    """Tasks with a true class each; workers 1.. are right 70 % of the time, worker 0 names the
    next class 80 % of the time (a systematic confusion)."""
    rng = np.random.default_rng(seed)
    classes = [f"c{i}" for i in range(k)]
    z = rng.integers(0, k, n_tasks)
    conf = []
    for w in range(n_workers):
        if w == 0:
            m = np.roll(np.eye(k), 1, axis=1) * 0.8 + 0.05
        else:
            m = np.full((k, k), 0.3 / (k - 1)) + np.eye(k) * (0.7 - 0.3 / (k - 1))
        conf.append(m / m.sum(1, keepdims=True))
    rows = []
    for t in range(n_tasks):
        for w in rng.choice(n_workers, per_task, replace=False):
            rows.append((t, f"w{w}", classes[rng.choice(k, p=conf[w][z[t]])]))
    tasks, workers, labels = map(list, zip(*rows))
    return classes, z, tasks, workers, labels


def test_one_em_step_by_hand() -> None:
    """Two tasks, one worker, n_iter=1, no smoothing: the M-step then E-step computed by hand."""
    ds = DawidSkene(n_iter=1, smoothing=0.0, none_class=False)
    ds.fit([0, 0, 1], ["w", "w", "w"], ["a", "b", "b"], classes=["a", "b"])
    # initial vote: q0 = (1/2, 1/2), q1 = (0, 1); pi = (1/4, 3/4)
    assert ds.priors_ == pytest.approx([0.25, 0.75])
    # theta[a] from q_a mass: label a 0.5, label b 0.5 -> (1/2, 1/2); theta[b]: a 0.5, b 1.5 -> (1/4, 3/4)
    np.testing.assert_allclose(ds.errors_[0], [[0.5, 0.5], [0.25, 0.75]])
    # E-step: task 0: a: 1/4 * 1/2 * 1/2 = 1/16; b: 3/4 * 1/4 * 3/4 = 9/64 -> q(a) = 4/13
    assert ds.probas_[0] == pytest.approx([4 / 13, 9 / 13])
    # task 1: a: 1/4 * 1/2 = 1/8; b: 3/4 * 3/4 = 9/16 -> q(a) = 2/11
    assert ds.probas_[1] == pytest.approx([2 / 11, 9 / 11])


@pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::FutureWarning", "ignore::UserWarning")
def test_matches_crowd_kit_on_a_seeded_stream() -> None:
    """crowd-kit's DawidSkene is the field's reference implementation: same posteriors (tolerance 1e-8)."""
    ck = pytest.importorskip("crowdkit.aggregation")
    pd = pytest.importorskip("pandas")
    classes, _, tasks, workers, labels = _stream(seed=0)
    df = pd.DataFrame({"task": tasks, "worker": workers, "label": labels})
    ref = ck.DawidSkene(n_iter=200, tol=1e-12).fit(df)
    ours = DawidSkene(n_iter=200, tol=0.0, smoothing=0.0, none_class=False).fit(tasks, workers, labels, classes=classes)
    expected = ref.probas_.loc[sorted(set(tasks)), classes].to_numpy()
    np.testing.assert_allclose(ours.probas_, expected, atol=1e-8)
    # crowd-kit re-estimates the priors after its last E-step, ours are the last M-step's: one step apart
    np.testing.assert_allclose(ours.priors_, ref.priors_.loc[classes].to_numpy(), atol=1e-5)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_systematic_confusion_is_learned_without_ground_truth(seed: int) -> None:
    """Worker 0 always names the next class: Dawid–Skene learns its confusion row and beats the
    majority vote (seeded; tolerance: at least 5 points of accuracy on 300 tasks)."""
    classes, z, tasks, workers, labels = _stream(seed=seed)
    ds = DawidSkene(none_class=False).fit(tasks, workers, labels, classes=classes)
    acc_ds = float((ds.probas_.argmax(1) == z).mean())
    votes = np.zeros((len(z), len(classes)))
    for t, lab in zip(tasks, labels):
        votes[t, classes.index(lab)] += 1
    rng = np.random.default_rng(seed)  # ties broken at random, as a vote would
    acc_mv = float(((votes + rng.random(votes.shape) * 1e-3).argmax(1) == z).mean())
    assert acc_ds >= acc_mv + 0.05, (acc_ds, acc_mv)
    w0 = ds.workers_.index("w0")
    learned = ds.errors_[w0]  # (classes, labels): worker 0 says class i+1 of class i
    for i, name in enumerate(classes):
        nxt = ds.labels_.index(classes[(i + 1) % len(classes)])
        assert learned[i].argmax() == nxt and learned[i, nxt] > 0.5, (name, learned[i])


def test_the_none_class_takes_scattered_weak_claims_and_leaves_consistent_ones() -> None:
    """Elements with many agreeing claims keep their class; elements with one stray claim each,
    scattered over classes, go to "none of these" once the number of claims an element received
    is itself an observation (a "support" worker; sgbelief.fusion.consensus adds it). Without it a
    single label is always best explained by its own class, and "none" is not identifiable."""
    rng = np.random.default_rng(0)
    classes = ["bed", "chair", "tv"]
    tasks, workers, labels, votes = [], [], [], []
    for v in range(60):  # real objects: 6 agreeing claims, confident
        for _ in range(6):
            tasks.append(v)
            workers.append("det|b1")
            labels.append(classes[v % 3])
            votes.append(0.8)
    for v in range(60, 200):  # clutter: one stray claim, weak
        tasks.append(v)
        workers.append("det|b0")
        labels.append(classes[int(rng.integers(3))])
        votes.append(0.4)
    plain = DawidSkene().fit(tasks, workers, labels, classes=classes, votes=votes)
    assert (plain.probas_[60:, -1] > 0.5).mean() < 0.1  # not identifiable from labels alone
    n_claims = np.bincount(tasks)
    for v, n in enumerate(n_claims):
        tasks.append(v)
        workers.append("<support>")
        labels.append(f"n{min(n, 6)}")
        votes.append(0.0)
    ds = DawidSkene().fit(tasks, workers, labels, classes=classes, votes=votes)
    none = ds.class_index(NONE_CLASS)
    assert ds.classes_[-1] == NONE_CLASS
    assert (ds.probas_[:60].argmax(1) == np.arange(60) % 3).all()
    assert (ds.probas_[60:, none] > 0.5).mean() > 0.9


def test_empty_and_degenerate_inputs() -> None:
    ds = DawidSkene().fit([], [], [], classes=["a"], n_tasks=0)
    assert ds.probas_.shape == (0, 2)
    ds = DawidSkene(n_iter=5).fit([0], ["w"], ["a"], classes=["a"])
    assert ds.probas_.sum() == pytest.approx(1.0)


# ---------------------------------------------------------------- the overdispersed emission

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from scipy.special import gammaln  # noqa: E402

from sgbelief.calibration.dawid_skene import (  # noqa: E402
    dirichlet_multinomial_cells,
    dirichlet_multinomial_log_likelihood,
)


def test_dirichlet_multinomial_cell_terms_by_hand() -> None:
    """lnG(n + s theta) - lnG(s theta): n = 2, s = 1, theta = 1/2 gives ln(3/2 * 1/2) (G(x+1) = x G(x));
    s infinite gives Dawid–Skene's n log theta."""
    theta = np.array([[0.5, 0.25]])
    got = dirichlet_multinomial_cells(np.array([2.0]), 1.0, theta)
    np.testing.assert_allclose(got, [[np.log(1.5 * 0.5), np.log(1.25 * 0.25)]], rtol=1e-12)
    np.testing.assert_allclose(dirichlet_multinomial_cells(np.array([2.0]), np.inf, theta), 2 * np.log(theta))
    # per-cell concentrations: one finite, one infinite
    both = dirichlet_multinomial_cells(np.array([2.0, 2.0]), np.array([1.0, np.inf]), np.vstack([theta, theta]))
    np.testing.assert_allclose(both, np.vstack([got, 2 * np.log(theta)]))


@pytest.mark.parametrize("s", [0.5, 3.0, 40.0])
def test_the_group_log_likelihood_is_scipys_dirichlet_multinomial(s: float) -> None:
    """Summed cell terms plus lnG(s) - lnG(s + N) are scipy's Dirichlet-multinomial log-pmf without
    the multinomial coefficient (tolerance 1e-10)."""
    from scipy.stats import dirichlet_multinomial

    theta = np.array([0.6, 0.3, 0.1])
    n = np.array([4.0, 0.0, 2.0])
    cells = dirichlet_multinomial_cells(n, s, theta[:, None])[:, 0].sum()
    ours = float(dirichlet_multinomial_log_likelihood(np.array([cells]), np.array([n.sum()]), s)[0])
    coefficient = gammaln(n.sum() + 1) - gammaln(n + 1).sum()
    assert ours == pytest.approx(dirichlet_multinomial.logpmf(n, s * theta, int(n.sum())) - coefficient, abs=1e-10)
    # the infinite concentration is the multinomial's limit (bias O(N²/s), rounding O(s log s · 1e-16))
    far = dirichlet_multinomial_cells(n, 1e7, theta[:, None])[:, 0].sum()
    limit = float(dirichlet_multinomial_log_likelihood(np.array([far]), np.array([n.sum()]), 1e7)[0])
    assert limit == pytest.approx(float((n * np.log(theta)).sum()), abs=1e-4)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), per_task=st.integers(1, 6), none_class=st.booleans())
def test_an_infinite_concentration_is_dawid_skene(seed: int, per_task: int, none_class: bool) -> None:
    """With inf the only concentration, the overdispersed model's fit is the independent one (1e-10)."""
    rng = np.random.default_rng(seed)
    classes = ["a", "b", "c"]
    n = 40
    tasks = np.repeat(np.arange(n), per_task)
    workers = [f"w{int(x)}" for x in rng.integers(0, 3, len(tasks))]
    labels = [classes[int(x)] for x in rng.integers(0, 3, len(tasks))]
    weights = rng.uniform(0.2, 1.0, len(tasks))
    plain = DawidSkene(none_class=none_class).fit(tasks, workers, labels, classes=classes, weights=weights)
    dm = DawidSkene(none_class=none_class, emission="dirichlet_multinomial", concentrations=(np.inf,)).fit(
        tasks, workers, labels, classes=classes, weights=weights)
    np.testing.assert_allclose(dm.probas_, plain.probas_, atol=1e-10)
    np.testing.assert_allclose(dm.errors_, plain.errors_, atol=1e-10)
    assert dm.n_iter_ == plain.n_iter_ and np.isinf(dm.concentrations_).all()


def _correlated_stream(seed: int, s_true: float | None, n_tasks: int = 400, per_task: int = 8, k: int = 3):
    """One detector-like worker labels every task ``per_task`` times. Its confusion: right 70 %,
    else uniform. With ``s_true`` each task first draws its own row from Dirichlet(s_true * row),
    so a task the worker mistakes it keeps mistaking (correlated errors); None: independent labels.
    A second worker labels every task once (right 80 %), so the classes stay identifiable."""
    rng = np.random.default_rng(seed)
    classes = [f"c{i}" for i in range(k)]
    z = rng.integers(0, k, n_tasks)
    row = np.full((k, k), 0.3 / (k - 1)) + np.eye(k) * (0.7 - 0.3 / (k - 1))
    ref = np.full((k, k), 0.2 / (k - 1)) + np.eye(k) * (0.8 - 0.2 / (k - 1))
    tasks, workers, labels = [], [], []
    for t in range(n_tasks):
        p = row[z[t]] if s_true is None else rng.dirichlet(s_true * row[z[t]])
        for lab in rng.choice(k, per_task, p=p):
            tasks.append(t), workers.append("det"), labels.append(classes[lab])
        tasks.append(t), workers.append("ref"), labels.append(classes[rng.choice(k, p=ref[z[t]])])
    return classes, z, tasks, workers, labels


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_correlated_errors_are_learned_and_the_posterior_is_honest(seed: int) -> None:
    """Seeded, 400 tasks. With correlated errors (s = 2) the fitted concentration of the repeating
    worker is small (<= 8; the worker labelled once has none to learn), the posterior's log-loss on
    the true class is lower than the independent model's, which is over-confident (its mean top
    posterior exceeds its accuracy by more than 0.05), and that excess shrinks by more than 0.05.
    With independent labels the concentration stays large (>= 64): the same accuracy within 0.01
    and the same log-loss within 0.005."""
    classes, z, tasks, workers, labels = _correlated_stream(seed, s_true=2.0)
    plain = DawidSkene(none_class=False).fit(tasks, workers, labels, classes=classes)
    dm = DawidSkene(none_class=False, emission="dirichlet_multinomial").fit(tasks, workers, labels, classes=classes)
    det = dm.workers_.index("det")
    assert dm.concentrations_[det] <= 8.0, dm.concentrations_

    def log_loss(ds: DawidSkene) -> float:
        return float(-np.log(np.clip(ds.probas_[np.arange(len(z)), z], 1e-12, 1)).mean())

    assert log_loss(dm) < log_loss(plain), (log_loss(dm), log_loss(plain))
    over = plain.probas_.max(1).mean() - (plain.probas_.argmax(1) == z).mean()
    assert over > 0.05, over

    assert dm.probas_.max(1).mean() - (dm.probas_.argmax(1) == z).mean() < over - 0.05

    classes, z, tasks, workers, labels = _correlated_stream(seed, s_true=None)
    plain = DawidSkene(none_class=False).fit(tasks, workers, labels, classes=classes)
    dm = DawidSkene(none_class=False, emission="dirichlet_multinomial").fit(tasks, workers, labels, classes=classes)
    assert dm.concentrations_[dm.workers_.index("det")] >= 64.0, dm.concentrations_
    acc = lambda ds: float((ds.probas_.argmax(1) == z).mean())  # noqa: E731
    assert acc(dm) == pytest.approx(acc(plain), abs=0.01)
    assert log_loss(dm) == pytest.approx(log_loss(plain), abs=0.005)


def test_an_independent_worker_keeps_the_multinomial_emission() -> None:
    """A worker named in ``independent_workers`` keeps s = inf even when its labels are correlated;
    the others still learn theirs (seeded; the same stream as above)."""
    classes, _, tasks, workers, labels = _correlated_stream(0, s_true=2.0)
    ds = DawidSkene(none_class=False, emission="dirichlet_multinomial").fit(
        tasks, workers, labels, classes=classes, independent_workers=["det"])
    assert np.isinf(ds.concentrations_[ds.workers_.index("det")])
    plain = DawidSkene(none_class=False).fit(tasks, workers, labels, classes=classes)
    np.testing.assert_allclose(ds.probas_, plain.probas_, atol=1e-10)  # "ref" labels once: nothing to learn


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), fractional=st.booleans())
def test_the_concentration_search_is_the_brute_force_argmax(seed: int, fractional: bool) -> None:
    """The search's shortcut (a single observation compared by its ln s alone) picks, per worker,
    the same s as evaluating Q_w(s) over every cell with the full terms (ties to the larger s)."""
    from sgbelief.calibration.dawid_skene import CONCENTRATIONS, _Groups

    rng = np.random.default_rng(seed)
    n_t, n_w, n_l, k = 30, 3, 4, 3
    rows = rng.integers(0, n_t, 200)
    cols = rng.integers(0, n_w, 200) * n_l + rng.integers(0, n_l, 200)
    data = rng.uniform(0.3, 1.0, 200) if fractional else np.ones(200)
    from scipy import sparse as sp
    cells = sp.csr_matrix((data, (rows, cols)), shape=(n_t, n_w * n_l))
    groups = _Groups(cells, n_w, n_l)
    theta = rng.dirichlet(np.ones(n_l), size=(n_w, k))
    q = rng.dirichlet(np.ones(k), size=n_t)
    got = groups.concentrations(theta, q, CONCENTRATIONS)
    th = theta.transpose(0, 2, 1).reshape(n_w * n_l, k)[groups.col]
    best = np.full(n_w, -np.inf)
    want = np.full(n_w, np.inf)
    for s in CONCENTRATIONS:
        per_cell = (q[groups.task] * dirichlet_multinomial_cells(groups.count, s, th)).sum(1)
        per_group = dirichlet_multinomial_log_likelihood(
            np.bincount(groups.cell_group, weights=per_cell, minlength=len(groups.totals)), groups.totals, s)
        q_w = np.bincount(groups.group_worker, weights=per_group, minlength=n_w)
        if np.isinf(s):
            best = q_w
            continue
        better = q_w > best + 1e-9 * np.abs(best)
        want[better], best[better] = s, q_w[better]
    np.testing.assert_array_equal(got, want)
