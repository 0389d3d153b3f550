"""ConceptGraphs drop-in backend on stand-ins with real keys, open3d clouds/boxes and torch similarities."""

from __future__ import annotations

import copy
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("open3d")

import cg_fake_conceptgraph as fake  # noqa: E402

from sgbelief.adapters.conceptgraphs import ClassVocabulary, ConceptGraphsBackend  # noqa: E402
from sgbelief.adapters.conceptgraphs.functions import BeliefLabelledObject  # noqa: E402
from sgbelief.adapters.conceptgraphs.standins import (  # noqa: E402
    DetectionList,
    MapObjectList,
    majority_class,
    make_detection,
)

CLASSES = ["chair", "table", "sofa"]


def cfg(**kw):
    base = dict(downsample_voxel_size=0.05, dbscan_remove_noise=False, dbscan_eps=0.1, dbscan_min_points=10,
                spatial_sim_type="iou", device="cpu", merge_overlap_thresh=0.5, merge_visual_sim_thresh=0.5,
                merge_text_sim_thresh=0.5, obj_min_points=1, obj_min_detections=1)
    base.update(kw)
    return SimpleNamespace(**base)


def blob(center, n=120, seed=0):
    return np.asarray(center, dtype=float) + 0.2 * np.random.default_rng(seed).random((n, 3))


def wrong_label_stream(generation="main", geo_key=False):
    """40 detections of one chair: 'table' more often (low confidence), 'chair' less often (high)."""
    r = np.random.default_rng(1).random(40)
    feat = np.random.default_rng(7).normal(size=16)
    out = []
    for k in range(40):
        is_table = k % 2 == 0 or k % 7 == 1
        cid, conf = (1, 0.5 + 0.15 * r[k]) if is_table else (0, 0.8 + 0.15 * r[k])
        det = make_detection(blob((0, 0, 0), seed=k), cid, CLASSES[cid], conf, k, generation=generation,
                             feature=feat, seed=k)
        if geo_key:
            det["geometric_label"] = "chair"
        out.append(det)
    return out


def run_main(functions, stream, c):
    objects = MapObjectList(device="cpu")
    for det in stream:
        if not objects:
            objects.append(det)
            continue
        objects = functions.merge_detections_to_objects(c, DetectionList([det]), objects, torch.tensor([[1.5]]))
    return objects


# ---------------------------------------------------------------- vocabulary
def test_vocabulary_maps_aliases_overrides_and_unknown_names():
    v = ClassVocabulary.default()
    assert v.predicate("chair") == "is_chair"
    assert v.predicate("Office Chair") == "is_chair"
    assert v.predicate("kitchen table") == "is_table_or_desk"
    assert v.predicate("potted plant") == "is_potted_plant"
    assert v.predicate("wall") is None


# ---------------------------------------------------------------- labels from beliefs
# no class list given: the vocabulary grows from the names detected so far, so the channel's first
# labels can precede their class (warned, by design)
@pytest.mark.filterwarnings("ignore::sgbelief.fusion.label_match.UnmatchedLabelWarning")
def test_majority_keeps_wrong_label_that_comod_with_geometric_channel_does_not():
    stream = wrong_label_stream()
    counts = Counter(d["class_id"][0] for d in stream)
    assert counts[1] > counts[0]  # the detector says "table" more often
    backend = ConceptGraphsBackend("comod", channel=lambda det, node, t: "chair")
    f = backend.functions("main")
    objects = run_main(f, copy.deepcopy(stream), cfg())
    assert len(objects) == 1
    assert majority_class(objects[0]["class_id"]) == 1  # ConceptGraphs' vote: table (wrong)
    assert f.get_most_common_class(objects) == [0]  # beliefs: chair
    beliefs = backend.beliefs(objects[0])
    assert beliefs["is_chair"].mean > 0.5
    assert "is_table_or_desk" not in beliefs or beliefs["is_table_or_desk"].mean <= 0.5
    assert backend.label_of(objects[0]) == "chair"
    # each detection counted exactly once
    assert backend.routed_detections == objects[0]["num_detections"] == 40


