"""``serve --output rosbag:PATH``: the service's footprints records recorded live into a ROS 2 bag.

Each footprints record (docs/service.md, "Records out") becomes one frame of the bag, exactly as the batch
writes it (:class:`~.bag_writer.BagRecorder`: a Detection3DArray and a MarkerArray per frame, stamped with the
record's ``timestamp_s``; ``PATH`` ending in ``.mcap`` is one MCAP file, else a bag folder).  Objects without a
centre (``status`` not ``ok``) are not in the messages and are counted; the bag is built under a hidden
temporary name and put in place when the service stops (SIGTERM, SIGINT or the end of its input).
"""

from __future__ import annotations

import threading
from collections import Counter

import numpy as np
import orjson

from ...batch import schema as S
from .bag_writer import BagOptions, BagRecorder
from .messages import FrameFootprints

__all__ = ["ROSBAG_PREFIX", "LiveBag", "frame_of_record"]

#: the ``--output`` value's prefix
ROSBAG_PREFIX = "rosbag:"


def frame_of_record(rec: dict, *, frame_id: str, ground_z_m: float) -> tuple[FrameFootprints | None, int]:
    """A footprints record -> (the frame of its objects with a centre, or None when its ``timestamp_s`` is not a
    time >= 0; the number of its objects left out)."""
    ts_s = rec.get("timestamp_s")
    objs = rec.get("objects") or []
    if not isinstance(ts_s, int | float) or isinstance(ts_s, bool) or not (np.isfinite(ts_s) and ts_s >= 0):
        return None, len(objs)
    ok = [o for o in objs if o.get("status", S.STATUS_OK) == S.STATUS_OK and o.get("x_m") is not None]
    n = len(ok)
    return FrameFootprints(
        stamp_ns=int(round(float(ts_s) * 1e9)), frame_id=frame_id,
        object_ids=["" if o.get("object_id") is None else str(o["object_id"]) for o in ok],
        classes=["" if o.get("class") is None else str(o["class"]) for o in ok],
        scores=np.array([np.nan if o.get("score") is None else float(o["score"]) for o in ok], dtype=np.float64),
        xy_world_m=np.array([[o["x_m"], o["y_m"]] for o in ok], dtype=np.float64).reshape(n, 2),
        cov_m2=np.array([o["cov_m2"] for o in ok], dtype=np.float64).reshape(n, 2, 2),
        ground_z_m=ground_z_m), len(objs) - n


class LiveBag:
    """A bag fed one footprints record (JSON text) at a time, from any thread.

    Parameters
    ----------
    path : str       the bag (``.mcap`` file or folder)
    ground_z_m : dict camera_id -> the ground height of that camera's world (default 0)
    options : BagOptions, optional
    """

    def __init__(self, path: str, *, ground_z_m: dict | None = None, options: BagOptions | None = None):
        self.rec = BagRecorder(path, options)
        self._ground = dict(ground_z_m or {})
        self._lock = threading.Lock()
        self.omitted: Counter = Counter()

    def write_record(self, data: bytes) -> None:
        """Record one footprints record (``data``: its JSON text)."""
        rec = orjson.loads(data)
        gz = float(self._ground.get(rec.get("camera_id"), self._ground.get(None, 0.0)))
        frame, left_out = frame_of_record(rec, frame_id=self.rec.options.frame_id, ground_z_m=gz)
        with self._lock:
            if frame is None:
                self.omitted["timestamp_s not a time >= 0"] += left_out
                return
            self.omitted["no centre"] += left_out
            self.rec.write_frame(frame)

    def close(self) -> dict:
        """Finish the bag, put it in place; what it holds (:meth:`BagRecorder.info` and the objects left out)."""
        with self._lock:
            self.rec.close()
            return {**self.rec.info(), "objects_not_in_bag": {k: v for k, v in self.omitted.items() if v}}

    def abort(self) -> None:
        with self._lock:
            self.rec.abort()
