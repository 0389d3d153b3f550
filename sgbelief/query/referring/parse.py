"""Utterances -> :class:`ReferringQuery`: the templated spatial language of Sr3D, read tolerantly.

Grammar (after normalisation: lower case; ``%...%`` template placeholders, quotes and end
punctuation dropped; runs of spaces collapsed; commas kept)::

    utterance := [frame ","] [verb] [article] TARGET clause
    frame     := ("facing" | "looking at" | "looking") ["at"] "the front of" [article] ANCHOR
               | ("facing" | "looking at" | "looking") [article] ANCHOR "from the side you sit on" ["it" | "them"]
    verb      := find | choose | select | pick [out] | locate | identify | show [me] | point to | ...
    clause    := [copula] RELATION anchor_np
               | "with" [article] ANCHOR "on" ("top" ["of" ("it" | "them")] | ("its" | "their") "top")
    copula    := ("that" | "which" | "who") ("is" | "are") | "that's"
    anchor_np := [article | "this" | "these"] ANCHOR | "it" | "them"      (a pronoun: the frame's anchor)
               | ANCHOR "and" [article] ANCHOR                             (between)

``RELATION`` is one of the phrases of :data:`RELATION_PHRASES` (longest match first), e.g.
"closest to", "nearest", "next to", "far away from", "between", "in the middle of", "on top of",
"lying on", "supporting", "above", "under", "on the left of", "to its right", "in front of",
"behind". The "with the Y on top" clause means the target *supports* Y. A view-dependent relation
after a frame ("facing the front of the bed, the lamp on its left") takes the frame's anchor.

Without a copula the relation is found as the earliest relation phrase after the target's first
word ("the box on the table", "the lamp in the middle of the bed and the sofa"); with one, the
target is everything before the copula, so class names may contain relation words.
"""

from __future__ import annotations

import re

from sgbelief.query.referring.model import ReferringQuery, Relation, UtteranceError

__all__ = ["RELATION_PHRASES", "normalise_utterance", "parse_utterance"]

R = Relation
#: relation phrase -> relation (the parser tries the longest phrase first)
RELATION_PHRASES: dict[str, Relation] = {
    # horizontal proximity (Sr3D: closest / farthest; its "near", "close to" mean closest)
    "closest to": R.CLOSEST, "the closest to": R.CLOSEST, "closer to": R.CLOSEST, "nearest to": R.CLOSEST,
    "the nearest to": R.CLOSEST, "nearest": R.CLOSEST, "nearer to": R.CLOSEST, "closest": R.CLOSEST,
    "near": R.NEAR, "near to": R.NEAR, "close to": R.NEAR, "next to": R.NEAR, "right next to": R.NEAR,
    "beside": R.NEAR, "besides": R.NEAR, "by": R.NEAR, "adjacent to": R.NEAR, "right beside": R.NEAR,
    "farthest from": R.FARTHEST, "the farthest from": R.FARTHEST, "farthest away from": R.FARTHEST,
    "furthest from": R.FARTHEST, "the furthest from": R.FARTHEST, "furthest away from": R.FARTHEST,
    "farther from": R.FARTHEST, "further from": R.FARTHEST, "most distant from": R.FARTHEST,
    "farthest": R.FARTHEST, "furthest": R.FARTHEST,
    "far from": R.FAR, "far away from": R.FAR, "away from": R.FAR, "distant from": R.FAR,
    # between
    "between": R.BETWEEN, "in between": R.BETWEEN, "in the middle of": R.BETWEEN,
    "in the center of": R.BETWEEN, "in the centre of": R.BETWEEN, "midway between": R.BETWEEN,
    "in the middle between": R.BETWEEN,
    # support
    "on top of": R.ON, "on": R.ON, "lying on": R.ON, "lying on top of": R.ON, "sitting on": R.ON,
    "sitting on top of": R.ON, "resting on": R.ON, "placed on": R.ON, "standing on": R.ON,
    "supported by": R.ON, "atop": R.ON, "upon": R.ON, "on the top of": R.ON,
    "supporting": R.SUPPORTING, "supports": R.SUPPORTING, "support": R.SUPPORTING, "holding up": R.SUPPORTING,
    # vertical
    "above": R.ABOVE, "over": R.ABOVE, "higher than": R.ABOVE,
    "below": R.BELOW, "under": R.BELOW, "beneath": R.BELOW, "underneath": R.BELOW, "lower than": R.BELOW,
    # allocentric
    "in front of": R.FRONT, "in the front of": R.FRONT, "at the front of": R.FRONT, "in front": R.FRONT,
    "on the back of": R.BACK, "at the back of": R.BACK, "in back of": R.BACK, "behind": R.BACK,
    "in the back of": R.BACK, "on the back side of": R.BACK, "at the rear of": R.BACK, "to the back of": R.BACK,
    "behind of": R.BACK,
}
for _side, _rel in (("left", R.LEFT), ("right", R.RIGHT)):
    for _p in (f"on the {_side} of", f"to the {_side} of", f"on the {_side} side of", f"to the {_side} side of",
               f"at the {_side} of", f"{_side} of", f"on its {_side}", f"to its {_side}", f"on their {_side}",
               f"to their {_side}", f"on the {_side}", f"to the {_side}", f"at its {_side}"):
        RELATION_PHRASES[_p] = _rel