# no class list given: the vocabulary grows from the names detected so far, so the channel's first
# labels can precede their class (warned, by design)
@pytest.mark.filterwarnings("ignore::sgbelief.fusion.label_match.UnmatchedLabelWarning")
def test_per_detection_geometric_label_key_on_ali_dev_strict_merge():
    stream = wrong_label_stream("ali-dev", geo_key=True)
    backend = ConceptGraphsBackend("comod")
    f = backend.functions("ali-dev")
    objects = MapObjectList(device="cpu")
    for det in stream:
        if not objects:
            objects.extend(DetectionList([det]))
            continue
        sims = torch.tensor([[1.5]])
        idx = f.match_detections_to_objects(sims, 1.1)
        objects = f.merge_obj_matches(DetectionList([det]), objects, idx, 0.05, False, 0.1, 10, "iou", "cpu")
        # the pipeline's inline relabel loop (Counter vote) cannot overwrite the belief label
        for obj in objects:
            obj["class_name"] = CLASSES[Counter(obj["class_id"]).most_common(1)[0][0]]
    obj = objects[0]
    assert "geometric_label" not in obj
    assert isinstance(obj, BeliefLabelledObject) and isinstance(obj["class_name"], str)
    assert obj["class_name"] == "chair"
    assert CLASSES[Counter(obj["class_id"]).most_common(1)[0][0]] == "table"
    # copies / pickles are plain dicts
    assert type(copy.deepcopy(obj)) is dict


def test_unknown_label_when_nothing_commits():
    backend = ConceptGraphsBackend("comod", unknown_label="unknown", unknown_class_id=-1)
    f = backend.functions("main")
    det = make_detection(blob((0, 0, 0)), 2, "sofa", 0.5, 0)
    objects = MapObjectList([det])
    assert f.get_most_common_class(objects) == [2]  # never seen by the backend: ConceptGraphs' vote
    backend.ensure_node(det)
    assert f.get_most_common_class(objects) == [-1]
    assert backend.label_of(det) == "unknown"


def test_without_abstention_the_most_probable_claimed_class_is_written():
    """abstain=False: an object whose classes all stay at or below tau gets the most probable one;
    the default abstains (unknown)."""
    labels = {}
    for abstain in (True, False):
        backend = ConceptGraphsBackend("comod", abstain=abstain, class_names=["chair", "sofa", "table"],
                                       print_summary=False)
        backend.graph.add_node("v")
        backend.route_detection(make_detection(blob((0, 0, 0)), 1, "sofa", 0.45, 0), {"v": 1.0})
        backend.route_detection(make_detection(blob((0, 0, 0)), 0, "chair", 0.3, 1), {"v": 1.0})
        p = {k: b.mean for k, b in backend.graph.beliefs("v").items()}
        assert max(p.values()) <= 0.5 and p["is_sofa"] > p["is_chair"]
        labels[abstain] = backend.committed_predicate("v")
    assert labels == {True: None, False: "is_sofa"}


@pytest.mark.parametrize("order", ["stools_first", "chairs_first", "interleaved"])
def test_the_label_weighs_each_class_against_its_exclusive_rivals(order):
    """Four stool claims at 0.7 and two chair claims at 0.95, no channel, cold start: both commit
    and the independent means rank chair first (a Beta's mean is its claims' average confidence,
    whatever their number). Ranked by rules.exclusive_marginal (each class's mass against its
    rival's), stool comes first, in any order of arrival; a baseline keeps its own probability."""
    names = ["chair", "stool", "sofa"]
    stools, chairs = [("stool", 0.7)] * 4, [("chair", 0.95)] * 2
    claims = {"stools_first": stools + chairs, "chairs_first": chairs + stools,
              "interleaved": [stools[0], chairs[0], stools[1], chairs[1], stools[2], stools[3]]}[order]

    def run(operator):
        backend = ConceptGraphsBackend(operator, class_names=names, print_summary=False)
        backend.graph.add_node("v")
        for t, (name, c) in enumerate(claims):
            backend.route_detection(make_detection(blob((0, 0, 0)), names.index(name), name, c, t), {"v": 1.0})
        return backend

    comod = run("comod")
    means = {k: b.mean for k, b in comod.graph.beliefs("v").items()}
    assert min(means.values()) > 0.5 and means["is_chair"] > means["is_stool"]
    assert comod.committed_predicate("v") == "is_stool"
    nb = run("naive_bayes")
    p = {k: nb.graph.probability("v", k) for k in ("is_chair", "is_stool")}
    assert nb.committed_predicate("v") == max(p, key=p.get)


