"""Retraction (R of paper §4.3) as a free function over an :class:`~sgbelief.graph.entry_log.EntryLog`.

Retracting an event removes its entries exactly: each touched pair's belief is recomputed from
what is left of its log (Eq. 4), so it is the belief the log would define had the event never
arrived. A revision committed via corroboration depends on the corroborating events
(``entry.corroborated_by``, written by ``transition(..., corroborated_by=)``); retracting it
retracts them too, transitively, within the cascade window T_cor when one is given.
"""

from __future__ import annotations

from sgbelief.errors import RetractionError
from sgbelief.graph.entry_log import EntryLog


def retraction_closure(log: EntryLog, event_id: str, cascade_window: int | None = None) -> list[str]:
    """The event and, transitively, the corroborating events its revision commits depend on, in
    the order they are retracted. RetractionError when ``event_id`` has no live entry (a
    precise one when it was compacted and is still remembered)."""
    order: list[str] = []
    stack = [event_id]
    seen: set[str] = set()
    while stack:
        eid = stack.pop()
        if eid in seen:
            continue
        seen.add(eid)
        found = log.event_entries(eid)
        if not found:
            if log.is_compacted(eid):  # a linear scan, on this error path only
                raise RetractionError(
                    f"event {eid!r} was folded into a compacted increment (older than the provenance "
                    "horizon T_prov) and can no longer be retracted"
                )
            if eid == event_id:
                raise RetractionError(
                    f"unknown event id {eid!r} (never recorded, already retracted, or compacted "
                    "beyond the remembered horizon)"
                )
            continue  # a dependent that was already retracted on its own
        order.append(eid)
        for entry in found:
            for dep in entry.corroborated_by or ():
                dep_entries = log.event_entries(dep)
                if cascade_window is not None and dep_entries:
                    if all(d.t - entry.t > cascade_window for d in dep_entries):
                        continue
                stack.append(dep)
    return order


def retract(log: EntryLog, event_id: str, *, cascade_window: int | None = None) -> list[str]:
    """Remove an event's increments exactly and return the retracted event ids.

    For a revision committed via corroboration, the corroborating events it depends on are
    retracted too (cascade bounded by ``cascade_window`` = T_cor when given). The whole cascade
    is found before anything changes, so a failed retraction leaves the store untouched."""
    ids = retraction_closure(log, event_id, cascade_window)
    log.remove([entry for eid in ids for entry in log.event_entries(eid)])
    return ids


__all__ = ["retract", "retraction_closure"]
