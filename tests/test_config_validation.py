"""Config and vocabulary YAML at the boundary (issue #21): finite floats, checked format/version, fuzz."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from sgbelief.errors import ConfigError, SgbeliefError
from sgbelief.eval.sim_config import load_sim_config, load_vocabulary
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.resources import config_path

VOCAB = "predicates:\n  is_car: {positive: [car], negative: [person]}\n"


def _float_keys(model: type, prefix: str = "") -> list[str]:
    keys = []
    for name, f in model.model_fields.items():
        ann = f.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):  # a nested section
            keys += _float_keys(ann, f"{prefix}{name}.")
        elif ann is float:
            keys.append(prefix + name)
    return keys


FLOAT_KEYS = _float_keys(OperatorConfig)


def _nested(key: str, value: object) -> dict[str, object]:
    out: dict[str, object] = {}
    cur = out
    parts = key.split(".")
    for p in parts[:-1]:
        cur = cur.setdefault(p, {})  # type: ignore[assignment]
    cur[parts[-1]] = value
    return out


def test_every_float_key_is_found() -> None:
    assert {"w0", "alpha", "tau", "calibration.kappa_min", "baselines.overwrite.strength"} <= set(FLOAT_KEYS)


@pytest.mark.parametrize("key", FLOAT_KEYS)
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_floats_are_rejected_with_a_clear_message(key: str, value: float) -> None:
    with pytest.raises(ConfigError, match=rf"key '{key}': Input should be a finite number"):
        OperatorConfig.from_mapping(_nested(key, value))


def test_inf_in_yaml_is_rejected(tmp_path: Path) -> None:
    p = tmp_path / "op.yaml"
    p.write_text("w0: .inf\n")
    with pytest.raises(ConfigError, match="key 'w0': Input should be a finite number"):
        OperatorConfig.from_yaml(p)


@pytest.mark.parametrize("text,key", [("version: 9\n", "version"), ("version: '1'\n", "version"),
                                      ("version: true\n", "version"), ("format: sgbelief.vocabulary\n", "format")])
def test_operator_config_checks_version_and_format(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "op.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        OperatorConfig.from_yaml(p)


@pytest.mark.parametrize("head,key", [("version: 7\n", "version"), ("version: '1'\n", "version"),
                                      ("format: sgbelief.operator_config\n", "format")])
def test_vocabulary_checks_version_and_format(tmp_path: Path, head: str, key: str) -> None:
    p = tmp_path / "v.yaml"
    p.write_text(head + VOCAB)
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        SubsumptionTable.from_yaml(p)
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        load_vocabulary(str(p))
    p.write_text("format: sgbelief.vocabulary\nversion: 1\n" + VOCAB)
    assert SubsumptionTable.from_yaml(p).predicates == ["is_car"]


def test_sim_config_rejects_non_finite_floats(tmp_path: Path) -> None:
    text = config_path("sim", "outdoor.yaml").read_text()
    p = tmp_path / "sim.yaml"
    p.write_text(text + "\n")
    load_sim_config(p)  # the copy loads
    import yaml

    doc = yaml.safe_load(text)
    doc["camera"] = {**doc["camera"], next(k for k, v in doc["camera"].items() if isinstance(v, float)): float("inf")}
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="camera.*finite"):
        load_sim_config(p)


_TOKENS = list("ab:{}[]-, \n\t'\"!&*#|>%@.0e1") + ["version", "format", "predicates", "positive", ".inf", ".nan",
                                                   "w0", "\xe9", "\x00"]
_yaml_text = st.one_of(
    st.binary(max_size=120),
    st.lists(st.sampled_from(_TOKENS), max_size=40).map(lambda xs: "".join(xs).encode("utf-8")),
    st.lists(st.sampled_from(_TOKENS), max_size=40).map(lambda xs: "".join(xs).encode("latin-1")),
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=_yaml_text)
def test_fuzz_yaml_loaders_give_project_errors(tmp_path: Path, data: bytes) -> None:
    p = tmp_path / "x.yaml"
    p.write_bytes(data)
    for load in (OperatorConfig.from_yaml, SubsumptionTable.from_yaml, load_vocabulary, load_sim_config):
        try:
            load(p)
        except SgbeliefError:
            pass
    assert p.read_bytes() == data
