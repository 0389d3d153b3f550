"""The EntryLog protocol: two implementations, each complete on its own, and the policies as free
functions over either (the same results as the store methods that call them)."""

from __future__ import annotations

import pytest

from sgbelief._fast.journal import JournalledProvenanceStore
from sgbelief.errors import RetractionError
from sgbelief.graph.compaction import compact
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.migration import move_node, remove_node
from sgbelief.graph.provenance import EntryStatus, ProvenanceStore
from sgbelief.graph.provenance_json import store_from_dict, store_to_dict
from sgbelief.graph.provenance_log import EntryRecord
from sgbelief.graph.retraction import retract, retraction_closure
from sgbelief.graph.store_methods import StoreMethods
from sgbelief.testing import store_state

STORES = [ProvenanceStore, JournalledProvenanceStore]
#: the operations of the protocol (methods and properties; the data attributes are set per instance)
OPERATIONS = sorted(name for name in vars(EntryLog) if not name.startswith("_"))


def test_both_stores_implement_every_operation_themselves() -> None:
    """Each store defines every protocol operation in its own class body: neither inherits one
    (the shared mixin holds only conveniences over them), and the journalled store is no
    subclass of the reference store."""
    assert not issubclass(JournalledProvenanceStore, ProvenanceStore)
    assert set(OPERATIONS) >= {"append", "commit", "transition", "remove", "drop_pair", "merge_pair", "fold",
                               "alpha_beta", "logs", "event_entries", "pending"}
    for cls in STORES:
        assert isinstance(cls(), EntryLog)
        missing = [name for name in OPERATIONS if name not in vars(cls)]
        assert missing == [], f"{cls.__name__} inherits {missing}"
    assert not set(OPERATIONS) & set(vars(StoreMethods))


def _filled(cls: type) -> EntryLog:
    s = cls()
    s.commit("a", "is_p", "e1", 1, 0.5, 0.25, 1)
    s.append(EntryRecord(node="a", predicate="is_p", event_id="e2", t=2, d_alpha=0.5, d_beta=0.5,
                         status=EntryStatus.QUARANTINED, stance=1))
    s.commit("b", "is_p", "e3", 3, 0.25, 0.5, -1)
    s.commit("b", "is_q", "e4", 4, 1.0, 0.0, 1)
    q = s.pending("a", "is_p")[0]
    s.transition(q, EntryStatus.COMMITTED, corroborated_by="e3")
    s.commit("a", "is_p", "e5", 9, 0.125, 0.5, -1)
    return s


@pytest.mark.parametrize("cls", STORES)
def test_free_functions_are_the_methods(cls: type) -> None:
    """retract / compact / move_node / remove_node / to_dict: the free function on one copy, the
    method on another, the same store after each."""
    for fn, method, args in [
        (retract, "retract", ("e2",)),
        (compact, "compact", (5,)),
        (move_node, "move_node", ("a", "b")),
        (remove_node, "remove_node", ("b",)),
    ]:
        a, b = _filled(cls), _filled(cls)
        assert fn(a, *args) == getattr(b, method)(*args)
        assert store_state(a) == store_state(b)
    s = _filled(cls)
    assert store_to_dict(s) == s.to_dict()
    assert store_state(store_from_dict(s.to_dict(), cls.from_logs)) == store_state(cls.from_dict(s.to_dict()))


@pytest.mark.parametrize("cls", STORES)
def test_retraction_cascades_through_the_corroboration(cls: type) -> None:
    s = _filled(cls)
    assert retraction_closure(s, "e2") == ["e2", "e3"]
    assert retract(s, "e2") == ["e2", "e3"]
    assert s.alpha_beta("a", "is_p") == (1.0 + 0.5 + 0.125, 1.0 + 0.25 + 0.5)
    assert not s.has_event("e3") and ("b", "is_p") not in s
    compact(s, 10)
    with pytest.raises(RetractionError, match="compacted"):
        retract(s, "e1")


@pytest.mark.parametrize("cls", STORES)
def test_migration_merges_buckets_into_one(cls: type) -> None:
    s = _filled(cls)
    compact(s, 10)  # a bucket on each of a/is_p, b/is_p, b/is_q
    before = (s.count_entries(), s.alpha_beta("a", "is_p"), s.alpha_beta("b", "is_p"))
    move_node(s, "a", "b")
    assert s.count_entries() == before[0]
    entries = s.entries("b", "is_p")
    assert [e.status for e in entries] == [EntryStatus.COMPACTED]
    assert s.alpha_beta("b", "is_p") == pytest.approx((before[1][0] + before[2][0] - 1.0,
                                                       before[1][1] + before[2][1] - 1.0))
    assert remove_node(s, "b") == before[0] and len(s) == 0