def test_the_backend_keeps_exclusive_classes_apart_unless_configured():
    assert ConceptGraphsBackend("comod", print_summary=False).operator.config.exclusive_evidence == "none"
    on = ConceptGraphsBackend("comod", operator_config={"exclusive_evidence": "rivals"}, print_summary=False)
    assert on.operator.config.exclusive_evidence == "rivals"
    assert on.operator.config.geometric_evidence == "label"  # the backend's other default still applies


def test_the_backend_reads_scores_with_the_agreement_shift_unless_configured_and_says_so():
    """The map-wide Dawid-Skene consensus is replaced in the backend by the agreement shift
    (docs/conceptgraphs.md, "Labels out"); a config that sets the calibration keeps its own; the
    summary names both settings."""
    off = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    assert off.operator.config.calibration.consensus.method == "agreement_shift"
    assert off.operator.consensus_classes == frozenset({"is_chair", "is_table", "is_sofa"})
    on = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False,
                              operator_config={"calibration": {"consensus": {"method": "dawid_skene"}}})
    assert on.operator.consensus_classes == frozenset({"is_chair", "is_table", "is_sofa"})
    # with the consensus off, the contested labels' consensus gate has nothing to ask: the backend says refuse
    assert off.operator.config.contested_labels == "refuse"
    assert on.operator.config.contested_labels == "consensus"
    text = off.summary([]).format()
    assert ("operator: comod (geometric_evidence=label, consensus=agreement_shift, exclusive_evidence=none, "
            "recalled_verdicts=retroactive, contested_labels=refuse)") in text
    assert off.summary([]).to_dict()["operator"]["consensus"] == "agreement_shift"


def test_a_merge_moves_the_operators_claim_table_with_the_beliefs():
    """ConceptGraphs merges two map objects: the consensus' claims and the support counts of the
    absorbed object become the kept one's (they were left under the absorbed id)."""
    be = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False,
                              operator_config={"calibration": {"consensus": {"method": "dawid_skene"}}})
    a = make_detection(blob((0, 0, 0), seed=1), 0, "chair", 0.8, 0, mask_idx=0, seed=1)
    b = make_detection(blob((3, 0, 0), seed=2), 0, "chair", 0.7, 0, mask_idx=1, seed=2)
    na, nb = be.ensure_node(a), be.ensure_node(b)
    be.route_detection(a, {na: 1.0})
    be.route_detection(b, {nb: 1.0})
    be.flush()
    cons = be.operator._consensus[id(be.graph.provenance)][1]
    per_node = Counter(cons.node)
    assert set(per_node) == {na, nb}
    n = sum(per_node.values())
    be.migrate(a, b)
    assert Counter(cons.node) == {na: n}
    assert cons.counts == {na: {"is_chair": n}}
    assert be.operator._claims_so_far(be.graph.provenance, na, "is_chair") == n
    probas = cons.fit_consensus()
    assert probas.shape[0] == 1 and cons.task_of(nb) == cons.task_of(na) == 0


