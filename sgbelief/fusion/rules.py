"""The steps of Algorithm 1 as small pure functions, each stating its equation.

The operators (:mod:`sgbelief.fusion.operators`) are these steps in the order of Algorithm 1; the
derivations behind the defaults are in ``docs/method.md``. Nothing here holds state.

==========================  ==========================================================
step                        function
==========================  ==========================================================
sign of the claim           :func:`claim_asserts`
verdict (compat)            :func:`verdict`
support stratum             :func:`support_stratum`
adjudication status         :func:`adjudication`
standing among classes      :func:`standing`
targeting of a claim        :func:`targeting`
consensus cell              :func:`consensus_cell`
calibrated LR (Eq. 2)       :func:`calibrated_log_lr` (of :mod:`sgbelief.calibration.isotonic`)
weight w = w0 kappa T(v)    :func:`evidence_weight`
increments (Eq. 3)          :func:`claim_increments`
Eq. 3 inverted (Λ̂, w)      :func:`claim_lambda_hat`, :func:`claim_weight`
geometric observation       :func:`verification_increments`
a rival class's claim       :func:`exclusion_increments`
one class among rivals      :func:`exclusive_marginal`
label's own predicates      :func:`label_observations`
revision test (KL > tau)    :func:`revision_kl_exceeds` (bound: :func:`kl_upper_bound`)
==========================  ==========================================================
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from scipy import special as _sp

from sgbelief.calibration.isotonic import calibrated_log_lr  # Eq. 2 lives with the calibrator; re-exported
from sgbelief.fusion.compatibility import Verdict
# Eq. 3 inverted: defined with the provenance log, which reads its entries' Lambda-hat back (the
# model layer cannot import this one); exported here, next to the equation they invert
from sgbelief.graph.provenance_log import EntryVerdict, claim_lambda_hat, claim_weight

__all__ = [
    "claim_asserts",
    "verdict",
    "support_stratum",
    "stratified_context",
    "adjudication",
    "standing",
    "targeting",
    "consensus_cell",
    "calibrated_log_lr",
    "evidence_weight",
    "claim_increments",
    "claim_lambda_hat",
    "claim_weight",
    "verification_increments",
    "exclusion_increments",
    "exclusive_marginal",
    "label_observations",
    "kl_upper_bound",
    "revision_kl_exceeds",
    "stance_of",
    "ENTRY_VERDICT",
]

_betaln = _sp.betaln
_digamma = _sp.digamma
_lgamma = math.lgamma
_log = math.log


def claim_asserts(confidence: float, lam: float | None = None) -> bool:
    """Whether a claim asserts phi (True) or denies it (False): the sign rule of Alg. 1 line 5.

    The paper reads the sign off the raw confidence, c >= 0.5 (``lam=None``; ``verdict_sign:
    raw``). A monotone distortion of c moves that crossing (an underconfident model says 0.4 of
    a true table), so the default reads it off the calibrated evidence instead: the claim asserts
    phi when Lambda_hat > 1 and denies it when Lambda_hat < 1 (raw sign at Lambda_hat = 1). That
    sign is invariant under any strictly increasing transform of the confidences.
    """
    if lam is None or lam == 1.0:
        return confidence >= 0.5
    return lam > 1.0


def verdict(outcome: int | None, asserts: bool) -> Verdict:
    """compat(phi_f, phi_g) with the sign of the claim (:func:`claim_asserts`).

    ``outcome`` is what the geometric label at (v, t) says of phi: 1 (label in phi's positive
    set), 0 (negative set) or None (no verifiable assertion)::

        compat = ∅  if outcome is None
                 ⊤  if (outcome == 1) == asserts
                 ⊥  otherwise
    """
    if outcome is None:
        return Verdict.NO_CLAIM
    return Verdict.CORROBORATES if (outcome == 1) == asserts else Verdict.CONTRADICTS


#: the verdict code a provenance entry records for each verdict (a geometric observation records
#: ``EntryVerdict.GEOMETRIC``)
ENTRY_VERDICT: dict[Verdict, EntryVerdict] = {
    Verdict.CORROBORATES: EntryVerdict.CORROBORATES,
    Verdict.CONTRADICTS: EntryVerdict.CONTRADICTS,
    Verdict.NO_CLAIM: EntryVerdict.NO_CLAIM,
}


def recalled_outcome(outcomes: Mapping[str, int], label_counts: Mapping[str, int], min_labels: int = 1) -> int | None:
    """y recalled from the channel's earlier labels of an element (``recalled_verdicts: unanimous``, docs/method.md §8).

    With n_y the labels of v that the vocabulary maps to outcome y for phi (its ``outcomes`` table):

        y_rec = 1     if n_1 >= min_labels and n_0 = 0
        y_rec = 0     if n_0 >= min_labels and n_1 = 0
        y_rec = None  otherwise (never labelled decisively, or the channel changed its mind)

    Labels that decide nothing for phi (absent from ``outcomes``) are not counted.
    """
    n1 = n0 = 0
    for label, n in label_counts.items():
        y = outcomes.get(label)
        if y == 1:
            n1 += n
        elif y == 0:
            n0 += n
    if n1 and not n0:
        return 1 if n1 >= min_labels else None
    if n0 and not n1:
        return 0 if n0 >= min_labels else None
    return None


def labels_contested(outcomes: Mapping[str, int], label_counts: Mapping[str, int]) -> bool:
    """Whether the channel contradicted itself about an element for phi (``contested_labels``, docs/method.md §8).

        contested  iff  n_1 > 0 and n_0 > 0

    with n_y the element's labels (so far, the claim's own frame included) that the vocabulary maps
    to outcome y for phi (its ``outcomes`` table); labels that decide nothing are not counted. It is
    the complement, among elements with both kinds of label, of :func:`recalled_outcome`'s unanimity:
    where the channel has asserted phi of v in one frame and denied it in another, one of those
    labels is its own error, and no single frame's label is taken as the truth about v.
    """
    pos = neg = False
    for label in label_counts:
        y = outcomes.get(label)
        if y == 1:
            pos = True
        elif y == 0:
            neg = True
    return pos and neg


def consensus_agrees(asserts: bool, posterior: float | None) -> bool:
    """Whether the map-wide consensus sides with a claim (``contested_labels: consensus``, docs/method.md §8):

        agrees  iff  q_v(phi) >= 1/2  for a claim asserting phi,   q_v(phi) < 1/2  for one denying it

    with q_v(phi) the Dawid–Skene posterior of the last fit, which weighs the channel's labels of v
    and the claims on v by the reliabilities learned from the whole map. No posterior (no fit yet,
    or v not in it): False, the refusal stands.
    """
    if posterior is None:
        return False
    return posterior >= 0.5 if asserts else posterior < 0.5


def support_stratum(n_prior_claims: int, n_strata: int) -> int:
    """The Mondrian support stratum of a claim: min(n, S - 1) for n earlier claims at (v, phi).

    A pair's first claim and its tenth are not exchangeable: spurious detections (hallucinated
    boxes, a confusion on a partly occluded element) are rarely repeated, so a first claim is
    right far less often than a repeated one at the same confidence. Calibrating per stratum keeps
    the calibration (and the conformal guarantee, which needs exchangeability within a cell)
    valid for each kind of claim. ``n_strata = 1`` is the paper's taxonomy (no stratification).
    """
    return n_prior_claims if n_prior_claims < n_strata - 1 else n_strata - 1


def stratified_context(context: str, stratum: int, n_strata: int) -> str:
    """The calibration context key of a claim: ``context`` itself when there is one stratum, else
    ``"<context>|s<stratum>"`` (the Mondrian cell (context, stratum) for each predicate)."""
    return context if n_strata <= 1 else f"{context}|s{stratum}"


def adjudication(label: str | None, outcome: int | None) -> str:
    """Whether the geometric channel could judge a claim at (v, t): ``"decisive"`` (its label gives
    an outcome y for phi), ``"ambiguous"`` (it labels v, but the label is in neither of phi's sets:
    ``otherprop``, ``shelves`` for a bookshelf) or ``"unseen"`` (no label at (v, t), or no channel).

    Claims of the three kinds are not exchangeable: the elements a channel labels decisively are
    the well-observed ones, and claims on clutter nobody can judge are right less often. Each kind
    is therefore calibrated in a cell of its own (docs/method.md §8).
    """
    if outcome is not None:
        return "decisive"
    return "unseen" if label is None else "ambiguous"


def standing(n_same: int, n_others: int, max_other: int) -> str:
    """A claim's standing among the exclusive classes already claimed at its element.

    ``n_same``: earlier claims of phi at v; ``n_others``: earlier claims at v of predicates that
    exclude phi; ``max_other``: the most claims any one of them received. ``"alone"`` (no rival
    class claimed), ``"leading"`` (phi has at least as many claims as any rival) or ``"trailing"``.
    An element claimed once as toilet, twice as bed and once as tv is probably none of them: its
    claims fall in the leading and trailing cells, which are calibrated on what such elements turn
    out to be.
    """
    if n_others == 0:
        return "alone"
    return "leading" if n_same >= max_other else "trailing"


def targeting(mass: float) -> str:
    """How squarely a claim lands on v: ``"whole"`` when T(v) >= 1/2 (v is the likeliest referent),
    else ``"part"`` (the box mostly covers something else).

    Eq. 3 scales a claim by T(v) but keeps its direction: a claim whose box grazes v moves v's belief
    a little *toward* what it asserts. Whether such claims are right about v is a property of the
    targeting scheme, measured like any other: grazing claims are calibrated in cells of their own.
    """
    return "whole" if mass >= 0.5 else "part"


def consensus_cell(context: str, stratum: int, status: str, rank: str, aim: str = "whole") -> str:
    """The calibration cell of a claim the channel cannot adjudicate: (context, support stratum,
    adjudication status, standing, targeting), as ``"<context>|s<stratum>|<status>|<standing>|<aim>"``."""
    return f"{context}|s{stratum}|{status}|{rank}|{aim}"


def evidence_weight(w0: float, kappa: float, mass: float) -> float:
    """Per-target evidence weight: w T(v) with w = w0 kappa_hat (Eq. 3 and its shrinkage)."""
    return w0 * kappa * mass


def claim_increments(lam: float, weight: float) -> tuple[float, float]:
    """Eq. 3: (d_alpha, d_beta) = (w T(v) Lambda / (1 + Lambda), w T(v) / (1 + Lambda)).

    ``weight`` is w T(v) (:func:`evidence_weight`). Under a Beta(1, 1) belief and weight 1 this is
    the exact Bayesian update of y by one observation of likelihood ratio Lambda.

    The equation inverts: Lambda = d_alpha / d_beta (:func:`claim_lambda_hat`) and
    w T(v) = d_alpha + d_beta (:func:`claim_weight`), so a log entry need not store either.
    """
    return weight * lam / (1.0 + lam), weight / (1.0 + lam)


def verification_increments(outcome: int, weight: float) -> tuple[float, float]:
    """A decisive geometric label as an observation of y at (v, phi) (``geometric_evidence: verdict``).

    The calibration buffer takes the decisive geometric label as the outcome y of a claim (§4.1);
    the same label is evidence about the pair, one pseudo-count in its direction::

        (d_alpha, d_beta) = (w T(v), 0) if outcome == 1 else (0, w T(v))

    With ``calibration.consensus.label_weights: reliability`` the caller's weight also carries the
    label's reliability, r or 1 - r (:func:`sgbelief.fusion.consensus.label_reliability`).
    """
    return (weight, 0.0) if outcome == 1 else (0.0, weight)


def exclusion_increments(d_alpha: float) -> tuple[float, float]:
    """A claim of phi as evidence about a class psi that excludes phi (``exclusive_evidence: rivals``).

    The exclusive classes of an element (``SubsumptionTable.exclusive_with``) and "none of them"
    are the categories of one categorical variable; a Dirichlet belief over it has, for each class
    psi, the marginal Beta(alpha_psi, sum of the other categories' alphas): the per-predicate Beta.
    A claim of phi with Eq. 3 increments (d_alpha, d_beta) puts d_alpha on the category phi and
    d_beta on "not phi", spread over the others without saying which. Seen from psi, mass on phi is
    mass on "not psi"; mass on "not phi" says nothing of psi against the rest. So at (v, psi)::

        (d_alpha_psi, d_beta_psi) = (0, d_alpha)

    An element claimed once as toilet, twice as bed and once as tv then holds for is_bed its own two
    claims against the toilet's and the tv's: it stays below the commit threshold, where two
    independent per-predicate Betas would commit it. The entry is written at rival pairs the log
    already holds, under the claim's event id (retracting the claim retracts it), and only for a
    claim committed at its own pair (a refused or quarantined claim moves nothing, here either).
    """
    return 0.0, d_alpha


def exclusive_marginal(alpha: float, beta: float, rival_alphas: Iterable[float], prior_alpha: float) -> tuple[float, float]:
    """The belief in phi when its exclusive rivals' evidence counts against it, whatever the order.

    :func:`exclusion_increments` is the same coupling applied as claims arrive; here it is applied
    when one class among exclusive ones is read out, from the per-pair Betas alone: each rival
    psi's mass on itself, alpha_psi - alpha_0 (its claims' d_alpha and its positive observations),
    is mass on "not phi"::

        B_excl(v, phi) = Beta(alpha_phi, beta_phi + sum over rivals psi at v of (alpha_psi - alpha_0))

    Order-free (every rival claim counts, made before or after phi's first claim) and a function
    of Eq. 4's beliefs, so retraction and reconstruction hold without entries of its own. Comparing
    its means ranks the classes by their own evidence against everything said against them: an
    element claimed four times as stool and twice as chair is a stool, whatever the confidences of
    the two chair claims. Meant for operators that do not write the coupling themselves
    (``exclusive_evidence: none``); with ``rivals`` part of that mass is in beta_phi already.
    """
    return alpha, beta + sum(a - prior_alpha for a in rival_alphas)


def label_observations(asserted: tuple[str, ...], claimed: str, node: object, t: int,
                       seen: dict[tuple[object, str], int]) -> list[str]:
    """The predicates a geometric label observes at v besides the claimed one (``geometric_evidence: label``).

    The label at (v, t) is evidence about what v is, whatever the claim named: a sofa the detector
    keeps calling ``tv`` is observed as a sofa. Each predicate psi the label asserts (its positive
    set holds the label), other than the claimed phi (observed already by
    :func:`verification_increments`), gets one observation y = 1, (d_alpha, d_beta) = (w0 T(v), 0),
    at most once per (v, psi, t): several claims about v in one frame see one label, not several.
    ``seen`` maps (v, psi) to the time of its last label observation and is updated in place.
    """
    out = []
    for psi in asserted:
        if psi != claimed and seen.get((node, psi)) != t:
            seen[(node, psi)] = t
            out.append(psi)
    return out


def stance_of(lam: float) -> int:
    """+1 when the evidence supports phi (Lambda > 1), -1 when it denies it, 0 when neutral."""
    return 1 if lam > 1.0 else -1 if lam < 1.0 else 0


def _digamma_estimate(x: float) -> float:
    """psi(x) for x > 0 in pure Python (absolute error < 1e-10): recurrence up to x >= 6, then
    the asymptotic series."""
    r = 0.0
    while x < 6.0:
        r -= 1.0 / x
        x += 1.0
    f = 1.0 / (x * x)
    return r + _log(x) - 0.5 / x - f * (1 / 12 - f * (1 / 120 - f * (1 / 252 - f * (1 / 240 - f / 132))))


def kl_upper_bound(a: float, b: float, da: float, db: float) -> float:
    """An upper bound on KL(Beta(a, b) || Beta(a + da, b + db)) for da, db >= 0 (§4.3 revision test).

    The KL between members of an exponential family is the Bregman divergence of its log-partition
    A(a, b) = ln B(a, b), so with delta = (da, db) and the Hessian H of A,
    KL = int_0^1 (1 - s) delta^T H((a, b) + s delta) delta ds, and
    delta^T H delta = da^2 psi'(a) + db^2 psi'(b) - (da + db)^2 psi'(a + b) <= da^2 psi'(a) + db^2 psi'(b).
    psi' decreases, so along the path (arguments >= a, b) it is at most its value at (a, b), and
    psi'(x) = sum_k 1 / (x + k)^2 < 1 / x^2 + 1 / x. Hence
    KL <= (da^2 (1/a + 1/a^2) + db^2 (1/b + 1/b^2)) / 2.
    """
    ia = 1.0 / a
    ib = 1.0 / b
    return 0.5 * (da * da * ia * (1.0 + ia) + db * db * ib * (1.0 + ib))


def revision_kl_exceeds(a: float, b: float, da: float, db: float, tau_rev: float) -> bool:
    """The revision test of §4.3: KL(Beta(a, b) || Beta(a + da, b + db)) > tau_rev.

    KL = ln B(a', b') - ln B(a, b) - da psi(a) - db psi(b) + (da + db) psi(a + b).
    The bound of :func:`kl_upper_bound` settles most calls; otherwise the KL is estimated with
    ``math.lgamma`` and a pure-Python digamma, and recomputed with ``scipy.special`` only when the
    estimate lies within a safe margin of ``tau_rev``: the decision is always the exact formula's.
    """
    a2, b2 = a + da, b + db
    margin = 1e-8 * (1.0 + a2 + b2 + da + db)
    if da >= 0.0 and db >= 0.0 and kl_upper_bound(a, b, da, db) < tau_rev - 2.0 * margin:
        return False
    dig = (da + db) * _digamma_estimate(a + b) - da * _digamma_estimate(a) - db * _digamma_estimate(b)
    est = (_lgamma(a2) + _lgamma(b2) - _lgamma(a2 + b2)) - (_lgamma(a) + _lgamma(b) - _lgamma(a + b)) + dig
    if abs(est - tau_rev) > margin:
        return est > tau_rev
    exact = _betaln(a2, b2) - _betaln(a, b) - da * _digamma(a) - db * _digamma(b) + (da + db) * _digamma(a + b)
    return bool(exact > tau_rev)
