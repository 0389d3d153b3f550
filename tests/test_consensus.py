"""Where the geometric channel is silent: the consensus calibration (Dawid–Skene over the map), the
claim cells it calibrates (adjudication, standing), and the exclusive-class coupling.

Hand-computed values for each step function; regressions for the failure modes of issue #30 (a lone
claim on an element the channel cannot adjudicate, scattered exclusive claims, a systematic
confusion with no channel); Eq. 4 and exact retraction with the options on. Engine equivalence
with the options on is in tests/test_engines.py.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief import SceneGraph, make_operator
from sgbelief.calibration.consensus import ConsensusCalibration, fit_cell
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.consensus import MapConsensus, silent_claim_outcome, support_bucket
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.rules import adjudication, consensus_cell, exclusion_increments, standing, targeting
from sgbelief.graph.provenance import EntryVerdict

CLASSES = ["bed", "chair", "sofa", "toilet", "tv"]


def _table() -> SubsumptionTable:
    specs = {f"is_{k}": {"positive": [k], "negative": [j for j in CLASSES if j != k]} for k in CLASSES}
    return SubsumptionTable(specs, name="five", labels=[*CLASSES, "otherprop"])


def _map_consensus(table: SubsumptionTable, config: OperatorConfig | None = None) -> MapConsensus:
    """A map's consensus over ``table``'s exclusive classes, as the operator builds it."""
    return MapConsensus((config or OperatorConfig()).calibration, frozenset(table.exclusive_predicates()),
                        table.asserted_tables(), table.outcome_tables())


# ----------------------------------------------------------------------------- step functions
def test_adjudication_standing_and_cell_by_hand() -> None:
    assert adjudication("chair", 1) == "decisive"
    assert adjudication("sofa", 0) == "decisive"
    assert adjudication("otherprop", None) == "ambiguous"
    assert adjudication(None, None) == "unseen"
    assert standing(0, 0, 0) == "alone"
    assert standing(2, 3, 2) == "leading"  # ties lead
    assert standing(1, 3, 2) == "trailing"
    assert consensus_cell("det", 2, "ambiguous", "alone", "part") == "det|s2|ambiguous|alone|part"
    assert targeting(0.5) == "whole" and targeting(0.49) == "part"
    assert exclusion_increments(0.7) == (0.0, 0.7)
    assert [support_bucket(n) for n in (1, 2, 3, 4, 5, 6, 9, 10, 50)] == [0, 1, 2, 3, 3, 4, 4, 5, 5]


def test_exclusive_predicates_follow_the_table() -> None:
    table = _table()
    assert table.exclusive_with("is_bed") == ("is_chair", "is_sofa", "is_toilet", "is_tv")
    assert table.exclusive_predicates() == frozenset(f"is_{k}" for k in CLASSES)
    # a predicate whose positive label another does not deny is not exclusive with it
    loose = SubsumptionTable({"is_car": {"positive": ["car"], "negative": ["person"]},
                              "is_parked": {"positive": ["parked car"], "negative": []}}, name="loose")
    assert loose.exclusive_with("is_car") == ()


def test_fit_cell_is_weighted_isotonic_regression() -> None:
    """Equal confidences pooled (weighted mean), then PAVA: hand-computed."""
    kx, ky = fit_cell(np.array([0.2, 0.2, 0.5, 0.9]), np.array([1.0, 0.0, 0.2, 0.8]), np.array([1.0, 1.0, 2.0, 1.0]))
    # points: 0.2 -> 0.5 (w 2), 0.5 -> 0.2 (w 2), 0.9 -> 0.8: the first two pool to 0.35
    assert kx == [0.2, 0.5, 0.9]
    assert ky == pytest.approx([0.35, 0.35, 0.8])


def test_consensus_likelihood_ratio_shrinks_level_by_level() -> None:
    """log Lambda = l1 log L1 + (1 - l1) [l2 log L2 + (1 - l2) log L_cold], l = min(1, n / target)."""
    cal = ConsensusCalibration(target_size=4, kappa_min=0.05, lr_max=1000.0, cold_start="raw")
    # fine level: 2 claims at c = 0.6 with q = 0.25; coarse: those plus 2 at c = 0.6 with q = 0.75
    fine, coarse = np.array([0, 0, 1, 1]), np.zeros(4, dtype=int)  # level keys per claim: cells 0 / 1, one pool
    cal.fit([fine, coarse], np.full(4, 0.6), np.array([0.25, 0.25, 0.75, 0.75]))
    lam, kappa = cal.likelihood_ratio(0.6, (0, 0))
    eps_fine, eps_coarse = 0.5 / 3, 0.5 / 5
    lo_coarse = math.log(0.5 / 0.5)  # pooled q = 0.5, inside [eps, 1 - eps]
    lo_fine = math.log(max(0.25, eps_fine) / (1 - max(0.25, eps_fine)))
    cold = math.log(0.6 / 0.4)
    expected = 0.5 * lo_fine + 0.5 * (1.0 * lo_coarse + 0.0 * cold)
    assert math.log(lam) == pytest.approx(expected)
    assert kappa == pytest.approx(0.5 + 0.5 * 1.0)
    assert eps_coarse < 0.5  # (the pooled fit needs no clip)
    assert cal.likelihood_ratio(0.6, (7,))[0] == pytest.approx(0.6 / 0.4)  # cold start


def test_silent_claim_outcome_takes_a_unanimous_channel_verdict() -> None:
    """q = n_pos / n_dec where the channel's decisive labels agree, else the posterior."""
    post = np.array([0.9, 0.9, 0.2, 0.6, 0.7])
    n_pos = np.array([0.0, 3.0, 2.0, 1.0, 0.0])
    n_dec = np.array([2.0, 3.0, 2.0, 3.0, 0.0])
    assert silent_claim_outcome(post, n_pos, n_dec) == pytest.approx([0.0, 1.0, 1.0, 0.6, 0.7])


