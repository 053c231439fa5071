"""Footprint tables -> a ROS 2 bag: per frame a ``vision_msgs/msg/Detection3DArray`` and a ``visualization_msgs/
msg/MarkerArray`` (:mod:`.messages`), optionally a Foxglove ``SceneUpdate`` (:mod:`.foxglove_scene`).

:class:`RosBagOut` is a :class:`~footprint_uq.batch.writers.FootprintWriter`: the batch hands it the footprint
table chunk by chunk (``process_file(..., writer_factory=bag_writer_factory(options))``), it cuts the rows into
frames and records each frame's messages as it completes.  Two outputs:

* ``run.mcap`` -- one MCAP file (ROS 2 profile: ``ros2msg`` schemas from the rosbags type store, CDR messages;
  zstd chunks), written with the ``mcap`` library; with ``foxglove=True`` it also holds the channel
  ``<prefix>/scene`` (``foxglove.SceneUpdate``, protobuf).  ``ros2 bag`` (rosbag2's MCAP storage), Foxglove and
  rosbags read the file directly (rosbags <= 0.11 cannot open the protobuf channel: write without ``--foxglove``
  for rosbags-based tools);
* ``run_bag/`` -- a rosbag2 folder (``metadata.yaml`` and one storage file, MCAP or sqlite3) written by rosbags.

Frames: consecutive rows with the same ``camera_id``, ``frame`` and ``timestamp_s`` (the columns present) are
one frame, one message per topic, stamped ``timestamp_s`` (required).  Rows without a centre (status ``partial``
or ``error``: their reason is in the footprint table's summary) and rows whose ``timestamp_s`` is not a time
>= 0 are not in the messages; :meth:`RosBagOut.info` counts them by reason (the job's summary holds it).

Atomic like every output: the file or folder is built under a hidden temporary name and renamed into place
when complete; an existing folder is replaced only when it is a bag (has ``metadata.yaml``) or empty.
"""

from __future__ import annotations

import os
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ...batch import schema as S
from ...batch.writers import FootprintWriter
from ...errors import ConfigError, InputError
from ...io.atomic import clean_temporaries_of, commit, fsync_dir, recover_folder, remove_tree, swap_in_folder, temp_path
from . import foxglove_scene
from .messages import FrameFootprints, detection3d_array, ellipse_marker_array
from .types import DEFAULT_DISTRO, EXTRA, typestore

__all__ = ["BagOptions", "BagRecorder", "RosBagOut", "bag_out_kind", "bag_writer_factory", "STORAGES",
           "DETECTIONS_TYPE",
           "MARKERS_TYPE"]

DETECTIONS_TYPE = "vision_msgs/msg/Detection3DArray"
MARKERS_TYPE = "visualization_msgs/msg/MarkerArray"
#: storages of a bag folder
STORAGES = ("mcap", "sqlite3")
_NS = 1_000_000_000


@dataclass
class BagOptions:
    """How footprints become a bag.

    Attributes
    ----------
    frame_id : str         header.frame_id of every message (the world frame W; REP 105's ``map`` by default)
    topic_prefix : str     topics ``<prefix>/detections``, ``<prefix>/ellipses`` (and ``<prefix>/scene``)
    distro : str           ROS 2 distribution of the message definitions (:data:`.types.DISTROS`)
    storage : str          a bag folder's storage (:data:`STORAGES`); a ``.mcap`` file is MCAP
    foxglove : bool        also write Foxglove SceneUpdates (``.mcap`` file only)
    camera : Camera        drawn in the Foxglove scene; its ``ground_z_m`` is the z of the poses
    ground_z_m : float     z of the poses when no camera is given
    """

    frame_id: str = "map"
    topic_prefix: str = "/footprints"
    distro: str = DEFAULT_DISTRO
    storage: str = "mcap"
    foxglove: bool = False
    camera: object = None
    ground_z_m: float = 0.0


def bag_out_kind(path) -> str | None:
    """``"mcap"`` for a ``.mcap`` file, ``"folder"`` for a path ending in a separator or an existing folder, else
    None (not a bag output)."""
    text = str(path)
    if text.lower().endswith(".mcap"):
        return "mcap"
    if text.endswith(("/", os.sep)) or Path(text).is_dir():
        return "folder"
    return None


