"""The fused engines equal the reference steps: Algorithm 1's for cal / comod, the baselines' step
for overwrite / majority / naive_bayes / refined; and the engine is chosen explicitly."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.fusion.events import EvidenceEvent
from sgbelief.testing import check_fast_matches_reference, random_stream

NAMES = ["cal", "comod", "cal_paper", "comod_paper"]
BASELINES = ["overwrite", "majority", "naive_bayes", "refined"]
LABELS = ["car", "truck", "person", "building", None]


@pytest.mark.parametrize("name", NAMES + BASELINES)
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
       strata=st.integers(1, 4), geo=st.sampled_from(["none", "verdict", "label"]),
       consensus=st.sampled_from(["none", "dawid_skene", "agreement_shift"]), every=st.integers(1, 6),
       recall=st.sampled_from(["none", "unanimous", "retroactive"]), min_labels=st.integers(1, 2),
       adjudicated=st.sampled_from(["channel", "consensus"]), silent=st.sampled_from(["current", "at_arrival"]),
       contested=st.sampled_from(["refuse", "weigh"]), score_test=st.sampled_from([None, 0.05, 0.5]),
       label_weights=st.sampled_from(["one", "reliability"]))
def test_engines_agree_on_random_streams(raw, name, tau_rev, strata, geo, consensus, every, recall, min_labels,
                                         adjudicated, silent, contested, score_test, label_weights) -> None:
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
              "recalled_verdicts": recall, "recall_min_labels": min_labels, "contested_labels": contested,
              "calibration": {"support_strata": strata, "target_size": 5, "min_refit": 1,
                              "consensus": {"method": consensus, "every": every, "growth": 0.0,
                                            "adjudicated_elements": adjudicated, "silent_weights": silent,
                                            "score_test_level": score_test, "label_weights": label_weights}}}
    check_fast_matches_reference(name, stream, config, final_tick=t + 100)


@settings(max_examples=120, deadline=None)
@given(raw=_streams(), name=st.sampled_from(BASELINES), t_prov=st.integers(1, 30), tau_t=st.sampled_from([0.0, 0.1, 0.3]),
       strength=st.sampled_from([9.0, 2.5]), reliability=st.sampled_from([0.8, 0.55]), window=st.integers(1, 4))
def test_baseline_engines_agree_on_random_streams(raw, name, t_prov, tau_t, strength, reliability, window) -> None:
    """Reports, maps, provenance (every entry, in order) and stats are equal."""
    stream, t = [], 0
    for i, (targets, pred, c, ctx, dt, labels) in enumerate(raw):
        t += dt
        total = sum(targets.values())
        if total > 1.0:
            targets = {k: v / total for k, v in targets.items()}
        stream.append((EvidenceEvent(targets, pred, c, ctx, t, f"e{i}"),
                       {node: labels[j % 3] for j, node in enumerate(sorted(targets))}))
    config = {"t_prov": t_prov, "tau_t": tau_t,
              "baselines": {"overwrite": {"strength": strength}, "naive_bayes": {"reliability": reliability},
                            "refined": {"window": window, "min_support": min(2, window)}}}
    check_fast_matches_reference(name, stream, config, final_tick=t + 100)


def test_the_engine_is_chosen_explicitly() -> None:
    from sgbelief._fast.baselines import FUSED_BASELINES
    from sgbelief._fast.calibrated import FUSED_CALIBRATED
    from sgbelief.api.operators import make_operator
    from sgbelief.fusion.operators import CoModulatedOperator, MajorityVoteOperator
    from sgbelief.fusion.operators.base import REFERENCE
    from sgbelief.fusion.registry import make_reference_operator as reference_operator

    assert make_operator("comod").engine is FUSED_CALIBRATED  # the public default
    assert make_operator("majority").engine is FUSED_BASELINES
    assert make_operator("comod", engine="reference").engine is REFERENCE
    assert reference_operator("comod").engine is REFERENCE  # the fusion layer's own registry
    assert CoModulatedOperator().engine is REFERENCE and MajorityVoteOperator(engine="reference").engine is REFERENCE
    assert CoModulatedOperator(engine=FUSED_CALIBRATED).engine is FUSED_CALIBRATED
    with pytest.raises(ValueError, match=r"sgbelief.make_operator\(.*engine='fast'\)"):
        CoModulatedOperator(engine="fast")
    with pytest.raises(ValueError, match="engine must be one of"):
        make_operator("comod", engine="turbo")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="apply"):
        MajorityVoteOperator(engine=object())  # type: ignore[arg-type]


def test_the_reference_builder_has_its_own_name_and_the_old_one_warns() -> None:
    import sgbelief.fusion as fusion
    import sgbelief.fusion.registry as registry
    from sgbelief.errors import SgbeliefDeprecationWarning

    assert fusion.make_reference_operator is registry.make_reference_operator
    assert "make_operator" not in fusion.__all__
    for module in (fusion, registry):
        with pytest.warns(SgbeliefDeprecationWarning, match="removed in sgbelief 0.2.0.*make_reference_operator"):
            assert module.make_operator is registry.make_reference_operator
    with pytest.raises(AttributeError):
        registry.no_such_name  # noqa: B018


def test_the_fusion_layer_never_imports_the_fast_engines() -> None:
    """Importing every reference module leaves sgbelief._fast unimported (run in a fresh process)."""
    import subprocess
    import sys

    code = ("import sys, sgbelief.fusion, sgbelief.fusion.registry, sgbelief.fusion.operators, sgbelief.graph.scene_graph; "
            "print(sorted(m for m in sys.modules if m.startswith('sgbelief._fast')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
