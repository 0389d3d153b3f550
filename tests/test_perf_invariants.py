"""Structural performance invariants (no wall-clock assertions): bounded provenance, amortised refits,
report=False changes nothing but the report."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.eval.random_stream import random_records
from sgbelief.eval.replay import make_runs, to_event
from sgbelief.calibration.mondrian import MondrianCalibrator


def test_provenance_live_entries_bounded_by_compaction_horizon() -> None:
    run = make_runs(["comod"], None, {"t_prov": 20})[0]
    recs = random_records(0, 3000, n_nodes=15)
    for i, r in enumerate(recs):
        ev, lab = to_event(r, f"x{i}")
        run.operator.update(run.graph, ev, lab)
    prov = run.graph.provenance
    last_t = recs[-1].t
    # every live un-compacted entry is younger than two horizons; logs hold <= 1 bucket each
    assert all(e.t >= last_t - 2 * 20 for e in prov.timeline_view())
    assert prov.n_compacted > 2000
    for key in prov.pairs():
        assert sum(e.status.value == "compacted" for e in prov.entries(*key)) <= 1


def test_report_false_gives_the_same_state() -> None:
    recs = random_records(3, 800, n_nodes=10)
    states = []
    for report in (True, False):
        run = make_runs(["comod"], None)[0]
        for i, r in enumerate(recs):
            ev, lab = to_event(r, f"x{i}")
            rep = run.operator.update(run.graph, ev, lab, report=report)
            assert report or rep.targets == ()
        prov = run.graph.provenance
        states.append(({k: prov.alpha_beta(*k) for k in prov.pairs()}, dict(run.operator.stats)))
    assert states[0] == states[1]


def test_calibration_refits_logarithmic_and_buffer_sorted() -> None:
    cal = MondrianCalibrator()
    fits = 0
    last = 0
    for i in range(20000):
        cal.add("k", "p", (i * 7919 % 1000) / 1000, i % 3 == 0)
        s = cal.slices[("k", "p")]
        if s.n_fit != last:
            fits, last = fits + 1, s.n_fit
    assert fits < 120
    s = cal.slices[("k", "p")]
    assert (s.sorted_negatives[1:] >= s.sorted_negatives[:-1]).all()
    assert (s.sorted_positives[1:] >= s.sorted_positives[:-1]).all()
    assert len(s.sorted_negatives) + len(s.sorted_positives) + len(s.c) == s.n


@settings(max_examples=300, deadline=None)
@given(
    st.floats(0.05, 5000.0), st.floats(0.05, 5000.0), st.floats(0.0, 3.0), st.floats(0.0, 3.0), st.floats(1e-4, 2.0)
)
def test_revision_test_decision_equals_the_exact_kl(a: float, b: float, da: float, db: float, tau: float) -> None:
    """The cheap KL estimate (lgamma + pure-Python digamma) never changes the revision decision."""
    from scipy.special import betaln, digamma

    from sgbelief.fusion.rules import _digamma_estimate, revision_kl_exceeds

    exact = betaln(a + da, b + db) - betaln(a, b) - da * digamma(a) - db * digamma(b) + (da + db) * digamma(a + b)
    assert revision_kl_exceeds(a, b, da, db, tau) == (exact > tau)
    assert abs(_digamma_estimate(a) - digamma(a)) < 1e-10 * max(1.0, abs(digamma(a)))


@settings(max_examples=500, deadline=None)
@given(st.floats(1e-3, 1e5), st.floats(1e-3, 1e5), st.floats(0.0, 10.0), st.floats(0.0, 10.0))
def test_kl_upper_bound_bounds_the_exact_kl(a: float, b: float, da: float, db: float) -> None:
    """The bound that lets the revision test skip the special functions is >= the exact KL
    (up to the exact formula's own rounding error)."""
    from scipy.special import betaln, digamma

    from sgbelief.fusion.rules import kl_upper_bound

    exact = betaln(a + da, b + db) - betaln(a, b) - da * digamma(a) - db * digamma(b) + (da + db) * digamma(a + b)
    assert exact <= kl_upper_bound(a, b, da, db) + 1e-9 * (1.0 + a + b)


def test_kl_upper_bound_is_tight_for_small_steps() -> None:
    """For a small step the KL is ~ (1/2) delta^T H delta; the bound is within a few times it."""
    from scipy.special import betaln, digamma

    from sgbelief.fusion.rules import kl_upper_bound

    a, b, da, db = 20.0, 30.0, 0.3, 0.1
    exact = betaln(a + da, b + db) - betaln(a, b) - da * digamma(a) - db * digamma(b) + (da + db) * digamma(a + b)
    assert exact <= kl_upper_bound(a, b, da, db) <= 3.0 * exact
