"""A decisive label's observation of y weighed by its reliability under the channel's confusion the
consensus learned (``calibration.consensus.label_weights: reliability``, docs/method.md §8): the
equation by hand, the consensus' look-up, and the operator's entries in both engines."""

from __future__ import annotations

import random

import numpy as np
import pytest

from sgbelief import SceneGraph, make_operator
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.consensus import label_reliability
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.graph.provenance import EntryVerdict

CLASSES = ["chair", "table", "sofa"]


def _table() -> SubsumptionTable:
    specs = {f"is_{k}": {"positive": [k], "negative": [j for j in CLASSES if j != k]} for k in CLASSES}
    return SubsumptionTable(specs, name="three", labels=[*CLASSES, "otherprop"])


def test_label_reliability_by_hand() -> None:
    # classes chair, table and none; labels chair, table, other
    theta = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.05, 0.05, 0.9]])
    pi = np.array([0.25, 0.25, 0.5])
    r = label_reliability(theta, pi)
    assert r.shape == (2, 3)
    # a `table` label, for chair: rivals' rate (0.25 * 0.8 + 0.5 * 0.05) / 0.75 = 0.3, LR = 0.1 / 0.3
    assert r[0, 1] == pytest.approx((1 / 3) / (1 + 1 / 3))
    # a `chair` label, for chair: rivals' rate (0.25 * 0.1 + 0.5 * 0.05) / 0.75 = 1 / 15, LR = 12
    assert r[0, 0] == pytest.approx(12 / 13)
    assert r[1, 1] == pytest.approx(12 / 13)
    # an `other` label, for chair: LR = 0.1 / ((0.025 + 0.45) / 0.75)
    assert r[0, 2] == pytest.approx((0.1 / (0.475 / 0.75)) / (1 + 0.1 / (0.475 / 0.75)))


def test_a_channel_that_is_never_wrong_keeps_its_labels_whole() -> None:
    theta = np.array([[1 - 2e-6, 1e-6, 1e-6], [1e-6, 1 - 2e-6, 1e-6], [1e-6, 1e-6, 1 - 2e-6]])
    r = label_reliability(theta, np.array([0.3, 0.3, 0.4]))
    assert r[0, 0] > 1 - 1e-5 and r[1, 1] > 1 - 1e-5  # asserting labels: r ~ 1
    assert r[0, 1] < 1e-5 and r[1, 0] < 1e-5  # denying labels: 1 - r ~ 1


def _stream(n_elements: int = 40, seed: int = 0, noisy: int = 3) -> list:
    """Claims of a detector right 80 % of the time; a channel that labels each element's class, but
    the first ``noisy`` chairs `table` in two frames of three (a persistent error)."""
    rng = random.Random(seed)
    items, t = [], 0
    truth = [CLASSES[i % 3] for i in range(n_elements)]
    for rep in range(6):
        for i, cls in enumerate(truth):
            claimed = cls if rng.random() < 0.8 else rng.choice([c for c in CLASSES if c != cls])
            label = cls
            if cls == "chair" and i // 3 < noisy and rep % 3 != 2:
                label = "table"
            items.append((EvidenceEvent({f"v{i}": 1.0}, f"is_{claimed}", rng.uniform(0.6, 0.95), "det", t,
                                        f"e{t}"), FrameLabels({f"v{i}": label})))
            t += 1
    return items


def _geometric_entries(g: SceneGraph) -> list:
    return [e for node in g.nodes() for p in (f"is_{k}" for k in CLASSES)
            for e in g.provenance.entries(node, p) if e.verdict == EntryVerdict.GEOMETRIC]


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_the_observation_counts_the_labels_reliability(engine: str) -> None:
    cfg = {"calibration": {"consensus": {"every": 30, "growth": 0.0, "label_weights": "reliability"}}}
    op = make_operator("comod", cfg, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    items = _stream()
    op.update_many(g, items[:200])
    cons = op._consensus_of(g.provenance)
    assert cons.n_fits >= 1
    # what the next claim's label will count, from the last fit; then the claim itself
    (event, labels), = items[200:201]
    node, = event.targets
    label = labels.labels[node]
    y = _table().outcome_tables()[event.predicate][label]
    r = cons.verdict_reliability(event.predicate, label, y)
    assert 0.0 < r < 1.0
    op.update_many(g, [(event, labels)])
    geo = [e for e in g.provenance.entries(node, event.predicate) if e.event_id == event.id
           and e.verdict == EntryVerdict.GEOMETRIC]
    assert len(geo) == 1
    assert (geo[0].d_alpha, geo[0].d_beta) == ((r, 0.0) if y == 1 else (0.0, r))  # w0 = 1, T(v) = 1
    # Eq. 4 still holds
    assert g.provenance.alpha_beta(node, event.predicate) == pytest.approx(
        g.provenance.reconstruct(node, event.predicate))


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_one_keeps_every_observation_whole(engine: str) -> None:
    op = make_operator("comod", {"calibration": {"consensus": {"every": 30, "growth": 0.0, "label_weights": "one"}}},
                       _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    op.update_many(g, _stream())
    geo = _geometric_entries(g)
    assert geo and all(e.d_alpha + e.d_beta == 1.0 for e in geo)


def test_before_a_fit_and_without_dawid_skene_labels_count_whole() -> None:
    for method, every in (("dawid_skene", 10_000), ("agreement_shift", 30)):
        cfg = {"calibration": {"consensus": {"method": method, "every": every, "growth": 0.0,
                                             "label_weights": "reliability"}}}
        op = make_operator("comod", cfg, _table())
        g = SceneGraph(create_nodes=True)
        op.update_many(g, _stream())
        cons = op._consensus_of(g.provenance)
        assert cons.verdict_reliability("is_chair", "table", 0) == 1.0
        assert all(e.d_alpha + e.d_beta == 1.0 for e in _geometric_entries(g))


def test_a_persistently_mislabelled_element_counts_its_labels_less() -> None:
    """The chairs the channel labels `table` in two frames of three: with the labels' reliability
    (below 1 for every label of a channel that errs) their `table` labels count for less than a
    whole denial each, so their chair belief is higher than with whole observations; the other
    chairs stay committed either way. (On a map this small the consensus sides with the labels on
    the mislabelled chairs, so r stays near 1: the belief moves by about 0.015.)"""
    cfg = {"calibration": {"consensus": {"every": 30, "growth": 0.0}}}
    means = {}
    for weights in ("one", "reliability"):
        cfg["calibration"]["consensus"]["label_weights"] = weights
        op = make_operator("comod", cfg, _table())
        g = SceneGraph(create_nodes=True)
        op.update_many(g, _stream(n_elements=60, seed=1, noisy=4))
        means[weights] = {f"v{i}": g.probability(f"v{i}", "is_chair") for i in range(0, 60, 3)}
        cons = op._consensus_of(g.provenance)
        assert 0.5 < cons.verdict_reliability("is_chair", "table", 0) < 1.0
    noisy = [f"v{i}" for i in range(0, 12, 3)]
    assert all(means["reliability"][v] > means["one"][v] for v in noisy)
    clean = [v for v in means["one"] if v not in noisy]
    assert all(means["reliability"][v] > 0.5 and means["one"][v] > 0.5 for v in clean)