def test_element_outcomes_count_the_channel_labels_per_class() -> None:
    """Per (element, class): labels that decide the class and those that corroborate it, merged
    elements counted as one; a label that decides nothing (otherprop here) counts for neither."""
    table = _table()
    cons = _map_consensus(table)
    cons.add_claim("a", "is_tv", "det", 0.7, "cell", False, "e1")
    cons.add_claim("b", "is_bed", "det", 0.7, "cell", False, "e2")
    cons.add_claim("c", "is_tv", "det", 0.7, "cell", False, "e3")
    for t, lab in enumerate(["tv", "tv", "otherprop"]):
        cons.add_label("a", t, lab)
    cons.add_label("b", 0, "bed")
    cons.add_label("c", 0, "chair")
    cons.merge_elements("a", "c")  # c's chair label is a's now
    probas = cons.fit_consensus()
    n_pos, n_dec = cons._element_outcomes(probas.shape[0])
    a, b, tv, bed = cons.task_of("a"), cons.task_of("b"), cons.class_of("is_tv"), cons.class_of("is_bed")
    assert (n_pos[a, tv], n_dec[a, tv]) == (2, 3)  # tv, tv for; chair against; otherprop silent
    assert (n_pos[a, bed], n_dec[a, bed]) == (0, 3)
    assert (n_pos[b, bed], n_dec[b, bed], n_pos[b, tv], n_dec[b, tv]) == (1, 1, 0, 1)
    off = _map_consensus(table, OperatorConfig(calibration={"consensus": {"adjudicated_elements": "consensus"}}))
    assert off.outcomes is None


def test_posterior_reads_the_last_fit() -> None:
    """``MapConsensus.posterior``: None before any fit and for an element or a class the last fit
    did not hold; otherwise the fit's q_v(phi), merged elements reading their representative's row;
    claims added after the fit do not move it until the next one."""
    table = _table()
    cons = _map_consensus(table)
    cons.add_claim("a", "is_tv", "det", 0.9, "cell", False, "e1")
    cons.add_claim("a", "is_tv", "det", 0.8, "cell", False, "e2")
    cons.add_claim("b", "is_bed", "det", 0.6, "cell", False, "e3")
    assert cons.posterior("a", "is_tv") is None  # no fit yet
    cons.refit()
    probas = cons.ds_.probas_
    assert cons.posterior("a", "is_tv") == pytest.approx(probas[cons.task_of("a"), cons.class_of("is_tv")])
    assert cons.posterior("b", "is_tv") == pytest.approx(probas[cons.task_of("b"), cons.class_of("is_tv")])
    assert cons.posterior("z", "is_tv") is None  # never claimed
    assert cons.posterior("a", "is_chair") is None  # a class the fit did not hold
    before = cons.posterior("a", "is_tv")
    cons.add_claim("a", "is_bed", "det", 0.9, "cell", False, "e4")
    cons.add_claim("c", "is_tv", "det", 0.9, "cell", False, "e5")
    assert cons.posterior("a", "is_tv") == before and cons.posterior("c", "is_tv") is None
    cons.merge_elements("a", "b")
    cons.refit()
    assert cons.posterior("b", "is_tv") == pytest.approx(cons.posterior("a", "is_tv"))


