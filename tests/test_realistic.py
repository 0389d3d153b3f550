"""The realistic suite (sgbelief.eval.realistic): seeded smoke tests of its generative model.

Statistical checks use one seed of the shipped config (about 650 objects, 4,000-6,000 claims per
detector) with the tolerance stated next to each assertion.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from sgbelief.cli import main
from sgbelief.errors import ConfigError
from sgbelief.eval.realistic import (
    KINDS, calibration_records, detector_rates, generate_world, realistic_cell, stream_records,
)
from sgbelief.eval.realistic_config import load_realistic_config
from sgbelief.eval.realistic_report import evidence_status, score_cell

#: ScanNet v2 instance shares per NYU40 class, % of labelled instances without wall / floor /
#: ceiling: the `count` column of ScanNet's scannetv2-labels.combined.tsv summed by `nyu40class`
#: (hand-copied; docs/simulation.md lists them all)
SCANNET_SHARES = {"otherprop": 22.8, "chair": 15.1, "otherfurniture": 6.7, "door": 6.6, "books": 5.3,
                  "cabinet": 4.8, "table": 4.3, "otherstructure": 3.5, "window": 3.2, "pillow": 2.5,
                  "picture": 2.3, "box": 2.3, "desk": 1.8, "shelves": 1.7, "sofa": 1.3, "sink": 1.3, "bed": 1.0,
                  "toilet": 0.7, "refridgerator": 0.6, "television": 0.6}
EIGHT = ("is_chair", "is_sofa", "is_bed", "is_table_or_desk", "is_toilet", "is_tv", "is_sink", "is_refrigerator")


@pytest.fixture(scope="module")
def world():  # type: ignore[no-untyped-def]
    return generate_world(0)


def test_config_mixture_reproduces_scannet_shares() -> None:
    """The layout model's expected label shares (annotated objects) match ScanNet's within 0.6
    percentage points for every class above 1 %, and within 35 % relative below."""
    cfg = load_realistic_config()
    shares = cfg.expected_label_shares()
    annotated = 1.0 - shares.get(None, 0.0)
    for label, pub in SCANNET_SHARES.items():
        got = 100 * shares[label] / annotated
        tol = 0.6 if pub > 1.0 else 0.35 * pub
        assert abs(got - pub) <= tol, (label, got, pub)


def test_world_class_shares_and_ambiguous_share(world) -> None:  # type: ignore[no-untyped-def]
    """A seed's realised label shares follow the config's mixture (binomial 4-sigma bands); most
    objects bear a label that asserts none of the eight predicates, a third or more an other-class
    label, and since NYU40 labels are exhaustive only the unannotated ones decide nothing."""
    cfg = world.config
    labels = [lab for room in world.rooms for lab in room.labels]
    n = len(labels)
    assert 400 < n < 1000
    count = Counter(labels)
    for label, p in cfg.expected_label_shares().items():
        sd = math.sqrt(p * (1 - p) / n)
        # rooms are clusters (a bathroom brings its toilet and sink): widen the band by 2
        assert abs(count[label] / n - p) <= 8 * sd + 0.005, (label, count[label] / n, p)
    cell = world.cell("rfcn", "mesh", "c")
    silent = sum(1 for lab in labels if all(cell.table.outcome(p, lab) is None for p in EIGHT))
    assert silent / n <= 0.15  # unannotated objects only: other* denies each of the eight
    asserts_none = sum(1 for lab in labels if all(cell.table.outcome(p, lab) != 1 for p in EIGHT))
    # cabinets, desks, other* + shelves + books + box + pillow + towel + ... + unannotated
    assert 0.60 <= asserts_none / n <= 0.90
    other = sum(1 for lab in labels if lab in ("otherprop", "otherfurniture", "otherstructure", "shelves", None))
    assert 0.30 <= other / n <= 0.50
    # every room type of the config is present (stratified), and rooms hold ScanNet-like counts
    assert {r.room_type for r in world.rooms} == set(cfg.room_types)
    assert 15 <= n / len(world.rooms) <= 40


def test_views_see_a_few_objects_per_frame(world) -> None:  # type: ignore[no-untyped-def]
    vis = np.asarray([v.visible.size for vs in world.views for v in vs])
    assert 3.0 <= vis.mean() <= 12.0
    assert (vis == 0).mean() < 0.1
    # co-visibility: most frames see at least two objects
    assert (vis >= 2).mean() > 0.8


@pytest.mark.parametrize("detector", ["rfcn", "ssd"])
def test_claims_follow_the_records(world, detector: str) -> None:  # type: ignore[no-untyped-def]
    """Matched/unmatched proportions per class follow the detector's records (Poisson 4-sigma), the
    recall of visible detectable objects is the records' recall (binomial 4-sigma), and the scores
    are the stream half's records (Kolmogorov-Smirnov p > 1e-3 against the pool they come from)."""
    cfg = world.config
    cl = world.claims(detector)
    rates = detector_rates(detector)
    coco = list(cfg.detection.coco_ids)
    rec = stream_records(detector)
    held = calibration_records(detector)
    assert len(rec) + len(held) == len(__import__("sgbelief.eval.detector_records", fromlist=["x"])
                                       .load_detector_records(cfg.detection.records[detector]))
    visible = Counter()
    for r, vs in enumerate(world.views):
        for v in vs:
            for o in v.visible:
                c = world.rooms[r].coco[o]
                if c is not None:
                    visible[c] += 1
    for k, name in enumerate(coco):
        mine = cl.coco == k
        tp = int((mine & (cl.kind == 0)).sum())
        fp = int((mine & (cl.kind > 0)).sum())
        recall, ratio = rates[name]
        n = visible[name]
        if n:
            assert abs(tp - recall * n) <= 4 * math.sqrt(n * recall * (1 - recall)) + 2, (name, tp, recall * n)
        if tp:
            assert abs(fp - ratio * tp) <= 4 * math.sqrt(ratio * tp) + 2, (name, fp, ratio * tp)
        cid = cfg.detection.coco_ids[name]
        for y, sel in ((1, mine & (cl.kind == 0)), (0, mine & (cl.kind > 0))):
            pool = rec.score[(rec.class_id == cid) & (rec.matched == y)]
            assert np.isin(cl.score[sel], pool).all()  # resampled from the stream half, never invented
    kinds = Counter(KINDS[k] for k in cl.kind)
    assert kinds["matched"] > 0 and kinds["localisation"] > 0 and kinds["similar"] > 0 and kinds["background"] > 0