# ---------------------------------------------------------------- return contracts
def test_same_return_contract_as_original_on_stand_ins():
    c = cfg()
    rng = np.random.default_rng(3)
    frames = []
    for t in range(4):
        frames.append([make_detection(blob((3 * j, 0, 0), seed=10 * t + j), j % 3, CLASSES[j % 3],
                                      0.7, t, mask_idx=j, feature=rng.normal(size=16) if t == 0 else None,
                                      seed=10 * t + j) for j in range(3)])

    def drive(merge, frames):
        objects = MapObjectList()
        for dets in frames:
            if not objects:
                objects.extend(dets)
                continue
            sim = torch.full((len(dets), len(objects)), float("-inf"))
            for i in range(len(dets)):
                sim[i, i] = 1.4
            sim[2, 2] = float("-inf")  # one unmatched detection per frame -> new object
            objects = merge(c, DetectionList(dets), objects, sim)
        return objects

    ref = drive(fake.merge_detections_to_objects, copy.deepcopy(frames))
    backend = ConceptGraphsBackend("comod")
    ours = drive(backend.functions("main").merge_detections_to_objects, copy.deepcopy(frames))
    assert type(ours) is MapObjectList and len(ours) == len(ref)
    for a, b in zip(ours, ref):
        assert a["class_id"] == b["class_id"] and a["image_idx"] == b["image_idx"]
        assert a["num_detections"] == b["num_detections"]
        assert len(a["pcd"].points) == len(b["pcd"].points)
        assert np.allclose(np.asarray(a["bbox"].get_box_points()), np.asarray(b["bbox"].get_box_points()))
        assert torch.allclose(a["clip_ft"], b["clip_ft"])
    assert len(backend.graph) == len(ours)
    assert backend.graph.evidence_count() == sum(o["num_detections"] for o in ours)


def _two_candidates(targeting: str):
    """One detection whose association row has two candidates above the threshold (1.5, 0.5)."""
    backend = ConceptGraphsBackend("majority", targeting=targeting)
    f = backend.functions("ali-dev")
    a = make_detection(blob((0, 0, 0)), 0, "chair", 0.9, 0, generation="ali-dev", seed=1)
    b = make_detection(blob((0.1, 0, 0)), 0, "chair", 0.9, 0, mask_idx=1, generation="ali-dev", seed=2)
    objects = MapObjectList([a, b])
    det = make_detection(blob((0.05, 0, 0)), 0, "chair", 0.9, 1, generation="ali-dev", seed=3)
    idx = f.match_detections_to_objects(torch.tensor([[1.5, 0.5]]), 0.2)
    backend.keep_reports = True
    objects = f.merge_obj_matches(DetectionList([det]), objects, idx, 0.05, False, 0.1, 10, "iou", "cpu")
    return backend, a, b, objects


def test_a_detections_claims_go_whole_to_the_object_it_merges_into_by_default():
    backend, a, b, objects = _two_candidates("merge")
    targets = [dict((o.node, o.mass) for o in r.targets) for r in backend.reports]
    # a's and b's own detections, and the new one whole to a (the argmax, which its geometry joins)
    assert sorted(targets, key=str) == sorted([{str(a["id"]): 1.0}, {str(a["id"]): 1.0}, {str(b["id"]): 1.0}], key=str)
    assert objects[0]["num_detections"] == 2 and objects[1]["num_detections"] == 1
    with pytest.raises(ValueError, match="targeting"):
        ConceptGraphsBackend("majority", targeting="argmax")


def test_spread_targeting_over_objects_above_threshold():
    backend = ConceptGraphsBackend("majority", targeting="spread")
    f = backend.functions("ali-dev")
    a = make_detection(blob((0, 0, 0)), 0, "chair", 0.9, 0, generation="ali-dev", seed=1)
    b = make_detection(blob((0.1, 0, 0)), 0, "chair", 0.9, 0, mask_idx=1, generation="ali-dev", seed=2)
    objects = MapObjectList([a, b])
    det = make_detection(blob((0.05, 0, 0)), 0, "chair", 0.9, 1, generation="ali-dev", seed=3)
    sims = torch.tensor([[1.5, 0.5]])  # 0.5 is above the threshold 0.2 -> T = (0.75, 0.25)
    idx = f.match_detections_to_objects(sims, 0.2)
    assert idx == [0]
    backend.keep_reports = True
    objects = f.merge_obj_matches(DetectionList([det]), objects, idx, 0.05, False, 0.1, 10, "iou", "cpu")
    targets = [dict((o.node, o.mass) for o in r.targets) for r in backend.reports]
    assert targets[-1] == pytest.approx({str(a["id"]): 0.75, str(b["id"]): 0.25})
    assert objects[0]["num_detections"] == 2 and objects[1]["num_detections"] == 1