def _monitor_stream(seed: int, n: int = 12, claims: int = 30, see: float = 0.15):
    """TVs (channel label tv) and monitors (channel label otherprop, which denies is_tv in an
    exhaustive table), each claimed 'tv' ``claims`` times at the same confidences; the channel sees
    an element a fraction ``see`` of the times it is claimed. Clutter the channel never sees gets
    one or two scattered claims: to the map-wide consensus a repeated 'tv' claim is then strong
    evidence of a tv, and a monitor's thirty claims outweigh its few otherprop labels."""
    rng = random.Random(seed)
    items = []
    for i in range(claims * 2 * n):
        v = rng.randrange(2 * n)
        node, lab = (f"tv{v}", "tv") if v < n else (f"mon{v - n}", "otherprop")
        ev = EvidenceEvent({node: 1.0}, "is_tv", rng.uniform(0.55, 0.9), "det", i, f"e{i}")
        items.append((ev, {node: lab if rng.random() < see else None}))
        if i % 4 == 0:
            c = f"clutter{rng.randrange(4 * n)}"
            ev = EvidenceEvent({c: 1.0}, f"is_{rng.choice(CLASSES)}", rng.uniform(0.55, 0.9), "det", i, f"c{i}")
            items.append((ev, {c: None}))
    return items


def _exhaustive_table() -> SubsumptionTable:
    labels = [*CLASSES, "otherprop"]
    specs = {f"is_{k}": {"positive": [k], "negative": [j for j in labels if j != k]} for k in CLASSES}
    return SubsumptionTable(specs, name="five-exhaustive", labels=labels)


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_claims_unseen_at_an_element_the_channel_denies_elsewhere_do_not_commit(engine: str) -> None:
    """A monitor the channel labels otherprop whenever it sees it (15 % of its claims) is not a tv: the
    claims that arrive while the channel looks elsewhere take that verdict as their consensus outcome
    (not the Dawid-Skene posterior, which follows the claims). Seeded; tolerance: at most 2 of 12
    monitors commit, at least 11 of 12 TVs; the posterior-only setting commits more monitors."""
    from sgbelief.fusion.channel import FrameLabels

    def run(adjudicated: str):
        # forward-only recall: with retroactive withdrawal the monitors' unseen claims go either way
        # (tests/test_label_memory.py); this test isolates the consensus outcome
        cfg = {"recalled_verdicts": "unanimous", "calibration": {"consensus": {"adjudicated_elements": adjudicated}}}
        op = make_operator("comod", cfg, _exhaustive_table(), engine=engine)
        g = SceneGraph(create_nodes=True)
        op.update_many(g, [(ev, FrameLabels(labels)) for ev, labels in _monitor_stream(5)])
        mon = sum(g.probability(f"mon{i}", "is_tv") > 0.5 for i in range(12))
        tvs = sum(g.probability(f"tv{i}", "is_tv") > 0.5 for i in range(12))
        return mon, tvs

    mon, tvs = run("channel")
    assert mon <= 2 and tvs >= 11, (mon, tvs)
    mon_posterior, _ = run("consensus")
    assert mon_posterior > mon, (mon_posterior, mon)


