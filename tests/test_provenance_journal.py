"""The journalled provenance store (sgbelief._fast.journal) is the reference store, observably:
written through ``commit`` (journaled, folded by compaction without objects, in numpy or record
by record) it equals, bit for bit and in every observable order, the reference store
(sgbelief.graph.provenance) under any sequence of writes, reads, queue transitions, compactions,
retractions and node moves (``sgbelief.testing.check_store_matches_reference``)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief import SceneGraph
from sgbelief._fast.folds import fold_journal_records, retired_ids
from sgbelief._fast.journal import JournalledProvenanceStore
from sgbelief.errors import RetractionError
from sgbelief.graph.provenance import EntryStatus, EntryVerdict, ProvenanceStore
from sgbelief.testing import apply_store_operations, check_store_matches_reference, provenance_signature

_NODES = ["a", "b", "c"]
_PREDS = ["is_p", "is_q"]
_FLOAT = st.sampled_from([0.0, 0.25, 0.5, 1.0, 0.1, 1e-9, 3.0, -0.0])
#: what an operator records of the event behind an entry (None: a baseline)
_VERDICT = st.sampled_from([None, *EntryVerdict])
_CONFIDENCE = st.sampled_from([None, 0.0, 0.3, 0.9, 1.0])
_STATUS = st.sampled_from([EntryStatus.COMMITTED, EntryStatus.DISCARDED, EntryStatus.RELEASED,
                           EntryStatus.RESOLVED, EntryStatus.QUARANTINED, EntryStatus.REFUSED])

# operations with a time step instead of a time: ("commit" / "record", ..., dt, ...)
_commit = st.tuples(st.just("commit"), st.sampled_from(_NODES), st.sampled_from(_PREDS),
                    st.sampled_from(["x", "y", None, "new"]), st.integers(-1, 3), _FLOAT, _FLOAT,
                    st.sampled_from([-1, 0, 1]), _VERDICT, _CONFIDENCE)
_op = st.one_of(
    _commit,
    st.tuples(st.just("record"), st.sampled_from(_NODES), st.sampled_from(_PREDS), st.sampled_from(["x", "new"]),
              st.integers(0, 2), _FLOAT, _FLOAT,
              st.sampled_from([EntryStatus.REFUSED, EntryStatus.QUARANTINED, EntryStatus.COMMITTED]),
              _VERDICT, _CONFIDENCE),
    st.tuples(st.just("transition"), st.integers(0, 5), _STATUS, st.sampled_from([1.0, 0.5])),
    st.tuples(st.just("transition_held"), st.integers(0, 5), _STATUS, st.sampled_from([1.0, 0.5])),
    st.tuples(st.just("reweigh_held"), st.integers(0, 5), _FLOAT, _FLOAT, st.sampled_from([-1, 0, 1])),
    st.tuples(st.just("compact"), st.integers(-2, 4)),
    st.tuples(st.just("retract"), st.sampled_from(["x", "y", "e0", "e3", "e7"]), st.sampled_from([None, 3])),
    st.tuples(st.just("read"), st.sampled_from(_NODES), st.sampled_from(_PREDS)),
    st.tuples(st.just("read_event"), st.sampled_from(["x", "y", "e1", "e4"])),
    st.tuples(st.just("move"), st.sampled_from(_NODES), st.sampled_from(_NODES)),
    st.tuples(st.just("remove"), st.sampled_from(_NODES)),
)
#: mostly commits in time order with unique ids, and compactions: the journal-folding paths
_stream_commit = st.tuples(st.just("commit"), st.sampled_from(_NODES), st.sampled_from(_PREDS),
                           st.sampled_from(["new", "new", "new", "x"]), st.sampled_from([0, 0, 1, 1, 2]),
                           _FLOAT, _FLOAT, st.sampled_from([-1, 0, 1]), _VERDICT, _CONFIDENCE)


@st.composite
def _streaming_ops(draw: st.DrawFn) -> list[tuple[Any, ...]]:
    ops: list[tuple[Any, ...]] = draw(st.lists(_stream_commit, min_size=5, max_size=50))
    for _ in range(draw(st.integers(1, 8))):
        ops.insert(draw(st.integers(0, len(ops))), ("compact", draw(st.integers(0, 6))))
    for _ in range(draw(st.integers(0, 3))):
        ops.insert(draw(st.integers(0, len(ops))), draw(_op))
    return ops


def _timed(ops: list[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """Time steps to times (mostly non-decreasing, a commit with dt < 0 one step back), "new"
    ids to fresh ones, compaction horizons relative to the current time."""
    out: list[tuple[Any, ...]] = []
    now = 0
    for i, op in enumerate(ops):
        kind = op[0]
        if kind == "commit":
            _, node, pred, eid, dt, da, db, stance, *known = op
            now += max(dt, 0)
            out.append(("commit", node, pred, f"e{i}" if eid == "new" else eid, now + min(dt, 0), da, db, stance,
                        *known))
        elif kind == "record":
            _, node, pred, eid, dt, da, db, status, *known = op
            now += dt
            out.append(("record", node, pred, f"e{i}" if eid == "new" else eid, now, da, db, status, 1, *known))
        elif kind == "compact":
            out.append(("compact", now - op[1]))
        else:
            out.append(op)
    return out


def _journalled(vector_fold_min: int) -> Any:
    def make(prior: tuple[float, float], *, remember_compacted: int) -> JournalledProvenanceStore:
        store = JournalledProvenanceStore(prior, remember_compacted=remember_compacted)
        store.vector_fold_min = vector_fold_min
        return store
    return make


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=st.one_of(st.lists(_op, max_size=40), _streaming_ops()), remember=st.sampled_from([0, 2, 100]),
       vector_fold_min=st.sampled_from([1, 10**9]))
def test_journalled_store_matches_reference(ops: list[tuple[Any, ...]], remember: int, vector_fold_min: int) -> None:
    """Journaled and folded in numpy from the first record (``vector_fold_min = 1``), or folded
    record by record: the reference store's results, beliefs and state."""
    check_store_matches_reference(_journalled(vector_fold_min), _timed(ops), remember_compacted=remember)


