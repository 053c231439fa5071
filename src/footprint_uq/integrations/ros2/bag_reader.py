"""ROS 2 bags in: ``vision_msgs/msg/Detection2DArray`` topics -> the canonical detection table, and a bag's
``sensor_msgs/msg/CameraInfo`` -> the camera (its pose from the usual options).

:class:`BagDetectionReader` has the interface of :class:`~footprint_uq.batch.readers.DetectionReader`
(``columns``, ``id_fields``, ``select``, iteration over :class:`~footprint_uq.batch.readers.Chunk`), so
``process_file(..., reader=BagDetectionReader(bag, topic=...))`` computes the footprints of a bag exactly as of a
CSV file.  :func:`read_bag_detections` is the same as one table.  :data:`BagFormat` is the bag in the batch's
format registry (``ros2-bag``: :func:`footprint_uq.read_detections`, ``validate --detections bag.mcap``), entered
there by name (:class:`~footprint_uq.batch.formats.LazyFormat`: ``batch/`` does not import this layer).

A bag is a rosbag2 folder (``metadata.yaml``; MCAP or sqlite3 storage) or a bare ``.mcap`` / ``.db3`` file, read
by rosbags (``AnyReader``: the message definitions come from the bag itself, so vision_msgs 3 (Foxy, Galactic)
and 4 (Humble on) both read).  Per detection (``Detection2D``) one row:

========================  ==========================================================================================
column                    from
========================  ==========================================================================================
``row``                   the detection's index in the topic (messages in log-time order, detections in order)
``frame``                 the message's index in the topic
``timestamp_s``           ``header.stamp`` of the array (Unix time, s)
``object_id``             ``id`` (vision_msgs 3: ``tracking_id``); null when empty
``class``, ``score``      the hypothesis of the highest score in ``results`` (null, NaN without one)
``u_min_px`` ...          ``bbox``: centre -/+ half the size (an axis-aligned box in pixels)
========================  ==========================================================================================

A rotated box (``bbox.center.theta`` not 0) or a size that is not a finite number > 0 is that detection's error
(its row, with the reason); the other detections go on.  A bag without the requested topic: one line naming the
bag's topics (:class:`~footprint_uq.errors.InputError`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

from ...batch import schema as S
from ...batch.formats import FormatOptions, is_ros2_bag, table_format
from ...batch.readers import Chunk, coerce_table
from ...errors import InputError
from ...io.ros_files import camera_from_ros_info, ros_camera_info
from .types import typestore

__all__ = ["DETECTION2D_ARRAY", "CAMERA_INFO", "BagDetectionReader", "read_bag_detections", "bag_camera_info",
           "camera_from_bag", "is_bag", "bag_topics", "bag_tables", "BagFormat"]

DETECTION2D_ARRAY = "vision_msgs/msg/Detection2DArray"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
_COLUMNS = ("frame", "timestamp_s", "object_id", "class", "score") + S.BOX2D_COLUMNS
_NUMERIC = S.BOX2D_COLUMNS


#: a ROS 2 bag: a ``.mcap`` or ``.db3`` file, or a folder with ``metadata.yaml`` (the format registry's test)
is_bag = is_ros2_bag


def _open(path):
    """An open rosbags ``AnyReader`` of the bag (InputError for a missing or unreadable one)."""
    ts = typestore()  # checks that rosbags is installed
    from rosbags.highlevel import AnyReader
    from rosbags.highlevel.anyreader import AnyReaderError

    p = Path(path)
    if not p.exists():
        raise InputError("detections", str(path), "an existing ROS 2 bag (a .mcap or .db3 file, or a bag folder)")
    reader = AnyReader([p], default_typestore=ts)
    try:
        reader.open()
    except (AnyReaderError, KeyError, ValueError, OSError) as e:
        other = _non_ros_channels(p)
        why = (f"its channels {', '.join(other)} are not ROS 2 (ros2msg / CDR), which rosbags cannot read; e.g. the "
               "--foxglove scene: write the bag without --foxglove") if other else f"{type(e).__name__}: {e}"
        raise InputError("detections", str(path), f"a readable ROS 2 bag ({why})") from None
    return reader


def _non_ros_channels(p: Path) -> list[str]:
    """``topic (schema encoding)`` of an MCAP file's channels that are not ROS 2 messages (empty when none or
    not an MCAP file)."""
    if p.suffix.lower() != ".mcap" or not p.is_file():
        return []
    try:
        from mcap.reader import make_reader

        with open(p, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - only a better message is at stake
        return []
    if summary is None:
        return []
    return sorted(f"{c.topic} ({summary.schemas[c.schema_id].encoding})" for c in summary.channels.values()
                  if c.schema_id in summary.schemas and summary.schemas[c.schema_id].encoding not in
                  ("ros2msg", "ros2idl", "omgidl"))


def bag_topics(reader) -> dict[str, str]:
    """topic -> message type of an open bag."""
    return {c.topic: c.msgtype for c in reader.connections}


def _pick_topic(reader, topic: str | None, msgtype: str, option: str, path) -> str | None:
    """The topic to read: ``topic`` (checked), else the bag's only topic of ``msgtype`` (None if it has none)."""
    topics = bag_topics(reader)
    listing = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
    if topic is not None:
        if topics.get(topic) != msgtype:
            raise InputError(option, topic, f"a {msgtype} topic of the bag {path} (its topics: {listing})")
        return topic
    found = sorted(t for t, m in topics.items() if m == msgtype)
    if len(found) > 1:
        raise InputError(option, None, f"one of the bag's {msgtype} topics {found} (the bag has several)")
    return found[0] if found else None


