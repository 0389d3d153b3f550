"""The monolithic compound channel: its error model against hand-computed cases, the suite wrapper, the file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.errors import FormatError
from sgbelief.eval.sim_config import LatentSpec, load_sim_config
from sgbelief.eval.sim_monolithic import (
    CompoundSpec,
    compound_latent,
    generate_claims,
    literal_latent,
    monolithic_channel,
    read_monolithic,
    write_monolithic,
)
from sgbelief.eval.simulate import simulate


def _sig(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def _phi(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


def test_literal_latent_hand_computed() -> None:
    spec = LatentSpec(mu_pos=2.0, mu_neg=-1.0, sigma=0.5, confident_wrong=0.1)
    assert literal_latent(spec, 1, 0.3, 1.0, False) == pytest.approx(2.0 + 0.3 + 0.5)
    assert literal_latent(spec, 1, 0.3, 1.0, True) == pytest.approx(-1.0 + 0.3 + 0.5)  # confidently wrong
    assert literal_latent(spec, 0, 0.0, -2.0, False) == pytest.approx(-1.0 - 1.0)


def test_compound_latent_hand_computed() -> None:
    # logit(sigmoid(1) * sigmoid(2)) by hand
    p = _sig(1.0) * _sig(2.0)
    assert compound_latent([1.0, 2.0]) == pytest.approx(math.log(p / (1 - p)), abs=1e-12)
    assert compound_latent([0.7]) == pytest.approx(0.7, abs=1e-12)
    # a certain part leaves the other part's reading alone
    assert compound_latent([40.0, -0.4]) == pytest.approx(-0.4, abs=1e-9)
    assert compound_latent([-40.0, 3.0]) < -35.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-20, 20), min_size=1, max_size=5))
def test_compound_latent_is_at_most_its_weakest_part(parts: list[float]) -> None:
    z = compound_latent(parts)
    assert math.isfinite(z)
    assert z <= min(parts) + 1e-9  # a conjunction is never more probable than any of its parts


def _config(relation: LatentSpec, *, certain: bool = True):
    cfg = load_sim_config("outdoor")
    d = cfg.model_dump()
    d["vlm"]["element_sigma"] = 0.0
    if certain:  # the object part read without error: z_phi = +-40
        d["vlm"]["latent"]["is_car"] = {"mu_pos": 40.0, "mu_neg": -40.0, "sigma": 1e-6, "confident_wrong": 0.0}
    d["monolithic"] = {"relation": relation.model_dump()}
    return type(cfg).model_validate(d)


def _claims(cfg, n: int, relations, *, rel_truth, car, seed: int = 1, offsets=None):
    nodes = [f"v{i:05d}" for i in range(n)]
    comp = CompoundSpec("q", "is_car", relations)
    return generate_claims(nodes, [comp], truth=lambda v, p: car(int(v[1:])),
                           relation_truth=lambda v, g: rel_truth(int(v[1:])), config=cfg,
                           rng=np.random.default_rng(seed), offsets=offsets)


def test_certain_components_give_the_compounds_own_error_rate_only() -> None:
    """Object part certain: 'car & g' is answered yes exactly when g is read as holding, so its error
    rate is the relation reading's: P(yes | car, g) = (1 - w) Phi(mu_pos / s) + w Phi(mu_neg / s)."""
    rel = LatentSpec(mu_pos=1.0, mu_neg=-1.0, sigma=1.0, confident_wrong=0.1)
    cfg = _config(rel)
    n = 20_000
    claims = _claims(cfg, n, (("is_at_intersection", False),), rel_truth=lambda i: i % 4 < 2, car=lambda i: i % 2)
    yes = np.array([c.z > 0 for c in claims])
    idx = np.arange(n)
    car, g = idx % 2 == 1, idx % 4 < 2
    p_true = 0.9 * _phi(1.0) + 0.1 * _phi(-1.0)  # 0.7731
    p_false = 0.9 * _phi(-1.0) + 0.1 * _phi(1.0)  # 0.2270
    tol = 4 * math.sqrt(0.25 / (n / 4))  # 4 standard errors at the widest
    assert yes[car & g].mean() == pytest.approx(p_true, abs=tol)
    assert yes[car & ~g].mean() == pytest.approx(p_false, abs=tol)
    assert not yes[~car].any()  # the certain object part says no: no relation error can make it yes
    truth = np.array([c.y for c in claims]).astype(bool)
    assert (truth == (car & g)).all()
    # the compound's error rate = the relation's alone, weighted by where the object holds
    err = (yes != truth).mean()
    assert err == pytest.approx(0.25 * (1 - p_true) + 0.25 * p_false, abs=tol)