_PHRASES = sorted(RELATION_PHRASES, key=len, reverse=True)
_PHRASE_RE = re.compile(r"(?<![a-z0-9])(" + "|".join(re.escape(p) for p in _PHRASES) + r")(?![a-z0-9])")
_ARTICLE = r"(?:the|a|an|this|these|that|those|some|one)"
_VERB = (r"(?:please\s+)?(?:find|choose|select|pick\s+out|pick|locate|identify|show\s+me|show|point\s+to|"
         r"point\s+at|look\s+for|get|grab|where\s+is|where\s+are|which\s+is|what\s+is|it\s+is|this\s+is)")
_LEAD = re.compile(rf"^(?:{_VERB}\s+)?(?:{_ARTICLE}\s+)?")
_COPULA = re.compile(r"(?:^|\s+)(?:(?:that|which|who)\s+(?:is|are|'s)|that's|which's)\s+(?:(?:the|a)\s+(?=(?:closest|nearest|farthest|furthest)\b))?"
                     r"|\s+(?:that|which)\s+(?=(?:supports?|holds?)\b)")
_WITH_ON_TOP = re.compile(
    rf"^(?P<target>.+?)\s+with\s+(?:{_ARTICLE}\s+)?(?P<anchor>.+?)\s+(?:on|at)\s+"
    r"(?:top(?:\s+of\s+(?:it|them))?|(?:its|their)\s+top)$")
_FRAME_FRONT = re.compile(
    rf"^(?:while\s+)?(?:if\s+you\s+(?:are\s+)?)?(?:facing|looking\s+at|looking\s+towards?|looking|you\s+face|face)\s+"
    rf"(?:at\s+)?(?:the\s+)?front\s+(?:side\s+)?of\s+(?:{_ARTICLE}\s+)?(?P<anchor>[^,]+?)\s*,\s*(?P<rest>.+)$")
_FRAME_SIT = re.compile(
    rf"^(?:facing|looking\s+at|looking)\s+(?:{_ARTICLE}\s+)?(?P<anchor>[^,]+?)\s+from\s+the\s+side\s+"
    rf"(?:you|one)\s+(?:would\s+)?sits?\s+on(?:\s+(?:it|them))?\s*,\s*(?P<rest>.+)$")
_FRAME_START = re.compile(r"^(?:while\s+)?(?:facing|looking)\b")
_PRONOUN = re.compile(r"^(?:it|them|its|their|itself)$")
_TAIL = re.compile(r"^(?:of\s+)?(?:it|them)$")


