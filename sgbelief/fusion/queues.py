"""Queue policy of the revision quarantine Q and the disagreement queue Q⊥ (§4.2-§4.3).

Both queues are the pending entries of the graph's provenance store (status ``quarantined`` /
``refused``), so they are saved, loaded and migrated with the graph; this module decides how
entries leave them:

- Q (revisions, KL(B || B') > tau_rev): a later event at the same (v, phi) within T_cor whose
  stance agrees commits the entry at full weight (recording the corroborating event, so a later
  retraction cascades to it: ``transition(..., corroborated_by=)``); one whose stance disagrees discards it; after T_cor steps it is
  released at reduced weight w/k; an explicit confirmation commits it.
- Q⊥ (refused ⊥ claims): a later T verdict at the same (v, phi) within T_disagree marks it
  resolved, *not* committed; after T_disagree it expires unresolved; an explicit confirmation
  either commits it (human override) or dismisses it.

A committed entry leaves the belief in one more way (``recalled_verdicts: retroactive``,
docs/method.md §8): a claim committed while the channel had not adjudicated its element is
withdrawn while every decisive label the element has received contradicts it
(:func:`withdraw_unadjudicated`), and reinstated when a later label asserts it
(:func:`reinstate_withdrawn`).
"""

from __future__ import annotations

from collections import deque
from typing import Any

from sgbelief.errors import QueueError
from sgbelief.fusion.protocol import QueueResolution
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance_log import EntryStatus, EntryVerdict, ProvenanceEntry

_QUARANTINED = EntryStatus.QUARANTINED
_REFUSED = EntryStatus.REFUSED
_WITHDRAWN = EntryStatus.WITHDRAWN
_COMMITTED = EntryStatus.COMMITTED


def quarantine_feedback(
    store: EntryLog, node: Any, predicate: str, stance: int, event_id: str, t: int
) -> list[QueueResolution]:
    """Let a new event at (v, phi) corroborate or disconfirm the revisions pending there."""
    pending = store.pending(node, predicate)
    if not pending or stance == 0:
        return []
    out: list[QueueResolution] = []
    for entry in pending:
        if entry.status is not EntryStatus.QUARANTINED or entry.event_id == event_id:
            continue
        if entry.stance == stance:
            store.transition(entry, EntryStatus.COMMITTED, corroborated_by=event_id)
            out.append(QueueResolution(entry.event_id, node, predicate, "corroborated", t))
        elif entry.stance == -stance:
            store.transition(entry, EntryStatus.DISCARDED)
            out.append(QueueResolution(entry.event_id, node, predicate, "discarded", t))
    return out


def resolve_disagreements(store: EntryLog, node: Any, predicate: str, t: int) -> list[QueueResolution]:
    """A T verdict at (v, phi): pending ⊥ entries there are resolved (never committed)."""
    out: list[QueueResolution] = []
    for entry in store.pending(node, predicate):
        if entry.status is EntryStatus.REFUSED:
            store.transition(entry, EntryStatus.RESOLVED)
            out.append(QueueResolution(entry.event_id, node, predicate, "resolved", t))
    return out


def withdraw_unadjudicated(store: EntryLog, node: Any, predicate: str, t: int) -> list[QueueResolution]:
    """Every decisive label of v so far denies phi: the claims for phi at v that were committed
    while the channel said nothing decisive there (status ``committed``, verdict ∅, stance +1)
    stop counting (status ``withdrawn``), and so does the evidence each wrote against its rival
    classes at v (``exclusive_evidence: rivals``, same event). A human's confirmation, a claim
    released from quarantine at w/k and a compacted bucket are never withdrawn.

    Eq. 4 holds as for any status change: the belief is the prior plus the entries still counted.
    """
    return _move_unadjudicated(store, node, predicate, t, _COMMITTED, _WITHDRAWN, "withdrawn")


