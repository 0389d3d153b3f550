"""OperatorConfig: shipped YAML equals the paper's defaults; invalid values name the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from sgbelief.errors import ConfigError, FormatError
from sgbelief.fusion.config import OperatorConfig


def test_shipped_defaults_are_the_papers() -> None:
    cfg = OperatorConfig.default()
    assert cfg == OperatorConfig()
    assert (cfg.alpha, cfg.tau_rev, cfg.t_cor, cfg.k, cfg.w0, cfg.t_prov, cfg.t_disagree, cfg.tau, cfg.tau_t) == (
        0.1, 0.5, 10, 4, 1.0, 1000, 10, 0.5, 0.1,
    )


@pytest.mark.parametrize(
    "text,key",
    [("tau_rev: -1\n", "tau_rev"), ("alpha: 1.5\n", "alpha"), ("calibration:\n  kappa_min: 0\n", "calibration.kappa_min"),
     ("t_cor: ten\n", "t_cor"), ("bogus: 1\n", "bogus"), ("baselines:\n  naive_bayes: {reliability: 0.2}\n", "baselines.naive_bayes.reliability")],
)
def test_invalid_values_name_the_key(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "op.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        OperatorConfig.from_yaml(p)


def test_malformed_yaml_names_the_line(tmp_path: Path) -> None:
    p = tmp_path / "op.yaml"
    p.write_text("alpha: 0.1\ntau_rev: [0.5\n")
    with pytest.raises(FormatError) as info:
        OperatorConfig.from_yaml(p)
    assert info.value.line is not None
