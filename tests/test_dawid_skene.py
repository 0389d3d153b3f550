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
