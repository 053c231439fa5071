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
from numba import njit

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
        # integer ids 0..65535 (the usual detector's) also by array, for :meth:`assign`'s ``int_ids`` path (2.6 MB,
        # made on its first use): their numbers (-1: none), their latest frame time not yet written to ``_seen``
        # and which ids those are -- ``_pending[1:1 + _pending[0]]``, each once (``_dirty``: listed already) -- (the
        # writes are moved to ``_seen`` before anything reads or changes it: the same dicts, in the same order, as
        # without the path).  The int64 ones are rows of one array, ``_state`` (:func:`_lookup_small`'s argument)
        self._state: np.ndarray | None = None
        self._small_num = self._small_seen = self._mark = self._dirty = None
        self._pending = np.zeros(1, np.int64)
        self._frame_keys: list = []

    def __len__(self) -> int:
        return len(self._num)

    def _release(self, key) -> None:
        self._owner.pop(self._num.pop(key), None)
        self._seen.pop(key, None)
        if self._small_num is not None and type(key) is int and 0 <= key < _N:
            self._small_num[key] = -1

    def _sync(self) -> None:
        """The frame times of the ``int_ids`` path into ``_seen`` (its keys are there already)."""
        n = int(self._pending[0])
        if n:
            keys = self._pending[1:1 + n].copy()
            self._pending[0] = 0
            self._dirty[keys] = 0
            seen = self._seen
            for k, t in zip(keys.tolist(), self._small_seen[keys].tolist(), strict=True):
                if k in seen:
                    seen[k] = t

    def _sweep(self) -> None:
        self._sync()
        old = self._now - self.hold_s
        for key in [k for k, t in self._seen.items() if t < old]:
            self._release(key)
        self._next_sweep = self._now + min(1.0, self.hold_s)

    def _assign(self, key, object_id, index: int, k: int, in_frame: set) -> int:
        if len(self._owner) >= _N:  # every number held: release the longest unseen id not in this frame
            self._sync()
            if in_frame is None:
                in_frame = set(self._frame_keys)
            key_old = min((kk for kk in self._seen if kk not in in_frame), key=self._seen.__getitem__)
            self._release(key_old)
        num = preferred_number(object_id, index, k)
        while num in self._owner:
            num = (num + 1) % _N
        self._num[key] = num
        self._owner[num] = key
        if self._small_num is not None and type(key) is int and 0 <= key < _N:
            self._small_num[key] = num
        return num

    def assign(self, ids: list | None, rows, t_s: float, int_ids: np.ndarray | None = None) -> np.ndarray:
        """Message ids (int64, one per entry of ``rows``: sorted, distinct indices) of the objects ``ids[rows]`` of a
        frame at time ``t_s`` (s).

        ``int_ids``: the frame's ids as int64 (``ids`` all Python ints; the caller's promise; ``ids`` None: they are
        ``int_ids.tolist()``, made only if needed): a frame of distinct ids in 0..65535 is then assigned by array,
        its ids known before looked up in one step, only its new ids one by one -- the same numbers and the same
        tables as without it (``tests/test_service_columnar.py``)."""
        if int_ids is not None:
            nums = self._assign_small(int_ids if len(rows) == len(int_ids) else int_ids[rows], rows, t_s)
            if nums is not None:
                return nums
            if ids is None:
                ids = int_ids.tolist()
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
        self._sync()
        self._seen.update(dict.fromkeys(keys, t_s))
        return np.array(nums, dtype=np.int64)

    def _assign_small(self, sel: np.ndarray, rows, t_s: float) -> np.ndarray | None:
        """:meth:`assign` of the integer ids ``sel`` (int64) by array; None (nothing changed): not distinct ids in
        0..65535, for the general path.  The look-up of a frame whose ids are all known is one compiled pass
        (:func:`_lookup_small`)."""
        m = len(sel)
        if m == 0:
            return None
        if self._state is None:  # (the ids the general path assigned so far, too)
            self._state, self._small_seen = np.zeros((4, 1 + _N), np.int64), np.zeros(_N)
            self._small_num, self._mark, self._dirty = self._state[0, :_N], self._state[1, :_N], self._state[2, :_N]
            self._pending = self._state[3]
            self._small_num[:] = -1
            for key, num in self._num.items():
                if type(key) is int and 0 <= key < _N:
                    self._small_num[key] = num
        # (the clock and its sweep before the look-up, as the general path does first when this one declines)
        if t_s > self._now:
            self._now = t_s
        if self._now >= self._next_sweep:
            self._sweep()
        nums = np.empty(m, np.int64)
        n_new = _lookup_small(sel, self._state, self._small_seen, t_s, nums)
        if n_new < 0:  # ids out of 0..65535, or an id twice (its occurrences are other objects)
            return None
        if n_new:  # (their keys enter ``_seen`` in the frame's order, as the general path's update does)
            new = np.flatnonzero(nums < 0)
            self._frame_keys = sel.tolist()
            rows_l = np.asarray(rows, dtype=np.int64)[new].tolist()
            for j, key, r in zip(new.tolist(), sel[new].tolist(), rows_l, strict=True):
                nums[j] = self._assign(key, key, r, 0, None)
            self._sync()
            self._seen.update(dict.fromkeys(sel[new].tolist(), t_s))
            self._small_seen[sel] = t_s
            listed = sel[self._dirty[sel] == 0]  # (the frame's ids, distinct, into the pending list once each)
            n = int(self._pending[0])
            self._pending[1 + n:1 + n + len(listed)] = listed
            self._pending[0] = n + len(listed)
            self._dirty[listed] = 1
        return nums


@njit(cache=True, nogil=True)
def _lookup_small(sel, state, small_seen, t_s, nums):  # pragma: no cover - compiled
    """:meth:`MessageIdMap._assign_small`'s look-up in one pass (``state`` (4, 65537) int64: the rows
    ``small_num``, ``mark``, ``dirty``, ``pending``): -1 when an id of ``sel (m,)`` is outside 0..65535 or there
    twice (``mark``: scratch); else each id's number into ``nums`` (-1: new) and the count of the new ones --
    with none new, their frame time ``t_s`` into ``small_seen`` too and each id not listed yet (``dirty``) onto
    the pending list ``pending[1:1 + pending[0]]`` (with some new, the caller does both after assigning them)."""
    small_num, mark, dirty, pending = state[0], state[1], state[2], state[3]
    m = sel.shape[0]
    for j in range(m):
        k = sel[j]
        if k < 0 or k >= small_seen.shape[0]:
            return -1
        mark[k] = j
    n_new = 0
    for j in range(m):
        k = sel[j]
        if mark[k] != j:
            return -1
        nums[j] = small_num[k]
        n_new += nums[j] < 0
    if n_new == 0:
        n = pending[0]
        for j in range(m):
            k = sel[j]
            small_seen[k] = t_s
            if dirty[k] == 0:
                dirty[k] = 1
                n += 1
                pending[n] = k
        pending[0] = n
    return n_new