@pytest.mark.parametrize("ops", [
    # an id materialised by a compaction that had to fall back, then journaled again: the old
    # entry's fold must not release the id while the journaled one lives
    [("commit", "a", "is_p", "x", 2, 0.5, 0.5, 0), ("commit", "a", "is_p", "x", 5, 0.5, 0.5, 0),
     ("compact", 1), ("commit", "a", "is_p", "x", 3, 0.5, 0.5, 0), ("compact", 2)],
    # an id with a pending (materialised) entry and a journaled one
    [("record", "a", "is_p", "x", 1, 0.5, 0.5, EntryStatus.REFUSED), ("compact", 5),
     ("commit", "b", "is_p", "x", 0, 0.5, 0.5, 0), ("transition", 0, EntryStatus.RESOLVED, 1.0),
     ("commit", "a", "is_p", "y", 4, 0.5, 0.5, 0), ("compact", 0), ("retract", "x", 3)],
    # records without ids, out of time order
    [("commit", "a", "is_p", None, 1, 0.5, 0.5, 0), ("commit", "a", "is_q", None, -1, 0.5, 0.5, 0),
     ("commit", "a", "is_p", "y", 3, 0.5, 0.5, 0), ("compact", 0), ("compact", -2)],
    # a held committed entry stops counting while the journal holds later commits of its pair
    [("record", "a", "is_p", "x", 1, 0.5, 0.5, EntryStatus.COMMITTED), ("commit", "a", "is_p", "y", 1, 0.25, 0.5, 0),
     ("transition_held", 0, EntryStatus.DISCARDED, 1.0), ("read", "a", "is_p")],
    # a committed entry weighed again while the journal holds later commits of its pair, then folded
    [("record", "a", "is_p", "x", 1, 0.5, 0.5, EntryStatus.COMMITTED), ("commit", "a", "is_p", "y", 1, 0.25, 0.5, 0),
     ("reweigh_held", 0, 0.1, 0.9, -1), ("read", "a", "is_p"), ("compact", -3), ("reweigh_held", 0, 0.2, 0.2, 0)],
    # the old timeline and old journal records of one pair fold in one pass (one fsum over both)
    [("record", "a", "is_p", "new", 1, 0.1, 0.1, EntryStatus.COMMITTED), ("commit", "a", "is_p", "new", 1, 0.2, 0.1, 0),
     ("commit", "b", "is_p", "new", 0, 0.3, 0.1, 0), ("compact", -3), ("read", "a", "is_p")],
])
@pytest.mark.parametrize("remember", [1, 100])
@pytest.mark.parametrize("vector_fold_min", [1, 10**9])
def test_journalled_store_matches_reference_on_known_cases(ops: list[tuple[Any, ...]], remember: int,
                                                           vector_fold_min: int) -> None:
    check_store_matches_reference(_journalled(vector_fold_min), _timed(ops), remember_compacted=remember)