# ---------------------------------------------------------------- post-processing
def test_merge_objects_migrates_beliefs_and_counts_each_detection_once():
    c = cfg(merge_overlap_thresh=0.3)
    feat = np.random.default_rng(5).normal(size=16)
    objs = [make_detection(blob((0, 0, 0), seed=s), 0, "chair", 0.8, s, feature=feat, seed=s) for s in range(3)]
    objs.append(make_detection(blob((9, 9, 9)), 1, "table", 0.8, 7, feature=-feat, seed=9))
    backend = ConceptGraphsBackend("comod")
    f = backend.functions("main")
    objects = MapObjectList(objs)
    for o in objects:
        backend.ensure_node(o)
    before = backend.graph.evidence_count()
    assert len(backend.graph) == 4 and before == 4
    ref = fake.merge_objects(c, MapObjectList(copy.deepcopy(objs)))
    merged = f.merge_objects(c, objects)
    assert len(merged) == len(ref) == 2
    assert sorted(o["num_detections"] for o in merged) == sorted(o["num_detections"] for o in ref)
    assert backend.graph.evidence_count() == before  # nothing lost, nothing counted twice
    live = [n for n in backend.graph.nodes()]
    assert len(live) == 2
    assert {backend.node_of(o) for o in merged} == set(live)
    # the object merged away twice by ConceptGraphs' loop still contributes once
    node = backend.node_of(merged[0] if merged[0]["num_detections"] > 1 else merged[1])
    assert backend.graph.evidence_count(node) == 3


def test_filter_objects_marks_removed_nodes():
    c = cfg(obj_min_detections=2)
    backend = ConceptGraphsBackend("comod")
    f = backend.functions("main")
    objects = MapObjectList([make_detection(blob((0, 0, 0)), 0, "chair", 0.8, 0)])
    backend.ensure_node(objects[0])
    node = backend.node_of(objects[0])
    out = f.filter_objects(c, objects)
    assert len(out) == 0
    assert backend.graph.nx.nodes[node]["cg_filtered"] is True


# ---------------------------------------------------------------- patching
def test_patch_swaps_and_restores_every_binding():
    mods = fake.install()
    try:
        ut, mp, sc = mods["conceptgraph.slam.utils"], mods["conceptgraph.slam.mapping"], mods["conceptgraph.slam.slam_classes"]
        pipe = mods["conceptgraph.slam.cfslam_pipeline_batch"]
        saved = {(m.__name__, n): getattr(m, n) for m in (ut, mp, pipe)
                 for n in ("merge_obj2_into_obj1", "merge_objects", "filter_objects", "merge_detections_to_objects",
                           "MapObjectList") if hasattr(m, n)}
        DL = sc.DetectionList
        gmc = DL.__dict__["get_most_common_class"]
        with pytest.raises(TypeError):
            sc.MapObjectList(device="cpu")
        backend = ConceptGraphsBackend("comod")
        with backend.patch():
            assert backend.generation == "main"
            for (modname, name), old in saved.items():
                assert getattr(__import__("sys").modules[modname], name) is not old, (modname, name)
            assert DL.__dict__["get_most_common_class"] is not gmc
            assert issubclass(sc.DetectionList, DL)
            objects = pipe.MapObjectList(device="cpu")  # kwargs accepted while patched
            objects.append(make_detection(blob((0, 0, 0)), 1, "table", 0.6, 0))
            det = make_detection(blob((0, 0, 0)), 0, "chair", 0.9, 1, seed=1)
            objects = pipe.merge_detections_to_objects(cfg(), DetectionList([det]), objects, torch.tensor([[1.2]]))
            # two claims (chair, table); the backend keeps exclusive classes apart (exclusive_evidence: none)
            claims = [e for e in backend.graph.provenance.iter_entries() if e.verdict is None or e.verdict.is_claim]
            assert len(claims) == 2 and backend.graph.evidence_count() == 2
            objects.get_most_common_class()
        for (modname, name), old in saved.items():
            assert getattr(__import__("sys").modules[modname], name) is old, (modname, name)
        assert sc.DetectionList is DL and DL.__dict__["get_most_common_class"] is gmc
        with pytest.raises(TypeError):
            pipe.MapObjectList(device="cpu")
    finally:
        fake.uninstall()


