from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("open3d")

from sgbelief.adapters.scannet import (  # noqa: E402
    LABELS_TSV,
    TSV_HEADER,
    ScanNetChannel,
    load_label_map,
    load_scene,
    load_scenes,
    write_label_map,
    write_scene_files,
)
from sgbelief.errors import FormatError  # noqa: E402
from sgbelief.fusion.channel import GeometricChannel  # noqa: E402
from sgbelief.graph.scene_graph import SceneGraphModel  # noqa: E402

OFFICE = [
    ("floor", (-3, -3, -0.01), (3, 3, 0.0)),
    ("desk", (0, 0, 0), (1.2, 0.6, 0.74)),
    ("monitor", (0.3, 0.2, 0.74), (0.8, 0.3, 1.1)),
    ("office chair", (0.3, 0.8, 0), (0.8, 1.3, 0.95)),
    ("window", (1.6, -0.5, 0.9), (1.7, 1.0, 2.0)),
    ("bookshelf", (0.0, 2.7, 0), (1.5, 3.0, 2.0)),
    ("couch", (0.0, 1.6, 0), (1.5, 2.2, 0.8)),
]


@pytest.fixture
def scannet_root(tmp_path: Path) -> Path:
    """Two scenes in the exact ScanNet v2 layout plus the label map at the root."""
    write_label_map(tmp_path / LABELS_TSV)
    write_scene_files(tmp_path / "scene0001_00", "scene0001_00", OFFICE, unannotated=[((2, 2, 0), (2.5, 2.5, 0.5))])
    write_scene_files(tmp_path / "scene0002_00", "scene0002_00",
                      [("floor", (-2, -2, -0.01), (2, 2, 0.0)), ("table", (0, 0, 0), (1, 1, 0.75))],
                      aggregation_name="scene0002_00_vh_clean.aggregation.json")
    return tmp_path


def test_label_map_real_header(scannet_root):
    lm = load_label_map(scannet_root / LABELS_TSV)
    header = (scannet_root / LABELS_TSV).read_text().splitlines()[0].split("\t")
    assert tuple(header) == TSV_HEADER
    e = lm.get("office chair")
    assert (e.nyu40_id, e.nyu40_class, e.scannet20_class) == (5, "chair", "chair")
    m = lm.get("monitor")
    assert m.nyu40_class == "otherprop" and m.scannet20_class is None
    assert lm.get("couch").label("scannet20") == "sofa"


def test_load_scene_objects(scannet_root):
    sc = load_scene(scannet_root / "scene0001_00")
    assert sc.scene_id == "scene0001_00"
    assert sorted(sc.objects) == list(range(len(OFFICE)))
    chair = sc.objects[3]
    assert chair.raw_label == "office chair" and chair.nyu40_label == "chair"
    assert np.allclose(chair.bbox, ((0.3, 0.8, 0.0), (0.8, 1.3, 0.95)))
    assert chair.centroid == pytest.approx((0.55, 1.05, 0.475))
    assert len(chair.points) == 8
    assert (sc.vertex_object == -1).sum() == 8  # the unannotated box
    assert sc.floor_z == pytest.approx(-0.005)
    g = SceneGraphModel()
    ids = sc.add_to_graph(g)
    assert ids[3] == "scene0001_00/3"
    a = g.node_attrs("scene0001_00/3")
    assert a["label"] == "chair" and a["raw_label"] == "office chair" and a["scene"] == "scene0001_00"
    assert np.allclose(a["bbox"], ((0.3, 0.8, 0.0), (0.8, 1.3, 0.95)))


def test_load_scenes_and_alt_aggregation_name(scannet_root):
    scenes = load_scenes(scannet_root)
    assert [s.scene_id for s in scenes] == ["scene0001_00", "scene0002_00"]
    assert scenes[1].objects[1].nyu40_label == "table"


