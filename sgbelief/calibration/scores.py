"""A detector's scores as probabilities, fitted once on annotated detections.

sgbelief reads a claim's confidence c as the probability that the claim is right: until the
geometric channel's outcomes calibrate it (§4.1), a claim with c < 0.5 is evidence *against* its
class. Many detectors' scores are not probabilities. Open-vocabulary detectors (YOLO-World,
Grounding DINO) report 0.2-0.5 for detections that are mostly right, and without a channel such a
run leaves most objects unknown (docs/conceptgraphs.md, "Detectors whose scores are not
probabilities"). Where a few frames are annotated, the map from score to probability can be fitted
once and handed to the backend (``ConceptGraphsBackend(..., confidence_map=cal)``)::

    p(s) = isotonic regression of y on s over the annotated detections      (y = 1: detection right)
    p    clipped to [eps, 1 - eps],  eps = 1 / (2 (n + 1))                  (as Eq. 2's p_hat)

the maximum-likelihood non-decreasing map (scipy's pool-adjacent-violators on the pooled scores,
:func:`~sgbelief.calibration.consensus.fit_cell`), linear between its knots and constant beyond them
(:func:`~sgbelief.calibration.isotonic.interpolate`). The clip keeps a fit on a few detections from
saying 0 or 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from sgbelief.calibration.consensus import fit_cell
from sgbelief.calibration.isotonic import interpolate, probability_clip

__all__ = ["ScoreCalibration"]

_FORMAT = "sgbelief.score_calibration"


class ScoreCalibration(BaseModel):
    """p(s): a detector score s mapped to the probability that the detection is right (module doc).

    Fit with :meth:`fit`, call as a function (``confidence_map=``), store with :meth:`to_dict` and
    read back with :meth:`from_dict` (validated: ascending scores, probabilities in [0, 1])."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    scores: tuple[float, ...] = Field(min_length=1, description="the fit's knots: strictly ascending scores")
    probabilities: tuple[float, ...] = Field(min_length=1, description="the isotonic fit at each knot (before the "
                                             "clip), non-decreasing, in [0, 1]")
    n: int = Field(ge=1, description="annotated detections the fit was made on")

    @model_validator(mode="after")
    def _knots(self) -> ScoreCalibration:
        x, p = self.scores, self.probabilities
        if len(x) != len(p):
            raise ValueError(f"scores and probabilities differ in length ({len(x)} and {len(p)})")
        if any(b <= a for a, b in zip(x, x[1:])):
            raise ValueError("scores must be strictly ascending")
        if any(not 0.0 <= q <= 1.0 for q in p) or any(b < a for a, b in zip(p, p[1:])):
            raise ValueError("probabilities must lie in [0, 1] and be non-decreasing")
        return self

    @classmethod
    def fit(cls, scores: Sequence[float] | np.ndarray, correct: Sequence[Any] | np.ndarray) -> ScoreCalibration:
        """Fit p(s) on annotated detections: ``scores[i]`` the detector's score of detection i,
        ``correct[i]`` whether its class was right (bool or 0 / 1)."""
        s = np.asarray(scores, dtype=np.float64).ravel()
        y = np.asarray(correct).ravel()
        if s.size == 0:
            raise ValueError("ScoreCalibration.fit: no annotated detections")
        if s.shape != y.shape:
            raise ValueError(f"ScoreCalibration.fit: {s.size} scores but {y.size} correctness flags")
        if not np.all(np.isfinite(s)):
            raise ValueError(f"ScoreCalibration.fit: score {s[~np.isfinite(s)][0]!r} at index "
                             f"{int(np.flatnonzero(~np.isfinite(s))[0])} is not finite")
        bad = ~np.isin(y, (0, 1))
        if bad.any():
            raise ValueError(f"ScoreCalibration.fit: correct[{int(np.flatnonzero(bad)[0])}] = "
                             f"{y[bad][0].item()!r}; expected True / False or 1 / 0")
        kx, py = fit_cell(s, y.astype(np.float64))
        # the ends of each constant block are knots enough: linear interpolation between the kept
        # knots gives the same p at every score
        keep = [i for i in range(len(kx)) if i in (0, len(kx) - 1) or py[i] != py[i - 1] or py[i] != py[i + 1]]
        return cls(scores=tuple(kx[i] for i in keep), probabilities=tuple(py[i] for i in keep), n=int(s.size))

    def __call__(self, score: float) -> float:
        """p(score): linear between the knots, constant beyond them, clipped to [eps, 1 - eps]."""
        p = interpolate(self.scores, self.probabilities, float(score))
        eps = probability_clip(self.n)
        return eps if p < eps else 1.0 - eps if p > 1.0 - eps else p

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:meth:`from_dict` reads it back)."""
        return {"format": _FORMAT, "version": 1, "scores": list(self.scores),
                "probabilities": list(self.probabilities), "n": self.n}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ScoreCalibration:
        """Read what :meth:`to_dict` wrote; a wrong format, version or field raises ValueError
        (pydantic's ValidationError names the field)."""
        body = dict(data)
        fmt, version = body.pop("format", None), body.pop("version", None)
        if fmt != _FORMAT or version != 1:
            raise ValueError(f"not a score calibration: format {fmt!r}, version {version!r} "
                             f"(expected {_FORMAT!r}, 1)")
        return cls.model_validate(body)