def test_scores_resample_the_records_with_per_object_persistence() -> None:
    """Without persistence the scores of each (class, matched) are an i.i.d. sample of the stream
    half's records (Kolmogorov-Smirnov p > 1e-3 for every pool with >= 30 claims); with the shipped
    persistence 0.5, half of the score quantile's variance sits between objects (intraclass
    correlation of the normal scores within [0.3, 0.7])."""
    cfg = load_realistic_config()
    iid = cfg.model_copy(update={"detection": cfg.detection.model_copy(update={"score_persistence": 0.0})})
    for detector in ("rfcn", "ssd"):
        rec = stream_records(detector)
        cl = generate_world(0, iid).claims(detector)
        for k, cid in enumerate(cfg.detection.coco_ids.values()):
            for y, sel in ((1, (cl.coco == k) & (cl.kind == 0)), (0, (cl.coco == k) & (cl.kind > 0))):
                pool = rec.score[(rec.class_id == cid) & (rec.matched == y)]
                if sel.sum() >= 30:
                    assert stats.ks_2samp(cl.score[sel], pool).pvalue > 1e-3, (detector, cid, y)
    world = generate_world(0)
    cl = world.claims("ssd")
    rec = stream_records("ssd")
    z = np.empty(len(cl))
    for k, cid in enumerate(cfg.detection.coco_ids.values()):
        for y, sel in ((1, (cl.coco == k) & (cl.kind == 0)), (0, (cl.coco == k) & (cl.kind > 0))):
            pool = np.sort(rec.score[(rec.class_id == cid) & (rec.matched == y)])
            # mid-rank of each score in its pool -> normal score (ties share their mid-rank)
            lo, hi = np.searchsorted(pool, cl.score[sel], "left"), np.searchsorted(pool, cl.score[sel], "right")
            z[sel] = stats.norm.ppf((lo + hi) / 2 / pool.size)
    groups: dict[tuple[int, int, int, int], list[float]] = {}
    for i in range(len(cl)):
        groups.setdefault((int(cl.room[i]), int(cl.obj[i]), int(cl.coco[i]), int(cl.kind[i] == 0)), []).append(z[i])
    big = [np.asarray(g) for g in groups.values() if len(g) >= 5]
    within = np.mean([g.var(ddof=1) for g in big])
    between = np.var([g.mean() for g in big], ddof=1) - within / np.mean([len(g) for g in big])
    icc = between / (between + within)
    assert 0.3 <= icc <= 0.7, icc


def test_unmatched_claims_land_on_other_objects(world) -> None:  # type: ignore[no-untyped-def]
    cl = world.claims("rfcn")
    coco = list(world.config.detection.coco_ids)
    for i in np.flatnonzero(cl.kind > 0):
        r, f, o = int(cl.room[i]), int(cl.frame[i]), int(cl.obj[i])
        assert o in world.views[r][f].visible  # in view at the claim's frame
        assert world.rooms[r].coco[o] != coco[int(cl.coco[i])]  # not an object of the claimed class
    for i in np.flatnonzero(cl.kind == 0):
        r, o = int(cl.room[i]), int(cl.obj[i])
        assert world.rooms[r].coco[o] == coco[int(cl.coco[i])]