def test_negated_relation_is_the_mirror_reading() -> None:
    rel = LatentSpec(mu_pos=1.0, mu_neg=-1.0, sigma=1.0, confident_wrong=0.0)
    cfg = _config(rel)
    a = _claims(cfg, 2000, (("is_stationary", False),), rel_truth=lambda i: i % 2 == 0, car=lambda i: 1)
    b = _claims(cfg, 2000, (("is_stationary", True),), rel_truth=lambda i: i % 2 == 0, car=lambda i: 1)
    # same draws (same seed, same order): the negated literal reads -z_g
    for x, y in zip(a, b):
        assert y.z == pytest.approx(-x.z, abs=1e-5)
        assert x.y + y.y == 1


def test_components_confusions_are_inherited() -> None:
    """Object part uncertain: an element whose component claims carry a large negative offset is
    read as no car by the compound prompt too; the relation error comes on top."""
    rel = LatentSpec(mu_pos=30.0, mu_neg=-30.0, sigma=1e-6, confident_wrong=0.0)  # relations read perfectly
    cfg = _config(rel, certain=False)
    spec = cfg.vlm.spec("is_car")
    n = 20_000
    claims = _claims(cfg, n, (("is_at_intersection", False),), rel_truth=lambda i: True, car=lambda i: 1,
                     offsets={("v00000", "is_car"): -50.0})
    assert claims[0].z < -20  # the element's own offset
    yes = np.array([c.z > 0 for c in claims[1:]])
    # with the relation certain, yes <=> the object part read as car: the component's own error rate
    p = (1 - spec.confident_wrong) * _phi(spec.mu_pos / spec.sigma) + spec.confident_wrong * _phi(spec.mu_neg / spec.sigma)
    assert yes.mean() == pytest.approx(p, abs=4 * math.sqrt(0.25 / n))


@pytest.fixture(scope="module")
def small_suite():
    cfg = load_sim_config("indoor", scenes=["scene0000_00", "scene0001_00"], scale=0.3)
    return simulate(cfg, seed=5)


def test_suite_channel_one_answer_per_visible_element_and_compound(small_suite) -> None:
    ch = monolithic_channel(small_suite)
    assert ch.claims, "no visible element"
    queries = sorted({c.query for c in ch.claims})
    assert len(queries) == 7  # the ScanNet query set
    keys = [(c.node, c.query) for c in ch.claims]
    assert len(keys) == len(set(keys)) == len(small_suite.views) * len(queries)
    for c in ch.claims:
        v = small_suite.views[c.node]
        assert c.t == v.t and c.labels == v.labels
    # views are unoccluded: the oracle names the element there unless its class has no usable label
    unlabeled = set(small_suite.config.oracle.unlabeled)
    for node, v in small_suite.views.items():
        lab = small_suite.nodes.nodes[node].label
        assert v.labels["oracle"] == (None if lab in unlabeled else lab)
    again = monolithic_channel(simulate(small_suite.config, seed=5))
    assert [c.z for c in again.claims] == [c.z for c in ch.claims]  # deterministic from the seed


def test_profiles_change_confidence_only(small_suite) -> None:
    ch = monolithic_channel(small_suite)
    a, b = ch.records("vlm_a", "oracle"), ch.records("vlm_b", "oracle")
    assert [(r.node, r.query, r.geometric) for r in a] == [(r.node, r.query, r.geometric) for r in b]
    assert a[0].context != b[0].context
    # a strictly increasing distortion of the same latent: the order of confidences within a compound is kept
    for q in {r.query for r in a}:
        ca = np.array([r.confidence for r in a if r.query == q])
        cb = np.array([r.confidence for r in b if r.query == q])
        za = np.argsort(ca, kind="stable")
        assert np.all(np.diff(cb[za]) >= -1e-6)


def test_file_round_trip_and_errors(tmp_path: Path, small_suite) -> None:
    recs = monolithic_channel(small_suite).records()
    p = write_monolithic(tmp_path / "monolithic.jsonl", recs)
    assert read_monolithic(p) == recs
    bad = tmp_path / "bad.jsonl"
    good = '{"node": "a", "query": "q", "t": 0, "confidence": 0.5, "context": "m", "geometric": null}'
    bad.write_text(good + "\n" + good.replace("0.5", "1.5") + "\n")
    with pytest.raises(FormatError, match=r"bad.jsonl:2.*confidence"):
        read_monolithic(bad)
    bad.write_text(good + "\n" + good + "\n")
    with pytest.raises(FormatError, match=r"bad.jsonl:2.*answered twice"):
        read_monolithic(bad)
    bad.write_text('{"format": "sgbelief.events", "version": 1}\n')
    with pytest.raises(FormatError, match=r"bad.jsonl:1.*sgbelief.monolithic"):
        read_monolithic(bad)


def test_offsets_are_the_component_claims_own(small_suite) -> None:
    """Every grounded component claim's (element, predicate) has its persistent offset recorded."""
    grounded = {(c.primary, c.predicate) for c in small_suite.claims if not c.hallucinated}
    assert grounded and grounded <= set(small_suite.offsets)