def test_the_check_finds_a_store_that_differs() -> None:
    """check_store_matches_reference fails on a store that rounds a compaction differently."""
    class Sloppy(ProvenanceStore):
        def compact(self, before_t: int) -> int:
            n = super().compact(before_t)
            for log in self.logs().values():
                if log.entries and log.entries[0].status is EntryStatus.COMPACTED:
                    log.entries[0].d_alpha += 1e-12
            return n

    ops = [("commit", "a", "is_p", "e1", 0, 0.1, 0.2, 1), ("commit", "a", "is_p", "e2", 0, 0.2, 0.2, 1), ("compact", 5)]
    check_store_matches_reference(JournalledProvenanceStore, ops)
    with pytest.raises(AssertionError, match="differ at the end"):
        check_store_matches_reference(Sloppy, ops)


def test_streaming_compaction_builds_no_entry_objects() -> None:
    """A committed-only stream: compaction folds journal records straight into buckets."""
    prov = JournalledProvenanceStore()
    for t in range(100):
        for node in _NODES:
            prov.commit(node, "is_p", f"e{t}", t, 0.5, 0.25, 1)
        if t % 10 == 0:
            prov.compact(t - 10)
    assert not prov.timeline_view()  # nothing was materialised
    assert prov.n_compacted == 3 * 80
    assert prov.journal_length == 3 * 20
    for node in _NODES:
        assert prov.alpha_beta(node, "is_p") == pytest.approx((1.0 + 50.0, 1.0 + 25.0))
        assert prov.reconstruct(node, "is_p") == pytest.approx(prov.alpha_beta(node, "is_p"))
    assert prov.journal_length == 0  # reconstruct materialised it
    assert prov.is_compacted("e79") and not prov.is_compacted("e80")


_queue_op = st.one_of(
    st.tuples(st.just("pending"), st.sampled_from(_NODES), st.integers(0, 3),
              st.sampled_from([EntryStatus.REFUSED, EntryStatus.QUARANTINED])),
    st.tuples(st.just("close"), st.integers(0, 5), st.sampled_from([EntryStatus.COMMITTED, EntryStatus.RESOLVED])),
    st.tuples(st.just("retract"), st.integers(0, 5)),
    st.tuples(st.just("expire"), st.integers(0, 6)),
)


@settings(max_examples=150, deadline=None)
@given(ops=st.lists(_queue_op, max_size=30), t_cor=st.integers(0, 4), t_disagree=st.integers(0, 4),
       store_cls=st.sampled_from([ProvenanceStore, JournalledProvenanceStore]))
def test_nothing_expires_is_exact(ops: list[tuple[Any, ...]], t_cor: int, t_disagree: int,
                                  store_cls: type[ProvenanceStore]) -> None:
    """When the per-tick shortcut says nothing expires, expire() returns nothing and leaves both
    queues (lazily deleted entries included) as they were."""
    from sgbelief.fusion import queues

    prov = store_cls()
    now = 0
    for i, op in enumerate(ops):
        if op[0] == "pending":
            now += op[2]
            prov.record(op[1], "is_p", f"e{i}", now, 0.5, 0.25, op[3])
        elif op[0] in ("close", "retract"):
            waiting = [e for e in list(prov.quarantine) + list(prov.disagreement) if e.alive and e.pending]
            if waiting:
                entry = waiting[op[1] % len(waiting)]
                if op[0] == "close":
                    prov.transition(entry, op[2])
                else:
                    prov.retract(entry.event_id)
        else:
            t = now + op[1]
            before = (list(prov.quarantine), list(prov.disagreement))
            if queues.nothing_expires(prov, t, t_cor=t_cor, t_disagree=t_disagree):
                assert queues.expire(prov, t, t_cor=t_cor, k=2.0, t_disagree=t_disagree) == []
                assert (list(prov.quarantine), list(prov.disagreement)) == before
            else:
                queues.expire(prov, t, t_cor=t_cor, k=2.0, t_disagree=t_disagree)