def _best_hypothesis(results) -> tuple[str | None, float]:
    best, score = None, -math.inf
    for r in results:
        h = getattr(r, "hypothesis", r)  # vision_msgs 4: r.hypothesis.class_id; 3: r.id, r.score
        cls = getattr(h, "class_id", None)
        cls = str(getattr(h, "id", "")) if cls is None else cls
        if best is None or h.score > score:
            best, score = cls, float(h.score)
    return best, (score if best is not None else math.nan)


def _box(det) -> tuple[tuple[float, float, float, float], str | None]:
    """(u_min, v_min, u_max, v_max) of a Detection2D's bbox and the reason it is unusable (None if usable)."""
    c = det.bbox.center
    pos = getattr(c, "position", c)  # vision_msgs 4: center.position.x; 3: geometry_msgs/Pose2D center.x
    cx, cy, theta = float(pos.x), float(pos.y), float(c.theta)
    w, h = float(det.bbox.size_x), float(det.bbox.size_y)
    box = (cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h)
    if theta != 0.0:
        return box, f"bbox.center.theta: {theta!r} is not 0 (a rotated box; expected an axis-aligned box)"
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        return box, f"bbox.size_x/size_y: ({w!r}, {h!r}) are not finite numbers > 0"
    return box, None


class BagDetectionReader:
    """The detections of one Detection2DArray topic of a ROS 2 bag, in chunks (module docstring: the columns).

    Parameters
    ----------
    path : a bag folder, ``.mcap`` or ``.db3`` file
    topic : str, optional
        The Detection2DArray topic (default: the bag's only one).
    chunk_rows : int
        Detections per chunk.
    """

    format = "rosbag"
    unit = "msg"
    lines = None

    def __init__(self, path, *, topic: str | None = None, chunk_rows: int = S.DEFAULT_CHUNK_ROWS):
        self.path = Path(path)
        if int(chunk_rows) < 1:
            raise InputError("chunk_rows", chunk_rows, "an integer >= 1")
        self.chunk_rows = int(chunk_rows)
        reader = _open(path)
        try:
            self.topic = _pick_topic(reader, topic, DETECTION2D_ARRAY, "topic", path)
            if self.topic is None:
                listing = ", ".join(f"{t} ({m})" for t, m in sorted(bag_topics(reader).items())) or "none"
                raise InputError("topic", None, f"a {DETECTION2D_ARRAY} topic in the bag {path} (its topics: "
                                 f"{listing})")
            self.total = sum(c.msgcount for c in reader.connections if c.topic == self.topic)
        finally:
            reader.close()
        self.columns = list(_COLUMNS)
        self.family_columns = list(_COLUMNS)
        self.numeric: tuple[str, ...] = _NUMERIC

    def select(self, numeric: tuple[str, ...]) -> None:
        """Only the 2-D box columns are numeric here (the batch asks for them)."""
        self.numeric = tuple(numeric)

    @property
    def id_fields(self) -> list[pa.Field]:
        return [pa.field(c, S.ID_TYPES[c]) for c in S.ID_COLUMNS if c in self.columns]

    def __iter__(self) -> Iterator[Chunk]:
        reader = _open(self.path)
        try:
            yield from self._chunks(reader)
        finally:
            reader.close()

    def _chunks(self, reader) -> Iterator[Chunk]:
        cols = {c: [] for c in _COLUMNS}
        reasons: list = []
        row0, msgs = 0, 0
        conns = [c for c in reader.connections if c.topic == self.topic]
        for frame, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
            msg = reader.deserialize(raw, conn.msgtype)
            t_s = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            for det in msg.detections:
                box, why = _box(det)
                cls, score = _best_hypothesis(det.results)
                oid = getattr(det, "id", None)
                oid = getattr(det, "tracking_id", "") if oid is None else oid
                for name, v in zip(_COLUMNS, (frame, t_s, oid or None, cls, score) + box, strict=True):
                    cols[name].append(v)
                reasons.append(why)
            msgs += 1
            if len(reasons) >= self.chunk_rows:
                yield self._chunk(cols, reasons, row0, msgs)
                row0 += len(reasons)
                cols, reasons, msgs = {c: [] for c in _COLUMNS}, [], 0
        if reasons or row0 == 0:
            yield self._chunk(cols, reasons, row0, msgs)

    def _chunk(self, cols: dict, reasons: list, row0: int, msgs: int) -> Chunk:
        n = len(reasons)
        t = pa.table({c: pa.array(v, type=S.ID_TYPES.get(c, pa.float64())) for c, v in cols.items()})
        numeric = tuple(c for c in self.numeric if c in t.column_names)
        t, pre = coerce_table(t, numeric)
        if any(r is not None for r in reasons):
            pre = list(pre) if pre is not None else [None] * n
            pre = [p if p is not None else r for p, r in zip(pre, reasons, strict=True)]
        return Chunk(t, np.arange(row0, row0 + n, dtype=np.int64), pre, [], msgs)


