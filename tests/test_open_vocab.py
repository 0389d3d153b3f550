"""Open-vocabulary subsumption: derived tables, taxonomy, mappings, class lists, `sgbelief vocab check`."""

from __future__ import annotations

from pathlib import Path

import pytest

from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary
from sgbelief.cli import main as cli_main
from sgbelief.errors import ConfigError, FormatError
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.open_vocab import LabelMapping, Taxonomy, derive_table, load_class_list

CLASSES = ["chair", "armchair", "office chair", "table", "desk", "sofa", "tv", "lamp", "stool",
           "otherprop", "wall"]


@pytest.fixture
def table() -> SubsumptionTable:
    return derive_table(CLASSES, "indoor", ignore=["wall"])


def test_concrete_classes_exclude_each_other(table: SubsumptionTable) -> None:
    assert table.verdict("is_tv", "sofa", 0.9) is Verdict.CONTRADICTS  # the sofa-called-tv case
    assert table.verdict("is_tv", "tv", 0.9) is Verdict.CORROBORATES
    assert table.verdict("is_lamp", "stool", 0.8) is Verdict.CONTRADICTS
    assert table.verdict("is_stool", "chair", 0.8) is Verdict.CONTRADICTS
    assert table.verdict("is_tv", "wall", 0.9) is Verdict.CONTRADICTS  # ignored class: still a channel label
    assert "is_wall" not in table


def test_separate_classes_stay_separate_unless_merged(table: SubsumptionTable) -> None:
    """The class list had chair / armchair and table / desk as separate classes: separate predicates."""
    assert {"is_chair", "is_armchair", "is_office_chair", "is_table", "is_desk"} <= set(table.predicates)
    assert table.outcome("is_table", "desk") == 0 and table.outcome("is_desk", "table") == 0
    assert table.outcome("is_chair", "armchair") == 0
    merged = derive_table(CLASSES, "indoor", ignore=["wall"], merge=["is_table_or_desk"])
    assert merged.outcome("is_table_or_desk", "desk") == 1 and "is_armchair" in merged
    with pytest.raises(ValueError, match="is_tables"):
        derive_table(CLASSES, "indoor", merge=["is_tables"])


def test_synonyms_merge_plurals_and_case_fold() -> None:
    t = derive_table(["Sofa", "couch", "Chair", "chairs", "TV", "television", "lamp"], "indoor")
    assert t.predicate_for_class("couch") == t.predicate_for_class("sofa") == "is_sofa"
    assert t.predicate_for_class("chairs") == t.predicate_for_class("Chair") == "is_chair"
    assert t.predicate_for_class("television") == "is_tv"
    assert set(t.predicates) == {"is_sofa", "is_chair", "is_tv", "is_lamp"}
    assert t.outcome("is_tv", "sofa") == 0 and t.outcome("is_sofa", "couch") == 1
    only_tv = derive_table(["tv", "sofa"], "indoor")  # a synonym outside the list still names its class
    assert only_tv.outcome("is_tv", "television") == 1 and only_tv.outcome("is_sofa", "television") == 0


def test_synonyms_and_hyponyms_share_a_predicate_when_merged() -> None:
    table = derive_table(CLASSES, "indoor", ignore=["wall"], merge=True)
    for lab in ("chair", "armchair", "office chair", "office_chair"):
        assert table.outcome("is_chair", lab) == 1
    assert table.outcome("is_table_or_desk", "desk") == 1 and table.outcome("is_table_or_desk", "table") == 1
    assert table.outcome("is_table_or_desk", "chair") == 0
    assert table.predicate_for_class("Office Chair") == "is_chair"
    assert set(table.specs["is_chair"].aliases) == {"chair", "armchair", "office chair"}


def test_ambiguous_and_hypernym_labels(table: SubsumptionTable) -> None:
    for pred in table.predicates:
        assert table.outcome(pred, "otherprop") is None
    assert "is_otherprop" not in table
    assert "otherprop" in table.ambiguous_labels
    # 'seating' covers chairs, sofas and stools: it decides neither is_chair nor is_sofa, contradicts is_tv
    assert table.outcome("is_chair", "seating") is None
    assert table.outcome("is_sofa", "seating") is None
    assert table.outcome("is_tv", "seating") == 0


def test_mapping_into_a_coarser_channel() -> None:
    t = derive_table("scannet200", "indoor", "scannet200_nyu40", ignore=["wall", "floor", "ceiling"], merge=True)
    assert t.outcome("is_tv", "television") == 1
    assert t.outcome("is_tv", "sofa") == 0
    assert t.outcome("is_chair", "chair") == 1  # every ScanNet200 class NYU40 calls chair is in is_chair
    assert t.outcome("is_stool", "chair") == 0
    assert t.outcome("is_alarm_clock", "otherprop") is None
    assert t.outcome("is_alarm_clock", "bed") == 0
    assert len(t.predicates) > 150


def test_shipped_tables_keep_working() -> None:
    assert SubsumptionTable.shipped("scannet").outcome("is_chair", "chair") == 1
    assert SubsumptionTable.shipped("kitti360").outcome("is_car", "truck") == 1


def test_class_vocabulary_open_vocabulary_yaml() -> None:
    from sgbelief.resources import config_path

    v = ClassVocabulary.from_yaml(config_path("conceptgraphs", "scannet200.yaml"))
    assert v.predicate("armchair") == "is_chair"
    assert v.predicate("tv") == "is_tv"
    assert v.predicate("wall") is None
    assert v.table().outcome("is_tv", "sofa") == 0
    v2 = ClassVocabulary.open_vocabulary(["couch", "tv"], taxonomy="indoor")
    assert ClassVocabulary.open_vocabulary(["armchair", "chair"]).predicate("armchair") == "is_armchair"
    assert v2.predicate("couch") == "is_sofa" and v2.table().outcome("is_sofa", "tv") == 0