@pytest.mark.parametrize("vector_fold_min", [1, 10**9])
def test_long_stream_with_a_reused_id_matches_reference(vector_fold_min: int) -> None:
    """Thousands of journaled ids (the id memory is pruned) and an old id reused late, folded
    in numpy or record by record."""
    ops: list[tuple[Any, ...]] = []
    for i in range(3000):
        ops.append(("commit", _NODES[i % 3], _PREDS[i % 2], "new", 1 if i % 2 else 0, 0.25, 0.5, 1))
        if i % 97 == 0:
            ops.append(("compact", 40))
        if i == 2500:
            ops.append(("commit", "a", "is_p", "e3", 0, 0.5, 0.5, 0))  # e3 was folded long ago
    ops.append(("compact", 5))
    check_store_matches_reference(_journalled(vector_fold_min), _timed(ops))


def _journal_state(prov: JournalledProvenanceStore) -> Any:
    return (list(prov._journal), [(k, log.alpha, log.beta, [e.as_tuple() for e in log.entries])
                                  for k, log in prov.pair_index().items()], prov.n_compacted, prov.compacted_ids())


def test_numpy_fold_leaves_a_log_with_more_than_its_bucket_to_the_loop() -> None:
    """A refused entry older than the horizon stays in its log: the numpy fold declines the pass
    without changing anything, and the loop's result is the reference store's."""
    ops = [("record", "a", "is_p", "x", 1, 0.5, 0.5, EntryStatus.REFUSED), ("compact", -2)]
    ops += [("commit", "a", "is_p", "new", 1, 0.25, 0.5, 1), ("commit", "b", "is_p", "new", 0, 0.5, 0.5, 1)] * 3
    prov = _journalled(1)((1.0, 1.0), remember_compacted=3)
    apply_store_operations(prov, _timed(ops))
    assert not prov.timeline_view() and prov.journal_length == 6 and len(prov.pair_index()[("a", "is_p")].entries) == 1
    before = _journal_state(prov)
    assert fold_journal_records(prov._objects, list(prov._journal)) is None  # the object log, unmaterialised
    assert _journal_state(prov) == before
    check_store_matches_reference(_journalled(1), _timed(ops + [("compact", -5)]), remember_compacted=3)


@pytest.mark.parametrize("store", [ProvenanceStore, _journalled(1), _journalled(10**9)])
def test_fold_errors_and_huge_times_as_the_loop(store: Any) -> None:
    """Increments whose sum overflows raise fsum's OverflowError on every path; times beyond 64
    bits fold through the loop."""
    prov = store((1.0, 1.0), remember_compacted=10)
    for t in range(3):
        prov.commit("a", "is_p", f"e{t}", t, 1e308, 1.0)
    with pytest.raises(OverflowError):
        prov.compact(10)
    big = store((1.0, 1.0), remember_compacted=10)
    for t in range(3):
        big.commit("a", "is_p", f"e{t}", 2**70 + t, 0.5, 0.25)
        big.commit("b", "is_p", f"f{t}", 2**70 + t, 0.5, 0.25)
    assert big.compact(2**71) == 6
    assert [e.as_tuple() for e in big.entries("a", "is_p")] == [(None, 2**70 + 2, 1.5, 0.75, "compacted")]


_journal_ids = st.lists(st.sampled_from(["e0", "e1", "e2", "e3", "e4", None]), max_size=40)


@given(_journal_ids, st.data())
def test_retired_ids_by_last_record_equal_the_count_down(ids: list[str | None], data: st.DataObject) -> None:
    """A compaction pass retires a journaled id at its last folded record. The pass over journal
    records only finds the order from each id's last position; the general pass counts each id's
    records down pair by pair. Both give the same ids in the same order."""
    raws: list[Any] = [(("v", "is_car"), eid, 0, 1.0, 0.0, 1, None) for eid in ids]
    cuts = sorted(data.draw(st.lists(st.integers(0, len(raws)), max_size=6)))
    bounds = [0, *cuts, len(raws)]
    groups = [raws[a:b] for a, b in zip(bounds, bounds[1:]) if b > a]
    fast = retired_ids([], [(0, g) for g in groups], raws, True)
    assert len(set(fast)) == len(fast) and None not in fast
    assert set(fast) == {i for i in ids if i is not None}
    # the same pass where a first pair's materialised entries retired an id outside the journal,
    # and a last pair with no journal record retired another: the general count-down
    general = retired_ids(["x", "z"], [(1, g) for g in groups], raws, True)
    assert general == ["x", *fast, "z"]
    # an id whose records are not all folded (a pair the pass skipped) is not retired
    if groups:
        kept = groups[:-1]
        partial = retired_ids(["x"], [(1, g) for g in kept], raws, False)
        seen = [r[1] for g in kept for r in g]
        assert partial == ["x", *[i for i in fast if i in seen and seen.count(i) == ids.count(i)]]
