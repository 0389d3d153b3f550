"""Subsumption tables, verdicts with the c < 0.5 sign flip, YAML errors, shipped vocabularies."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from sgbelief.errors import ConfigError, FormatError, UnknownPredicateError
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.resources import config_path


@pytest.fixture
def table() -> SubsumptionTable:
    return SubsumptionTable.shipped("kitti360")


def test_verdicts_and_sign_flip(table: SubsumptionTable) -> None:
    assert table.verdict("is_car", "truck", 0.9) is Verdict.CORROBORATES
    assert table.verdict("is_pedestrian", "car", 0.9) is Verdict.CONTRADICTS
    assert table.verdict("is_pedestrian", "car", 0.2) is Verdict.CORROBORATES  # "not a pedestrian" on a car
    assert table.verdict("is_car", "car", 0.3) is Verdict.CONTRADICTS
    assert table.verdict("is_car", "caravan", 0.9) is Verdict.NO_CLAIM  # ambiguous: in neither set
    assert table.verdict("is_car", None, 0.9) is Verdict.NO_CLAIM
    assert table.verdict("is_unknown", "car", 0.9) is Verdict.NO_CLAIM


def test_outcome_ignores_claim_side(table: SubsumptionTable) -> None:
    assert table.outcome("is_car", "bus") == 1
    assert table.outcome("is_car", "person") == 0
    assert table.outcome("is_car", "caravan") is None


def test_aliases(table: SubsumptionTable) -> None:
    assert table.predicate_for_class("Pickup Truck") == "is_car"
    assert table.predicate_for_class("stop sign") == "is_traffic_sign"
    assert table.predicate_for_class("unicorn") is None
    with pytest.raises(UnknownPredicateError, match="is_car"):
        table.require("is_carr")


@pytest.mark.parametrize("name", ["scannet", "kitti360"])
def test_shipped_vocabularies_are_consistent(name: str) -> None:
    raw = yaml.safe_load(config_path("vocab", f"{name}.yaml").read_text())
    labels = set(raw["labels"])
    t = SubsumptionTable.from_yaml(config_path("vocab", f"{name}.yaml"))
    assert len(t.predicates) >= 8
    for pred, spec in t.specs.items():
        pos, neg = set(spec.positive), set(spec.negative)
        assert pos and neg, pred
        assert not pos & neg and not pos & set(spec.silent)
        assert pos | neg | set(spec.silent) <= labels
        if not raw.get("exhaustive"):  # explicit, not "everything else": some labels stay undecided
            assert labels - pos - neg, f"{pred}: negative set covers every other label"


def test_scannet_labels_are_exhaustive() -> None:
    """NYU40 gives each object one label: otherprop / otherfurniture deny a class; only a kind that
    overlaps it (shelves for a bookshelf) or what it is set into (a window in a wall) is silent."""
    t = SubsumptionTable.shipped("scannet")
    assert t.outcome("is_tv", "otherprop") == 0
    assert t.outcome("is_bed", "otherfurniture") == 0
    assert t.outcome("is_bookshelf", "shelves") is None and t.outcome("is_chair", "shelves") == 0
    assert t.outcome("is_tv", "television") == 1
    assert t.outcome("is_window", "wall") is None and t.outcome("is_door", "wall") is None
    assert t.outcome("is_sink", "counter") is None and t.outcome("is_chair", "counter") == 0
    for pred, spec in t.specs.items():
        assert set(spec.positive) | set(spec.negative) | set(spec.silent) == t.labels, pred


def test_an_exhaustive_vocabulary_derives_its_negative_sets(tmp_path: Path) -> None:
    p = tmp_path / "v.yaml"
    p.write_text("exhaustive: true\nlabels: [chair, sofa, wall, window, otherprop]\npredicates:\n"
                 "  is_chair: {positive: [chair]}\n  is_window: {positive: [window], silent: [wall]}\n")
    t = SubsumptionTable.from_yaml(p)
    assert t.specs["is_chair"].negative == ["sofa", "wall", "window", "otherprop"]  # in label order
    assert t.specs["is_window"].negative == ["chair", "sofa", "otherprop"]
    assert t.verdict("is_chair", "otherprop", 0.9) is Verdict.CONTRADICTS
    assert t.verdict("is_window", "wall", 0.9) is Verdict.NO_CLAIM
    assert t.exclusive_with("is_chair") == ("is_window",)
    from sgbelief.eval.sim_config import load_vocabulary

    assert load_vocabulary(str(p))["predicates"]["is_chair"]["negative"] == ["sofa", "wall", "window", "otherprop"]


@pytest.mark.parametrize(("text", "match"), [
    ("exhaustive: true\nlabels: [a, b]\npredicates:\n  is_a: {positive: [a], negative: [b]}\n",
     r"is_a.*'negative' is derived"),
    ("labels: [a, b]\npredicates:\n  is_a: {positive: [a], negative: [b], silent: [b]}\n",
     r"is_a.*'silent' needs 'exhaustive: true'"),
    ("exhaustive: true\npredicates:\n  is_a: {positive: [a]}\n", r"'exhaustive: true' needs the channel's 'labels'"),
    ("exhaustive: true\nlabels: [a, b]\npredicates:\n  is_a: {positive: [a], silent: [c]}\n",
     r"is_a.*\['c'\] missing from 'labels'"),
    ("exhaustive: true\nlabels: [a, b]\npredicates:\n  is_a: {positive: [a], silent: [a]}\n",
     r"\['a'\] are in both the positive and the silent set"),
])
def test_mistakes_in_an_exhaustive_vocabulary_are_named(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "v.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        SubsumptionTable.from_yaml(p)
    assert "v.yaml" in str(info.value)
    from sgbelief.eval.sim_config import load_vocabulary

    if "exhaustive" in text:
        with pytest.raises(ConfigError, match="v.yaml"):
            load_vocabulary(str(p))


def test_scannet_has_required_predicates() -> None:
    t = SubsumptionTable.shipped("scannet")
    for p in ["is_chair", "is_bookshelf", "is_table_or_desk", "is_sofa", "is_bed", "is_cabinet", "is_window", "is_door"]:
        assert p in t
    k = SubsumptionTable.shipped("kitti360")
    assert {"car", "truck", "bus"} <= set(k.specs["is_car"].positive)


def test_malformed_yaml_names_the_line(tmp_path: Path) -> None:
    p = tmp_path / "v.yaml"
    p.write_text("predicates:\n  is_chair:\n    positive: [chair\n    negative: [table]\n")
    with pytest.raises(FormatError) as info:
        SubsumptionTable.from_yaml(p)
    assert "v.yaml" in str(info.value) and info.value.line is not None


def test_invalid_vocabulary_names_the_key(tmp_path: Path) -> None:
    p = tmp_path / "v.yaml"
    p.write_text("predicates:\n  is_chair:\n    positive: [chair]\n    negative: [chair]\n")
    with pytest.raises(ConfigError, match="is_chair"):
        SubsumptionTable.from_yaml(p)
    p.write_text("predicates:\n  is_chair:\n    positiv: [chair]\n")
    with pytest.raises(ConfigError, match="positiv"):
        SubsumptionTable.from_yaml(p)


def test_resolve_accepts_instance_path_or_shipped_name(table: SubsumptionTable) -> None:
    assert SubsumptionTable.resolve(table) is table
    assert SubsumptionTable.resolve("kitti360").predicates == table.predicates
    assert SubsumptionTable.resolve(config_path("vocab", "scannet.yaml")).name == "scannet"
    with pytest.raises(ConfigError, match=r"unknown vocabulary 'no_such_vocabulary'.*kitti360, scannet"):
        SubsumptionTable.resolve("no_such_vocabulary")


def test_a_folder_named_like_a_shipped_table_does_not_hide_it(tmp_path, monkeypatch) -> None:
    (tmp_path / "scannet").mkdir()  # e.g. a user's ScanNet data folder in the working directory
    monkeypatch.chdir(tmp_path)
    assert SubsumptionTable.resolve("scannet").name == "scannet"