# ----------------------------------------------------------------------------- streams
def _map_stream(seed: int, *, n_real: int = 40, n_clutter: int = 60, label: str | None = "otherprop",
                scattered: bool = False, t0: int = 0):
    """Real elements: 8 agreeing confident claims each, with a decisive label half the time;
    clutter: one weak claim each (or two to four scattered ones), the channel silent or ambiguous."""
    rng = random.Random(seed)
    claims = []  # (node, class, confidence, label), interleaved in time as a robot would see them
    for v in range(n_real):
        k = CLASSES[v % len(CLASSES)]
        claims += [(f"r{v}", k, rng.uniform(0.6, 0.95), k if rng.random() < 0.5 else None) for _ in range(8)]
    for v in range(n_clutter):
        claims += [(f"c{v}", rng.choice(CLASSES), rng.uniform(0.4, 0.75), label)
                   for _ in range(rng.randint(2, 4) if scattered else 1)]
    rng.shuffle(claims)
    items = []
    for i, (node, k, c, lab) in enumerate(claims):
        t = t0 + i + 1
        items.append((EvidenceEvent({node: 1.0}, f"is_{k}", c, "det", t, f"e{t}"), {node: lab}))
    return items, t0 + len(claims)


def _run(items, config=None, name="comod"):
    from sgbelief.fusion.channel import FrameLabels

    op = make_operator(name, config, _table())
    g = SceneGraph(create_nodes=True)
    op.update_many(g, [(ev, FrameLabels(labels)) for ev, labels in items])
    return op, g


@pytest.mark.parametrize("label", ["otherprop", None])
def test_a_lone_claim_the_channel_cannot_adjudicate_does_not_commit(label) -> None:
    """On a map where lone weak claims land on clutter, a new lone claim on an element whose label
    is ambiguous (or absent) is calibrated on what such claims turned out to be: it does not commit."""
    items, t = _map_stream(0, label=label)
    op, g = _run(items)
    from sgbelief.fusion.channel import FrameLabels

    for i, c in enumerate((0.45, 0.55, 0.65)):  # confidences of the clutter's range (real: 0.6-0.95)
        op.update(g, EvidenceEvent({f"new{i}": 1.0}, "is_tv", c, "det", t + 1 + i, f"new{i}"), FrameLabels({f"new{i}": label}))
        assert g.probability(f"new{i}", "is_tv") <= 0.5, (c, g.probability(f"new{i}", "is_tv"))
    # the consensus was fitted on the map (not the cold start) and real elements still commit
    cons = next(iter(op._consensus.values()))[1]
    assert cons.n_fits >= 2
    committed_real = sum(g.probability(f"r{v}", f"is_{CLASSES[v % 5]}") > 0.5 for v in range(40))
    assert committed_real >= 38


@pytest.mark.parametrize("order", [("toilet", "bed", "bed", "tv"), ("bed", "toilet", "bed", "tv"),
                                   ("bed", "bed", "toilet", "tv"), ("tv", "bed", "toilet", "bed")])
def test_scattered_exclusive_claims_do_not_commit(order) -> None:
    """An element claimed once as toilet, twice as bed and once as tv is none of them, in any order."""
    items, t = _map_stream(1, label=None, scattered=True)
    op, g = _run(items)
    from sgbelief.fusion.channel import FrameLabels

    for i, k in enumerate(order):
        op.update(g, EvidenceEvent({"odd": 1.0}, f"is_{k}", 0.7, "det", t + 1 + i, f"odd{i}"), FrameLabels({"odd": None}))
    for k in set(order):
        assert g.probability("odd", f"is_{k}") <= 0.5, (order, k, g.probability("odd", f"is_{k}"))


def test_without_the_coupling_two_scattered_claims_of_one_class_commit() -> None:
    """The regression above fails without the options: per-predicate Betas commit is_bed."""
    items, t = _map_stream(1, label=None, scattered=True)
    cfg = {"exclusive_evidence": "none", "calibration": {"consensus": {"method": "none"}}}
    op, g = _run(items, cfg)
    from sgbelief.fusion.channel import FrameLabels

    for i, k in enumerate(("toilet", "bed", "bed", "tv")):
        op.update(g, EvidenceEvent({"odd": 1.0}, f"is_{k}", 0.7, "det", t + 1 + i, f"odd{i}"), FrameLabels({"odd": None}))
    assert g.probability("odd", "is_bed") > 0.5