class _McapFile:
    """A single MCAP file (ROS 2 profile) written with the ``mcap`` library."""

    def __init__(self, tmp: Path):
        try:
            from mcap.writer import CompressionType
            from mcap.writer import Writer as McapWriter
        except ImportError as e:
            raise ConfigError("out", f"{e.name} not installed", EXTRA) from None
        self._f = open(tmp, "wb")
        self._w = McapWriter(self._f, compression=CompressionType.ZSTD)
        self._w.start(profile="ros2", library="footprint-uq")

    def add(self, topic: str, schema_name: str, schema_encoding: str, schema_data: bytes, msg_encoding: str) -> int:
        sid = self._w.register_schema(schema_name, schema_encoding, schema_data)
        return self._w.register_channel(topic, msg_encoding, sid)

    def write(self, channel: int, stamp_ns: int, data: bytes) -> None:
        self._w.add_message(channel, stamp_ns, data, stamp_ns)

    def close(self) -> None:
        try:
            self._w.finish()
        finally:
            self._f.close()

    def abort(self) -> None:
        self._f.close()


class _Rosbag2Folder:
    """A rosbag2 folder (metadata.yaml + one storage file) written with rosbags.

    Every call runs in one thread of its own: the batch writes from its writer thread and closes from the
    caller's, and an sqlite3 connection may only be used by the thread that made it."""

    def __init__(self, bag_path: Path, storage: str):
        from rosbags.rosbag2 import StoragePlugin  # installed: typestore() checked it
        from rosbags.rosbag2 import Writer as Rosbag2Writer

        self._pool = ThreadPoolExecutor(1, thread_name_prefix="footprint-uq-rosbag2")
        self._w = Rosbag2Writer(bag_path, version=9, storage_plugin=getattr(StoragePlugin, storage.upper()))
        self._call(self._w.open)

    def _call(self, fn, *args, **kw):
        return self._pool.submit(fn, *args, **kw).result()

    def add_ros(self, topic: str, msgtype: str, ts) -> object:
        return self._call(self._w.add_connection, topic, msgtype, typestore=ts)

    def write(self, connection, stamp_ns: int, data: bytes) -> None:
        self._call(self._w.write, connection, stamp_ns, data)

    def close(self) -> None:
        try:
            self._call(self._w.close)
        finally:
            self._pool.shutdown()

    def abort(self) -> None:
        try:
            self._call(self._w.abort)
        finally:
            self._pool.shutdown()


