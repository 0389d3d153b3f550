"""The baselines' rules, the compaction schedule and the moved modules: one rule on floats and on
arrays alike, one schedule for both engines, GC settings that restore the caller's, shims that warn."""

from __future__ import annotations

import gc
import importlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.operators import CompactionSchedule, MajorityVoteRule, NaiveBayesRule, OverwriteRule
from sgbelief.fusion.protocol import STAT_KEYS, increment_stance, new_stats

_CONF = st.lists(st.one_of(st.sampled_from([0.0, 0.5, 1.0, 0.499999, 0.5000001]), st.floats(0.0, 1.0)), min_size=1, max_size=40)


def _bits(xs: object) -> list[str]:
    return [float(x).hex() for x in np.asarray(xs, dtype=np.float64).ravel()]


@settings(max_examples=200, deadline=None)
@given(cs=_CONF, reliability=st.floats(0.0, 1.0), strength=st.floats(0.0, 50.0),
       prior=st.sampled_from([(1.0, 1.0), (0.5, 2.0), (2.0, 0.75)]))
def test_each_rule_gives_on_an_array_what_it_gives_on_each_float(cs, reliability, strength, prior) -> None:
    """The batched engine applies the operator's own rule to arrays: bit for bit the floats'."""
    arr = np.array(cs, dtype=np.float64)
    for rule in (MajorityVoteRule(), NaiveBayesRule(reliability)):
        p, q = rule.split(arr)
        assert _bits(p) == _bits([rule.split(c)[0] for c in cs])
        assert _bits(q) == _bits([rule.split(c)[1] for c in cs])
    rule = OverwriteRule(strength)
    ta, tb = rule.target(arr, *prior)
    assert _bits(ta) == _bits([rule.target(c, *prior)[0] for c in cs])
    assert _bits(tb) == _bits([rule.target(c, *prior)[1] for c in cs])


@settings(max_examples=100, deadline=None)
@given(c=st.floats(0.0, 1.0), strength=st.floats(0.0, 50.0), prior=st.sampled_from([(1.0, 1.0), (0.5, 2.0)]))
def test_overwrite_target_is_the_two_cases_bit_for_bit(c, strength, prior) -> None:
    a0, b0 = prior
    want = (a0 + strength, b0) if c >= 0.5 else (a0, b0 + strength)
    assert _bits(OverwriteRule(strength).target(c, a0, b0)) == _bits(want)


def test_rule_increments_follow_their_kind() -> None:
    assert MajorityVoteRule().increments(0.8, 0.5, (3.0, 4.0), (1.0, 1.0)) == (0.5 * 0.8, 0.5 * (1.0 - 0.8))
    assert OverwriteRule(9.0).increments(0.8, 0.5, (3.0, 4.0), (1.0, 1.0)) == (10.0 - 3.0, 1.0 - 4.0)
    assert OverwriteRule(9.0).increments(0.2, 0.5, (3.0, 4.0), (1.0, 1.0)) == (1.0 - 3.0, 10.0 - 4.0)


@given(da=st.floats(-5, 5), db=st.floats(-5, 5))
def test_increment_stance_on_floats_and_arrays(da: float, db: float) -> None:
    want = 1 if da > db else -1 if da < db else 0
    assert increment_stance(da, db) == want
    assert increment_stance(np.array([da]), np.array([db])).tolist() == [want]


def test_stats_start_at_zero_with_every_key() -> None:
    assert new_stats() == dict.fromkeys(STAT_KEYS, 0) and len(STAT_KEYS) == 14


@settings(max_examples=200, deadline=None)
@given(t_prov=st.integers(1, 50), t_compact=st.one_of(st.none(), st.integers(1, 50)),
       saved=st.one_of(st.none(), st.tuples(st.integers(0, 40), st.integers(1, 50))),
       ts=st.lists(st.integers(0, 500), max_size=30))
def test_the_schedule_runs_a_pass_on_the_first_tick_of_each_epoch(t_prov, t_compact, saved, ts) -> None:
    """``advance`` tick by tick (the streaming engine) agrees with the array form the batched
    engine uses, from a fresh graph or one compacted under another interval."""
    sched = CompactionSchedule.of(OperatorConfig(t_prov=t_prov, t_compact=t_compact))
    assert sched.interval == (t_compact or t_prov)
    meta: dict = {}
    if saved is not None:
        meta["compaction_epoch"], interval = saved
        if interval != t_prov:
            meta["compaction_interval"] = interval
    ts = sorted(ts)
    start = sched.last_epoch(meta)
    passes = [t for t in ts if sched.advance(meta, t)]
    epoch = sched.epoch(np.array(ts, dtype=np.int64))
    opens = np.flatnonzero(epoch > np.maximum.accumulate(np.r_[start, epoch[:-1]])) if ts else []
    assert passes == [ts[i] for i in opens]
    if passes:
        assert meta["compaction_epoch"] == passes[-1] // sched.interval
        assert meta.get("compaction_interval", t_prov) == sched.interval
        assert sched.horizon(passes[-1]) == passes[-1] - t_prov


# ------------------------------------------------------------------ the garbage collector
def test_gc_settings_restore_the_callers() -> None:
    from sgbelief._fast.gc import REPLAY_GC_THRESHOLD, gc_paused, relaxed_gc, young_collections_only

    before, enabled = gc.get_threshold(), gc.isenabled()
    with relaxed_gc():
        assert gc.get_threshold()[0] == max(REPLAY_GC_THRESHOLD, before[0])
        with relaxed_gc(10):  # nested: never lowers the outer setting
            assert gc.get_threshold()[0] == max(REPLAY_GC_THRESHOLD, before[0])
    with young_collections_only():
        assert gc.get_threshold()[:2] == before[:2] and gc.get_threshold()[2] > 10**8
    with gc_paused():
        assert not gc.isenabled()
    assert gc.get_threshold() == before and gc.isenabled() == enabled


def test_gc_checkpoints_freeze_and_release() -> None:
    from sgbelief._fast.gc import checkpoint, release_checkpoints

    try:
        checkpoint()
        assert gc.get_freeze_count() > 0
    finally:
        release_checkpoints()
    assert gc.get_freeze_count() == 0


# ------------------------------------------------------------------ moved modules
@pytest.mark.parametrize(("module", "name", "home"), [
    ("sgbelief.eval.batched", "batched_replay", "sgbelief._fast.batched"),
    ("sgbelief.eval.batched", "EventColumns", "sgbelief._fast.batched"),
    ("sgbelief.eval.batched", "provenance_signature", "sgbelief.testing"),
    ("sgbelief.eval.batched", "random_records", "sgbelief.eval.random_stream"),
])
def test_moved_names_still_work_and_warn(module: str, name: str, home: str) -> None:
    shim = importlib.import_module(module)
    with pytest.warns(DeprecationWarning, match=f"{home}.*removed in sgbelief 0.2.0"):
        value = getattr(shim, name)
    assert value is getattr(importlib.import_module(home), name)
    assert name in dir(shim)


def test_the_old_batched_operator_names_still_answer() -> None:
    import sgbelief.eval.batched as shim

    with pytest.warns(DeprecationWarning, match="pair_rule"):
        assert shim.BATCHED_OPERATORS == ("majority", "naive_bayes", "overwrite")
    with pytest.raises(AttributeError):
        shim.no_such_name  # noqa: B018


@pytest.mark.parametrize("module", ["gc_tuning.py", "query/retrieval.py"])
def test_shims_that_imported_upward_are_gone(module: str) -> None:
    from pathlib import Path

    import sgbelief

    assert not (Path(sgbelief.__file__).parent / module).exists()

