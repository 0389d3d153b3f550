"""ali-dev's match step (one numpy pass, torch's rules) and the identity map's per-node index."""

from __future__ import annotations

import uuid

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
from sgbelief.adapters.conceptgraphs.functions import make_functions
from sgbelief.adapters.conceptgraphs.identity import IdentityMap

torch = pytest.importorskip("torch")


def torch_match(agg_sim: object, threshold: float) -> list[int | None]:
    """ConceptGraphs ali-dev's own row loop (the reference the replacement must equal)."""
    out: list[int | None] = []
    for i in range(agg_sim.shape[0]):  # type: ignore[attr-defined]
        if agg_sim[i].max() <= threshold:  # type: ignore[index]
            out.append(None)
        else:
            out.append(int(agg_sim[i].argmax().item()))  # type: ignore[index]
    return out


def _functions() -> object:
    backend = ConceptGraphsBackend("comod", context="t", class_names=["chair", "table"], print_summary=False)
    return make_functions(backend, "ali-dev")


VALUES = st.sampled_from([float("-inf"), 0.5, 1.2, 1.2000000476837158, 2.0, float("nan")])


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 5), cols=st.integers(1, 6), data=st.data(),
       threshold=st.sampled_from([float("-inf"), 1.2, 0.5]), dtype=st.sampled_from(["float32", "float64"]))
def test_match_equals_torch_row_loop(rows: int, cols: int, data: st.DataObject, threshold: float, dtype: str) -> None:
    # scores drawn from a few values: ties, -inf rows, NaN, and a float32 score equal to a
    # threshold that float32 cannot hold exactly (1.2)
    values = data.draw(st.lists(VALUES, min_size=rows * cols, max_size=rows * cols))
    agg = torch.tensor(values, dtype=getattr(torch, dtype)).reshape(rows, cols)
    f = _functions()
    assert f.match_detections_to_objects(agg, threshold) == torch_match(agg, threshold)  # type: ignore[attr-defined]


def test_match_keeps_torch_errors_for_an_empty_map() -> None:
    f = _functions()
    agg = torch.zeros((2, 0))
    with pytest.raises((RuntimeError, IndexError)):
        torch_match(agg, float("-inf"))
    with pytest.raises((RuntimeError, IndexError)):
        f.match_detections_to_objects(agg, float("-inf"))  # type: ignore[attr-defined]


def test_match_accepts_a_numpy_matrix() -> None:
    f = _functions()
    agg = np.array([[0.1, 0.9, 0.9], [float("-inf")] * 3])
    assert f.match_detections_to_objects(agg, 0.0) == [1, None]  # type: ignore[attr-defined]


def _obj(k: int, uid: object = None) -> dict:
    d = {"image_idx": [k], "mask_idx": [0], "color_path": [f"f{k}"], "class_id": [0]}
    if uid is not None:
        d["id"] = uid
    return d


def test_retire_drops_only_that_nodes_objects_and_keeps_tombstones() -> None:
    ids = IdentityMap()
    a, b, c = _obj(1), _obj(2), _obj(3)
    na, nb = ids.register(a), ids.register(b)
    copy_of_a = dict(a)
    ids.rebind(copy_of_a, na)
    nc = ids.register(c)
    ids.rebind(c, nb)  # c now stands for nb: retiring nc must not drop it
    ids.retire(na)
    assert id(a) not in ids._by_id and id(copy_of_a) not in ids._by_id
    assert ids.lookup(dict(a)) == na  # a stale copy still finds its node by fingerprint
    ids.retire(nc)
    assert ids.lookup(c) == nb and ids._by_id[id(c)][0] is c
    ids.retire(nb)
    assert ids._by_id == {} and ids.lookup(dict(b)) == nb


def test_uuid_ids_are_their_string() -> None:
    ids = IdentityMap()
    u = uuid.uuid4()
    obj = _obj(1, u)
    assert ids.lookup(obj) is None
    assert ids.register(obj) == str(u)
    assert ids.lookup(_obj(9, u)) == str(u)
    assert ids.lookup(_obj(9, uuid.uuid4())) is None


def test_match_compares_in_the_matrix_dtype() -> None:
    # float32(1.2) > 1.2 in float64, == 1.2 in float32: torch compares in float32, no match
    agg = torch.tensor([[1.2, -1.0], [2.0, 2.0]], dtype=torch.float32)
    f = _functions()
    assert torch_match(agg, 1.2) == [None, 0]
    assert f.match_detections_to_objects(agg, 1.2) == [None, 0]  # type: ignore[attr-defined]