def test_relations_on_loaded_scene(scannet_root):
    from sgbelief.query import QueryEngine

    g = SceneGraphModel()
    load_scene(scannet_root / "scene0001_00").add_to_graph(g)
    e = QueryEngine(g)
    assert e.geometric("scene0001_00/3", "is_near_window") is True
    assert e.geometric("scene0001_00/1", "is_workspace_height") is True
    assert e.geometric("scene0001_00/1", "is_unobstructed") is False  # the monitor
    assert e.geometric("scene0001_00/2", "is_on_top_of_desk") is True
    assert e.geometric("scene0001_00/5", "is_facing_seating") is True  # couch in front
    assert e.geometric("scene0001_00/5", "is_accessible") is True


def test_channel(scannet_root):
    sc = load_scene(scannet_root / "scene0001_00")
    ch = ScanNetChannel(sc, max_distance=0.05)
    assert isinstance(ch, GeometricChannel)
    assert ch.label("scene0001_00/3", 0) == "chair"
    assert ch.label("scene0001_00/99", 0) is None
    assert ch.label_points(np.array([[0.3, 0.8, 0.95], [0.31, 0.8, 0.0]])) == "chair"  # at chair corners
    assert ch.label_points([[2.0, 2.0, 0.0]]) is None  # unannotated box corner
    assert ch.label_points([[9.0, 9.0, 9.0]]) is None  # too far from every vertex
    ch.set_points("det7", np.array([[1.6, -0.5, 0.9], [1.7, 1.0, 2.0], [0.0, 0.0, 0.74]]), "scene0001_00")
    assert ch.label("det7", 3) == "window"  # 2 window votes vs 1 desk vote
    assert ScanNetChannel(sc, label_space="raw").label("scene0001_00/3", 0) == "office chair"


def test_missing_files(scannet_root):
    d = scannet_root / "scene0001_00"
    (d / "scene0001_00.aggregation.json").unlink()
    with pytest.raises(FileNotFoundError, match="aggregation"):
        load_scene(d)
    with pytest.raises(FileNotFoundError, match="scene folder not found"):
        load_scene(scannet_root / "nope")
    (scannet_root / "scene0002_00" / "scene0002_00_vh_clean_2.0.010000.segs.json").unlink()
    with pytest.raises(FileNotFoundError, match="segs.json"):
        load_scene(scannet_root / "scene0002_00")


def test_missing_label_map(tmp_path):
    write_scene_files(tmp_path / "s", "scene0003_00", OFFICE[:2])
    with pytest.raises(FileNotFoundError, match=LABELS_TSV):
        load_scene(tmp_path / "s")


def test_vertex_count_mismatch(scannet_root):
    segs = scannet_root / "scene0001_00" / "scene0001_00_vh_clean_2.0.010000.segs.json"
    doc = json.loads(segs.read_text())
    doc["segIndices"] = doc["segIndices"][:-3]
    segs.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="entries but the mesh .* has 64 vertices"):
        load_scene(scannet_root / "scene0001_00")


def test_label_absent_from_tsv(scannet_root):
    agg = scannet_root / "scene0001_00" / "scene0001_00.aggregation.json"
    doc = json.loads(agg.read_text())
    doc["segGroups"][1]["label"] = "hyperdesk"
    agg.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="'hyperdesk' is not a raw_category"):
        load_scene(scannet_root / "scene0001_00")
    sc = load_scene(scannet_root / "scene0001_00", on_unknown_label="skip")
    assert 1 not in sc.objects and sc.skipped[0][0] == 1


def test_bad_json_and_fields(scannet_root):
    agg = scannet_root / "scene0001_00" / "scene0001_00.aggregation.json"
    agg.write_text('{"segGroups": [ {"objectId": 0, "label": "floor"} ]}')
    with pytest.raises(FormatError, match="missing field 'segments'"):
        load_scene(scannet_root / "scene0001_00")
    agg.write_text("{not json")
    with pytest.raises(FormatError, match="invalid JSON"):
        load_scene(scannet_root / "scene0001_00")
    tsv = scannet_root / LABELS_TSV
    tsv.write_text("id\tname\n1\tchair\n")
    with pytest.raises(FormatError, match="lacks column"):
        load_label_map(tsv)
