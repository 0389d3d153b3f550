from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.errors import FormatError
from sgbelief.eval.formats import (
    EventModel,
    EventRecord,
    NodesFile,
    ReadStats,
    iter_events,
    read_events,
    read_nodes,
    read_truth,
    validate_event,
    write_events,
    write_nodes,
    write_truth,
)

GOOD = {"t": 3, "id": "e1", "targets": {"a": 0.7, "b": 0.2}, "predicate": "is_car",
        "confidence": 0.9, "context": "vlm_a", "geometric": {"a": "car", "b": None}}


def _write_lines(path, objs):
    path.write_text("".join((o if isinstance(o, str) else json.dumps(o)) + "\n" for o in objs))


def test_round_trip(tmp_path):
    recs = [EventRecord(t=i, targets={"n1": 0.5, "n2": 0.05}, predicate="is_chair", confidence=i / 10,
                        context="vlm_b", geometric={"n1": "chair", "n2": None}, id=f"e{i}") for i in range(10)]
    recs.append(EventRecord(t=11, targets={}, predicate="is_chair", confidence=1.0, context="x", geometric={}))
    p = tmp_path / "events.jsonl"
    assert write_events(p, recs) == 11
    st_ = ReadStats()
    back = read_events(p, stats=st_)
    assert back == recs
    assert st_.header == {"format": "sgbelief.events", "version": 1}
    assert st_.events == 11 and st_.skipped == 0
    # without header
    write_events(p, recs, header=False)
    assert read_events(p) == recs


def test_int_masses_and_missing_geometric(tmp_path):
    p = tmp_path / "e.jsonl"
    obj = dict(GOOD)
    obj.pop("geometric")
    obj["targets"] = {"a": 1}
    obj["confidence"] = 1
    _write_lines(p, [obj])
    (rec,) = read_events(p)
    assert rec.targets == {"a": 1.0} and isinstance(rec.targets["a"], float)
    assert rec.confidence == 1.0 and rec.geometric == {} and rec.id == "e1"


BAD_CASES = [
    ({**GOOD, "confidence": float("nan")}, "confidence"),
    ({**GOOD, "confidence": 1.2}, "confidence"),
    ({**GOOD, "confidence": "0.5"}, "confidence"),
    ({**GOOD, "targets": {"a": 1.5}}, "targets"),
    ({**GOOD, "targets": {"a": 0.7, "b": 0.6}, "geometric": {}}, "targets"),
    ({**GOOD, "targets": {"a": -0.1}, "geometric": {}}, "targets"),
    ({**GOOD, "predicate": ""}, "predicate"),
    ({**GOOD, "t": 2.5}, "t"),
    ({**GOOD, "t": "3"}, "t"),
    ({**GOOD, "t": True}, "t"),
    ({**GOOD, "t": -1}, "t"),
    ({k: v for k, v in GOOD.items() if k != "context"}, "context"),
    ({**GOOD, "geometric": {"zz": "car"}}, "geometric"),
    ({**GOOD, "geometric": {"a": 3}}, "geometric"),
    ({**GOOD, "id": 7}, "id"),
]


@pytest.mark.parametrize("obj,field", BAD_CASES)
def test_bad_line_names_line_and_field(tmp_path, obj, field):
    p = tmp_path / "e.jsonl"
    lines = [{"format": "sgbelief.events", "version": 1}, {**GOOD, "id": "g1"}, {**GOOD, "id": "g2"}, obj,
             {**GOOD, "id": "g3"}]  # ids are unique within a log
    p.write_text("".join(json.dumps(o) + "\n" for o in lines))  # json.dumps writes NaN literally
    with pytest.raises(FormatError) as ei:
        list(iter_events(p))
    err = ei.value
    assert err.line == 4 and str(p) in str(err) and ":4:" in str(err)
    assert field in str(err)


def test_bad_json_and_skip(tmp_path):
    p = tmp_path / "e.jsonl"
    _write_lines(p, [GOOD, '{"t": 1, "targets":', "", {**GOOD, "id": "e2"}, "[1, 2]", {**GOOD, "confidence": -1}])
    with pytest.raises(FormatError, match=r":2: bad JSON"):
        list(iter_events(p))
    st_ = ReadStats()
    recs = list(iter_events(p, skip_bad_lines=True, stats=st_))
    assert len(recs) == 2 and st_.skipped == 3 and st_.events == 2 and st_.lines == 6
    assert any(":5:" in e for e in st_.errors) and any(":6:" in e and "confidence" in e for e in st_.errors)


