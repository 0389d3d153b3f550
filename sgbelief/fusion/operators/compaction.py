"""When an operator runs a compaction pass, and what the pass folds (Alg. 1, last lines).

One schedule for every engine: the streaming one (:meth:`BaseOperator.tick
<sgbelief.fusion.operators.base.BaseOperator.tick>`) asks it tick by tick, the batched one
(:mod:`sgbelief._fast.batched`) for a whole stream of event times at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sgbelief.fusion.config import OperatorConfig

#: graph.meta keys: the epoch of the last pass, and the interval it was counted in (absent: T_prov)
EPOCH_KEY = "compaction_epoch"
INTERVAL_KEY = "compaction_interval"


@dataclass(frozen=True)
class CompactionSchedule:
    """Time is cut into epochs of ``interval`` steps (``compaction_interval``: ``t_compact``, or
    T_prov when unset). The first tick of a new epoch runs a pass that folds every settled entry
    older than its horizon t - T_prov into one bucket per pair.

    The graph's meta holds the epoch of the last pass, and the interval it was counted in when
    that is not T_prov, so a graph compacted under another interval converts its epoch (a saved
    map replayed with another ``t_compact`` keeps its schedule).
    """

    t_prov: int
    interval: int

    @classmethod
    def of(cls, config: OperatorConfig) -> CompactionSchedule:
        return cls(config.t_prov, config.compaction_interval)

    def epoch(self, t: Any) -> Any:
        """The epoch of time t (an int, or an int array)."""
        return t // self.interval

    def horizon(self, t: Any) -> Any:
        """A pass at time t folds the settled entries with t' < t - T_prov (an int, or an int array)."""
        return t - self.t_prov

    def last_epoch(self, meta: dict[str, Any]) -> int:
        """The epoch of the graph's last pass, counted in this schedule's interval (0: none yet)."""
        last = meta.get(EPOCH_KEY, 0)
        saved = meta.get(INTERVAL_KEY, self.t_prov)
        return last if saved == self.interval else last * saved // self.interval

    def record(self, meta: dict[str, Any], epoch: int) -> None:
        """Note in the graph's meta that a pass ran in ``epoch``."""
        meta[EPOCH_KEY] = epoch
        if self.interval != self.t_prov:
            meta[INTERVAL_KEY] = self.interval
        elif INTERVAL_KEY in meta:
            del meta[INTERVAL_KEY]

    def advance(self, meta: dict[str, Any], t: int) -> bool:
        """Whether a tick to time t runs a pass; when it does, the pass is recorded in ``meta``."""
        epoch = t // self.interval
        if epoch > self.last_epoch(meta):
            self.record(meta, epoch)
            return True
        return False