class BagRecorder:
    """Frames (:class:`~.messages.FrameFootprints`) -> a ROS 2 bag at ``path``: a ``.mcap`` path is one MCAP file,
    any other a bag folder.  Built under a hidden temporary name; :meth:`close` puts it in place, :meth:`abort`
    removes it.  Used by :class:`RosBagOut` (the batch) and by ``serve --output rosbag:PATH`` (:mod:`.live`)."""

    def __init__(self, path, options: BagOptions | None = None):
        self.options = o = options or BagOptions()
        self.kind = "mcap" if str(path).lower().endswith(".mcap") else "folder"
        if o.foxglove and self.kind != "mcap":
            raise InputError("foxglove", str(path), "an .mcap output file (Foxglove scenes are protobuf channels, "
                             "which a rosbag2 folder cannot hold)")
        if o.storage not in STORAGES:
            raise InputError("storage", o.storage, f"one of {list(STORAGES)}")
        if not isinstance(o.frame_id, str) or not o.frame_id.strip() or o.frame_id != o.frame_id.strip():
            raise InputError("frame_id", o.frame_id, "a frame name (non-empty, no surrounding spaces)")
        self.path = Path(str(path).rstrip("/" + os.sep) or str(path))
        if self.kind == "folder":
            self._check_folder()
        elif self.path.is_dir():
            raise InputError("out", str(self.path), "an .mcap file path (this is a folder)")
        if self.kind == "folder":
            recover_folder(self.path)  # staging folders (and a half-done swap) of a killed run on the same output
        else:
            clean_temporaries_of(self.path)  # left by a killed run on the same output
        self.tmp = temp_path(self.path)
        self.ts = typestore(o.distro)
        self.ground_z_m = float(o.camera.ground_z_m) if o.camera is not None else float(o.ground_z_m)
        self.frames = 0
        self.objects = 0
        self.messages: Counter = Counter()
        self._done = False
        self._open()

    def _check_folder(self) -> None:
        p = self.path
        if p.exists() and not p.is_dir():
            raise InputError("out", str(p), "a bag folder path (this is a file)")
        if p.is_dir() and any(p.iterdir()) and not (p / "metadata.yaml").exists():
            raise InputError("out", str(p), "a new, empty or bag folder (this folder holds other files: not "
                             "replaced)")

    def _open(self) -> None:
        o, ts = self.options, self.ts
        prefix = o.topic_prefix.rstrip("/")
        topics = [(f"{prefix}/detections", DETECTIONS_TYPE), (f"{prefix}/ellipses", MARKERS_TYPE)]
        if self.kind == "mcap":
            self._sink = _McapFile(self.tmp)
            self._channels = [self._sink.add(topic, typ, "ros2msg",
                                             ts.generate_msgdef(typ, ros_version=2)[0].encode(), "cdr")
                              for topic, typ in topics]
            if o.foxglove:
                sch = foxglove_scene.scene_schema()
                self._channels.append(self._sink.add(f"{prefix}/scene", sch.name, sch.encoding, bytes(sch.data),
                                                     "protobuf"))
        else:
            self.tmp.mkdir()
            self._sink = _Rosbag2Folder(self.tmp / self.path.name, o.storage)
            self._channels = [self._sink.add_ros(topic, typ, ts) for topic, typ in topics]
        self.topics = [t for t, _ in topics] + ([f"{prefix}/scene"] if o.foxglove else [])

    def write_frame(self, f: FrameFootprints) -> None:
        """Record one frame: its Detection3DArray, MarkerArray (and SceneUpdate), stamped ``f.stamp_ns``."""
        ts = self.ts
        payloads = [ts.serialize_cdr(detection3d_array(ts, f), DETECTIONS_TYPE),
                    ts.serialize_cdr(ellipse_marker_array(ts, f), MARKERS_TYPE)]
        if self.options.foxglove:
            payloads.append(foxglove_scene.scene_update(f, self.options.camera).encode())
        for ch, topic, data in zip(self._channels, self.topics, payloads, strict=True):
            self._sink.write(ch, f.stamp_ns, bytes(data))
            self.messages[topic] += 1
        self.frames += 1
        self.objects += len(f.object_ids)

    def info(self) -> dict:
        """What the bag holds."""
        return {"kind": self.kind, "path": str(self.path), "storage": "mcap" if self.kind == "mcap" else
                self.options.storage, "frame_id": self.options.frame_id, "distro": self.options.distro,
                "topics": self.topics, "frames": self.frames, "objects": self.objects,
                "messages": dict(self.messages)}

    def close(self, *, fsync: bool = True, before_commit=None) -> None:
        """Finish the bag and put it in place (``before_commit`` runs just before)."""
        if self._done:
            return
        self._done = True
        try:
            self._sink.close()
            if before_commit is not None:
                before_commit()
            if self.kind == "mcap":
                commit(self.tmp, self.path, fsync=fsync)
                return
            staged = self.tmp / self.path.name
            if fsync:
                for p in staged.iterdir():
                    with open(p, "rb") as fh:
                        os.fsync(fh.fileno())
                fsync_dir(staged)
            swap_in_folder(staged, self.path, fsync=fsync)
            remove_tree(self.tmp)
        except BaseException:
            remove_tree(self.tmp)
            raise

    def abort(self) -> None:
        """Drop the bag (never raises)."""
        if self._done:
            return
        self._done = True
        try:
            self._sink.abort()
        except Exception:  # noqa: BLE001 - the output is being dropped
            pass
        finally:
            remove_tree(self.tmp)


