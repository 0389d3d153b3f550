"""Scores below 0.5 with no channel: the backend learns their shift from agreement, or says so.

sgbelief reads a confidence as the probability that the claim is right, so with no channel every
claim below 0.5 counts against its class. In ConceptGraphs' own loop (benchmarks/bench_cg_harness.py,
no channel, confidences U(0.15, 0.55) whatever the class) that left 13-15 of 15-17 objects unknown
(docs/conceptgraphs.md, "Detectors whose scores are not probabilities"). By default the backend
learns how far the scores sit below how often its claims agree (``calibration.consensus.method:
agreement_shift``) and its summary says by how much, or, when the scores do not show which claims
agree, counts the claims at one level and says so; a configuration without it gets the warning.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend, LowConfidenceWarning
from sgbelief.adapters.conceptgraphs.standins import make_detection
from sgbelief.adapters.conceptgraphs.summary import (LOW_CONFIDENCE_MIN_CLAIMS, BackendSummary, low_confidence_note,
                                                      score_reading_note)

NAMES = ["chair", "sofa", "table"]
#: the backend without the agreement shift: nothing but the raw scores (or a channel, or a map)
RAW = {"calibration": {"consensus": {"method": "none"}}}


def test_note_only_without_a_channel_for_a_majority_below_half_past_the_minimum():
    assert low_confidence_note(10, 5, has_channel=False) is not None  # half counts
    assert low_confidence_note(10, 4, has_channel=False) is None
    assert low_confidence_note(10, 10, has_channel=True) is None
    assert low_confidence_note(0, 0, has_channel=False) is None
    assert low_confidence_note(99, 99, has_channel=False, min_claims=100) is None
    note = low_confidence_note(100, 87, has_channel=False, min_claims=100)
    assert note is not None and note.startswith("87 of 100 claims have a confidence below 0.5")
    assert "channel=" in note and "confidence_map=" in note


def _route(backend: ConceptGraphsBackend, confidences: list[float]) -> None:
    blob = np.random.default_rng(0).random((50, 3))
    for t, c in enumerate(confidences):
        node = f"v{t % 5}"
        if node not in backend.graph:
            backend.graph.add_node(node)
        k = t % len(NAMES)
        backend.route_detection(make_detection(blob, k, NAMES[k], c, t), {node: 1.0})


def test_a_run_of_low_confidences_warns_once_at_a_frame_end_and_the_summary_notes_it():
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False, operator_config=RAW)
    _route(backend, [0.3] * (LOW_CONFIDENCE_MIN_CLAIMS - 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowConfidenceWarning)
        backend.end_frame()  # 99 claims: too few to judge
    _route(backend, [0.3])
    with pytest.warns(LowConfidenceWarning, match=f"{LOW_CONFIDENCE_MIN_CLAIMS} of {LOW_CONFIDENCE_MIN_CLAIMS} claims") as rec:
        backend.end_frame()
    assert rec[0].filename == __file__  # attributed to the caller outside sgbelief (errors.warn_at_caller)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowConfidenceWarning)
        backend.end_frame()  # once
    s = backend.summary()
    assert s.below_half == LOW_CONFIDENCE_MIN_CLAIMS
    assert len(s.notes) == 1 and "note: " + s.notes[0] in s.format()
    assert s.to_dict()["notes"] == s.notes
    assert s.unknown == s.objects == 5  # what the note warns of: nothing commits


@pytest.mark.parametrize("case", ["confident", "channel", "confidence_map"])
def test_no_warning_when_claims_are_confident_or_a_channel_or_a_map_is_given(case):
    kw: dict = {}
    confidences = [0.3] * 150
    if case == "confident":
        confidences = [0.8] * 150
    elif case == "channel":
        kw["channel"] = lambda det, node, t: "chair"
    else:
        kw["confidence_map"] = lambda c: 0.5 + c  # the user's map to probabilities
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False, operator_config=RAW, **kw)
    _route(backend, confidences)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowConfidenceWarning)
        backend.end_frame()
    s = backend.summary()
    assert s.notes == [] and "note:" not in s.format()
    assert s.below_half == 0 or case == "channel"


def _route_noisy(backend: ConceptGraphsBackend, seed: int, informative: bool, n: int = 300) -> None:
    """Five objects (classes chair, sofa, table, chair, sofa) claimed n times in all; a claim names the
    object's class with probability 0.75, another class otherwise. Informative scores: U(0.3, 0.5)
    for a right claim, U(0.1, 0.3) for a wrong one; otherwise U(0.2, 0.45) whatever the claim."""
    rng = np.random.default_rng(seed)
    blob = rng.random((50, 3))
    for t in range(n):
        node, truth = f"v{t % 5}", (t % 5) % len(NAMES)
        if node not in backend.graph:
            backend.graph.add_node(node)
        right = rng.random() < 0.75
        k = truth if right else int(rng.choice([x for x in range(len(NAMES)) if x != truth]))
        c = (rng.uniform(0.3, 0.5) if right else rng.uniform(0.1, 0.3)) if informative else rng.uniform(0.2, 0.45)
        backend.route_detection(make_detection(blob, k, NAMES[k], float(c), t), {node: 1.0})
        if t % 10 == 9:
            with warnings.catch_warnings():
                warnings.simplefilter("error", LowConfidenceWarning)
                backend.end_frame()


def test_by_default_low_scores_that_inform_are_read_shifted_up_and_the_summary_says_by_how_much():
    """Scores below 0.5 that rank right claims above wrong ones (seed 1): no warning, the rank test
    rejects, the fitted shift is positive, every object gets its class, and the summary's note names
    the shift and how a claim at 0.35 reads."""
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False)
    _route_noisy(backend, 1, informative=True)
    (reading,) = backend.operator.score_readings(backend.graph).values()
    assert reading.reads_scores and reading.p_value < 0.05 and reading.fitted > 0.5
    s = backend.summary()
    assert s.unknown == 0 and s.labelled == 5
    assert {v: backend.node_label(v) for v in (f"v{i}" for i in range(5))} == {f"v{i}": NAMES[i % 3] for i in range(5)}
    assert len(s.notes) == 1 and "read +" in s.notes[0] and "a claim at 0.35 reads as" in s.notes[0]
    assert backend.operator.config.calibration.consensus.method == "agreement_shift"


def test_by_default_scores_that_say_nothing_are_counted_at_one_level():
    """The same stream with scores unrelated to which claims are right (seed 1): the rank test does
    not reject, every claim is read at one level above 1/2, every object gets its class (the vote's
    answer here), and the note says the map counts the claims."""
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False)
    _route_noisy(backend, 1, informative=False)
    (reading,) = backend.operator.score_readings(backend.graph).values()
    assert not reading.reads_scores and reading.p_value >= 0.05
    assert max(reading.fitted, reading.stated) > 0.0
    s = backend.summary()
    assert s.unknown == 0 and {v: backend.node_label(v) for v in (f"v{i}" for i in range(5))} == {f"v{i}": NAMES[i % 3] for i in range(5)}
    assert len(s.notes) == 1 and "read at one level" in s.notes[0] and "counts them" in s.notes[0]


def test_the_reading_notes_by_hand():
    from sgbelief.calibration.agreement_shift import ContextReading

    up = score_reading_note({"det": ContextReading(1.0, 120, True, 0.001, -0.6)})
    assert up == ["no channel: the scores of det are read +1.00 higher in log-odds, learned from how often 120 claims "
                  "on objects with several claims agree (a claim at 0.35 reads as 0.59; docs/method.md §8)"]
    down = score_reading_note({"det": ContextReading(-0.4, 80, True, 0.01, 1.2)})
    assert "fitted shift -0.40" in down[0] and "read as the scores say" in down[0]
    level = score_reading_note({"det": ContextReading(0.8, 90, False, 0.43, -0.5)})
    assert level == ["no channel: the scores of det do not show which of its claims agree with the other claims on "
                     "their objects (rank test p = 0.43 over 90 claims); every claim is read at one level, 0.69, so "
                     "the map counts them (docs/method.md §8)"]  # sigmoid(max(0.8, -0.5)) = 0.690
    assert score_reading_note({}) == []


def test_summary_without_notes_formats_as_before():
    s = BackendSummary(objects=1, labelled=1, unknown=0, filtered=0, detections=3, events=3)
    assert "note:" not in s.format() and s.to_dict()["below_half"] == 0
