from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

from sgbelief.errors import FormatError
from sgbelief.eval.detector_records import (
    AVAILABLE_RECORDS,
    available_records,
    load_detector_records,
    predicate_pool,
    split_half,
)


@pytest.mark.parametrize("name", AVAILABLE_RECORDS)
def test_loads_without_pickle(name):
    real_load = np.load
    calls = []

    def spy(*a, **k):
        calls.append(k.get("allow_pickle"))
        return real_load(*a, **k)

    with mock.patch("numpy.load", spy):
        r = load_detector_records(name)
    assert calls == [False]
    assert len(r) > 30000
    assert r.score.dtype == np.float32 and r.class_id.dtype == np.int16
    assert r.matched.dtype == np.uint8 and r.image_index.dtype == np.int32
    assert 0.0 <= r.score.min() and r.score.max() <= 1.0
    assert set(np.unique(r.matched).tolist()) == {0, 1}
    assert name in available_records()


def test_known_counts():
    r = load_detector_records("rfcn-resnet-101-iou-0.60")
    assert len(r) == 34025 and int(r.matched.sum()) == 21085
    s, m = predicate_pool(r, "is_chair")
    assert len(s) == 1334
    assert len(predicate_pool(r, "is_vegetation")[0]) == 0


def test_split_half_disjoint_by_image_and_seeded():
    r = load_detector_records()
    a, b = split_half(r, seed=3)
    assert len(a) + len(b) == len(r)
    assert not set(np.unique(a.image_index)) & set(np.unique(b.image_index))
    n_img = len(np.unique(r.image_index))
    assert abs(len(np.unique(a.image_index)) - n_img / 2) <= 1
    a2, _ = split_half(r, seed=3)
    a3, _ = split_half(r, seed=4)
    assert np.array_equal(a.score, a2.score) and not np.array_equal(a.image_index, a3.image_index)


def test_rejects_pickled_file(tmp_path):
    p = tmp_path / "bad.npz"
    np.savez(p, image_index=np.array([np.array([1])], dtype=object), class_id=np.zeros(1),
             score=np.zeros(1), matched=np.zeros(1))
    with pytest.raises(FormatError):
        load_detector_records(path=p)
    with pytest.raises(FileNotFoundError):
        load_detector_records("nope")