def test_exclusion_entries_are_recorded_under_the_claim_and_retract_with_it() -> None:
    op = make_operator("comod", None, _table())
    g = SceneGraph(create_nodes=True)
    op.update(g, EvidenceEvent({"v": 1.0}, "is_bed", 0.8, "det", 1, "a"), None)
    op.update(g, EvidenceEvent({"v": 1.0}, "is_chair", 0.8, "det", 2, "b"), None)
    entries = g.provenance.entries("v", "is_bed")
    excl = [e for e in entries if e.verdict is EntryVerdict.EXCLUSION]
    assert len(excl) == 1 and excl[0].event_id == "b" and excl[0].d_alpha == 0.0
    (own_b,) = [e for e in g.provenance.entries("v", "is_chair") if e.event_id == "b"]
    assert excl[0].d_beta == pytest.approx(own_b.d_alpha)  # the claim's d_alpha, against the rival
    # no entry at a rival pair the log did not hold (is_sofa never claimed)
    assert ("v", "is_sofa") not in g.provenance
    before = g.provenance.alpha_beta("v", "is_bed")
    op.retract(g, "b")
    after = g.provenance.alpha_beta("v", "is_bed")
    assert after == pytest.approx((before[0], before[1] - own_b.d_alpha))
    assert g.provenance.reconstruct("v", "is_bed") == pytest.approx(after)


def test_a_refused_claim_excludes_nothing() -> None:
    from sgbelief.fusion.channel import FrameLabels

    op = make_operator("comod", None, _table())
    g = SceneGraph(create_nodes=True)
    op.update(g, EvidenceEvent({"v": 1.0}, "is_bed", 0.8, "det", 1, "a"), None)
    op.update(g, EvidenceEvent({"v": 1.0}, "is_chair", 0.9, "det", 2, "b"), FrameLabels({"v": "bed"}))  # ⊥
    assert not [e for e in g.provenance.entries("v", "is_bed") if e.verdict is EntryVerdict.EXCLUSION]


def test_a_systematic_confusion_is_learned_with_no_channel() -> None:
    """No channel: chairs are claimed 'sofa' 35 % of the time by one context. The consensus' Dawid–Skene
    learns that confusion and still names the chairs (tolerance: 90 % of 60 chairs)."""
    rng = random.Random(3)
    cons = MapConsensus(OperatorConfig().calibration, frozenset(f"is_{k}" for k in CLASSES))
    for v in range(120):
        k = "chair" if v < 60 else rng.choice(["bed", "sofa", "tv"])
        for _ in range(6):
            said = "sofa" if (k == "chair" and rng.random() < 0.35) else k
            cons.add_claim(f"v{v}", f"is_{said}", "det", rng.uniform(0.5, 0.9), "cell", False, f"e{v}")
    probas = cons.fit_consensus()
    chairs = [cons.task_of(f"v{v}") for v in range(60)]
    assert (probas[chairs].argmax(1) == cons.class_of("is_chair")).mean() >= 0.9
    ds = cons.ds_
    row = ds.errors_[ds.workers_.index("det"), ds.class_index("is_chair")]
    said_sofa = sum(row[j] for j, lab in enumerate(ds.labels_) if lab.startswith("is_sofa|"))
    assert 0.2 < said_sofa < 0.5  # the learned confusion, near the true 0.35


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), retract=st.integers(0, 59))
def test_eq4_and_exact_retraction_with_the_options_on(seed: int, retract: int) -> None:
    """Every pair's belief is the prior plus its counted entries (Eq. 4), before and after retracting
    an event, with consensus and exclusion on (refits every 5 claims)."""
    rng = random.Random(seed)
    items = []
    for t in range(60):
        v = f"n{rng.randrange(6)}"
        lab = rng.choice([None, "otherprop", *CLASSES])
        items.append((EvidenceEvent({v: 1.0}, f"is_{rng.choice(CLASSES)}", rng.random(), "det", t, f"e{t}"), {v: lab}))
    cfg = {"calibration": {"consensus": {"every": 5, "growth": 0.0}}}
    op, g = _run(items, cfg)
    prov = g.provenance
    for node, pred in list(prov.pairs()):
        assert prov.alpha_beta(node, pred) == pytest.approx(prov.reconstruct(node, pred))
    op.retract(g, f"e{retract}")
    assert not prov.has_event(f"e{retract}")
    for node, pred in list(prov.pairs()):
        assert prov.alpha_beta(node, pred) == pytest.approx(prov.reconstruct(node, pred))


