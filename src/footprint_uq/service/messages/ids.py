"""The messages' object ids: a detector's ``object_id`` -> CPM ``objectId`` / SDSM ``objectID`` (0..65535).

Mapping (per camera, i.e. per station; :class:`MessageIdMap`):

* an **integer** ``object_id`` in 0..65535 asks for its own value; any other id (text, a larger or negative
  integer, null) asks for ``CRC-32(tag + text) mod 65536`` of a typed text -- ``"i:<n>"`` for an integer,
  ``"s:<text>"`` for text, ``"n:<index>"`` for a null id (its index in the frame) -- so the integer ``7``
  and the text ``"7"`` are different objects and ask for different numbers;
* the number asked for is taken if no other live id holds it, else the next free number upwards (mod
  65536): **collisions are resolved, never shared**; within one message every number is unique;
* **stable**: an id keeps its number for as long as it is seen; a number is released when its id has not
  been seen for :data:`MESSAGE_ID_HOLD_S` seconds of frame time (``timestamp_s``), and only then may it be
  given to another id (so a receiver does not see one number jump between two objects within that time);
* the same ``object_id`` twice in one frame: the second (third, ...) occurrence is another object and gets
  its own number (asked for as ``"<tag>:<text>#<k>"``), stable as long as the detector repeats it;
* at most 65536 ids are live; beyond that the longest unseen one is released early.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["MessageIdMap", "MESSAGE_ID_HOLD_S", "preferred_number"]

#: seconds (frame time) a number stays with an id that is no longer seen
MESSAGE_ID_HOLD_S = 60.0
_N = 65536


def _key(object_id, index: int, k: int):
    base = ("n", index) if object_id is None else object_id  # int and str keys never compare equal
    return base if k == 0 else (base, k)


def preferred_number(object_id, index: int = 0, occurrence: int = 0) -> int:
    """The number ``object_id`` asks for (module doc); ``index``: its place in the frame (used for null ids)."""
    if occurrence == 0 and type(object_id) is int and 0 <= object_id < _N:
        return object_id
    if object_id is None:
        text = f"n:{index}"
    elif isinstance(object_id, str):
        text = f"s:{object_id}"
    else:
        text = f"i:{int(object_id)}"
    if occurrence:
        text += f"#{occurrence}"
    return zlib.crc32(text.encode("utf-8", "surrogatepass")) & 0xFFFF


class MessageIdMap:
    """One camera's ``object_id`` -> message id table (module doc).  Not thread-safe: one per camera, used by the
    thread that processes that camera's frames."""

    def __init__(self, hold_s: float = MESSAGE_ID_HOLD_S):
        self.hold_s = float(hold_s)
        self._num: dict = {}  # key -> number
        self._owner: dict[int, object] = {}  # number -> key
        self._seen: dict = {}  # key -> frame time last seen
        self._now = -np.inf
        self._next_sweep = -np.inf

    def __len__(self) -> int:
        return len(self._num)

    def _release(self, key) -> None:
        self._owner.pop(self._num.pop(key), None)
        self._seen.pop(key, None)

    def _sweep(self) -> None:
        old = self._now - self.hold_s
        for key in [k for k, t in self._seen.items() if t < old]:
            self._release(key)
        self._next_sweep = self._now + min(1.0, self.hold_s)

    def _assign(self, key, object_id, index: int, k: int, in_frame: set) -> int:
        if len(self._owner) >= _N:  # every number held: release the longest unseen id not in this frame
            key_old = min((kk for kk in self._seen if kk not in in_frame), key=self._seen.__getitem__)
            self._release(key_old)
        num = preferred_number(object_id, index, k)
        while num in self._owner:
            num = (num + 1) % _N
        self._num[key] = num
        self._owner[num] = key
        return num

    def assign(self, ids: list, rows, t_s: float) -> np.ndarray:
        """Message ids (int64, one per entry of ``rows``: sorted, distinct indices) of the objects ``ids[rows]`` of a
        frame at time ``t_s`` (s)."""
        rows = np.asarray(rows, dtype=np.int64).tolist()
        sel = ids if len(rows) == len(ids) else [ids[i] for i in rows]  # (rows are sorted and unique)
        occ = None  # occurrence of each id in the frame (None: every id once, none null)
        distinct = set(sel)
        if len(distinct) == len(sel) and None not in distinct:  # the usual frame: its keys are its ids
            keys = sel
        else:
            count: dict = {}
            occ = []
            for i, oid in zip(rows, sel, strict=True):
                base = ("n", i) if oid is None else oid
                occ.append(count.get(base, 0))
                count[base] = occ[-1] + 1
            keys = [_key(oid, i, k) for i, oid, k in zip(rows, sel, occ, strict=True)]
        if t_s > self._now:
            self._now = t_s
        if self._now >= self._next_sweep:
            self._sweep()
        nums = list(map(self._num.get, keys))
        if None in nums:
            in_frame = set(keys)
            for j, n in enumerate(nums):
                if n is None:
                    nums[j] = self._assign(keys[j], sel[j], rows[j], 0 if occ is None else occ[j], in_frame)
        self._seen.update(dict.fromkeys(keys, t_s))
        return np.array(nums, dtype=np.int64)