def reinstate_withdrawn(store: EntryLog, node: Any, predicate: str, t: int) -> list[QueueResolution]:
    """A label of v now asserts phi, so its labels no longer deny it unanimously: the claims
    :func:`withdraw_unadjudicated` withdrew at (v, phi) count again (status ``committed``), with
    their evidence against rival classes; exactly the map the withdrawal interrupted."""
    return _move_unadjudicated(store, node, predicate, t, _WITHDRAWN, _COMMITTED, "reinstated")


def _move_unadjudicated(store: EntryLog, node: Any, predicate: str, t: int, old: EntryStatus, new: EntryStatus,
                        kind: str) -> list[QueueResolution]:
    """(v, phi)'s unadjudicated asserting claims in status ``old`` move to ``new``, with the
    exclusion entries their events wrote at v."""
    out: list[QueueResolution] = []
    for entry in store.entries(node, predicate):
        if entry.status is not old or entry.stance != 1 or entry.verdict is not EntryVerdict.NO_CLAIM:
            continue
        store.transition(entry, new)
        out.append(QueueResolution(entry.event_id, node, predicate, kind, t))
        for other in store.event_entries(entry.event_id):
            if other.node == node and other.verdict is EntryVerdict.EXCLUSION and other.status is old:
                store.transition(other, new)
    return out


def _expire(
    queue: deque[ProvenanceEntry], status: EntryStatus, window: int, t: int, new: EntryStatus, scale: float,
    store: EntryLog, kind: str,
) -> list[QueueResolution]:
    out: list[QueueResolution] = []
    while queue:
        entry = queue[0]
        if not entry.alive or entry.status is not status:
            queue.popleft()  # already resolved: lazy deletion
            continue
        if t - entry.t <= window:
            break
        queue.popleft()
        store.transition(entry, new, scale=scale)
        out.append(QueueResolution(entry.event_id, entry.node, entry.predicate, kind, t))
    return out


def nothing_expires(store: EntryLog, t: int, *, t_cor: int, t_disagree: int) -> bool:
    """True when ``expire`` at time t would change nothing: each queue is empty or its head is
    live, still pending and within its window (checked per tick, so it must be cheap)."""
    q = store.quarantine
    if q:
        head = q[0]
        if not head.alive or head.status is not _QUARANTINED or t - head.t > t_cor:
            return False
    d = store.disagreement
    if d:
        head = d[0]
        if not head.alive or head.status is not _REFUSED or t - head.t > t_disagree:
            return False
    return True


def expire(store: EntryLog, t: int, *, t_cor: int, k: float, t_disagree: int) -> list[QueueResolution]:
    """Timeouts at time t: revisions older than T_cor are released at w/k, ⊥ entries older than
    T_disagree expire unresolved. Amortised O(1): both queues are in arrival (time) order."""
    out = _expire(store.quarantine, EntryStatus.QUARANTINED, t_cor, t, EntryStatus.RELEASED, 1.0 / k, store, "released")
    out += _expire(store.disagreement, EntryStatus.REFUSED, t_disagree, t, EntryStatus.EXPIRED, 1.0, store, "expired")
    return out


def confirm(store: EntryLog, event_id: str, *, accept: bool = True, t: int = 0) -> list[QueueResolution]:
    """Explicit operator decision on a queued event.

    A quarantined revision is committed at full weight (``accept``) or discarded. A refused ⊥
    claim is committed as a human override (``accept``; status ``confirmed``) or dismissed.
    """
    entries = [e for e in store.event_entries(event_id) if e.status in (EntryStatus.QUARANTINED, EntryStatus.REFUSED)]
    if not entries:
        raise QueueError(f"event {event_id!r} has no entry waiting in a queue")
    out: list[QueueResolution] = []
    for entry in entries:
        if entry.status is EntryStatus.QUARANTINED:
            new = EntryStatus.CONFIRMED if accept else EntryStatus.DISCARDED
        else:
            new = EntryStatus.CONFIRMED if accept else EntryStatus.DISMISSED
        store.transition(entry, new)
        out.append(QueueResolution(event_id, entry.node, entry.predicate, "confirmed" if accept else new.value, t))
    return out