def test_the_paper_variant_turns_both_off() -> None:
    op = make_operator("comod_paper", None, _table())
    assert op.config.exclusive_evidence == "none"
    assert op.config.calibration.consensus.method == "none"
    assert not op.consensus_classes and not op.excludes_rivals


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_vocabulary_set_after_construction_turns_the_consensus_on(engine: str) -> None:
    """The ConceptGraphs backend learns its class list after it built the operator and then sets
    ``operator.vocabulary``: the exclusive classes, and the consensus over them, follow it (they were
    computed once at construction, so the consensus never ran in the backend)."""
    op = make_operator("comod", vocabulary=None, engine=engine)
    assert op.consensus_classes == frozenset()
    op.vocabulary = _table()
    assert op.consensus_classes == frozenset(f"is_{k}" for k in CLASSES)
    g = SceneGraph(vocabulary=_table())
    g.add_node("v")
    op.update(g, EvidenceEvent(id="e0", t=0, predicate="is_chair", confidence=0.8, targets={"v": 1.0},
                               context="det"))
    held = op._consensus[id(g.provenance)][1]
    assert held.exclusive == op.consensus_classes and len(held.node) == 1
    op.vocabulary = SubsumptionTable({"is_a": {"positive": ["a"], "negative": ["b"]},
                                      "is_b": {"positive": ["b"], "negative": ["a"]}}, name="ab", labels=["a", "b"])
    assert op.consensus_classes == frozenset({"is_a", "is_b"})


def test_a_detectors_repeated_mistakes_on_one_object_count_as_correlated() -> None:
    """No channel but one label per element (so the channel's worker exists): 150 elements of five
    classes, each claimed 8 times by one context whose claims on an element are drawn from that
    element's own row, Dirichlet(2 x (70 % right, the rest spread)): a detector that mistakes an
    object keeps mistaking it. With the default emission the context's concentration is learned
    small (<= 16) while the support and the channel keep the independent emission (inf), and the
    posterior's log-loss on the true class is lower than the independent model's (seeded). One
    confidence for every claim, so every claim is in one confidence bin: the Dirichlet is over the
    worker's (class, bin) labels, and repeats of a class spread over bins look partly independent
    to it (with confidences drawn from U(0.5, 0.9) this stream's s comes out 64; docs/method.md §8)."""

    def fit(emission: str) -> tuple[MapConsensus, list[int]]:
        rng = np.random.default_rng(5)
        cons = MapConsensus(OperatorConfig(calibration={"consensus": {"emission": emission}}).calibration,
                            frozenset(f"is_{k}" for k in CLASSES))
        truth = []
        row = np.full((5, 5), 0.3 / 4) + np.eye(5) * (0.7 - 0.3 / 4)
        for v in range(150):
            k = int(rng.integers(5))
            truth.append(k)
            own = rng.dirichlet(2.0 * row[k])
            for j, said in enumerate(rng.choice(5, 8, p=own)):
                cons.add_claim(f"v{v}", f"is_{CLASSES[said]}", "det", 0.7, "cell", False, f"e{v}.{j}")
            cons.add_label(f"v{v}", 0, "otherprop")
        cons.fit_consensus()
        return cons, truth

    (dm, truth), (plain, _) = fit("dirichlet_multinomial"), fit("multinomial")
    conc = dict(zip(dm.ds_.workers_, dm.ds_.concentrations_))
    assert conc["det"] <= 16 and np.isinf(conc["<support>"]) and np.isinf(conc["<geometric>"]), conc
    assert np.isinf(plain.ds_.concentrations_).all()

    def log_loss(cons: MapConsensus) -> float:
        p = [cons.ds_.probas_[cons.task_of(f"v{v}"), cons.class_of(f"is_{CLASSES[k]}")] for v, k in enumerate(truth)]
        return float(-np.mean(np.log(np.clip(p, 1e-12, 1.0))))

    assert log_loss(dm) < log_loss(plain), (log_loss(dm), log_loss(plain))


