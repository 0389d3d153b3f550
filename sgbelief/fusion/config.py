"""Operator hyperparameters (Table 1) as a validated, immutable pydantic model.

The calibration section, :class:`~sgbelief.calibration.config.CalibrationConfig`, lives with the
calibrator in :mod:`sgbelief.calibration`; it is re-exported here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from sgbelief.calibration.config import CalibrationConfig  # re-exported: its home is the calibration package
from sgbelief.errors import ConfigError, FormatError


class _Frozen(BaseModel):
    # every float must be finite: ``w0: .inf`` or ``alpha: .nan`` is rejected here, at the boundary
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class OverwriteConfig(_Frozen):
    strength: float = Field(9.0, gt=0.0, description="pseudo-counts of the belief an event overwrites to")


class MajorityConfig(_Frozen):
    pass


class NaiveBayesConfig(_Frozen):
    reliability: float = Field(0.8, ge=0.5, le=1.0, description="fixed assumed reliability r")


class RefinedConfig(_Frozen):
    window: int = Field(10, ge=1, description="last N claims per (v, phi) kept by the temporal filter")
    min_support: int = Field(3, ge=1, description="claims needed before the filter asserts anything")


class BaselinesConfig(_Frozen):
    overwrite: OverwriteConfig = OverwriteConfig()
    majority: MajorityConfig = MajorityConfig()
    naive_bayes: NaiveBayesConfig = NaiveBayesConfig()
    refined: RefinedConfig = RefinedConfig()


class OperatorConfig(_Frozen):
    """Hyperparameters of the operators; defaults are the paper's (Table 1) plus tau_T = 0.1."""

    format: Literal["sgbelief.operator_config"] = "sgbelief.operator_config"
    version: int = Field(1, strict=True, description="schema version (this sgbelief reads 1)")
    alpha: float = Field(0.1, gt=0.0, lt=1.0, description="conformal miscoverage level")
    tau_rev: float = Field(0.5, gt=0.0, description="revision threshold on KL(B || B'), nats")
    t_cor: int = Field(10, ge=0, description="corroboration window of the quarantine Q")
    k: float = Field(4.0, ge=1.0, description="timeout release weight divisor (w / k)")
    w0: float = Field(1.0, gt=0.0, description="base per-evidence weight")
    t_prov: int = Field(1000, ge=1, description="provenance horizon: entries older than this many time steps are settled; compaction folds them, and a silent claim's weight follows the consensus refits only until then")
    t_compact: int | None = Field(
        None,
        ge=1,
        description="time steps between compaction passes (null: T_prov); a shorter interval spreads "
        "the folding over more, smaller passes (lower worst-case latency of one update)",
    )
    t_disagree: int = Field(10, ge=0, description="conflict-drop window of Q_bot")
    tau: float = Field(0.5, ge=0.0, lt=1.0, description="commit threshold")
    tau_t: float = Field(0.1, ge=0.0, lt=1.0, description="targeting-mass threshold")
    geometric_evidence: Literal["none", "verdict", "label"] = Field(
        "verdict",
        description="comod: a decisive geometric label also enters the belief as one observation of y at "
        "the claimed pair (verdict, default), also of the predicates the label itself asserts (label: the "
        "ConceptGraphs backend's default, docs/method.md §3), or is used only to refuse and calibrate "
        "(none, the paper)",
    )
    exclusive_evidence: Literal["none", "rivals"] = Field(
        "rivals",
        description="cal / comod: a committed claim of a class is also evidence against the classes that exclude it "
        "at the same element (rivals: the Dirichlet coupling of docs/method.md §8) or only about its own predicate (none, "
        "the paper)",
    )
    recalled_verdicts: Literal["none", "unanimous", "retroactive"] = Field(
        "retroactive",
        description="comod: a claim the channel does not adjudicate in its own frame is refused when the labels the "
        "channel gave its element in earlier frames all contradict it (unanimous; docs/method.md §8); retroactive "
        "(default) also withdraws the claims the element received unadjudicated before its labels, once those all "
        "contradict them; none: only the claim's own frame counts (the paper)",
    )
    recall_min_labels: int = Field(1, ge=1, description="decisive earlier labels needed before a verdict is recalled")
    contested_labels: Literal["refuse", "weigh", "consensus"] = Field(
        "consensus",
        description="comod, with recalled verdicts on: a claim its own frame's label contradicts, at an element whose "
        "labels have both asserted and denied the predicate (the channel contradicted itself there, docs/method.md "
        "§8), is weighed as cal weighs it when the map-wide consensus sides with the claim (consensus, default; "
        "refused when no consensus runs), always (weigh), or refused like any contradicted claim (refuse, the paper)",
    )
    verdict_sign: Literal["calibrated", "raw"] = Field(
        "calibrated",
        description="sign of a claim for the verdict: calibrated Lambda_hat > 1 (default, invariant under "
        "monotone transforms of c) or raw c >= 0.5 (the paper)",
    )
    calibration: CalibrationConfig = CalibrationConfig()
    baselines: BaselinesConfig = BaselinesConfig()

    @field_validator("version")
    @classmethod
    def _version(cls, v: int) -> int:
        if v != 1:
            raise ValueError(f"unsupported version {v} (this sgbelief reads version 1)")
        return v

    @property
    def compaction_interval(self) -> int:
        """Time steps between compaction passes: ``t_compact``, or T_prov when unset."""
        return self.t_compact if self.t_compact is not None else self.t_prov

    @classmethod
    def from_yaml(cls, path: str | Path) -> OperatorConfig:
        p = Path(path)
        try:
            raw = yaml.safe_load(p.read_text(encoding="utf-8"))
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            raise FormatError(
                f"malformed YAML: {getattr(exc, 'problem', exc)}", path=p, line=mark.line + 1 if mark else None
            ) from exc
        except UnicodeDecodeError as exc:
            raise FormatError(f"not UTF-8 text (byte offset {exc.start})", path=p) from None
        if raw is None:
            raw = {}
        if not isinstance(raw, dict):
            raise ConfigError(f"{p}: an operator config must be a YAML mapping")
        return cls.from_mapping(raw, source=str(p))

    @classmethod
    def from_mapping(cls, data: dict[str, Any], *, source: str = "config") -> OperatorConfig:
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            msgs = []
            for err in exc.errors()[:3]:
                key = ".".join(str(x) for x in err["loc"])
                msgs.append(f"key '{key}': {err['msg'].removeprefix('Value error, ')}")
            raise ConfigError(f"{source}: " + "; ".join(msgs)) from exc

    @classmethod
    def default(cls) -> OperatorConfig:
        """The shipped ``sgbelief/configs/operators/default.yaml`` (equal to the code defaults)."""
        from sgbelief.resources import config_path

        try:
            return cls.from_yaml(config_path("operators", "default.yaml"))
        except FileNotFoundError:
            return cls()