def read_bag_detections(path, *, topic: str | None = None) -> tuple[pa.Table, list | None]:
    """All detections of a bag's Detection2DArray topic as one table (columns of the module docstring) and the
    reasons of its unusable detections (None when all are usable; else one entry per row, None for usable)."""
    chunks = list(BagDetectionReader(path, topic=topic, chunk_rows=1 << 62))
    c = chunks[0]
    return c.table, c.pre_errors


def bag_camera_info(path, *, topic: str | None = None) -> dict | None:
    """The first ``sensor_msgs/msg/CameraInfo`` of the bag (``topic``, default its only CameraInfo topic), checked
    (:func:`footprint_uq.io.ros_files.ros_camera_info`), or None when the bag has none."""
    reader = _open(path)
    try:
        t = _pick_topic(reader, topic, CAMERA_INFO, "camera-info-topic", path)
        if t is None:
            return None
        conns = [c for c in reader.connections if c.topic == t]
        for conn, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            d = {"k": np.asarray(m.k, dtype=np.float64).tolist(), "d": np.asarray(m.d, dtype=np.float64).tolist(),
                 "r": np.asarray(m.r, dtype=np.float64).tolist(), "distortion_model": m.distortion_model,
                 "width": int(m.width), "height": int(m.height)}
            return ros_camera_info(d, f"{path} {t}")
        return None
    finally:
        reader.close()


def camera_from_bag(path, *, pose, topic: str | None = None, ground_z_m=None):
    """The camera of the bag's CameraInfo (K, D, size) at ``pose`` (the pose options' value: a pose file or the
    paper's pose parameters); InputError when the bag has no CameraInfo."""
    info = bag_camera_info(path, topic=topic)
    if info is None:
        raise InputError("camera", None, f"a --camera file, or a {CAMERA_INFO} topic in the bag {path}")
    return camera_from_ros_info(info, pose=pose, ground_z_m=ground_z_m)


def bag_tables(path, options: FormatOptions) -> Iterator[pa.Table]:
    """The canonical tables of a bag's Detection2DArray topic (``options.topic``, default its only one) with their
    ``error`` column, for the format registry; a CameraInfo of another size than ``options.image_size_px`` stops
    the job (one line)."""
    if options.image_size_px is not None:
        info = bag_camera_info(path)
        want = tuple(int(v) for v in options.image_size_px)
        got = None if info is None else tuple(int(v) for v in info["image_size_px"])
        if got is not None and got != want:
            raise InputError(f"{path}: CameraInfo", f"{got[0]} x {got[1]} px", f"images of the "
                             f"camera's size {want[0]} x {want[1]} px (detections made on the camera's images)")
    for ch in BagDetectionReader(path, topic=options.topic):
        err = ch.pre_errors if ch.pre_errors is not None else [None] * ch.table.num_rows
        yield ch.table.append_column("error", pa.array(err, pa.string()))


#: the bag as a detector format (``--format ros2-bag``; detected from .mcap / .db3 / a bag folder)
BagFormat = table_format("ros2-bag", bag_tables, sniff=is_bag, id_columns=_COLUMNS[:5])
