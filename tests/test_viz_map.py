"""sgbelief.viz: what a map picture shows (committed labels, refused claims, geometry) and the
matplotlib figures, counted by their artists; ``sgbelief show`` end to end on simulated-style,
ScanNet and ConceptGraphs maps."""

from __future__ import annotations

import gzip
import json
import pickle
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from sgbelief.cli import main  # noqa: E402
from sgbelief.eval.formats import write_nodes  # noqa: E402
from sgbelief.graph.persistence import load_graph  # noqa: E402
from sgbelief.graph.provenance import EntryStatus  # noqa: E402
from sgbelief.api.scene_graph import SceneGraph  # noqa: E402
from sgbelief.viz.map_figure import OBJECT_GID, REFUSED_GID, NoGeometryError, map_figure  # noqa: E402
from sgbelief.viz.map_state import map_state, object_view  # noqa: E402
from sgbelief.viz.style import REFUSED_STATUSES, format_probability  # noqa: E402

ROUNDS = 40
#: (node, geometric label, predicate, confidence) per round; the third claim is contradicted by geometry
CLAIMS = (("s/car", "car", "is_car", 0.8), ("s/ped", "person", "is_pedestrian", 0.7), ("s/car", "car", "is_pedestrian", 0.9))
NODES = {
    "s/car": {"scene": "s", "label": "car", "centroid": [2.0, 1.0, 0.7], "bbox_min": [0.0, 0.0, 0.0], "bbox_max": [4.0, 2.0, 1.4]},
    "s/ped": {"scene": "s", "label": "person", "centroid": [15.0, 3.0, 0.9], "bbox_min": [14.7, 2.7, 0.0],
              "bbox_max": [15.3, 3.3, 1.8], "track": [[0, 10.0, 3.0, 0.9], [3 * ROUNDS, 20.0, 3.0, 0.9]]},
    "s/tree": {"scene": "s", "label": "vegetation", "centroid": [8.0, -4.0, 3.0], "bbox_min": [6.0, -6.0, 0.0],
               "bbox_max": [10.0, -2.0, 6.0]},
}


def write_scene(d: Path, *, with_nodes: bool = True) -> tuple[Path, Path]:
    """An evidence log (events.jsonl), truth.json and (optionally) nodes.json of a three-object scene."""
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    t = 0
    for k in range(ROUNDS):
        for node, label, pred, c in CLAIMS:
            lines.append(json.dumps({"t": t, "targets": {node: 1.0}, "predicate": pred, "confidence": c - 0.01 * (k % 7),
                                     "context": "vlm", "geometric": {node: label}}))
            t += 1
    d.mkdir(parents=True, exist_ok=True)
    (d / "events.jsonl").write_text("\n".join(lines) + "\n")
    (d / "truth.json").write_text(json.dumps({"s/car": {"is_car": 1, "is_pedestrian": 0},
                                              "s/ped": {"is_car": 0, "is_pedestrian": 1}}))
    if with_nodes:
        write_nodes(d / "nodes.json", {"suite": "test", "nodes": NODES, "scenes": {"s": {
            "kind": "outdoor", "t_start": 0, "t_end": t, "ego_track": [[0, -5.0, -1.0, 1.6, 0.0], [t, 25.0, -1.0, 1.6, 0.0]]}}})
    return d / "events.jsonl", d / "truth.json"


@pytest.fixture(scope="module")
def saved_maps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("scene")
    ev, truth = write_scene(d)
    assert main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operators", "comod,cal",
                 "--save-graph", str(d / "maps"), "--no-progress"]) == 0
    return d


def _objects(fig) -> list:
    return [p for ax in fig.axes for p in ax.patches if p.get_gid() == OBJECT_GID]


def _rings(fig) -> int:
    return sum(len(c.get_offsets()) for ax in fig.axes for c in ax.collections if c.get_gid() == REFUSED_GID)