def test_stand_in_lists_accept_keywords():
    assert MapObjectList(device="cuda") == []
    assert DetectionList([1, 2], device="cpu") == [1, 2]


# ---------------------------------------------------------------- relabel what changed
class ReleasingOperator:
    """A FusionOperator (protocol only, not a BaseOperator): majority vote, plus a queued batch of
    claims on another node that ``tick`` releases at time ``at`` and reports as a QueueResolution."""

    name = "releasing"

    def __init__(self, node, predicate, at):
        from sgbelief.fusion.registry import make_reference_operator

        self.inner = make_reference_operator("majority")
        self.held = (node, predicate, at)

    def update(self, graph, event, channel=None):
        return self.inner.update(graph, event, channel)

    def probability(self, graph, node, predicate):
        return self.inner.probability(graph, node, predicate)

    def tick(self, graph, t):
        from sgbelief.fusion.events import EvidenceEvent
        from sgbelief.fusion.protocol import QueueResolution

        out = list(self.inner.tick(graph, t))
        if self.held is not None and t >= self.held[2]:
            node, pred, _ = self.held
            self.held = None
            for k in range(3):
                self.inner.update(graph, EvidenceEvent({node: 1.0}, pred, 0.99, "queue", t, id=f"held-{k}"))
            out.append(QueueResolution("held-0", node, pred, "released", t))
        return out


def test_ali_dev_relabels_an_untouched_object_whose_beliefs_a_queue_release_changed():
    a = make_detection(blob((0, 0, 0)), 0, "chair", 0.9, 0, generation="ali-dev", seed=1)
    b = make_detection(blob((5, 0, 0)), 1, "table", 0.9, 0, mask_idx=1, generation="ali-dev", seed=2)
    for key, value in (("class_id", 2), ("conf", np.float32(0.6)), ("image_idx", 0), ("mask_idx", 1)):
        b[key].append(value)  # b's history: table at 0.9, then sofa at 0.6 (class names by id: CLASSES)
    backend = ConceptGraphsBackend(ReleasingOperator(str(b["id"]), "is_sofa", at=1), class_names=CLASSES)
    f = backend.functions("ali-dev")
    objects = MapObjectList([a, b])
    f.sync_labels(objects)
    assert [o["class_name"] for o in objects] == ["chair", "table"]
    # frame 1: one detection, on a only; the tick at t = 1 releases three sofa claims onto b
    det = make_detection(blob((0, 0, 0)), 0, "chair", 0.9, 1, generation="ali-dev", seed=3)
    sims = torch.tensor([[1.5, float("-inf")]])
    objects = f.merge_obj_matches(DetectionList([det]), objects, f.match_detections_to_objects(sims, 1.1),
                                  0.05, False, 0.1, 10, "iou", "cpu")
    assert backend.label_of(objects[1]) == "sofa"
    assert objects[1]["class_name"] == "sofa"  # relabelled though no detection touched it
    objects[1]["class_name"] = "table"  # the script's vote write keeps the belief label
    assert objects[1]["class_name"] == "sofa"