def test_class_list_errors_name_file_and_line(tmp_path: Path) -> None:
    p = tmp_path / "classes.txt"
    p.write_text("chair\n# comment\ntable\nChair\n")
    with pytest.raises(FormatError) as info:
        load_class_list(p)
    assert info.value.line == 4 and "classes.txt" in str(info.value) and "first on line 1" in str(info.value)
    y = tmp_path / "classes.yaml"
    y.write_text("classes:\n  - chair\n  - 3\n")
    with pytest.raises(FormatError) as info:
        load_class_list(y)
    assert info.value.line == 3
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(FormatError, match="empty"):
        load_class_list(tmp_path / "empty.txt")
    ok = tmp_path / "ok.json"
    ok.write_text('["a", "b"]')
    assert load_class_list(ok).names == ("a", "b")


def test_mapping_file_errors_name_file_line_and_key(tmp_path: Path) -> None:
    p = tmp_path / "m.yaml"
    p.write_text("format: sgbelief.label_mapping\nsource: a\ntarget: b\nmap:\n  chair: chair\n  sofa: [x]\n")
    with pytest.raises(FormatError) as info:
        LabelMapping.from_yaml(p)
    assert info.value.line == 6 and "map.sofa" in str(info.value) and "m.yaml" in str(info.value)
    p.write_text("format: sgbelief.label_mapping\nsource: a\nmap: {}\n")
    with pytest.raises(FormatError, match="target"):
        LabelMapping.from_yaml(p)
    p.write_text("format: sgbelief.label_mapping\nsource: a\ntarget: b\nmap: {chair: chair}\nextra: 1\n")
    with pytest.raises(FormatError) as info:
        LabelMapping.from_yaml(p)
    assert info.value.line == 5 and "extra" in str(info.value)
    p.write_text("format: sgbelief.label_mapping\nmap: [unclosed\n")
    with pytest.raises(FormatError) as info:
        LabelMapping.from_yaml(p)
    assert info.value.line is not None


def test_taxonomy_errors(tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    p.write_text("format: sgbelief.taxonomy\ngroups:\n  is_chair: [chair]\n  is_seat: [Chair]\n")
    with pytest.raises(FormatError, match="both group") as info:
        Taxonomy.from_yaml(p)
    assert "t.yaml" in str(info.value)
    p.write_text("format: sgbelief.taxonomy\ngroups:\n  chair: [chair]\n")
    with pytest.raises(FormatError, match="groups"):
        Taxonomy.from_yaml(p)
    p.write_text("format: sgbelief.vocabulary\n")
    with pytest.raises(FormatError, match="format"):
        Taxonomy.from_yaml(p)


def test_cg_vocabulary_rejects_mixed_keys(tmp_path: Path) -> None:
    p = tmp_path / "v.yaml"
    p.write_text("format: sgbelief.cg_vocabulary\nclass_list: coco80\nsubsumption: vocab/scannet.yaml\n")
    with pytest.raises(ConfigError, match="subsumption"):
        ClassVocabulary.from_yaml(p)


def test_vocab_check_cli(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert cli_main(["vocab", "check", "coco80", "--predicate", "is_tv"]) == 0
    out = capsys.readouterr().out
    assert "is_tv  [tv]" in out and "T: ['television', 'tv'," in out  # a synonym names the listed class
    assert cli_main(["vocab", "check", "coco80", "--predicate", "is_dining_table"]) == 0
    assert cli_main(["vocab", "check", "scannet200", "--predicate", "is_desk"]) == 0  # separate by default
    capsys.readouterr()
    assert cli_main(["vocab", "check", "scannet200", "--merge", "is_table_or_desk", "--predicate",
                     "is_table_or_desk"]) == 0
    assert "desk" in capsys.readouterr().out
    lst = tmp_path / "mine.txt"
    lst.write_text("sofa\ntv\notherprop\n")
    assert cli_main(["vocab", "check", str(lst), "--matrix"]) == 0
    out = capsys.readouterr().out
    assert "is_tv" in out and "⊥" in out and "T" in out
    assert cli_main(["vocab", "check", "scannet200", "--mapping", "scannet200_nyu40", "--json",
                     "--predicate", "is_tv"]) == 0
    import json

    data = json.loads(capsys.readouterr().out)
    assert data["verdicts"]["is_tv"]["sofa"] == "⊥" and data["verdicts"]["is_tv"]["television"] == "T"
    assert cli_main(["vocab", "check", "scannet", "--predicate", "is_chair"]) == 0
    capsys.readouterr()
    bad = tmp_path / "bad.txt"
    bad.write_text("a\na\n")
    assert cli_main(["vocab", "check", str(bad)]) == 1
    assert "bad.txt:2" in capsys.readouterr().err


def test_from_class_list_is_a_deprecated_derive_table(table: SubsumptionTable) -> None:
    with pytest.warns(DeprecationWarning, match="derive_table"):
        old = SubsumptionTable.from_class_list(CLASSES, "indoor", ignore=["wall"])  # no merge, as derive_table
    assert old.specs == table.specs and old.labels == table.labels and old.name == table.name
    assert old.ambiguous_labels == table.ambiguous_labels and "otherprop" in old.ambiguous_labels


def test_compatibility_does_not_import_the_derivation() -> None:
    import subprocess
    import sys

    code = "import sys, sgbelief.fusion.compatibility; print('sgbelief.fusion.open_vocab' in sys.modules)"
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(root), "PATH": ""}).stdout.strip()
    assert out == "False"