# ------------------------------------------------------------------------------ map state
def test_state_of_a_replayed_map(saved_maps: Path) -> None:
    g = load_graph(saved_maps / "maps" / "comod")
    st = map_state(g)
    views = {o.node: o for o in st.objects}
    assert set(views) == {"s/car", "s/ped", "s/tree"}  # geometry travelled from nodes.json
    assert views["s/car"].label == "is_car" and views["s/car"].probability > 0.9
    assert views["s/ped"].label == "is_pedestrian"
    assert views["s/tree"].label is None and not views["s/tree"].has_evidence
    assert views["s/car"].box == ((0.0, 0.0, 0.0), (4.0, 2.0, 1.4))
    # every contradicted claim refused; closed ones (expired after T_disagree) still count as refused claims
    assert len(st.refused) == ROUNDS
    assert {c.status for c in st.refused} <= REFUSED_STATUSES and {"expired", "refused"} <= {c.status for c in st.refused}
    assert all(c.node == "s/car" and c.predicate == "is_pedestrian" for c in st.refused)
    (site,) = st.sites()
    assert site.node == "s/car" and site.claims == ROUNDS and site.position == pytest.approx((2.0, 1.0, 0.7))
    # the calibration-only operator refuses nothing
    assert map_state(load_graph(saved_maps / "maps" / "cal")).refused == ()


def test_committed_label_is_strictly_above_tau() -> None:
    g = SceneGraph()
    g.add_node("a", bbox=((0, 0, 0), (1, 1, 1)))
    g.add_node("b", centroid=(3, 3, 0))
    g.provenance.commit("a", "is_car", "e1", 0, 1.0, 1.0)  # Beta(2, 2): P = 0.5 exactly
    g.provenance.commit("b", "is_car", "e2", 0, 1.0, 0.999)
    a, b = object_view(g, "a", 0.5), object_view(g, "b", 0.5)
    assert a.label is None and a.has_evidence and a.probability == 0.5
    assert b.label == "is_car" and b.box is None and b.position == (3.0, 3.0, 0.0)
    assert object_view(g, "b", b.probability).label is None  # P > tau, not >=
    assert format_probability(b.probability) == "0.500"  # never printed as if it sat on tau
    assert format_probability(0.5) == "0.50" and format_probability(0.734) == "0.73"


def test_refused_site_of_a_moving_object_follows_its_track() -> None:
    g = SceneGraph()
    g.add_node("p", centroid=(0, 0, 0), track=[[0, 0.0, 0.0, 0.0], [10, 10.0, 0.0, 0.0]])
    for t in (2, 4):
        g.provenance.record("p", "is_car", f"e{t}", t, 1.0, 0.0, EntryStatus.REFUSED, -1)
    st = map_state(g)
    assert [c.position for c in st.refused] == [(2.0, 0.0, 0.0), (4.0, 0.0, 0.0)]
    assert st.sites()[0].position == pytest.approx((3.0, 0.0, 0.0))
    assert object_view(g, "p").position_at(99) == (10.0, 0.0, 0.0)  # held at the track's ends


# ------------------------------------------------------------------------------ figures
def test_map_figure_draws_one_patch_per_located_object(saved_maps: Path) -> None:
    g = load_graph(saved_maps / "maps" / "comod")
    g.add_node("s/pole", centroid=(12.0, -3.0, 2.0))  # a point only: drawn as a dot
    g.add_node("s/ghost")  # no geometry: not drawn, said in the caption
    st = map_state(g)
    fig = map_figure(st, title="test map")
    try:
        objs = _objects(fig)
        assert len(objs) == 4
        assert sum(type(p).__name__ == "Circle" for p in objs) == 1
        assert _rings(fig) == 1  # one refused site (s/car)
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any(t.startswith("car (1)") for t in legend) and any(t.startswith("pedestrian (1)") for t in legend)
        assert any("no evidence (2)" in t for t in legend) and any("refused claims (⊥): 40 at 1 object" in t for t in legend)
        texts = " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
        assert "1 object without geometry not drawn" in texts and "s/car  40 refused" in texts
        assert fig.axes[0].get_xlabel() == "x [m]" and fig.axes[0].get_ylabel() == "y [m]"
        assert "test map" in fig._suptitle.get_text()
    finally:
        plt.close(fig)