def normalise_utterance(text: str) -> str:
    """Lower case, template placeholders and punctuation (but commas) removed, spaces collapsed."""
    s = str(text).lower().replace("\u2019", "'").replace("`", "'")
    s = re.sub(r"%[a-z_0-9]*%", " ", s)
    s = re.sub(r"[\"“”()\[\]{};:!?.]", " ", s)
    s = re.sub(r"\s*,\s*", ", ", s)
    return re.sub(r"\s+", " ", s).strip(" ,")


def _strip_np(text: str) -> str:
    s = re.sub(rf"^(?:{_ARTICLE}\s+)+", "", text.strip(" ,"))
    return s.strip(" ,")


def parse_utterance(utterance: str) -> ReferringQuery:
    """Parse an Sr3D-style utterance into a :class:`ReferringQuery`; raises
    :class:`UtteranceError` naming the part it could not read."""
    if not isinstance(utterance, str) or not utterance.strip():
        raise UtteranceError("empty utterance", str(utterance), str(utterance), 0)
    s = normalise_utterance(utterance)

    def fail(reason: str, part: str) -> UtteranceError:
        pos = s.find(part) if part else 0
        return UtteranceError(reason, s, part or s, max(pos, 0))

    frame_anchor: str | None = None
    rest = s
    m = _FRAME_FRONT.match(s) or _FRAME_SIT.match(s)
    if m:
        frame_anchor = _strip_np(m.group("anchor"))
        rest = m.group("rest")
    elif _FRAME_START.match(s):
        head = s.split(",", 1)[0]
        raise fail("a viewpoint frame must read 'facing the front of the <anchor>, ...' "
                   "(or 'facing the <anchor> from the side you sit on it, ...')", head)

    body = rest[_LEAD.match(rest).end():]  # type: ignore[union-attr]
    with_top = _WITH_ON_TOP.match(body)
    if with_top:
        target = _strip_np(with_top.group("target"))
        anchor = _strip_np(with_top.group("anchor"))
        if not target or not anchor:
            raise fail("no class name", body)
        return ReferringQuery(target, R.SUPPORTING, [anchor], utterance=utterance)

    cop = _COPULA.search(body)
    if cop:
        target_text, relpart = body[:cop.start()], body[cop.end():]
        rm = _PHRASE_RE.match(relpart)
        if rm is None:
            raise fail("no spatial relation after the copula", relpart or body)
    else:
        first = re.match(r"\S+", body)
        start = first.end() if first else 0
        rm = None
        for cand in _PHRASE_RE.finditer(body, start):
            if cand.start() > 0 and body[cand.start() - 1] == " ":
                rm = cand
                break
        if rm is None:
            raise fail("no spatial relation phrase (e.g. 'closest to', 'between', 'on top of', "
                       "'on the left of')", body)
        target_text, relpart = body[:rm.start()], body[rm.start():]
        rm = _PHRASE_RE.match(relpart)
        assert rm is not None
    phrase = rm.group(1)
    relation = RELATION_PHRASES[phrase]
    anchor_text = relpart[rm.end():].strip(" ,")
    target = _strip_np(target_text)
    if not target:
        raise fail("no target class before the relation", phrase)

    if relation is R.BETWEEN:
        parts = re.split(rf"\s+and\s+(?:{_ARTICLE}\s+)?", anchor_text, maxsplit=1)
        if len(parts) != 2 or not _strip_np(parts[0]) or not _strip_np(parts[1]):
            raise fail("'between' needs two anchors ('between the X and the Y')", anchor_text or phrase)
        return ReferringQuery(target, relation, [_strip_np(parts[0]), _strip_np(parts[1])], utterance=utterance)

    anchor = _strip_np(anchor_text)
    if not anchor or _PRONOUN.match(anchor) or _TAIL.match(anchor):
        if frame_anchor is None:
            raise fail("the anchor is a pronoun or missing, and no 'facing the front of the X,' frame names it",
                       anchor_text or phrase)
        anchor = frame_anchor
    return ReferringQuery(target, relation, [anchor], utterance=utterance)
