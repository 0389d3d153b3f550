"""Event / truth / nodes readers on hostile input: non-UTF-8 bytes, duplicate ids, fuzzed bytes (issue #21)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.errors import FormatError, SgbeliefError
from sgbelief.eval.formats import ReadStats, iter_events, read_events, read_nodes, read_truth

GOOD = {"t": 0, "id": "e1", "targets": {"a": 1.0}, "predicate": "is_car", "confidence": 0.9, "context": "vlm"}


def _line(**kw: object) -> bytes:
    return (json.dumps({**GOOD, **kw}) + "\n").encode()


@pytest.mark.parametrize("bad", [b"\xe9t\xe9\n", b"\x00\xff\xfe\x80garbage\n",
                                 '{"t": 0, "context": "caf\u00e9"}\n'.encode("latin-1")])
def test_non_utf8_line_is_a_format_error_naming_the_line(tmp_path: Path, bad: bytes) -> None:
    p = tmp_path / "events.jsonl"
    p.write_bytes(_line(id="e1") + bad + _line(id="e2"))
    with pytest.raises(FormatError, match=r"events\.jsonl:2: not UTF-8") as ei:
        read_events(p)
    assert ei.value.line == 2
    stats = ReadStats()
    recs = read_events(p, skip_bad_lines=True, stats=stats)
    assert [r.id for r in recs] == ["e1", "e2"] and stats.skipped == 1 and ":2:" in stats.errors[0]


def test_non_utf8_truth_and_nodes_are_format_errors(tmp_path: Path) -> None:
    p = tmp_path / "truth.json"
    p.write_bytes(b'{"a": {"is_car": 1}, "\xe9": {}}')
    with pytest.raises(FormatError, match="not UTF-8"):
        read_truth(p)
    with pytest.raises(FormatError, match="not UTF-8"):
        read_nodes(p)


def test_duplicate_event_id_is_rejected_naming_its_line(tmp_path: Path) -> None:
    p = tmp_path / "events.jsonl"
    p.write_bytes(_line(id="e1") + _line(id="e2", t=1) + _line(id="e1", t=2))
    with pytest.raises(FormatError, match=r"events\.jsonl:3: field 'id': duplicate event id 'e1'"):
        read_events(p)
    stats = ReadStats()
    recs = read_events(p, skip_bad_lines=True, stats=stats)
    assert [(r.id, r.t) for r in recs] == [("e1", 0), ("e2", 1)] and stats.skipped == 1


def test_events_without_ids_are_not_duplicates(tmp_path: Path) -> None:
    p = tmp_path / "events.jsonl"
    no_id = {k: v for k, v in GOOD.items() if k != "id"}
    p.write_text((json.dumps(no_id) + "\n") * 3)
    assert len(read_events(p)) == 3


_json_garbage = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["t", "id", "targets", "predicate", "confidence", "context", "geometric", "format",
                         "version", "a"]), inner, max_size=6),
    max_leaves=12)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=200))
def test_fuzz_event_bytes_give_project_errors(tmp_path: Path, data: bytes) -> None:
    p = tmp_path / "events.jsonl"
    p.write_bytes(_line() + data)
    for skip in (False, True):
        try:
            read_events(p, skip_bad_lines=skip)
        except SgbeliefError:
            pass
    for reader in (read_truth, read_nodes):
        p2 = tmp_path / "other.json"
        p2.write_bytes(data)
        try:
            reader(p2)
        except SgbeliefError:
            pass
    assert p.read_bytes() == _line() + data  # readers never touch the file


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(objs=st.lists(_json_garbage, min_size=1, max_size=4))
def test_fuzz_json_shaped_event_lines_give_project_errors(tmp_path: Path, objs: list[object]) -> None:
    p = tmp_path / "events.jsonl"
    p.write_text("".join(json.dumps(o) + "\n" for o in objs))
    try:
        read_events(p)
    except SgbeliefError:
        pass
    stats = ReadStats()
    try:
        recs = list(iter_events(p, skip_bad_lines=True, stats=stats))
    except FormatError as exc:  # a bad header stays fatal with skip_bad_lines
        assert exc.line == 1 and "header" in str(exc)
    else:
        assert stats.events == len(recs) and stats.events + stats.skipped <= len(objs)
