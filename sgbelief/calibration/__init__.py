"""Calibration of foundation-model confidences against the geometric channel (§4.1, Eq. 1 and Eq. 2).

:mod:`.mondrian` (the streaming Mondrian calibrator), :mod:`.slice` (one slice of its buffer),
:mod:`.isotonic` (the isotonic fit and Eq. 2), :mod:`.conformal` (Eq. 1 and the prediction sets),
:mod:`.config` (its knobs), :mod:`.scores` (a detector's scores mapped to probabilities on annotated
detections, for detectors whose scores are not). Below the fusion operators; imports no other sgbelief package.
"""