def test_a_class_no_detection_named_is_labelled_from_the_geometric_labels():
    """A sofa the detector always calls 'table': comod observes 'sofa' from the channel (geometric
    evidence ``label``), the backend considers is_sofa at that object and names it 'sofa' (its
    class id from the class list), though no detection said so."""
    feat = np.random.default_rng(7).normal(size=16)
    stream = [make_detection(blob((0, 0, 0), seed=k), 1, "table", 0.9, k, feature=feat, seed=k) for k in range(8)]
    backend = ConceptGraphsBackend("comod", channel=lambda det, node, t: "sofa", class_names=CLASSES)
    f = backend.functions("main")
    objects = run_main(f, copy.deepcopy(stream), cfg())
    assert majority_class(objects[0]["class_id"]) == 1  # ConceptGraphs' vote: table
    assert backend.label_of(objects[0]) == "sofa"
    assert f.get_most_common_class(objects) == [2]
    assert backend.summary(objects).unknown == 0
    # with the claimed pair's verdict alone the object commits to nothing
    verdict_only = ConceptGraphsBackend("comod", channel=lambda det, node, t: "sofa", class_names=CLASSES,
                                        operator_config={"geometric_evidence": "verdict"})
    g = verdict_only.functions("main")
    objects = run_main(g, copy.deepcopy(stream), cfg())
    assert verdict_only.label_of(objects[0]) == "unknown"
    assert verdict_only.summary(objects).unknown == 1


def test_the_backend_observes_labels_unless_its_config_says_otherwise():
    assert ConceptGraphsBackend("comod").operator.config.geometric_evidence == "label"
    assert ConceptGraphsBackend("comod", operator_config={"tau": 0.6}).operator.config.geometric_evidence == "label"
    kept = ConceptGraphsBackend("comod", operator_config={"geometric_evidence": "verdict"})
    assert kept.operator.config.geometric_evidence == "verdict"
    forced = ConceptGraphsBackend("comod", operator_config={"geometric_evidence": "verdict"}, geometric_evidence="none")
    assert forced.operator.config.geometric_evidence == "none"
    from sgbelief.errors import ConfigError

    with pytest.raises(ConfigError, match="geometric_evidence"):
        ConceptGraphsBackend("comod", geometric_evidence="sometimes")


def test_the_summary_says_why_a_label_differs_from_the_vote():
    """ConceptGraphs' loop with no channel and confidences that carry no information (issue #30):
    comod's label differs from the vote where the vote's count is tied (its pick is its tie rule;
    comod's the confidence-weighted ranking), where the claims routed to an object are not its
    own detections (a detection split between two candidates, merged into the other), where the
    confidences outrank a count, and where nothing commits. The summary names each case."""
    names = ["chair", "stool", "sofa"]
    backend = ConceptGraphsBackend("comod", class_names=names, print_summary=False)
    objects = {}

    def obj(key, claims):  # a map object whose own detections are `claims`: each routed to it whole
        first, *rest = claims
        o = make_detection(blob((0, 0, 0)), names.index(first[0]), first[0], first[1], 0, mask_idx=len(objects))
        node = backend.ensure_node(o)
        for t, (name, c) in enumerate(rest, start=1):
            backend.route_detection(make_detection(blob((0, 0, 0)), names.index(name), name, c, t), {node: 1.0})
            o["class_id"].append(names.index(name))
        objects[key] = o
        return node

    obj("tie", [("chair", 0.6), ("stool", 0.9), ("chair", 0.62), ("stool", 0.95)])
    split = obj("split", [("chair", 0.7), ("chair", 0.7), ("sofa", 0.7)])
    other = obj("other", [("sofa", 0.8)])
    for t in (5, 6):  # two sofa detections split between `split` and `other`; ConceptGraphs merged them into `other`
        backend.route_detection(make_detection(blob((0, 0, 0)), 2, "sofa", 0.95, t), {split: 0.5, other: 0.5})
        objects["other"]["class_id"].append(2)
    obj("ranking", [("stool", 0.56), ("stool", 0.56), ("stool", 0.56), ("chair", 0.97), ("chair", 0.97)])
    obj("unknown", [("sofa", 0.3)])
    s = backend.summary(list(objects.values()))
    got = {d["vote"] + " -> " + d["label"]: d["why"] for d in s.differing}
    assert got == {"chair -> stool": "tie", "chair -> sofa": "split", "stool -> chair": "ranking",
                   "sofa -> unknown": "unknown"}
    assert "(unknown 1, tie 1, split 1, ranking 1)" in s.format()
    # without the objects the vote is over the routed claims: the split object's vote is then sofa
    assert {d["vote"] for d in backend.summary().differing} == {"chair", "stool", "sofa"}
