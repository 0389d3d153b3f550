from __future__ import annotations

import collections
import math

import numpy as np
import pytest
import yaml

from sgbelief.errors import ConfigError
from sgbelief.eval.formats import read_events, read_nodes, read_truth
from sgbelief.eval.sim_config import load_sim_config, load_vocabulary
from sgbelief.eval.sim_diagnostics import most_contradicted, suite_statistics
from sgbelief.eval.simulate import simulate


@pytest.fixture(scope="module")
def outdoor_small():
    cfg = load_sim_config("outdoor", scenes=["d00", "d04"])
    return simulate(cfg, seed=7)


@pytest.fixture(scope="module")
def indoor_small():
    cfg = load_sim_config("indoor", scenes=[f"scene{i:04d}_00" for i in range(20)], scale=0.5)
    return simulate(cfg, seed=7)


def _tiny(kind: str):
    if kind == "outdoor":
        return load_sim_config("outdoor", scenes=["d00"], scale=0.3)
    return load_sim_config("indoor", scenes=["scene0000_00", "scene0001_00"], scale=0.3)


@pytest.mark.parametrize("kind", ["outdoor", "indoor"])
def test_same_seed_byte_identical_files(tmp_path, kind):
    cfg = _tiny(kind)
    simulate(cfg, seed=3, out_dir=tmp_path / "a")
    simulate(cfg, seed=3, out_dir=tmp_path / "b")
    simulate(cfg, seed=4, out_dir=tmp_path / "c")
    for name in ("events.jsonl", "truth.json", "nodes.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert (tmp_path / "a" / "events.jsonl").read_bytes() != (tmp_path / "c" / "events.jsonl").read_bytes()


def test_written_files_are_valid(tmp_path, outdoor_small):
    paths = outdoor_small.write(tmp_path)
    events = read_events(paths["events"])
    truth = read_truth(paths["truth"])
    nodes = read_nodes(paths["nodes"])
    assert len(events) == len(outdoor_small.claims) > 1000
    assert set(truth) == set(nodes.nodes)
    ts = [e.t for e in events]
    assert ts == sorted(ts)
    for e in events[:2000]:
        assert set(e.geometric) <= set(e.targets) and set(e.targets) <= set(truth)
        assert sum(e.targets.values()) <= 1 + 1e-9
        assert min(e.targets.values()) >= 0.01
    assert all(p in truth[next(iter(truth))] for p in ["is_car", "is_pedestrian", "is_traffic_sign"])
    n = next(iter(nodes.nodes.values()))
    assert "is_stationary" in n.geometric_predicates and "road_distance_px" in n.attributes


def test_profiles_differ_only_in_confidence(outdoor_small):
    a = outdoor_small.events_for("vlm_a")
    b = outdoor_small.events_for("vlm_b")
    assert len(a) == len(b)
    for ea, eb in zip(a, b):
        assert (ea.t, ea.id, ea.targets, ea.predicate, ea.geometric) == (eb.t, eb.id, eb.targets, eb.predicate,
                                                                          eb.geometric)
        assert ea.context == "llava-1.6" and eb.context == "qwen3-vl"
    ca = np.array([e.confidence for e in a])
    cb = np.array([e.confidence for e in b])
    assert np.mean(np.abs(ca - cb)) > 0.05
    # per predicate both confidences are increasing functions of the same latent score
    z = np.array([c.z for c in outdoor_small.claims])
    for pred in ["is_car", "is_pedestrian", "is_traffic_sign"]:
        m = np.array([e.predicate == pred for e in a])
        order = np.argsort(z[m], kind="stable")
        assert np.all(np.diff(ca[m][order]) >= 0) and np.all(np.diff(cb[m][order]) >= 0)


def test_channel_swap_changes_only_geometric(outdoor_small):
    o = outdoor_small.events_for(channel="oracle")
    s = outdoor_small.events_for(channel="segmenter")
    assert [(e.t, e.targets, e.confidence) for e in o] == [(e.t, e.targets, e.confidence) for e in s]
    assert sum(e.geometric != f.geometric for e, f in zip(o, s)) > 0.1 * len(o)


def test_outdoor_realised_statistics(outdoor_small):
    st = suite_statistics(outdoor_small)
    freq = st["label_frequency"]
    assert freq["car"] == max(freq[k] for k in freq if k not in ("sidewalk", "road"))
    assert freq["person"] < 0.08 and freq["traffic sign"] < 0.08
    assert abs(outdoor_small.stats["segmenter_miou"] - 0.43) <= 0.05
    assert 0.05 < st["low_confidence_fraction"] < 0.5
    assert st["masses_at_or_below_tau_t"] > 0.05  # tiny masses are left for the operator's tau_T filter
    assert st["hallucinated_fraction"] > 0.02
    assert 0 < st["bottom_rate"] < 0.5
    confs = np.array([e.confidence for e in outdoor_small.events])
    assert (confs > 0.9).mean() > 0.05
    hard = most_contradicted(outdoor_small)
    assert hard is not None and hard["events"] >= 20 and hard["contradictions"] >= 5
    # confidently wrong claims: pedestrian asserted (c >= 0.5) on a car
    nodes = outdoor_small.nodes.nodes
    assert any(c.predicate == "is_pedestrian" and c.primary and nodes[c.primary].label == "car" and c.z > 0
               for c in outdoor_small.claims)


def test_indoor_statistics_and_candidate_filter(indoor_small):
    st = suite_statistics(indoor_small)
    freq = st["label_frequency"]
    assert max(freq, key=freq.get) == "chair"
    assert abs(indoor_small.stats["segmenter_miou"] - 0.43) <= 0.05
    filt = indoor_small.config.detector.candidate_filter
    nodes = indoor_small.nodes.nodes
    for e in indoor_small.events:
        if e.predicate in filt:
            assert all(nodes[n].label in filt[e.predicate] for n in e.targets)
    n = next(v for v in nodes.values() if v.label == "chair")
    assert n.front is not None and "is_workspace_height" in n.geometric_predicates


def test_detector_records_source_keeps_claims():
    cfg = _tiny("indoor")
    par = simulate(cfg, seed=1)
    rec = simulate(cfg, seed=1, fm_source="detector_records")
    assert [(c.t, c.targets, c.predicate) for c in par.claims] == [(c.t, c.targets, c.predicate) for c in rec.claims]
    zp = np.array([c.z for c in par.claims])
    zr = np.array([c.z for c in rec.claims])
    assert not np.allclose(zp, zr)
    # real detector scores are >= 0.3, so chair claims' latent scores are >= logit(0.3)
    chair = np.array([c.predicate == "is_chair" for c in rec.claims])
    assert zr[chair].min() >= math.log(0.3 / 0.7) - 1e-6


def test_config_errors_name_the_key(tmp_path):
    raw = yaml.safe_load(open(load_sim_config.__globals__["config_dir"]() / "sim" / "outdoor.yaml"))
    raw["detector"]["box_jitter"] = -1
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"detector\.box_jitter"):
        load_sim_config(p)
    raw = yaml.safe_load(open(load_sim_config.__globals__["config_dir"]() / "sim" / "outdoor.yaml"))
    raw["classes"]["hovercraft"] = raw["classes"]["car"]
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match="hovercraft"):
        load_sim_config(p)
    with pytest.raises(ConfigError, match="not found"):
        load_sim_config("no_such_suite")
    with pytest.raises(ConfigError, match="profile"):
        simulate(_tiny("outdoor"), seed=0, profile="vlm_z")


def test_labels_match_vocabulary():
    for name in ("outdoor", "indoor"):
        cfg = load_sim_config(name)
        vocab = load_vocabulary(cfg.vocabulary)
        assert set(cfg.classes) <= set(vocab["labels"])
        assert set(cfg.evaluated_predicates) <= set(vocab["predicates"])
        assert {"vlm_a", "vlm_b"} <= set(cfg.vlm.profiles)
