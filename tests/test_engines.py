"""The fused engine of cal / comod equals the reference path (Algorithm 1's named steps)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.fusion.events import EvidenceEvent
from sgbelief.testing import check_fast_matches_reference, random_stream

NAMES = ["cal", "comod", "cal_paper", "comod_paper"]
LABELS = ["car", "truck", "person", "building", None]


@pytest.mark.parametrize("name", NAMES)
def test_engines_agree_on_the_conformance_stream(name: str) -> None:
    check_fast_matches_reference(name, random_stream(400, seed=3), {"t_prov": 60, "tau_rev": 0.3}, final_tick=5000)


def _streams():
    target = st.sampled_from([f"n{i}" for i in range(5)])
    event = st.tuples(
        st.dictionaries(target, st.floats(0.0, 1.0), min_size=1, max_size=3),
        st.sampled_from(["is_car", "is_pedestrian"]),
        st.floats(0.0, 1.0),
        st.sampled_from(["vlm_a", "vlm_b"]),
        st.integers(0, 4),
        st.lists(st.sampled_from(LABELS), min_size=3, max_size=3),
    )
    return st.lists(event, max_size=60)


@settings(max_examples=120, deadline=None)
@given(raw=_streams(), name=st.sampled_from(NAMES), tau_rev=st.sampled_from([0.05, 0.5]),
       strata=st.integers(1, 4), geo=st.sampled_from(["none", "verdict"]))
def test_engines_agree_on_random_streams(raw, name, tau_rev, strata, geo) -> None:
    """Maps, provenance (every entry, in order), queues, stats and calibration buffers are equal."""
    stream, t = [], 0
    for i, (targets, pred, c, ctx, dt, labels) in enumerate(raw):
        t += dt
        total = sum(targets.values())
        if total > 1.0:  # masses are a distribution over the map's elements
            targets = {k: v / total for k, v in targets.items()}
        ev = EvidenceEvent(targets, pred, c, ctx, t, f"e{i}")
        stream.append((ev, {node: labels[j % 3] for j, node in enumerate(sorted(targets))}))
    config = {"tau_rev": tau_rev, "t_prov": 25, "t_cor": 3, "t_disagree": 3, "geometric_evidence": geo,
              "calibration": {"support_strata": strata, "target_size": 5, "min_refit": 1}}
    check_fast_matches_reference(name, stream, config, final_tick=t + 100)
