"""Colours and markers shared by the matplotlib figures and the rerun recording.

A predicate keeps its colour across maps: colours follow the sorted vocabulary (or the sorted
predicates a map holds), so the ``comod`` and ``cal`` pictures of one log can be compared side by
side. The shade of an object encodes its probability: :func:`shade_alpha` maps P in (tau, 1] to an
opacity, the same in both back ends.
"""

from __future__ import annotations

from collections.abc import Iterable

#: qualitative colours for committed labels: matplotlib's tab20 strong shades first, without its
#: reds (red marks refused claims) and greys (grey means uncommitted)
LABEL_COLOURS: tuple[str, ...] = (
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#bcbd22", "#17becf",
    "#aec7e8", "#ffbb78", "#98df8a", "#c5b0d5", "#c49c94", "#f7b6d2", "#dbdb8d", "#9edae5",
)
#: objects whose predicates all stay at or below tau
UNCOMMITTED_COLOUR = "#9a9a9a"
#: objects that no claim has touched
NO_EVIDENCE_COLOUR = "#d0d0d0"
#: sites of refused claims (as the paper's KITTI-360 figure marks them)
REFUSED_COLOUR = "#e8001c"
#: the ego trajectory
EGO_COLOUR = "#1f4fd8"

#: what happened to an event at its pair, as the provenance names it -> marker colour
STATUS_COLOURS: dict[str, str] = {
    "committed": "#2a9d3f",
    "confirmed": "#2a9d3f",
    "released": "#7b3fa0",
    "quarantined": "#f0a020",
    "discarded": "#b07020",
    "refused": REFUSED_COLOUR,
    "expired": REFUSED_COLOUR,
    "resolved": "#ff7f7f",
    "dismissed": "#ff7f7f",
    "compacted": "#333333",
    "withdrawn": "#c05050",
}
#: what each status means, for legends
STATUS_MEANINGS: dict[str, str] = {
    "committed": "committed",
    "confirmed": "confirmed by the operator",
    "released": "released from quarantine (weight w/k)",
    "quarantined": "quarantined: revision pending",
    "discarded": "discarded from quarantine",
    "refused": "refused, pending in Q⊥",
    "expired": "refused, expired unresolved",
    "resolved": "refused, later resolved by a ⊤",
    "dismissed": "refused, dismissed",
    "compacted": "compacted",
    "withdrawn": "withdrawn: the element's labels, later, all contradicted it",
}
#: the refusal family: a ⊥ claim, whether still pending (refused) or closed since
REFUSED_STATUSES: frozenset[str] = frozenset({"refused", "resolved", "expired", "dismissed"})
#: verdict symbol -> matplotlib marker
VERDICT_MARKERS: dict[str, str] = {"⊤": "^", "⊥": "X", "∅": "o", "?": "o", "exclusion": "v"}


def label_colours(predicates: Iterable[str]) -> dict[str, str]:
    """Predicate -> colour, in sorted order (cycling when there are more predicates than colours)."""
    return {p: LABEL_COLOURS[i % len(LABEL_COLOURS)] for i, p in enumerate(sorted(set(predicates)))}


def display_name(predicate: str) -> str:
    """``is_traffic_sign`` -> ``traffic sign``: how a predicate reads in a legend or a box label."""
    return predicate.removeprefix("is_").replace("_", " ")


def format_probability(p: float, tau: float = 0.5) -> str:
    """P with two decimals, three when two would round onto tau (0.503 must not read as 0.50)."""
    text = f"{p:.2f}"
    return f"{p:.3f}" if float(text) == tau and p != tau else text


def shade_alpha(probability: float, tau: float) -> float:
    """Fill opacity of a committed object: 0.3 just above tau, 1.0 at P = 1 (linear in between)."""
    if tau >= 1.0:
        return 1.0
    share = (probability - tau) / (1.0 - tau)
    return 0.3 + 0.7 * min(1.0, max(0.0, share))


def hex_to_rgb(colour: str) -> tuple[int, int, int]:
    """``#rrggbb`` -> (r, g, b) in 0..255 (rerun's colour components)."""
    c = colour.lstrip("#")
    return int(c[0:2], 16), int(c[2:4], 16), int(c[4:6], 16)
