"""The backend says when most claims carry a confidence below 0.5 and no channel can calibrate them.

sgbelief reads a confidence as the probability that the claim is right, so with no channel every
claim below 0.5 counts against its class. In ConceptGraphs' own loop (benchmarks/bench_cg_harness.py,
no channel, confidences U(0.15, 0.55) whatever the class) that left 13-15 of 15-17 objects unknown
(docs/conceptgraphs.md, "Detectors whose scores are not probabilities"): the user must hear it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend, LowConfidenceWarning
from sgbelief.adapters.conceptgraphs.standins import make_detection
from sgbelief.adapters.conceptgraphs.summary import LOW_CONFIDENCE_MIN_CLAIMS, BackendSummary, low_confidence_note

NAMES = ["chair", "sofa", "table"]


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
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False)
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
    backend = ConceptGraphsBackend("comod", class_names=NAMES, print_summary=False, **kw)
    _route(backend, confidences)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowConfidenceWarning)
        backend.end_frame()
    s = backend.summary()
    assert s.notes == [] and "note:" not in s.format()
    assert s.below_half == 0 or case == "channel"


def test_summary_without_notes_formats_as_before():
    s = BackendSummary(objects=1, labelled=1, unknown=0, filtered=0, detections=3, events=3)
    assert "note:" not in s.format() and s.to_dict()["below_half"] == 0