#: the settings that make an operator config the paper's own (§4, Table 1): reported beside the default
PAPER_SETTINGS: dict[str, Any] = {
    "geometric_evidence": "none",
    "exclusive_evidence": "none",
    "verdict_sign": "raw",
    "recalled_verdicts": "none",
    "contested_labels": "refuse",
    "calibration": {"lr_reference": "slice", "kappa_pooling": "slice", "support_strata": 1,
                    "consensus": {"method": "none"}},
}


def paper_variant(config: OperatorConfig) -> OperatorConfig:
    """``config`` with the method options of :data:`PAPER_SETTINGS` (everything else unchanged)."""
    cal = CalibrationConfig.model_validate({**config.calibration.model_dump(), **PAPER_SETTINGS["calibration"]})
    top = {k: v for k, v in PAPER_SETTINGS.items() if k != "calibration"}
    return config.model_copy(update={**top, "calibration": cal})


def resolve_config(config: OperatorConfig | dict[str, Any] | str | Path | None) -> OperatorConfig:
    """Accept a config instance, a mapping, a YAML path, or None (defaults)."""
    if config is None:
        return OperatorConfig()
    if isinstance(config, OperatorConfig):
        return config
    if isinstance(config, dict):
        return OperatorConfig.from_mapping(config)
    return OperatorConfig.from_yaml(config)