@settings(max_examples=200, deadline=None)
@given(data=st.data(), cold=st.sampled_from(["raw", "neutral"]), target=st.sampled_from([1, 5, 50]))
def test_the_batched_likelihood_ratios_equal_the_scalar_ones(data, cold, target) -> None:
    """ConsensusCalibration.likelihood_ratios (the reweighing's batch) gives, claim by claim, what
    likelihood_ratio gives: tolerance 1e-12 relative (numpy's interpolation and logs against the
    scalar ones), on random fits over three levels, keys that were fitted or not, any confidence."""
    n = data.draw(st.integers(1, 40))
    levels = [data.draw(st.lists(st.integers(0, 4), min_size=n, max_size=n)) for _ in range(3)]
    c = data.draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n))
    q = data.draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n))
    cal = ConsensusCalibration(target_size=target, cold_start=cold).fit(
        [np.asarray(lv) for lv in levels], np.asarray(c), np.asarray(q))
    m = data.draw(st.integers(1, 30))
    qc = np.asarray(data.draw(st.lists(st.floats(0.0, 1.0), min_size=m, max_size=m)))
    keys = [np.asarray(data.draw(st.lists(st.integers(0, 6), min_size=m, max_size=m))) for _ in range(3)]
    lams, kappas = cal.likelihood_ratios(qc, keys)
    for i in range(m):
        lam, kappa = cal.likelihood_ratio(float(qc[i]), tuple(int(k[i]) for k in keys))
        assert math.isclose(lams[i], lam, rel_tol=1e-12), (i, lams[i], lam)
        assert math.isclose(kappas[i], kappa, rel_tol=1e-12, abs_tol=1e-15), (i, kappas[i], kappa)


def test_merged_elements_count_toward_the_next_refit() -> None:
    """MapConsensus.due: claims whose element was merged into another count as new claims do
    (they agree or disagree with other claims now); a refit resets the count."""
    from sgbelief.calibration.config import CalibrationConfig

    cfg = CalibrationConfig.model_validate({"consensus": {"method": "agreement_shift", "every": 4, "growth": 0.0}})
    mc = MapConsensus(cfg, frozenset({"is_a", "is_b"}))
    for i in range(4):
        mc.add_claim(f"v{i}", "is_a", "det", 0.6, "cell", False, f"e{i}", t=i)
    assert mc.due()
    mc.refit()
    assert not mc.due() and mc.moved_since_fit == 0
    mc.add_claim("v0", "is_b", "det", 0.6, "cell", False, "e4", t=4)  # one new claim: 1 of 4
    mc.merge_elements("v0", "v1")  # v1's one claim moves: 2 of 4
    assert mc.moved_since_fit == 1 and not mc.due()
    mc.merge_elements("v0", "v2")
    mc.merge_elements("v0", "v0")  # a merge into itself moves nothing
    assert not mc.due()
    mc.merge_elements("v3", "v0")  # v0 now holds 4 claims (its own 2, v1's, v2's): 7 of 4
    assert mc.moved_since_fit == 6 and mc.due()
    mc.refit()
    assert not mc.due() and mc.moved_since_fit == 0
    mc.frozen = True
    mc.merge_elements("v9", "v3")
    assert not mc.due()


def test_refit_consensus_refits_after_merges_with_no_new_claim() -> None:
    """CalibratedOperator.refit_consensus: a merge after the last claim (ConceptGraphs' end-of-run
    merge) makes the consensus refit once, outside an update; nothing happens before a consensus
    exists or when nothing changed since the last fit."""
    cfg = {"calibration": {"consensus": {"method": "agreement_shift", "every": 4, "growth": 0.0}}}
    from sgbelief.fusion.open_vocab import derive_table

    op = make_operator("comod", config=cfg, vocabulary=derive_table(["a", "b"]))
    g = SceneGraph(create_nodes=True)
    assert op.refit_consensus(g) == []
    for i, (node, cls) in enumerate([("v0", "a"), ("v1", "a"), ("v2", "b"), ("v3", "a")]):
        op.update(g, EvidenceEvent({node: 1.0}, f"is_{cls}", 0.7, "det", t=i, id=f"e{i}"))
    cons = op._consensus_of(g.provenance)
    assert cons.n_fits == 0 and cons.changed_since_fit()
    op.refit_consensus(g)  # the four claims
    assert cons.n_fits == 1 and not cons.changed_since_fit()
    assert op.refit_consensus(g) == [] and cons.n_fits == 1  # nothing changed since
    op.merge_nodes(g, "v0", "v1")
    assert cons.changed_since_fit() and not cons.due()  # one moved claim: not due, but changed
    op.refit_consensus(g)
    assert cons.n_fits == 2 and not cons.changed_since_fit()
    assert op.score_readings(g)["det"].claims == 2  # v0 now holds two claims: they enter the fit
