"""Stable identities for ConceptGraphs map objects, kept *outside* the object dicts.

ConceptGraphs' merge rejects keys it does not know (``main`` raises NotImplementedError on any
non-list/int value and *sums* ints, ``ali-dev`` raises ValueError on any unknown key), so no uuid or
belief can live in the dict.  Plain ``dict`` objects cannot be weak-referenced either, so the map is:

1. ``obj['id']`` when present (``ali-dev`` puts a ``uuid.UUID`` on every detection): node ``str(id)``;
2. otherwise an identity table ``id(obj) -> (obj, node)`` holding a strong reference, so the
   ``id()`` cannot be recycled while the entry lives (entries are dropped when a node is retired);
3. a fingerprint fallback, the object's first detection ``(image_idx[0], mask_idx[0])``, which a
   merge never changes (lists are only extended) and which survives ``copy.deepcopy`` (as done by
   ``to_serializable``, ``prepare_objects_save_vis`` and the visualisation copies).
"""

from __future__ import annotations

import itertools
from typing import Any

Fingerprint = tuple[Any, ...]

#: :meth:`IdentityMap.find` found the node without computing the object's fingerprint
NOT_COMPUTED: Any = object()


def fingerprint(obj: dict) -> Fingerprint | None:
    """Identity of the first detection of ``obj`` (None when the keys are missing or empty)."""
    try:
        img, msk = obj["image_idx"], obj["mask_idx"]
        first = (_plain(img[0]), _plain(msk[0]))
    except (KeyError, IndexError, TypeError):
        return None
    path = obj.get("color_path")
    if isinstance(path, list) and path:
        first = first + (str(path[0]),)
    return first


def _plain(value: Any) -> Any:
    if type(value) is int or type(value) is str:  # no .item(): spare the failing look-up
        return value
    try:
        return value.item()  # numpy / torch scalars
    except AttributeError:
        return value


class IdentityMap:
    """Object dict -> graph node id, with tombstones for nodes merged away."""

    def __init__(self, prefix: str = "cg") -> None:
        self._prefix = prefix
        self._counter = itertools.count()
        self._by_id: dict[int, tuple[dict, str]] = {}
        self._by_fp: dict[Fingerprint, str] = {}
        self._absorbed: dict[str, str] = {}  # absorbed node -> node that absorbed it
        #: node ids handed out (registered or rebound)
        self._known: set[str] = set()
        #: node -> the ``id()`` keys of ``_by_id`` bound to it (retiring a node costs O(its
        #: objects), not a scan of every entry)
        self._keys_of: dict[str, set[int]] = {}
        #: ``obj['id']`` -> its node id (``str(uuid)`` once per uuid, not once per look-up)
        self._uid_nodes: dict[Any, str] = {}

    def _uid_node(self, uid: Any) -> str:
        try:
            node = self._uid_nodes.get(uid)  # a miss (every new object's) raises no KeyError to catch
        except TypeError:  # an unhashable id: its string
            return str(uid)
        if node is None:
            node = self._uid_nodes[uid] = str(uid)
        return node

    def lookup(self, obj: dict) -> str | None:
        """Node registered for ``obj`` (resolving tombstones is left to :meth:`resolve`)."""
        return self.find(obj)[0]

    def find(self, obj: dict) -> tuple[str | None, Any]:
        """(:meth:`lookup`'s node, the fingerprint it computed, or :data:`NOT_COMPUTED`): a miss is
        followed by :meth:`register`, which takes the fingerprint instead of computing it again."""
        uid = obj.get("id") if isinstance(obj, dict) else None
        if uid is not None and not isinstance(uid, (bool, int, float)):
            node = self._uid_node(uid)
            return (node if node in self._known else None), NOT_COMPUTED
        entry = self._by_id.get(id(obj))
        if entry is not None and entry[0] is obj:
            return entry[1], NOT_COMPUTED
        fp = fingerprint(obj)
        if fp is not None:
            return self._by_fp.get(fp), fp
        return None, fp

    def register(self, obj: dict, fp: Any = NOT_COMPUTED) -> str:
        """Give ``obj`` a new node id and remember it. ``fp``: ``obj``'s fingerprint when the caller
        has it (from :meth:`find`); by default it is computed."""
        uid = obj.get("id")
        if uid is not None and not isinstance(uid, (bool, int, float)):
            node = self._uid_node(uid)
        else:
            node = f"{self._prefix}-{next(self._counter)}"
            while node in self._known:
                node = f"{self._prefix}-{next(self._counter)}"
        self._bind(obj, node, fp)
        return node

    def rebind(self, obj: dict, node: str) -> None:
        """Remember that ``obj`` (e.g. a replacement dict) stands for ``node``."""
        self._bind(obj, node)

    def _bind(self, obj: dict, node: str, fp: Any = NOT_COMPUTED) -> None:
        self._known.add(node)
        key = id(obj)
        old = self._by_id.get(key)
        if old is not None and old[1] != node:
            keys = self._keys_of.get(old[1])
            if keys is not None:
                keys.discard(key)
        self._by_id[key] = (obj, node)
        keys = self._keys_of.get(node)
        if keys is None:
            self._keys_of[node] = {key}
        else:
            keys.add(key)
        if fp is NOT_COMPUTED:
            fp = fingerprint(obj)
        if fp is not None:
            self._by_fp.setdefault(fp, node)

    def absorb(self, absorbed: str, keep: str) -> None:
        """Record that ``absorbed`` was merged into ``keep``."""
        self._absorbed[absorbed] = keep
        self._drop_strong_refs(absorbed, keep_tombstone=True)

    def retire(self, node: str) -> None:
        """Forget the strong references to objects of ``node`` (filtered objects)."""
        self._drop_strong_refs(node, keep_tombstone=True)

    def resolve(self, node: str) -> str:
        """Follow absorption tombstones to the node that holds the evidence now."""
        absorbed = self._absorbed
        if node not in absorbed:
            return node
        seen = set()
        while node in absorbed and node not in seen:
            seen.add(node)
            node = absorbed[node]
        return node

    def is_absorbed(self, node: str) -> bool:
        return node in self._absorbed

    def _drop_strong_refs(self, node: str, *, keep_tombstone: bool) -> None:
        keys = self._keys_of.pop(node, None)
        if not keys:
            return
        by_id = self._by_id
        for key in keys:  # every tombstone names `node`: the order does not matter
            obj = by_id.pop(key)[0]
            # keep a fingerprint tombstone so a later look-up of a stale copy still finds the node
            fp = fingerprint(obj)
            if keep_tombstone and fp is not None:
                self._by_fp.setdefault(fp, node)