def test_bad_header(tmp_path):
    p = tmp_path / "e.jsonl"
    _write_lines(p, [{"format": "sgbelief.events", "version": 99}, GOOD])
    with pytest.raises(FormatError, match="version"):
        list(iter_events(p))
    _write_lines(p, [{"format": "other", "version": 1}, GOOD])
    with pytest.raises(FormatError, match="format"):
        list(iter_events(p))


def test_writer_is_atomic_on_error(tmp_path):
    p = tmp_path / "e.jsonl"
    write_events(p, [GOOD])
    before = p.read_text()
    with pytest.raises(FormatError) as ei:
        write_events(p, [GOOD, {**GOOD, "confidence": 2.0}])
    assert ei.value.line == 3  # header + 2
    assert p.read_text() == before
    assert [x.name for x in tmp_path.iterdir()] == ["e.jsonl"]


def test_atomic_writes_get_a_normal_file_mode(tmp_path):
    # the temp file behind an atomic write is created 0600; the result must not stay private
    import os
    import stat

    from sgbelief.graph.persistence import atomic_write_text

    old = os.umask(0o022)
    try:
        p = tmp_path / "e.jsonl"
        write_events(p, [GOOD])
        assert stat.S_IMODE(p.stat().st_mode) == 0o644
        p.chmod(0o640)  # an existing file keeps its mode
        atomic_write_text(p, "x")
        assert stat.S_IMODE(p.stat().st_mode) == 0o640
    finally:
        os.umask(old)


# fast path and pydantic path must agree on acceptance
_json_scalar = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.floats(allow_nan=True, allow_infinity=True),
                         st.text(max_size=3))


@st.composite
def _maybe_event(draw):
    obj = dict(GOOD)
    for key in ["t", "confidence", "predicate", "context", "id"]:
        if draw(st.booleans()):
            obj[key] = draw(_json_scalar)
    if draw(st.booleans()):
        obj["targets"] = draw(st.dictionaries(st.sampled_from(["a", "b", "c"]), _json_scalar, max_size=3))
    if draw(st.booleans()):
        obj["geometric"] = draw(st.one_of(st.none(), st.dictionaries(st.sampled_from(["a", "b", "z"]),
                                                                       _json_scalar, max_size=2)))
    if draw(st.booleans()):
        obj.pop(draw(st.sampled_from(sorted(obj))))
    return obj


@settings(max_examples=300, deadline=None)
@given(_maybe_event())
def test_fast_and_pydantic_paths_agree(obj):
    try:
        validate_event(obj)
        fast_ok = True
    except FormatError:
        fast_ok = False
    try:
        EventModel.model_validate(obj)
        slow_ok = True
    except Exception:
        slow_ok = False
    assert fast_ok == slow_ok, obj


def test_truth_round_trip_and_errors(tmp_path):
    p = tmp_path / "truth.json"
    truth = {"n1": {"is_car": 1, "is_pedestrian": 0}, "n2": {"is_car": 0}}
    write_truth(p, truth)
    assert read_truth(p) == truth
    p.write_text(json.dumps(truth))  # header-less
    assert read_truth(p) == truth
    p.write_text(json.dumps({"n1": {"is_car": 2}}))
    with pytest.raises(FormatError, match=r"n1\.is_car"):
        read_truth(p)
    p.write_text('{"n1": ')
    with pytest.raises(FormatError, match="bad JSON"):
        read_truth(p)


def test_nodes_round_trip_and_errors(tmp_path):
    p = tmp_path / "nodes.json"
    doc = NodesFile.model_validate({
        "suite": "toy",
        "scenes": {"s0": {"kind": "indoor", "t_start": 0, "t_end": 9, "ego_track": [[0, 0, 0, 1.5, 0.0]]}},
        "nodes": {"s0/0001": {"scene": "s0", "label": "chair", "centroid": [1, 2, 0.4],
                              "bbox_min": [0.7, 1.7, 0], "bbox_max": [1.3, 2.3, 0.9], "front": [1, 0, 0],
                              "geometric_predicates": {"is_near_window": True}}},
    })
    write_nodes(p, doc)
    back = read_nodes(p)
    assert back == doc
    bad = json.loads(p.read_text())
    bad["nodes"]["s0/0001"]["bbox_max"] = [0, 0, 0]
    p.write_text(json.dumps(bad))
    with pytest.raises(FormatError, match="s0/0001"):
        read_nodes(p)


def test_nan_not_written(tmp_path):
    with pytest.raises(FormatError):
        write_events(tmp_path / "x.jsonl", [{**GOOD, "confidence": math.nan}])
