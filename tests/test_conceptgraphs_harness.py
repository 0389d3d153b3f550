"""ConceptGraphs' real per-frame loop with and without the backend (skipped unless
$SGBELIEF_CONCEPTGRAPH_PATH points at a concept-graphs checkout whose imports resolve)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

PATH = os.environ.get("SGBELIEF_CONCEPTGRAPH_PATH")
if not PATH or not Path(PATH, "conceptgraph").is_dir():
    pytest.skip("SGBELIEF_CONCEPTGRAPH_PATH not set to a concept-graphs checkout", allow_module_level=True)
pytest.importorskip("torch")
pytest.importorskip("open3d")
pytest.importorskip("faiss")
pytest.importorskip("cv2")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import cg_harness as H  # noqa: E402

try:
    CG = H.import_conceptgraph(PATH)
except ImportError as exc:  # pragma: no cover - depends on the environment
    pytest.skip(f"conceptgraph not importable: {exc}", allow_module_level=True)


@pytest.fixture(scope="module")
def world() -> H.World:
    return H.render_world(n_frames=int(os.environ.get("SGBELIEF_HARNESS_FRAMES", "60")))


@pytest.fixture(scope="module")
def vote(world: H.World) -> H.RunResult:
    return H.run(world, CG, PATH)


def test_the_real_loop_runs_and_the_vote_is_measurable(vote: H.RunResult) -> None:
    assert vote.n_objects >= 10
    assert 0.0 <= vote.accuracy <= 1.0


@pytest.mark.parametrize("channel", ["oracle", "segmenter", "none"])
def test_backend_inside_the_real_loop(world: H.World, vote: H.RunResult, channel: str) -> None:
    op = os.environ.get("SGBELIEF_HARNESS_OPERATOR", "comod")
    cfg = os.environ.get("SGBELIEF_HARNESS_OPERATOR_CONFIG") or None
    backend = H.make_backend(op, H.make_channel(world, channel), operator_config=cfg)
    r = H.run(world, CG, PATH, backend=backend)
    assert r.summary.objects == r.n_objects
    assert r.summary.unknown == sum(lab == "unknown" for lab in r.labels)
    if os.environ.get("SGBELIEF_HARNESS_TARGETS"):  # the targets (off by default: see RESULTS.md)
        if channel == "oracle":
            assert vote.accuracy <= 0.90 and r.accuracy >= 0.95
        elif channel == "segmenter":
            assert r.accuracy >= vote.accuracy
        else:
            assert r.accuracy >= vote.accuracy - 0.02
