"""ScoreCalibration: a detector's scores mapped to probabilities on annotated detections."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError
from sklearn.isotonic import IsotonicRegression

from sgbelief.calibration.isotonic import probability_clip
from sgbelief.calibration.scores import ScoreCalibration


def test_hand_computed_fit():
    # scores 0.2 (wrong), 0.3 (right), 0.4 (wrong), 0.6 (right), 0.6 (right): pool-adjacent-violators
    # pools 0.3 and 0.4 into 1/2; the two 0.6 detections are one point of mean 1
    cal = ScoreCalibration.fit([0.2, 0.3, 0.4, 0.6, 0.6], [0, 1, 0, 1, 1])
    eps = probability_clip(5)  # 1/12
    assert cal.n == 5
    assert cal(0.2) == pytest.approx(eps) and cal(0.1) == pytest.approx(eps)  # clipped, constant below
    assert cal(0.3) == cal(0.35) == cal(0.4) == pytest.approx(0.5)
    assert cal(0.5) == pytest.approx(0.75)  # linear between 0.4 and 0.6
    assert cal(0.6) == cal(0.99) == pytest.approx(1 - eps)
    assert cal.scores == (0.2, 0.3, 0.4, 0.6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1000).map(lambda i: i / 1000), st.booleans()), min_size=1, max_size=60),
       st.lists(st.floats(-0.5, 1.5, allow_nan=False), min_size=1, max_size=20))
def test_equals_scikit_learn_isotonic_clipped(data, queries):
    """p(s) is scikit-learn's IsotonicRegression(out_of_bounds="clip") prediction, clipped to
    [eps, 1 - eps] (tolerance 1e-9: scikit-learn and scipy sum in different orders). Scores on a
    1e-3 grid: scikit-learn also pools scores closer than about 1e-15, which a detector's are not."""
    s = np.array([d[0] for d in data])
    y = np.array([d[1] for d in data], dtype=float)
    cal = ScoreCalibration.fit(s, y)
    eps = probability_clip(len(s))
    ref = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(s, y)
    for q in queries:
        expected = min(max(float(ref.predict([q])[0]), eps), 1 - eps)
        assert cal(q) == pytest.approx(expected, abs=1e-9)


def test_round_trip_through_json_and_validation():
    cal = ScoreCalibration.fit([0.1, 0.2, 0.5, 0.7], [False, True, True, True])
    back = ScoreCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back == cal and back(0.3) == cal(0.3)
    d = cal.to_dict()
    with pytest.raises(ValueError, match="not a score calibration"):
        ScoreCalibration.from_dict({**d, "format": "x"})
    with pytest.raises(ValidationError, match="strictly ascending"):
        ScoreCalibration.from_dict({**d, "scores": d["scores"][::-1]})
    with pytest.raises(ValidationError, match="probabilities"):
        ScoreCalibration.from_dict({**d, "probabilities": [1.5] * len(d["scores"])})
    with pytest.raises(ValidationError, match="differ in length"):
        ScoreCalibration.from_dict({**d, "probabilities": d["probabilities"][:1]})


@pytest.mark.parametrize("scores, correct, match", [
    ([], [], "no annotated detections"),
    ([0.1, 0.2], [1], "2 scores but 1"),
    ([0.1, float("nan")], [1, 0], "index 1 is not finite"),
    ([0.1, 0.2], [1, 2], r"correct\[1\] = 2"),
])
def test_bad_input_names_what_is_wrong(scores, correct, match):
    with pytest.raises(ValueError, match=match):
        ScoreCalibration.fit(scores, correct)


def test_a_deflated_detector_is_read_as_it_performs():
    """Scores U(0.3, 0.6) when right, U(0.1, 0.45) when wrong (seeded): raw, most right detections
    are below 0.5; mapped, a score above 0.45 is right with probability near 1 and one below 0.3
    near 0 (tolerance: 0.05 on 2,000 detections)."""
    rng = np.random.default_rng(3)
    right = rng.random(2000) < 0.55
    s = np.where(right, rng.uniform(0.3, 0.6, 2000), rng.uniform(0.1, 0.45, 2000))
    assert np.mean(s[right] < 0.5) > 0.6
    cal = ScoreCalibration.fit(s, right)
    assert cal(0.5) > 0.95 and cal(0.2) < 0.05
    mid = (s > 0.3) & (s < 0.45)
    assert abs(np.mean([cal(x) for x in s[mid]]) - right[mid].mean()) < 0.05
