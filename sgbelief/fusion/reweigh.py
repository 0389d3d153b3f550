"""Silent claims weighed under the current consensus calibration (docs/method.md §8).

A claim the geometric channel cannot adjudicate is weighed by the consensus calibration of its
cell (Eq. 2, then Eq. 3's increments). That calibration is refitted as the map grows, O(log n)
times over a stream (:class:`~sgbelief.fusion.consensus.MapConsensus`). Weighed once, at arrival,
a claim keeps the calibration of that moment: the map's first claims are weighed before any refit
(on §4.1's calibrator, which has no outcome for them), and a lone claim early in the stream is
weighed by a fit that cannot yet tell a first sighting of a real object from a stray detection on
clutter: the stray never gets a second claim, and only later fits learn what that means.

``calibration.consensus.silent_weights: current`` (the default) weighs every committed silent
claim with the calibration of now. After each refit, for each claim of the consensus table that
the channel did not adjudicate and whose entry is still committed in the log::

    (Lambda_hat, kappa_hat) = the current calibration of the claim's cell at its confidence  (Eq. 2)
    (d_alpha, d_beta)       = Eq. 3 with weight w0 kappa_hat T(v)
    at each exclusive rival pair holding an entry of the claim's event: (0, d_alpha)  (exclusion_increments)

and the beliefs of the pairs touched are recomputed from their logs (Eq. 4). What stays as it was:

* claims older than the provenance horizon T_prov (``t_prov``; arrival t' < t - T_prov at the
  refit's time t): they are settled, as compaction treats them (a pass at time t folds exactly the
  settled entries with t' < t - T_prov into one bucket per pair, which holds only sums). A claim's
  weight thus follows the refits for T_prov steps after it arrives, whether or when compaction
  passes run (``t_compact``): a map does not depend on its compaction schedule;
* pending entries (quarantined revisions, refused claims) and whatever a queue resolution did to
  them (a release at w/k), and the decisions taken when the claim arrived (its quarantine test,
  refusals, the rival pairs it reached): only the committed increments follow the calibration;
* claims the channel adjudicated (§4.1's calibrator, Property 1 unchanged).

The work is one pass over the table per refit, O(n) at O(log n) refits whose sizes grow
geometrically: O(1) amortised per claim (docs/performance.md).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sgbelief.fusion.consensus import MapConsensus
from sgbelief.fusion.rules import claim_increments, evidence_weight, exclusion_increments, stance_of
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import EntryStatus, EntryVerdict, ProvenanceEntry

__all__ = ["reweigh_silent_claims", "silent_claim_increments"]

_COMMITTED = EntryStatus.COMMITTED
_SILENT = EntryVerdict.NO_CLAIM
_EXCLUSION = EntryVerdict.EXCLUSION


def silent_claim_increments(lam: float, kappa: float, mass: float, w0: float) -> tuple[float, float, int]:
    """(d_alpha, d_beta, stance) of a silent claim under (Lambda_hat, kappa_hat): Eq. 3 with weight
    w0 kappa_hat T(v), its stance the sign of log Lambda_hat."""
    d_alpha, d_beta = claim_increments(lam, evidence_weight(w0, kappa, mass))
    return d_alpha, d_beta, stance_of(lam)


def reweigh_silent_claims(prov: EntryLog, consensus: MapConsensus, w0: float, settled_before: float
                          ) -> list[tuple[str, Any, str]]:
    """Weigh every committed silent claim of ``consensus``'s table that arrived at or after
    ``settled_before`` (t - T_prov) with its current calibration (module docstring); returns
    (event id, node, predicate) of each entry that changed.

    A claim's entry is the committed, silent (∅) entry of its event at (element, predicate). An
    event whose claims at one element cannot be told apart (two targets merged into one element
    since) keeps its entries as they are."""
    changes: list[tuple[ProvenanceEntry, float, float, int]] = []
    rows_of: dict[tuple[str, Any], list[tuple[str, int]]] = {}
    for event_id, node, predicate, row in consensus.silent_claims(settled_before):
        rows_of.setdefault((event_id, node), []).append((predicate, row))
    entries_of = prov.event_entries
    found: list[tuple[ProvenanceEntry, list[ProvenanceEntry], int]] = []
    for (event_id, node), rows in rows_of.items():
        entries = [e for e in entries_of(event_id) if e.node == node and e.status is _COMMITTED]
        if not entries:
            continue  # retracted, folded by compaction, pending, or its node left the map
        claims = [e for e in entries if e.verdict is _SILENT]
        if len(rows) != 1 or len(claims) != 1 or claims[0].predicate != rows[0][0]:
            continue
        found.append((claims[0], entries, rows[0][1]))
    if not found:
        return []
    lams, kappas = consensus.rows_likelihood_ratios([row for _, _, row in found])
    for (claim, entries, row), lam, kappa in zip(found, lams.tolist(), kappas.tolist()):
        d_alpha, d_beta, stance = silent_claim_increments(lam, kappa, consensus.row_mass(row), w0)
        if d_alpha == claim.d_alpha and d_beta == claim.d_beta:
            continue
        changes.append((claim, d_alpha, d_beta, stance))
        ea, eb = exclusion_increments(d_alpha)
        changes.extend((e, ea, eb, e.stance) for e in _exclusions(entries))
    if changes:
        prov.reweigh(changes)
    return [(e.event_id, e.node, e.predicate) for e, _, _, _ in changes]  # type: ignore[misc]


def _exclusions(entries: Iterable[ProvenanceEntry]) -> list[ProvenanceEntry]:
    """The committed exclusion entries (a claim's evidence against its rivals) among ``entries``."""
    return [e for e in entries if e.verdict is _EXCLUSION]
