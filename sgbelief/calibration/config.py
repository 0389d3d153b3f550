"""The calibrator's knobs (§4.1) as a validated, immutable pydantic model.

:class:`~sgbelief.fusion.config.OperatorConfig` holds one as its ``calibration`` field; the
derivations behind the defaults (``lr_reference``, ``kappa_pooling``, ``support_strata``, the cold
start) are in ``docs/method.md``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["CalibrationConfig", "ConsensusConfig"]


class ConsensusConfig(BaseModel):
    """Calibration from agreement where the geometric channel is silent (docs/method.md §8)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    method: Literal["none", "dawid_skene", "agreement_shift"] = Field(
        "dawid_skene",
        description="claims the channel cannot adjudicate are calibrated on the map-wide Dawid-Skene consensus "
        "(dawid_skene), read as their confidence shifted in log-odds by one constant per detector context learned "
        "from the map's agreement (agreement_shift: what a map of tens of objects identifies, the ConceptGraphs "
        "backend's choice without a channel; docs/method.md §8), or on the adjudicated claims' calibration like "
        "every other claim (none, the paper)",
    )
    score_test_level: float | None = Field(
        0.05, gt=0.0, lt=1.0,
        description="agreement_shift only: level of the one-sided rank test that a detector context's scores "
        "predict which of its claims agree with the other claims on their elements; a context whose test does not "
        "reject has its claims read at one common level, so the map counts them (docs/method.md §8). null: every "
        "context's scores are read",
    )
    every: int = Field(100, ge=1, description="claims between two refits of the consensus, at least")
    growth: float = Field(0.25, ge=0.0, description="... and at least this fraction of the claims held (O(log n) refits)")
    bins: int = Field(4, ge=1, description="confidence bins per context (by rank) for the Dawid-Skene workers")
    smoothing: float = Field(0.5, ge=0.0, description="Dirichlet pseudo-count of the Dawid-Skene M-step")
    n_iter: int = Field(50, ge=1, description="EM iterations at most per refit")
    emission: Literal["multinomial", "dirichlet_multinomial"] = Field(
        "dirichlet_multinomial",
        description="how a detector context's claims on one element are modelled: independent given its class "
        "(multinomial, Dawid-Skene) or correlated, Dirichlet-multinomial around the context's confusion row with a "
        "concentration learned from the map (dirichlet_multinomial, default: a detector that mistakes an object "
        "keeps mistaking it; the channel's labels and the support stay independent; docs/method.md §8)",
    )
    silent_weights: Literal["current", "at_arrival"] = Field(
        "current",
        description="the calibration a committed silent claim is weighed with: the current one, every such claim "
        "inside the provenance horizon weighed again after each refit (current, default; docs/method.md §8), or the "
        "one in force when it arrived (at_arrival)",
    )
    label_weights: Literal["one", "reliability"] = Field(
        "reliability",
        description="comod with geometric_evidence verdict or label: how much of a pseudo-count a decisive label's "
        "observation of y counts: its reliability under the channel's confusion the Dawid-Skene consensus learned "
        "(reliability, default: a label the channel often gives to elements of the other class counts for less; "
        "docs/method.md §8), or one whole pseudo-count (one, the default before; also before the first fit and with "
        "method agreement_shift or none)",
    )
    adjudicated_elements: Literal["channel", "consensus"] = Field(
        "channel",
        description="outcome of a silent claim on an element the channel labelled decisively at other times: the "
        "channel's verdict when its decisive labels there agree (channel, default; docs/method.md §8), or the "
        "Dawid-Skene posterior like any other silent claim (consensus)",
    )


class CalibrationConfig(BaseModel):
    """Knobs of the Mondrian isotonic calibrator and the conformal sets (§4.1)."""

    # every float must be finite (``lr_max: .inf`` is rejected here, at the boundary)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    target_size: int = Field(50, ge=1, description="kappa_hat = min(1, effective size / target_size)")
    kappa_min: float = Field(0.05, gt=0.0, le=1.0, description="floor of kappa_hat")
    lr_max: float = Field(1000.0, gt=1.0, description="Lambda_hat clipped to [1/lr_max, lr_max]")
    refit_growth: float = Field(0.1, gt=0.0, description="refit after the slice grew by this fraction")
    min_refit: int = Field(8, ge=1, description="... or by at least this many outcomes")
    cold_start: Literal["raw", "neutral"] = "raw"
    lr_reference: Literal["slice", "uniform"] = Field(
        "uniform",
        description="odds Lambda_hat is measured against: the uniform prior Beta(1, 1) (default, docs/method.md) "
        "or the slice's base rate among claims (the paper's reading)",
    )
    kappa_pooling: Literal["slice", "pooled"] = Field(
        "slice",
        description="kappa_hat from the (context, predicate) slice's size alone (paper) or from the pooled "
        "levels the shrunk estimate actually uses",
    )
    support_strata: int = Field(
        4,
        ge=1,
        description="Mondrian strata by the number of earlier claims at (v, phi): 0, 1, ..., S-1 or more "
        "(1: no stratification, the paper's taxonomy)",
    )
    adaptive_gamma: float = Field(0.005, ge=0.0, lt=1.0, description="adaptive conformal step size")
    buffer_size: int | None = Field(
        262_144,
        ge=16,
        description="most recent verification outcomes kept per Mondrian slice (sliding window); null keeps all",
    )
    consensus: ConsensusConfig = Field(
        ConsensusConfig(),
        description="calibration of the claims the geometric channel cannot adjudicate (map-wide agreement)",
    )
