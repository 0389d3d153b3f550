"""The referring-utterance grammar: every Sr3D template form, tolerant variants, and errors."""

from __future__ import annotations

import pytest

from sgbelief.query.referring import ReferringQuery, Relation, UtteranceError, parse_utterance

R = Relation

# (utterance, target, relation, anchors): the Sr3D template forms (lead verbs, copulas, every wording
# of each relation, the viewpoint frames, the "with the Y on top" forms, placeholders left in)
CASES = [
    ("select the trash can that is closest to the doors", "trash can", R.CLOSEST, ("doors",)),
    ("the chair that is closer to the desk", "chair", R.CLOSEST, ("desk",)),
    ("find the chair that is close to the desk", "chair", R.NEAR, ("desk",)),
    ("choose the chair that is near the desk", "chair", R.NEAR, ("desk",)),
    ("the office chair that is next to the desk", "office chair", R.NEAR, ("desk",)),
    ("choose the pillow that is beside the bed", "pillow", R.NEAR, ("bed",)),
    ("find the lamp that is beside the couch", "lamp", R.NEAR, ("couch",)),
    ("the X that is nearest the Y", "x", R.CLOSEST, ("y",)),
    ("select the box that is farthest from the door", "box", R.FARTHEST, ("door",)),
    ("the box that is far from the door", "box", R.FAR, ("door",)),
    ("the X that is far away from the Y", "x", R.FAR, ("y",)),
    ("the lamp that is between the bed and the sofa", "lamp", R.BETWEEN, ("bed", "sofa")),
    ("choose the chair that is in the middle of the desk and the bookshelf", "chair", R.BETWEEN, ("desk", "bookshelf")),
    ("select the table that is in the center of the couch and the tv stand", "table", R.BETWEEN, ("couch", "tv stand")),
    ("the X in the middle of the Y and the Z", "x", R.BETWEEN, ("y", "z")),
    ("the table that is supporting the lamp", "table", R.SUPPORTING, ("lamp",)),
    ("the X that is supporting the Y", "x", R.SUPPORTING, ("y",)),
    ("select the desk that is  supporting the monitor", "desk", R.SUPPORTING, ("monitor",)),
    ("the desk with %anchor_article% monitor on top of it", "desk", R.SUPPORTING, ("monitor",)),
    ("find the kitchen cabinets with %anchor_article% microwave on top of them", "kitchen cabinets", R.SUPPORTING,
     ("microwave",)),
    ("choose the nightstand with a lamp on its top", "nightstand", R.SUPPORTING, ("lamp",)),
    ("select the tables with the books on their top", "tables", R.SUPPORTING, ("books",)),
    ("the table with the lamp on top", "table", R.SUPPORTING, ("lamp",)),
    ("the X on top of the Y", "x", R.ON, ("y",)),
    ("the pillow that is on top of the bed", "pillow", R.ON, ("bed",)),
    ("find the pillow that is on the bed", "pillow", R.ON, ("bed",)),
    ("choose the book that is lying on the table", "book", R.ON, ("table",)),
    ("the box on the table", "box", R.ON, ("table",)),
    ("the picture that is above the bed", "picture", R.ABOVE, ("bed",)),
    ("select the picture that is over the bed", "picture", R.ABOVE, ("bed",)),
    ("the box that is below the desk", "box", R.BELOW, ("desk",)),
    ("the box that is under the desk", "box", R.BELOW, ("desk",)),
    ("find the shoes that are beneath the bed", "shoes", R.BELOW, ("bed",)),
    ("choose the trash can that is underneath the desk", "trash can", R.BELOW, ("desk",)),
    ("looking at the front of the bed, choose the nightstand that is on the left of it", "nightstand", R.LEFT, ("bed",)),
    ("looking at the front of the bed, select the nightstand that is to the left of it", "nightstand", R.LEFT, ("bed",)),
    ("looking at the front of the desk, pick the chair that is on the left side of the desk", "chair", R.LEFT, ("desk",)),
    ("facing the front of the bed, choose the lamp that is on the right of it", "lamp", R.RIGHT, ("bed",)),
    ("facing the front of the kitchen cabinets, select the trash can that is to the right of them", "trash can",
     R.RIGHT, ("kitchen cabinets",)),
    ("facing the front of the couch, pick the plant that is on the right side of the couch", "plant", R.RIGHT, ("couch",)),
    ("facing the front of the dresser, choose the box that is on the back of it", "box", R.BACK, ("dresser",)),
    ("looking at the front of the dresser, choose the box that is behind it", "box", R.BACK, ("dresser",)),
    ("choose the chair that is in front of the desk", "chair", R.FRONT, ("desk",)),
    ("select the table that is in front of the couch", "table", R.FRONT, ("couch",)),
    ("find the rug that is in front of the bed", "rug", R.FRONT, ("bed",)),
    ("facing the couch from the side you sit on it, choose the pillow that is to the left of this couch", "pillow",
     R.LEFT, ("couch",)),
    ("looking the office chair from the side you sit on it, choose the desk that is on the right of this office chair",
     "desk", R.RIGHT, ("office chair",)),
    ("facing the front of the Y, the X on its left", "x", R.LEFT, ("y",)),
    ("facing the front of the bed, the nightstand to its right", "nightstand", R.RIGHT, ("bed",)),
    ("the chair to the left of the desk", "chair", R.LEFT, ("desk",)),
    ("Select the Trash Cans that are closest to the Doors.", "trash cans", R.CLOSEST, ("doors",)),
    ("the trashcan which is nearest to the door", "trashcan", R.CLOSEST, ("door",)),
    ("pick out the box that's the farthest from the door", "box", R.FARTHEST, ("door",)),
    ("the table that supports the lamp", "table", R.SUPPORTING, ("lamp",)),
]


@pytest.mark.parametrize("utterance,target,relation,anchors", CASES)
def test_sr3d_template_forms_parse(utterance: str, target: str, relation: Relation, anchors: tuple[str, ...]) -> None:
    q = parse_utterance(utterance)
    assert (q.target, q.relation, q.anchors) == (target, relation, anchors)
    assert q.utterance == utterance


@pytest.mark.parametrize("utterance,part", [
    ("the chair", "chair"),
    ("the chair on its left", "on its left"),
    ("the lamp between the bed", "the bed"),
    ("facing the bed the chair on the left", "facing the bed the chair on the left"),
    ("the that is closest to the door", "closest to"),
    ("the chair that is purple", "purple"),
    ("", ""),
])
def test_unreadable_utterances_name_the_part(utterance: str, part: str) -> None:
    with pytest.raises(UtteranceError) as err:
        parse_utterance(utterance)
    assert err.value.part == (part or utterance)
    assert repr(err.value.part) in str(err.value) or not utterance


def test_structured_query_validates_its_fields() -> None:
    q = ReferringQuery(target="lamp", relation="between", anchors=["bed", "sofa"])
    assert q.relation is R.BETWEEN and q.anchors == ("bed", "sofa")
    assert ReferringQuery("box", "supported-by", "table").relation is R.ON
    assert q == ReferringQuery("lamp", R.BETWEEN, ("bed", "sofa"), utterance="x")  # utterance not compared
    with pytest.raises(ValueError, match="takes 2 anchor"):
        ReferringQuery("lamp", "between", ["bed"])
    with pytest.raises(ValueError, match="unknown relation 'inside'"):
        ReferringQuery("lamp", "inside", ["bed"])
    with pytest.raises(ValueError, match="target"):
        ReferringQuery(" ", "near", ["bed"])
    with pytest.raises(AttributeError):
        q.target = "chair"  # type: ignore[misc]
    assert parse_utterance(str(q)) == q