def test_map_figure_region_strips_and_no_geometry(saved_maps: Path) -> None:
    g = load_graph(saved_maps / "maps" / "comod")
    st = map_state(g)
    fig = map_figure(st, region=(-1.0, 5.0, -1.0, 3.0))
    try:
        assert len(_objects(fig)) == 1  # only the car overlaps the window
    finally:
        plt.close(fig)
    long = SceneGraph()
    for i in range(30):  # a 'drive': 3 km along x, 10 m wide
        long.add_node(f"o{i}", bbox=((100.0 * i, 0.0, 0.0), (100.0 * i + 4, 10.0, 2.0)))
    fig = map_figure(map_state(long), max_strips=4)
    try:
        assert len(fig.axes) == 4 and len(_objects(fig)) == 30
    finally:
        plt.close(fig)
    bare = SceneGraph()
    bare.add_node("x")
    with pytest.raises(NoGeometryError, match="none of the map's 1 objects has a box or a centroid"):
        map_figure(map_state(bare))
    with pytest.raises(NoGeometryError, match="inside x"):
        map_figure(st, region=(100.0, 101.0, 100.0, 101.0))


# ------------------------------------------------------------------------------ CLI
def _png(path: Path) -> bytes:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    return data


def test_show_cli_map_and_trace(saved_maps: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "map.png"
    assert main(["show", str(saved_maps / "maps" / "comod"), "--out", str(out), "--nodes",
                 str(saved_maps / "nodes.json")]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    _png(out)
    assert main(["show", str(saved_maps / "maps" / "comod"), "--out", str(tmp_path / "near.png"), "--around", "s/car",
                 "--radius", "6"]) == 0
    _png(tmp_path / "near.png")
    assert main(["show", str(saved_maps / "maps" / "comod"), "--node", "s/car", "--out", str(tmp_path / "t.png")]) == 0
    _png(tmp_path / "t.png")
    capsys.readouterr()
    assert main(["show", str(saved_maps / "maps" / "comod"), "--node", "nope", "--out", str(tmp_path / "x.png")]) == 1
    assert "unknown node 'nope'" in capsys.readouterr().err
    assert main(["show", str(saved_maps / "maps" / "comod"), "--node", "s/tree", "--out", str(tmp_path / "x.png")]) == 1
    assert "no claim touched it" in capsys.readouterr().err
    assert main(["show", str(saved_maps / "maps" / "comod"), "--region", "5", "1", "0", "1", "--out",
                 str(tmp_path / "x.png")]) == 1
    assert "--region" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_show_cli_map_without_geometry_fails_clearly(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev, truth = write_scene(tmp_path, with_nodes=False)
    assert main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operators", "comod",
                 "--save-graph", str(tmp_path / "maps"), "--no-progress"]) == 0
    capsys.readouterr()
    out = tmp_path / "map.png"
    assert main(["show", str(tmp_path / "maps" / "comod"), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "sgbelief show: error: none of the map's 2 objects has a box or a centroid" in err and "--nodes" in err
    assert not out.exists()
    # the geometry can come afterwards from the nodes.json the map was made from
    write_scene(tmp_path / "with")
    assert main(["show", str(tmp_path / "maps" / "comod"), "--out", str(out), "--nodes",
                 str(tmp_path / "with" / "nodes.json")]) == 0
    _png(out)


def test_show_cli_on_a_scannet_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("open3d")
    from sgbelief.adapters.scannet import LABELS_TSV, write_label_map, write_scene_files

    write_label_map(tmp_path / LABELS_TSV)
    write_scene_files(tmp_path / "scene0001_00", "scene0001_00", [
        ("floor", (-3, -3, -0.01), (3, 3, 0.0)), ("desk", (0, 0, 0), (1.2, 0.6, 0.74)),
        ("office chair", (0.3, 0.8, 0), (0.8, 1.3, 0.95)), ("couch", (0.0, 1.6, 0), (1.5, 2.2, 0.8))])
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    for t in range(30):
        node, label, pred = (("scene0001_00/2", "chair", "is_chair"), ("scene0001_00/3", "sofa", "is_sofa"),
                             ("scene0001_00/2", "chair", "is_sofa"))[t % 3]
        lines.append(json.dumps({"t": t, "targets": {node: 1.0}, "predicate": pred, "confidence": 0.8,
                                 "context": "vlm", "geometric": {node: label}}))
    (tmp_path / "events.jsonl").write_text("\n".join(lines) + "\n")
    (tmp_path / "truth.json").write_text(json.dumps({"scene0001_00/2": {"is_chair": 1}}))
    assert main(["replay", str(tmp_path / "events.jsonl"), "--truth", str(tmp_path / "truth.json"), "--vocab",
                 str(Path(__file__).parents[1] / "sgbelief" / "configs" / "vocab" / "scannet.yaml"), "--operators", "comod",
                 "--save-graph", str(tmp_path / "maps"), "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["show", str(tmp_path / "maps" / "comod"), "--out", str(tmp_path / "m.png")]) == 1  # ids only
    assert main(["show", str(tmp_path / "maps" / "comod"), "--out", str(tmp_path / "m.png"), "--scannet", str(tmp_path)]) == 0
    _png(tmp_path / "m.png")
    g = load_graph(tmp_path / "maps" / "comod")
    from sgbelief.cli.show import _scannet_boxes

    boxes = _scannet_boxes(tmp_path)
    fig = map_figure(map_state(g, boxes={n: b for n, b in boxes.items() if n in g}))
    try:
        assert len(_objects(fig)) == 2 and _rings(fig) == 1
    finally:
        plt.close(fig)


def _cg_object(class_ids: list[int], confs: list[float], frames: list[int], centre: tuple[float, float, float], seed: int) -> dict:
    pts = np.random.default_rng(seed).normal(centre, 0.2, size=(60, 3))
    return {"class_id": class_ids, "conf": confs, "image_idx": frames, "class_name": [["chair", "table"][c] for c in class_ids],
            "num_detections": len(class_ids), "pcd_np": pts}


def test_show_cli_on_a_conceptgraphs_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    results = {"objects": [_cg_object([0, 0, 1, 0], [0.9, 0.8, 0.6, 0.85], [0, 1, 2, 3], (0.0, 0.0, 0.5), 1),
                           _cg_object([1, 1, 1], [0.9, 0.7, 0.8], [1, 2, 3], (2.0, 1.0, 0.4), 2)],
               "bg_objects": None, "class_names": ["chair", "table"]}
    src = tmp_path / "full_pcd_test.pkl.gz"
    with gzip.open(src, "wb") as f:
        pickle.dump(results, f)
    assert main(["import-cg", str(src), "--operator", "comod", "--out", str(tmp_path / "cg")]) == 0
    assert main(["show", str(tmp_path / "cg"), "--out", str(tmp_path / "cg.png")]) == 0
    _png(tmp_path / "cg.png")
    fig = map_figure(map_state(load_graph(tmp_path / "cg")))
    try:
        objs = _objects(fig)
        assert len(objs) == 2 and all(type(p).__name__ == "Rectangle" for p in objs)
    finally:
        plt.close(fig)


def test_show_draws_one_scene_of_a_multi_scene_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sgbelief.viz.map_state import nodes_by_scene, scene_of

    g = SceneGraph()
    g.add_node("a/1", bbox=((0, 0, 0), (1, 1, 1)))
    g.add_node("b/1", bbox=((0, 0, 0), (2, 2, 1)))
    g.add_node("x", scene="c", centroid=(1, 1, 1))  # the attribute wins over the id
    g.provenance.commit("b/1", "is_car", "e", 0, 3.0, 0.0)
    g.save(tmp_path / "m")
    assert [scene_of(g, n) for n in ("a/1", "b/1", "x")] == ["a", "b", "c"]
    assert nodes_by_scene(g) == {"a": ["a/1"], "b": ["b/1"], "c": ["x"]}
    assert main(["show", str(tmp_path / "m"), "--out", str(tmp_path / "1.png")]) == 0
    assert "the map holds 3 scenes (a, b, c)" in capsys.readouterr().err
    assert main(["show", str(tmp_path / "m"), "--around", "b/1", "--out", str(tmp_path / "2.png")]) == 0
    assert "scenes" not in capsys.readouterr().err  # --around: the node's own scene
    assert main(["show", str(tmp_path / "m"), "--scene", "zz", "--out", str(tmp_path / "3.png")]) == 1
    assert "--scene: no node of the map belongs to scene 'zz'; its scenes: a, b, c" in capsys.readouterr().err
    fig = map_figure(map_state(g, nodes=nodes_by_scene(g)["b"]))
    try:
        assert len(_objects(fig)) == 1
    finally:
        plt.close(fig)