class RosBagOut(FootprintWriter):
    """A ROS 2 bag of footprint tables (module docstring; :class:`BagRecorder`): ``write(table)`` per chunk,
    ``close()`` at the end."""

    format = "rosbag"

    def __init__(self, path, schema: pa.Schema, options: BagOptions | None = None):
        if "timestamp_s" not in schema.names:
            raise InputError("timestamp_s", "missing", "a timestamp_s column (Unix time, s): the messages' "
                             "header.stamp")
        super().__init__(path, schema)  # (cleans what a killed run left; the recorder makes the temporary)
        self.rec = BagRecorder(path, options)
        self.path, self.tmp = self.rec.path, self.rec.tmp
        self._carry: pa.Table | None = None
        self.omitted: Counter = Counter()

    def _write(self, table: pa.Table) -> None:
        if self._carry is not None:
            table = pa.concat_tables([self._carry, table.cast(self._carry.schema)]) if table.num_rows else self._carry
            self._carry = None
        if not table.num_rows:
            return
        starts = _frame_starts(table)
        for k in range(len(starts) - 2):
            self._frame(table.slice(starts[k], starts[k + 1] - starts[k]))
        self._carry = table.slice(starts[-2])  # the last frame may go on in the next chunk

    def _frame(self, t: pa.Table) -> None:
        ts_s = _floats(t, "timestamp_s")[0]
        ok = np.asarray(t.column("status").cast(pa.string()).to_pylist(), dtype=object) == S.STATUS_OK
        if not (np.isfinite(ts_s) and ts_s >= 0.0):
            self.omitted[f"timestamp_s {float(ts_s)!r} is not a time >= 0"] += t.num_rows
            return
        if (~ok).any():
            self.omitted["no centre (status partial or error)"] += int((~ok).sum())
        self.rec.write_frame(_frame_footprints(t.filter(pa.array(ok)), int(round(ts_s * _NS)),
                                               self.rec.options.frame_id, self.rec.ground_z_m))

    def info(self) -> dict:
        """What the bag holds (the job summary's ``bag`` entry)."""
        return {"bag": {**self.rec.info(), "rows_not_in_bag": int(sum(self.omitted.values())),
                        "not_in_bag": dict(self.omitted)}}

    def _close(self) -> None:
        if self._carry is not None:
            carry, self._carry = self._carry, None
            self._frame(carry)

    def _sync(self) -> None:
        if self.rec.kind == "mcap":
            super()._sync()

    def close(self) -> None:
        if self._done:
            return
        self._done = True
        try:
            self._close()
        except BaseException:
            self._close_fd()
            self.rec.abort()
            raise
        self._close_fd()
        self.rec.close(fsync=self.fsync, before_commit=self.before_commit)

    def abort(self) -> None:
        if self._done:
            return
        self._done = True
        self._close_fd()
        self.rec.abort()


def _floats(t: pa.Table, name: str) -> np.ndarray:
    col = t.column(name)
    if not pa.types.is_floating(col.type):
        col = pc.cast(col, pa.float64(), safe=False)
    return col.fill_null(np.nan).to_numpy(zero_copy_only=False).astype(np.float64, copy=False)


def _frame_starts(t: pa.Table) -> list[int]:
    """Row offsets where a frame starts (a change of camera_id, frame or timestamp_s), then ``t.num_rows``."""
    n = t.num_rows
    change = np.zeros(max(n - 1, 0), dtype=bool)
    for name in ("camera_id", "frame", "timestamp_s"):
        if name not in t.column_names:
            continue
        col = t.column(name)
        if name == "timestamp_s":
            v = _floats(t, name).view(np.int64)  # NaN == NaN bit patterns: one frame of bad timestamps
        else:
            col = col.dictionary_encode() if not pa.types.is_dictionary(col.type) else col
            v = col.combine_chunks().indices.fill_null(-1).to_numpy(zero_copy_only=False)
        change |= v[1:] != v[:-1]
    return [0] + (np.flatnonzero(change) + 1).tolist() + [n]


def _frame_footprints(t: pa.Table, stamp_ns: int, frame_id: str, ground_z_m: float) -> FrameFootprints:
    n = t.num_rows
    names = t.column_names

    def strings(name, default):
        if name not in names:
            return default
        return ["" if v is None else str(v) for v in t.column(name).cast(pa.string()).to_pylist()]

    rows = t.column("row").to_pylist()
    ids = strings("object_id", [f"row {r}" for r in rows])
    cxx, cxy, cyy = (_floats(t, c) for c in ("cov_xx_m2", "cov_xy_m2", "cov_yy_m2"))
    cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2).reshape(n, 2, 2)
    return FrameFootprints(stamp_ns=stamp_ns, frame_id=frame_id, object_ids=ids, classes=strings("class", [""] * n),
                           scores=_floats(t, "score") if "score" in names else np.full(n, np.nan),
                           xy_world_m=np.stack([_floats(t, "x_m"), _floats(t, "y_m")], -1).reshape(n, 2),
                           cov_m2=cov, ground_z_m=ground_z_m)


def bag_writer_factory(options: BagOptions):
    """A ``writer_factory`` for :func:`footprint_uq.batch.process.process_file`: ``(out, schema, fsync)`` ->
    :class:`RosBagOut`."""

    def make(out, schema: pa.Schema, *, fsync: bool = True) -> RosBagOut:
        w = RosBagOut(out, schema, options)
        w.fsync = bool(fsync)
        return w

    make.format = "rosbag"
    return make
