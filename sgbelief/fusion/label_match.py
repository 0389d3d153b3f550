"""Matching a geometric channel's label spellings to the labels of a subsumption table.

A channel (a segmenter, a dataset's label images, mesh labels) spells its labels its own way:
``Chairs``, ``office_chair``, ``tv-screen``. :func:`label_key` folds case, spaces, hyphens,
underscores and a plural ending, :func:`label_index` indexes a table's labels by exact and folded
spelling, and :func:`check_class_names` checks a channel's declared class list against a table.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from typing import Any

from sgbelief.errors import ChannelMismatchError, SgbeliefWarning
from sgbelief.fusion.compatibility import normalise_class_name, singular_name

__all__ = ["UnmatchedLabelWarning", "check_class_names", "label_index", "label_key", "table_labels"]


class UnmatchedLabelWarning(SgbeliefWarning):
    """A geometric label that matches no label of the vocabulary: claims checked against it stay unverified."""


def label_key(label: str) -> str:
    """The matching key of a label: normalised, then singular."""
    return singular_name(normalise_class_name(label))


def table_labels(table: Any) -> set[str]:
    """Every channel label a subsumption table knows: its label list, else those its predicates
    name, plus its ambiguous labels (known, deciding nothing)."""
    labels = set(table.labels) if getattr(table, "labels", None) else set()
    if not labels:
        for spec in table.specs.values():
            labels.update(spec.positive)
            labels.update(spec.negative)
    labels.update(getattr(table, "ambiguous_labels", ()))
    return labels


def label_index(labels: Iterable[str]) -> tuple[dict[str, str], dict[str, str]]:
    """(exact, folded): normalised spelling -> label, and :func:`label_key` -> label (first in sorted order)."""
    exact: dict[str, str] = {}
    loose: dict[str, str] = {}
    for lab in sorted(labels):
        exact.setdefault(normalise_class_name(lab), lab)
        loose.setdefault(label_key(lab), lab)
    return exact, loose


def check_class_names(names: Sequence[str], table: Any, *, what: str = "channel class list") -> list[str]:
    """The names of ``names`` that resolve to no label of ``table``. Raises
    :class:`ChannelMismatchError` when none resolves; warns naming those that do not."""
    exact, loose = label_index(table_labels(table))
    missing = [n for n in names if normalise_class_name(n) not in exact and label_key(n) not in loose]
    if names and len(missing) == len(names):
        shown = ", ".join(sorted(exact)[:30]) + (" ..." if len(exact) > 30 else "")
        raise ChannelMismatchError(
            f"none of the {what}'s {len(names)} names matches a label of the vocabulary "
            f"({', '.join(map(repr, list(names)[:10]))}{' ...' if len(names) > 10 else ''}); "
            f"the vocabulary's labels: {shown}")
    if missing:
        warnings.warn(f"{len(missing)} of the {what}'s names match no label of the vocabulary and "
                      f"will give no verdict: {', '.join(map(repr, missing[:20]))}"
                      f"{' ...' if len(missing) > 20 else ''}", UnmatchedLabelWarning, stacklevel=3)
    return missing