def test_channels_coverage_and_content(world) -> None:  # type: ignore[no-untyped-def]
    mesh, seg, none = (world.cell("rfcn", ch, "c") for ch in ("mesh", "segmenter", "none"))
    annotated = [e for e in mesh.events if mesh.labels[next(iter(e.targets))] is not None]
    seen = np.mean([next(iter(e.geometric.values())) is not None for e in annotated])
    assert abs(seen - 0.5) < 0.03  # coverage 0.5 per claim, n ~ 4,000: 0.03 is > 3 sigma
    for e in mesh.events:  # the mesh channel reports the true NYU40 label or nothing
        node = next(iter(e.targets))
        assert e.geometric[node] in (None, mesh.labels[node])
    seg_seen = np.mean([next(iter(e.geometric.values())) is not None for e in seg.events])
    assert abs(seg_seen - 0.5) < 0.03
    wrong = [e for e in seg.events if (lab := next(iter(e.geometric.values()))) is not None
             and lab != seg.labels[next(iter(e.targets))]]
    assert 0.15 < len(wrong) / (seg_seen * len(seg.events)) < 0.6  # a segmenter that errs, not a coin
    assert all(v is None for e in none.events for v in e.geometric.values())
    # the channel changes only the labels: times, targets, predicates and confidences are shared
    for a, b in zip(mesh.events, seg.events):
        assert (a.t, a.targets, a.predicate, a.confidence, a.id) == (b.t, b.targets, b.predicate, b.confidence, b.id)


def test_determinism_transform_and_truth() -> None:
    a = realistic_cell(3, "ssd", "segmenter", "c", config=load_realistic_config(scale=0.25))
    b = realistic_cell(3, "ssd", "segmenter", "c", config=load_realistic_config(scale=0.25))
    c = realistic_cell(4, "ssd", "segmenter", "c", config=load_realistic_config(scale=0.25))
    assert a.events == b.events and a.truth == b.truth
    assert a.events != c.events
    cube = realistic_cell(3, "ssd", "segmenter", "c3", config=load_realistic_config(scale=0.25))
    assert [e.confidence for e in cube.events] == [e.confidence ** 3 for e in a.events]
    ts = [e.t for e in a.events]
    assert ts == sorted(ts)
    for node, row in a.truth.items():
        for p in EIGHT:
            assert row[p] == int(a.table.outcome(p, a.labels[node]) == 1)
    assert set(a.predicates) == set(EIGHT) and all(e.predicate in EIGHT for e in a.events)
    assert len(a.pairs()) == len(a.events)


def test_score_cell_false_commit_breakdown() -> None:
    cell = realistic_cell(1, "rfcn", "mesh", "c", config=load_realistic_config(scale=0.25))
    rows = score_cell(cell, ["majority", "refined"])
    status = evidence_status(cell)
    assert set(status.values()) <= {"adjudicable", "ambiguous", "unseen"}
    for row in rows:
        fc = row["false_commits"]
        # every false commit is counted once, under one status; they are the per-class false positives
        assert fc["total"] == fc["adjudicable"] + fc["ambiguous"] + fc["unseen"]
        assert fc["total"] == sum(s["fp"] for s in row["per_predicate"].values())
        assert fc["total"] == sum(fc["by_label"].values()) == sum(fc["object_label"].values())
        assert fc["object_label"]["unannotated"] == fc["by_label"].get("None", 0)
    none = score_cell(realistic_cell(1, "rfcn", "none", "c", config=load_realistic_config(scale=0.25)), ["majority"])
    assert none[0]["false_commits"]["unseen"] == none[0]["false_commits"]["total"]


def test_bad_config_names_file_and_key(tmp_path: Path) -> None:
    cfg = load_realistic_config()
    raw = cfg.model_dump()
    raw["objects"]["chair"]["rooms"]["garage"] = 1.0
    import yaml

    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"bad\.yaml.*objects.*garage"):
        load_realistic_config(p)
    raw = cfg.model_dump()
    raw["channels"]["segmenter"]["chair"]["confusions"] = {"armchair": 1.0}
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"bad\.yaml.*'armchair'"):
        load_realistic_config(p)


def test_cli_bench_realistic_tiny(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    rc = main(["bench", "--suite", "realistic", "--scale", "0.1", "--operators", "majority,refined", "--out", str(out),
               "--quiet"])
    assert rc == 0
    doc = json.loads((out / "realistic.json").read_text())
    rows = doc["rows"]
    assert len(rows) == 2 * 3 * 2 * 2  # detectors x channels x transforms x operators
    assert {(r["source"], r["channel"], r["profile"]) for r in rows} == {
        (d, c, t) for d in ("rfcn", "ssd") for c in ("mesh", "segmenter", "none") for t in ("c", "c3")}
    md = (out / "realistic.md").read_text()
    assert "### rfcn / channel mesh / confidence c " in md and "adjudicable" in md


def test_grid_realistic_axis() -> None:
    from sgbelief.eval.grid import GridCell, grid_cells, run_grid, summarize

    cells = [c for c in grid_cells(["outdoor", "realistic"]) if c.suite == "realistic"]
    assert len(cells) == 2 * 2 * 3
    cell = GridCell("realistic", "c", "ssd", "none")
    rows = run_grid([0], cells=[cell], scale=0.1, operators=("majority", "refined"))
    assert {r["operator"] for r in rows} == {"majority", "refined"}
    assert all(GridCell(r["suite"], r["profile"], r["source"], r["channel"]) == cell for r in rows)
    assert cell.label in summarize(rows)["cells"]
