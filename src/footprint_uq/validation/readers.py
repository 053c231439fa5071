"""Labelled data in: 2-D detections paired with ground-truth ground points, per camera.

Every reader yields :class:`LabelChunk` objects (one camera, a block of objects).  Per object: the 2-D
box (the detection), the ground truth in the camera's world frame W, and -- where the row cannot be
used -- why.  Nothing is dropped silently: a malformed line is an error row with its line number; an
object without a 3-D annotation (a KITTI ``location`` of ``0 0 0``, ``DontCare``) is a detection without
truth; a truth without a usable 2-D box is a truth without detection; a label file without its
calibration (or the reverse) is reported by :class:`FolderReport`.

Formats (docs/validation.md, "Inputs"):

* **KITTI layout / Rope3D** (:func:`read_kitti_folder`): ``calib/<id>.txt`` (``P2``), ``denorm/<id>.txt``
  (ground plane) and ``label_2/<id>.txt`` (one object per line: ``type truncated occluded alpha u_min
  v_min u_max v_max h w l x y z rotation_y [score]``; ``x y z`` is the bottom centre of the 3-D box in
  the camera frame, metres).  The world frame is that of
  :func:`footprint_uq.io.dataset_files.camera_from_rope3d` (origin at the camera's foot point on the
  denorm plane, z up).
* **DAIR-V2X-I** (:func:`read_dair_v2x_folder`): ``label/camera/<id>.json`` (a list of objects with
  ``type``, ``2d_box`` {xmin, ymin, xmax, ymax}, ``3d_dimensions`` {h, w, l}, ``3d_location`` {x, y, z}
  (the 3-D box centre in the virtual-LiDAR frame, the world frame of the calibration) and ``rotation``),
  with the calibration of :func:`footprint_uq.io.dataset_files.camera_from_dair_v2x`
  (``calib/camera_intrinsic`` + ``calib/virtuallidar_to_camera``).
* **TUMTraf OpenLABEL** (:func:`read_openlabel`): ``openlabel.frames.<n>.objects.<uuid>.object_data``
  with a ``cuboid`` (``val`` = x, y, z, qx, qy, qz, qw, length, width, height: the 3-D box centre in
  the station frame of the calibration) and, for camera labels, a 2-D ``bbox`` (``val`` = u_centre,
  v_centre, width, height, pixels); the camera from
  :func:`footprint_uq.io.dataset_files.camera_from_tumtraf_file`.
* **Campaigns as recorded**: a folder of camera folders, each a KITTI layout and one calibration group
  (:func:`read_camera_folders`), and a folder of OpenLABEL sequences, each with its camera's
  ``calibration.json`` (:func:`read_openlabel_sequences`).
* **Pairs table** (:func:`read_pairs_table`): CSV / JSON Lines / Parquet with the 2-D detection columns
  of docs/batch.md (``u_min_px v_min_px u_max_px v_max_px``, optional ``cov_uu_px2 cov_uv_px2
  cov_vv_px2``, ``camera_id frame object_id class``) and the truth ``x_m, y_m`` (world frame) or
  ``lat_deg, lon_deg`` (WGS84, with the camera's geodetic origin): the probe-vehicle workflow.
* **A detector's own files + a truth table** (:func:`read_detections_with_truth`): YOLO labels, a YOLOv5
  CSV, COCO results, MOTChallenge files (:mod:`footprint_uq.batch.formats`) paired with a table of
  ``frame, object_id`` and the truth by ``(frame, object_id)``.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from .._files import is_stream, read_input_bytes
from ..batch.formats import open_reader
from ..batch.process import MAX_PIXEL_VAR_PX2, PSD_TOL
from ..batch.readers import open_detections
from ..batch.schema import BOX2D_COLUMNS, COV_COLUMNS
from ..errors import ConfigError, InputError
from ..io.dataset_files import camera_from_dair_v2x, camera_from_rope3d, camera_from_tumtraf_file
from ..products.geo import GeoReference

__all__ = ["LabelChunk", "FolderReport", "read_kitti_folder", "parse_kitti_labels", "read_dair_v2x_folder",
           "parse_dair_v2x_labels", "read_openlabel", "read_pairs_table", "read_detections_with_truth",
           "TRUTH_XY_COLUMNS", "TRUTH_VELOCITY_COLUMNS", "TRUTH_GEO_COLUMNS", "NO_TRUTH", "NO_DETECTION",
           "ROPE3D_IMAGE_SIZE_PX", "camera_folders", "read_camera_folders", "openlabel_sequences",
           "read_openlabel_sequences", "SEQUENCE_CALIBRATION", "row_problems", "MAX_BOX_PX", "MAX_TRUTH_RANGE_M",
           "MAX_TRUTH_Z_M", "MAX_COORD_M"]

#: truth columns of a pairs table: world frame, or WGS84 (needs the camera's geodetic origin)
TRUTH_XY_COLUMNS = ("x_m", "y_m")
TRUTH_GEO_COLUMNS = ("lat_deg", "lon_deg")
#: optional truth velocity of a pairs table: true east / north, m/s (as ``objects --tracks`` writes its velocity);
#: with them, ``timestamp_s`` and ``object_id`` are needed (docs/validation.md, "Velocity and heading")
TRUTH_VELOCITY_COLUMNS = ("v_east_mps", "v_north_mps")
#: reasons of the two kinds of unpaired rows (not errors: counted apart)
NO_TRUTH = "no truth"
NO_DETECTION = "no detection"
#: Rope3D images are 1920 x 1080 (the size is not in its calibration files)
ROPE3D_IMAGE_SIZE_PX = (1920, 1080)
#: sane ranges of a labelled row's numbers (beyond them the row is an error row, never a pair): a box corner
#: this far from the image is no detection; a truth this far from its camera (horizontally) or from its ground
#: plane was not seen by it; a coordinate beyond MAX_COORD_M is beyond any local or projected frame (UTM, ECEF)
MAX_BOX_PX = 1e6
MAX_TRUTH_RANGE_M = 1e5
MAX_TRUTH_Z_M = 1e4
MAX_COORD_M = 1e9
#: KITTI label fields after the type: truncated occluded alpha bbox(4) dimensions(3) location(3) rotation_y
_KITTI_FIELDS = 14


@dataclass
class LabelChunk:
    """A block of labelled objects seen by one camera.

    Attributes
    ----------
    source : str                    file the rows come from
    camera_key : str                calibration group: objects with the same key share one calibration draw
    camera : Camera or None         None when the rows cannot be placed (every row then has an ``error``)
    line : (n,) int64               1-based line (text label files, CSV: the physical line; JSON Lines:
                                    the line), 0-based row (Parquet) or 0-based index in a JSON list
    frame, object_id, cls : (n,) object   identifiers (str or None)
    box_xyxy_px : (n, 4) float      ``u_min, v_min, u_max, v_max``; NaN: no detection
    truth_xy_world_m : (n, 2) float truth in W; NaN: no truth
    truth_z_m : (n,) float          height of the truth point above the camera's ground plane (NaN if unknown)
    yaw_world_rad : (n,) float      labelled yaw of the object's length axis, counter-clockwise from +x (NaN)
    cov_uv_px2 : (n, 2, 2) or None  detector pixel covariance of the contact point
    error : list of (str or None)   why the row cannot be used (malformed, no truth, no detection, ...)
    budget : ErrorBudget or None    the camera's own budget (registry), None: the job's budget
    time_s : (n,) float or None     the frame's time, s (NaN: none): tracks for velocity and heading
    truth_v_world_mps : (n, 2) float or None   truth velocity in W, m/s (NaN: none; docs/validation.md,
                                    "Velocity and heading")
    """

    source: str
    camera_key: str
    camera: object
    line: np.ndarray
    frame: np.ndarray
    object_id: np.ndarray
    cls: np.ndarray
    box_xyxy_px: np.ndarray
    truth_xy_world_m: np.ndarray
    truth_z_m: np.ndarray
    yaw_world_rad: np.ndarray
    error: list
    cov_uv_px2: np.ndarray | None = None
    budget: object = None
    time_s: np.ndarray | None = None
    truth_v_world_mps: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.line)


@dataclass
class FolderReport:
    """Frames of a dataset folder that cannot be paired: label files without calibration and the reverse."""

    frames: int = 0
    labels_without_calibration: list = field(default_factory=list)
    calibration_without_labels: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"frames": self.frames, "labels_without_calibration": list(self.labels_without_calibration),
                "calibration_without_labels": list(self.calibration_without_labels)}


def _obj(values) -> np.ndarray:
    values = list(values)
    a = np.empty(len(values), dtype=object)
    a[:] = values
    return a


def _chunk(source, key, camera, rows: list[dict], *, budget=None) -> LabelChunk:
    """A chunk from per-row dicts (keys: line, frame, object_id, cls, box, truth, z, yaw, error)."""
    n = len(rows)
    nan2, nan4 = [np.nan] * 2, [np.nan] * 4
    return LabelChunk(
        source=str(source), camera_key=key, camera=camera,
        line=np.array([r["line"] for r in rows], dtype=np.int64),
        frame=_obj(r.get("frame") for r in rows), object_id=_obj(r.get("object_id") for r in rows),
        cls=_obj(r.get("cls") for r in rows),
        box_xyxy_px=np.array([r.get("box", nan4) for r in rows], dtype=np.float64).reshape(n, 4),
        truth_xy_world_m=np.array([r.get("truth", nan2) for r in rows], dtype=np.float64).reshape(n, 2),
        truth_z_m=np.array([r.get("z", np.nan) for r in rows], dtype=np.float64),
        yaw_world_rad=np.array([r.get("yaw", np.nan) for r in rows], dtype=np.float64),
        error=[r.get("error") for r in rows], budget=budget,
        time_s=np.array([r.get("time", np.nan) for r in rows], dtype=np.float64) if any("time" in r for r in rows)
        else None)


def _file_key(*paths) -> str:
    """Calibration group key: a hash of the calibration files' bytes (identical calibrations share a draw)."""
    h = hashlib.sha1()
    for p in paths:  # a FIFO was read once already (the camera): its name stands for it
        h.update(str(Path(p).resolve()).encode() if is_stream(p) else Path(p).read_bytes())
    return h.hexdigest()[:12]


def _box_problem(box) -> str | None:
    """Why a 2-D box is not a detection (None: it is one)."""
    b = np.asarray(box, dtype=np.float64)
    if not np.all(np.isfinite(b)):
        return "box not finite"
    if b[2] < b[0] or b[3] < b[1]:
        return f"box {b.tolist()}: expected u_min <= u_max and v_min <= v_max"
    return None


# ---------------------------------------------------------------------------------------------------
# KITTI layout (Rope3D)
# ---------------------------------------------------------------------------------------------------
def _kitti_line(text: str, lineno: int, frame: str, T_world_cam) -> dict:
    """One label line -> row dict (errors as ``error``)."""
    row = {"line": lineno, "frame": frame, "object_id": str(lineno)}
    parts = text.split()
    if not parts:
        row["error"] = "malformed label line (empty line)"
        return row
    row["cls"] = parts[0]
    if len(parts) - 1 not in (_KITTI_FIELDS, _KITTI_FIELDS + 1):
        row["error"] = f"malformed label line ({len(parts)} fields, expected 15 or 16: type + 14 numbers [+ score])"
        return row
    try:
        v = np.array([float(x) for x in parts[1:]])
    except ValueError as e:
        row["error"] = f"malformed label line ({str(e).split(': ', 1)[-1]} is not a number)"
        return row
    if not np.all(np.isfinite(v)):
        row["error"] = "malformed label line (a value is not finite)"
        return row
    box, loc, ry = v[3:7], v[10:13], v[13]
    problem = None if np.all(box == 0) else _box_problem(box)
    if problem is not None:
        row["error"] = f"malformed label line ({problem})"
        return row
    if not np.all(box == 0):
        row["box"] = box.tolist()
    if parts[0].lower() == "dontcare" or np.all(loc == 0) or np.all(loc <= -999):
        row["error"] = NO_TRUTH  # KITTI's 0 0 0 / -1000: no 3-D annotation, not a point at the camera
        return row
    if "box" not in row:
        row["error"] = NO_DETECTION
    p = T_world_cam[:3, :3] @ loc + T_world_cam[:3, 3]
    d = T_world_cam[:3, :3] @ np.array([np.cos(ry), 0.0, -np.sin(ry)])  # KITTI: ry about the camera's y (down)
    row.update(truth=p[:2].tolist(), z=float(p[2]), yaw=float(np.arctan2(d[1], d[0])))
    return row


def parse_kitti_labels(text: str, *, camera, frame: str = "") -> list[dict]:
    """Rows of a KITTI ``label_2`` text for ``camera`` (bottom centres moved from its camera frame to W)."""
    T = np.asarray(camera.T_world_cam)
    return [_kitti_line(ln, i, frame, T) for i, ln in enumerate(text.splitlines(), start=1)]


def _read_label_text(path) -> tuple[str | None, str | None]:
    try:
        return read_input_bytes(path, "labels").decode("utf-8-sig"), None
    except UnicodeDecodeError as e:
        return None, f"label file not UTF-8 (byte 0x{e.object[e.start]:02x} at offset {e.start})"
    except OSError as e:
        return None, f"label file unreadable ({e.strerror or e})"
    except InputError as e:  # a device, a FIFO nobody writes
        return None, f"label file unreadable ({e.expected})"


def _folder(folder, sub: str) -> Path:
    p = Path(folder) / sub
    if not p.is_dir():
        raise ConfigError("labels", str(folder), f"a KITTI-layout folder with {sub}/ (calib/, denorm/, label_2/)")
    return p


def read_kitti_folder(folder, *, image_size_px=ROPE3D_IMAGE_SIZE_PX, report: FolderReport | None = None
                      ) -> Iterator[LabelChunk]:
    """Rope3D / KITTI-layout folder -> one :class:`LabelChunk` per label file.

    Parameters
    ----------
    folder : path with ``calib/``, ``denorm/``, ``label_2/`` (files ``<id>.txt`` matched by name)
    image_size_px : (width, height); Rope3D's is 1920 x 1080
    report : FolderReport, optional
        Filled with the frames that cannot be paired (label without calibration: its rows are error rows
        too; calibration without a label file: counted only).
    """
    report = report if report is not None else FolderReport()
    labels, calib = _folder(folder, "label_2"), _folder(folder, "calib")
    label_ids = sorted(p.stem for p in labels.glob("*.txt"))
    calib_ids = sorted(p.stem for p in calib.glob("*.txt"))
    report.calibration_without_labels.extend(sorted(set(calib_ids) - set(label_ids)))
    for fid in label_ids:
        report.frames += 1
        lab = labels / f"{fid}.txt"
        text, err = _read_label_text(lab)
        cfile, dfile = calib / f"{fid}.txt", Path(folder) / "denorm" / f"{fid}.txt"
        cam, key = None, ""
        if err is None and not (cfile.is_file() and dfile.is_file()):
            report.labels_without_calibration.append(fid)
            err = "no calibration for this frame (calib/ or denorm/ file missing)"
        if err is None:
            try:
                cam = camera_from_rope3d(cfile, denorm=dfile, image_size_px=image_size_px)
                key = f"kitti:{_file_key(cfile, dfile)}"
            except InputError as e:
                err = f"calibration refused ({e})"
        if err is not None:
            n = 1 if text is None else max(1, len(text.splitlines()))
            yield _chunk(lab, key, None, [{"line": i + 1, "frame": fid, "error": err} for i in range(n)])
            continue
        yield _chunk(lab, key, cam, parse_kitti_labels(text, camera=cam, frame=fid))


# ---------------------------------------------------------------------------------------------------
# campaigns as recorded: a folder of camera folders, a folder of OpenLABEL sequences
# ---------------------------------------------------------------------------------------------------
def camera_folders(folder) -> list[Path]:
    """The camera folders of a campaign folder: its sub-folders with ``label_2/`` (KITTI layout), by name;
    [] if there are none."""
    root = Path(folder)
    return sorted((p for p in root.iterdir() if p.is_dir() and (p / "label_2").is_dir()), key=lambda p: p.name) \
        if root.is_dir() else []


def read_camera_folders(folder, *, image_size_px=ROPE3D_IMAGE_SIZE_PX, report: FolderReport | None = None
                        ) -> Iterator[LabelChunk]:
    """A campaign recorded as one folder per camera -> :class:`LabelChunk` objects, camera by camera.

    ``folder/<camera>/`` is a KITTI layout (``calib/``, ``denorm/``, ``label_2/``: :func:`read_kitti_folder`)
    and **one calibration group**: every frame of a camera folder shares its calibration draw
    (``camera_key`` ``camera-folder:<camera>``), whatever its per-frame calibration files say.  The frames of
    ``report`` are named ``<camera>/<frame id>``.  Sub-folders without ``label_2/`` are not read (listed in
    ``report.calibration_without_labels`` as ``<name>/``)."""
    report = report if report is not None else FolderReport()
    cams = camera_folders(folder)
    if not cams:
        raise ConfigError("labels", str(folder), "a folder of camera folders, each a KITTI layout (label_2/, "
                          "calib/, denorm/)")
    names = {c.name for c in cams}
    report.calibration_without_labels.extend(f"{p.name}/" for p in sorted(Path(folder).iterdir())
                                             if p.is_dir() and p.name not in names)
    for cam in cams:
        sub = FolderReport()
        for ch in read_kitti_folder(cam, image_size_px=image_size_px, report=sub):
            if ch.camera is not None:
                ch.camera_key = f"camera-folder:{cam.name}"
            ch.frame = _obj(f"{cam.name}/{f}" for f in ch.frame)
            yield ch
        report.frames += sub.frames
        report.labels_without_calibration.extend(f"{cam.name}/{f}" for f in sub.labels_without_calibration)
        report.calibration_without_labels.extend(f"{cam.name}/{f}" for f in sub.calibration_without_labels)


#: the calibration file of an OpenLABEL sequence folder (not a frame file)
SEQUENCE_CALIBRATION = "calibration.json"


def openlabel_sequences(folder) -> list[Path]:
    """The sequence folders of a campaign folder: its sub-folders holding OpenLABEL ``.json`` files, by name."""
    root = Path(folder)
    if not root.is_dir():
        return []
    return sorted((p for p in root.iterdir() if p.is_dir() and any(q.name != SEQUENCE_CALIBRATION
                                                                   for q in p.glob("*.json"))), key=lambda p: p.name)


def read_openlabel_sequences(folder, *, calibration=None, ground_z_m: float = 0.0, image_size_px=None
                             ) -> Iterator[LabelChunk]:
    """A folder of OpenLABEL sequences -> :class:`LabelChunk` objects, sequence by sequence.

    ``folder/<sequence>/`` holds the sequence's OpenLABEL files (``*.json``, :func:`read_openlabel`) and its
    camera's TUMTraf calibration as ``calibration.json``; a sequence without one uses ``calibration`` (the
    ``--calibration`` file), and neither is a one-line error naming the sequence.  The calibration group is the
    calibration file's content: the sequences of one camera (same calibration) share its draw.  Frames are named
    ``<sequence>/<frame>``."""
    seqs = openlabel_sequences(folder)
    if not seqs:
        raise ConfigError("labels", str(folder), "a folder of OpenLABEL sequence folders (each with *.json frames)")
    calibs = []
    for seq in seqs:  # every sequence's calibration known before the first is read: a missing one fails the job up
        own = seq / SEQUENCE_CALIBRATION  # front, not after minutes of work on the others
        calib = own if own.is_file() else calibration
        if calib is None:
            raise InputError("--calibration", f"missing for sequence {seq.name!r}",
                             f"a {SEQUENCE_CALIBRATION} in the sequence folder or --calibration CAMERA.json")
        calibs.append(calib)
    return _openlabel_sequence_chunks(seqs, calibs, ground_z_m, image_size_px)


def _openlabel_sequence_chunks(seqs, calibs, ground_z_m, image_size_px) -> Iterator[LabelChunk]:
    for seq, calib in zip(seqs, calibs, strict=True):
        files = sorted(p for p in seq.glob("*.json") if p.name != SEQUENCE_CALIBRATION)
        for ch in read_openlabel(files, calibration=calib, ground_z_m=ground_z_m, image_size_px=image_size_px):
            ch.frame = _obj(f"{seq.name}/{f}" for f in ch.frame)
            yield ch


# ---------------------------------------------------------------------------------------------------
# DAIR-V2X-I
# ---------------------------------------------------------------------------------------------------
def _num_map(obj, key, names):
    v = obj.get(key)
    if not isinstance(v, dict) or any(k not in v for k in names):
        raise ValueError(f"{key} is not a mapping with {', '.join(names)}")
    try:
        out = [float(v[k]) for k in names]
    except (TypeError, ValueError):
        raise ValueError(f"{key} holds a value that is not a number") from None
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{key} holds a value that is not finite")
    return out


def _dair_object(obj, i: int, frame: str) -> dict:
    row = {"line": i, "frame": frame, "object_id": str(obj.get("track_id", i)) if isinstance(obj, dict) else str(i)}
    if not isinstance(obj, dict):
        row["error"] = f"malformed label object (a {type(obj).__name__}, expected a mapping)"
        return row
    row["cls"] = str(obj.get("type", "")) or None
    try:
        box = _num_map(obj, "2d_box", ("xmin", "ymin", "xmax", "ymax"))
        h, _w, _l = _num_map(obj, "3d_dimensions", ("h", "w", "l"))
        loc = np.array(_num_map(obj, "3d_location", ("x", "y", "z")))
    except ValueError as e:
        row["error"] = f"malformed label object ({e})"
        return row
    problem = None if np.all(np.asarray(box) == 0) else _box_problem(box)
    if problem is not None:
        row["error"] = f"malformed label object ({problem})"
        return row
    if not np.all(np.asarray(box) == 0):
        row["box"] = box
    if np.all(loc == 0):
        row["error"] = NO_TRUTH
        return row
    if "box" not in row:
        row["error"] = NO_DETECTION
    # the 3-D box centre in the virtual-LiDAR frame (= W, z up, ground z = 0): the bottom centre is h/2 lower
    rot = obj.get("rotation")
    yaw = float(rot) if isinstance(rot, int | float) and np.isfinite(rot) else np.nan
    row.update(truth=loc[:2].tolist(), z=float(loc[2] - h / 2), yaw=yaw)
    return row


def parse_dair_v2x_labels(objects, *, frame: str = "") -> list[dict]:
    """Rows of a DAIR-V2X-I label list (``label/camera/<id>.json``): 2-D box and the 3-D box in the
    virtual-LiDAR frame, which is the world frame of :func:`footprint_uq.io.dataset_files.camera_from_dair_v2x`."""
    return [_dair_object(o, i, frame) for i, o in enumerate(objects)]


def _json_list(path):
    try:
        data = json.loads(read_input_bytes(path, "labels").decode("utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, InputError) as e:
        return None, f"label file not readable JSON ({type(e).__name__}: {str(e).splitlines()[0][:120]})"
    if not isinstance(data, list):
        return None, f"label file holds a {type(data).__name__}, expected a list of objects"
    return data, None


def read_dair_v2x_folder(folder, *, report: FolderReport | None = None) -> Iterator[LabelChunk]:
    """DAIR-V2X-I folder (``calib/camera_intrinsic``, ``calib/virtuallidar_to_camera``, ``label/camera``)
    -> one :class:`LabelChunk` per frame."""
    report = report if report is not None else FolderReport()
    root = Path(folder)
    labels = root / "label" / "camera"
    intr = root / "calib" / "camera_intrinsic"
    if not labels.is_dir() or not intr.is_dir():
        raise ConfigError("labels", str(folder), "a DAIR-V2X-I folder with label/camera/ and calib/camera_intrinsic/")
    label_ids = sorted(p.stem for p in labels.glob("*.json"))
    report.calibration_without_labels.extend(sorted({p.stem for p in intr.glob("*.json")} - set(label_ids)))
    for fid in label_ids:
        report.frames += 1
        lab = labels / f"{fid}.json"
        objs, err = _json_list(lab)
        ifile, efile = intr / f"{fid}.json", root / "calib" / "virtuallidar_to_camera" / f"{fid}.json"
        cam, key = None, ""
        if err is None and not (ifile.is_file() and efile.is_file()):
            report.labels_without_calibration.append(fid)
            err = "no calibration for this frame (camera_intrinsic/ or virtuallidar_to_camera/ file missing)"
        if err is None:
            try:
                cam = camera_from_dair_v2x(ifile, extrinsic=efile)
                key = f"dair:{_file_key(ifile, efile)}"
            except InputError as e:
                err = f"calibration refused ({e})"
        if err is not None:
            n = max(1, len(objs) if objs is not None else 1)
            yield _chunk(lab, key, None, [{"line": i, "frame": fid, "error": err} for i in range(n)])
            continue
        yield _chunk(lab, key, cam, parse_dair_v2x_labels(objs, frame=fid))


# ---------------------------------------------------------------------------------------------------
# TUMTraf OpenLABEL
# ---------------------------------------------------------------------------------------------------
def _shape(obj_data, kind: str, n: int):
    """The ``val`` of the first ``kind`` shape (``cuboid``/``bbox``, a mapping or a list of them), or None."""
    s = obj_data.get(kind)
    if isinstance(s, list):
        s = s[0] if s else None
    if s is None:
        return None
    if not isinstance(s, dict) or not isinstance(s.get("val"), list) or len(s["val"]) != n:
        raise ValueError(f"{kind} is not a mapping with 'val' of {n} numbers")
    try:
        v = np.array([float(x) for x in s["val"]])
    except (TypeError, ValueError):
        raise ValueError(f"{kind}.val holds a value that is not a number") from None
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{kind}.val holds a value that is not finite")
    return v


def _openlabel_object(uid, obj, i, frame, ground_z_m) -> dict:
    row = {"line": i, "frame": frame, "object_id": str(uid)}
    od = obj.get("object_data") if isinstance(obj, dict) else None
    if not isinstance(od, dict):
        row["error"] = "malformed OpenLABEL object (no object_data mapping)"
        return row
    row["cls"] = str(od.get("type", "")).lower() or None
    try:
        cub = _shape(od, "cuboid", 10)
        bb = _shape(od, "bbox", 4)
    except ValueError as e:
        row["error"] = f"malformed OpenLABEL object ({e})"
        return row
    if bb is not None:
        box = [bb[0] - bb[2] / 2, bb[1] - bb[3] / 2, bb[0] + bb[2] / 2, bb[1] + bb[3] / 2]
        problem = _box_problem(box) if bb[2] >= 0 and bb[3] >= 0 else "bbox with a negative width or height"
        if problem is not None:
            row["error"] = f"malformed OpenLABEL object ({problem})"
            return row
        row["box"] = box
    if cub is None:
        row["error"] = NO_TRUTH
        return row
    if bb is None:
        row["error"] = NO_DETECTION
    qx, qy, qz, qw = cub[3:7]
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    row.update(truth=cub[:2].tolist(), z=float(cub[2] - cub[9] / 2 - ground_z_m), yaw=float(yaw))
    return row


def _openlabel_frames(path):
    try:
        data = json.loads(read_input_bytes(path, "labels").decode("utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError("labels", str(path), f"a readable OpenLABEL JSON file ({type(e).__name__})") from None
    top = data.get("openlabel") if isinstance(data, dict) else None
    frames = top.get("frames") if isinstance(top, dict) else None
    if not isinstance(frames, dict):
        raise ConfigError(f"{path}: openlabel.frames", "missing", "a mapping frame -> {objects: {...}}")
    return frames


def _frame_time(frame) -> float | None:
    """``frame_properties.timestamp`` (s) of an OpenLABEL frame, or None (absent or not a finite number)."""
    props = frame.get("frame_properties") if isinstance(frame, dict) else None
    t = props.get("timestamp") if isinstance(props, dict) else None
    try:
        t = float(t)
    except (TypeError, ValueError):
        return None
    return t if np.isfinite(t) else None


def read_openlabel(paths, *, calibration, ground_z_m: float = 0.0, image_size_px=None) -> Iterator[LabelChunk]:
    """TUMTraf OpenLABEL JSON file(s) of one camera -> one :class:`LabelChunk` per frame.

    Parameters
    ----------
    paths : path or sequence of paths (one file per frame in the dev kit, or several frames per file)
    calibration : the camera's TUMTraf calibration JSON (its world frame is the station frame of the labels)
    ground_z_m : height of the road in the station frame
    """
    cam = camera_from_tumtraf_file(calibration, ground_z_m=ground_z_m, image_size_px=image_size_px)
    key = f"tumtraf:{_file_key(calibration)}"
    for path in [paths] if isinstance(paths, (str, Path)) else list(paths):
        for fname, fr in _openlabel_frames(path).items():
            objs = fr.get("objects", {}) if isinstance(fr, dict) else None
            if not isinstance(objs, dict):
                yield _chunk(path, key, cam, [{"line": 0, "frame": str(fname),
                                               "error": "malformed OpenLABEL frame (objects is not a mapping)"}])
                continue
            rows = [_openlabel_object(u, o, i, str(fname), ground_z_m) for i, (u, o) in enumerate(objs.items())]
            t = _frame_time(fr)
            if t is not None:  # the frame's time: tracks and truth velocities from consecutive frames
                for r in rows:
                    r["time"] = t
            if rows:
                yield _chunk(path, key, cam, rows)


# ---------------------------------------------------------------------------------------------------
# Pairs table (probe vehicle)
# ---------------------------------------------------------------------------------------------------
def _truth_columns(columns, where) -> tuple[str, ...]:
    cols = set(columns)
    if all(c in cols for c in TRUTH_XY_COLUMNS):
        return TRUTH_XY_COLUMNS
    if all(c in cols for c in TRUTH_GEO_COLUMNS):
        return TRUTH_GEO_COLUMNS
    raise InputError(f"{where}: columns", sorted(cols)[:12], "the truth columns x_m, y_m (world frame) or "
                     "lat_deg, lon_deg (WGS84), beside u_min_px, v_min_px, u_max_px, v_max_px")


def _column(table: pa.Table, name: str, n: int) -> np.ndarray:
    if name not in table.column_names:
        return np.full(n, np.nan)
    return table.column(name).to_numpy(zero_copy_only=False).astype(np.float64, copy=False)


def _ids(table: pa.Table, name: str, n: int) -> np.ndarray:
    if name not in table.column_names:
        return np.full(n, None, dtype=object)
    return np.asarray(table.column(name).to_pylist(), dtype=object)


def _line_of(fmt: str):
    return {"csv": 2, "jsonl": 1, "parquet": 0}[fmt]


def _table_errors(box, truth, cov_cols, pre) -> list:
    """Per row: None, NO_TRUTH, NO_DETECTION or the reason of an error row."""
    n = len(box)
    box_nan, truth_nan = np.isnan(box), np.isnan(truth)
    out = list(pre) if pre is not None else [None] * n
    bad_box = box_nan.any(1) & ~box_nan.all(1)
    bad_truth = truth_nan.any(1) & ~truth_nan.all(1)
    with np.errstate(invalid="ignore"):  # (an inf box is not "inverted": row_problems names it)
        order = np.isfinite(box).all(1) & ((box[:, 2] < box[:, 0]) | (box[:, 3] < box[:, 1]))
    for i in np.flatnonzero(bad_box | bad_truth | order | box_nan.all(1) | truth_nan.all(1) | cov_cols):
        if out[i] is not None:
            continue
        if bad_box[i]:
            out[i] = f"field {BOX2D_COLUMNS[int(np.flatnonzero(box_nan[i])[0])]} is empty (a partial box)"
        elif bad_truth[i]:
            out[i] = "a truth coordinate is empty (both or neither)"
        elif order[i]:
            out[i] = f"box {box[i].tolist()}: expected u_min <= u_max and v_min <= v_max"
        elif cov_cols[i]:
            out[i] = "cov_uu_px2/cov_uv_px2/cov_vv_px2: one or two empty (all three or none)"
        elif box_nan[i].all():
            out[i] = NO_DETECTION
        else:
            out[i] = NO_TRUTH
    return out


def _pixel_cov(table, n):
    if not all(c in table.column_names for c in COV_COLUMNS):
        return None, np.zeros(n, dtype=bool)
    uu, uv, vv = (_column(table, c, n) for c in COV_COLUMNS)
    nan = np.isnan(np.stack([uu, uv, vv], 1))
    partial = nan.any(1) & ~nan.all(1)
    cov = np.stack([np.stack([uu, uv], -1), np.stack([uv, vv], -1)], -2)
    cov[nan.all(1)] = 0.0
    return cov, partial


def _resolve_cameras(cameras):
    """``{camera_id: (camera, budget or None, GeoReference or None)}`` from a Camera, a dict or a registry."""
    if hasattr(cameras, "backproject"):
        return {None: (cameras, None, None)}, True
    out = {}
    for cid, c in dict(cameras).items():
        if hasattr(c, "backproject"):
            out[str(cid)] = (c, None, None)
        else:  # a batch.fleet.RegistryEntry
            geo = None
            if c.origin_lat_deg is not None:
                geo = GeoReference(c.heading_offset_deg or 0.0, c.origin_lat_deg, c.origin_lon_deg)
            out[str(cid)] = (c.camera, c.budget, geo)
    return out, False


def read_pairs_table(path, cameras, *, georef: GeoReference | None = None, chunk_rows: int = 131_072
                     ) -> Iterator[LabelChunk]:
    """A pairs table (CSV / JSON Lines / Parquet) -> :class:`LabelChunk` objects, streamed in chunks.

    Parameters
    ----------
    path : the table (docs/validation.md, "Pairs table")
    cameras : Camera (every row), or mapping ``camera_id -> Camera`` or a camera registry
        (:func:`footprint_uq.batch.fleet.load_registry`: per-camera budget and geodetic origin)
    georef : GeoReference, optional
        World frame on the map, for truth given as ``lat_deg, lon_deg`` (registry entries carry their own).
    chunk_rows : rows read at a time (memory grows with it, not with the file)
    """
    reader = open_detections(path, chunk_rows=chunk_rows)
    truth_cols = _truth_columns(reader.columns, str(path))
    missing = [c for c in BOX2D_COLUMNS if c not in reader.columns]
    if missing:
        raise InputError(f"{path}: columns", missing[0], "the 2-D box columns u_min_px, v_min_px, u_max_px, v_max_px")
    cams, single = _resolve_cameras(cameras)
    if not single and "camera_id" not in reader.columns:
        raise InputError(f"{path}: camera_id", "missing", "a camera_id column (several cameras are given)")
    geo_needed = truth_cols == TRUTH_GEO_COLUMNS
    if geo_needed and single and (georef is None or not georef.has_origin):
        raise InputError("origin", "missing", "--origin-lat/--origin-lon (the truth is lat_deg, lon_deg)")
    vel = all(c in reader.columns for c in TRUTH_VELOCITY_COLUMNS)
    if vel or any(c in reader.columns for c in TRUTH_VELOCITY_COLUMNS):
        need = [c for c in (*TRUTH_VELOCITY_COLUMNS, "timestamp_s", "object_id") if c not in reader.columns]
        if need:
            raise InputError(f"{path}: columns", need[0], "v_east_mps and v_north_mps (truth velocity) together with "
                             "timestamp_s and object_id (the tracks that estimate the velocity)")
    reader.select(BOX2D_COLUMNS + truth_cols + tuple(c for c in COV_COLUMNS if c in reader.columns)
                  + (TRUTH_VELOCITY_COLUMNS if vel else ()))
    off = _line_of(reader.format)
    for ch in reader:
        yield from _split_table_chunk(ch, path, cams, single, truth_cols, georef, off, vel)


def _velocity_errors(v: np.ndarray, t: np.ndarray, errors: list) -> np.ndarray:
    """Truth velocity rows checked in place of ``errors`` (a partial or non-finite velocity, a velocity without
    a time: that row's error); returns ``v`` with NaN where the row is an error."""
    nan = np.isnan(v)
    for i in np.flatnonzero(nan.any(1) & ~nan.all(1) | (np.isinf(v).any(1)) | (~nan.all(1) & ~np.isfinite(t))):
        if errors[i] is not None and errors[i] not in (NO_TRUTH, NO_DETECTION):
            continue
        if np.isinf(v[i]).any():
            j = int(np.flatnonzero(np.isinf(v[i]))[0])
            errors[i] = f"field {TRUTH_VELOCITY_COLUMNS[j]} is {v[i, j]}: expected a finite velocity in m/s"
        elif nan[i].any():
            errors[i] = "v_east_mps/v_north_mps: one empty (both or neither)"
        else:
            errors[i] = f"timestamp_s {t[i]}: a truth velocity needs a finite time"
    bad = np.array([e is not None and e not in (NO_TRUTH, NO_DETECTION) for e in errors], dtype=bool)
    return np.where(bad[:, None] | ~np.isfinite(v), np.nan, v)


def _camera_groups(t: pa.Table, n: int, single: bool):
    """``(camera_id or None, row indices)`` per camera of a chunk, in order of first appearance (vectorised)."""
    if single:
        return [(None, np.arange(n))]
    col = t.column("camera_id").combine_chunks()
    if col.type != pa.string():
        col = pc.cast(col, pa.string())
    enc = col.dictionary_encode()
    idx = enc.indices.to_numpy(zero_copy_only=False)
    idx = np.where(enc.indices.is_null().to_numpy(zero_copy_only=False), -1, np.nan_to_num(idx, nan=-1)).astype(
        np.int64)
    names = enc.dictionary.to_pylist()
    order = np.argsort(idx, kind="stable")
    uniq, start = np.unique(idx[order], return_index=True)
    parts = np.split(order, start[1:])
    first = [p[0] for p in parts]
    return [(None if u < 0 else names[u], p) for _, u, p in sorted(zip(first, uniq.tolist(), parts, strict=True))]


def _nan_values(t: pa.Table, names, pre) -> list | None:
    """``pre`` with the reason of rows holding a NaN value (not an empty field / null: JSON Lines, Parquet;
    in CSV, pyarrow reads nan, NaN, NA, null as empty) in one of the numeric columns ``names``."""
    out = list(pre) if pre is not None else None
    for name in names:
        if name not in t.column_names or not pa.types.is_floating(t.column(name).type):
            continue
        nan = pc.fill_null(pc.is_nan(t.column(name)), False).to_numpy(zero_copy_only=False)
        for i in np.flatnonzero(nan):
            out = out if out is not None else [None] * t.num_rows
            if out[i] is None:
                out[i] = f"field {name} is NaN (leave it empty, or null, where there is none)"
    return out


def _geo_range(truth: np.ndarray, errors: list) -> None:
    """Error rows where a lat_deg / lon_deg truth is outside [-90, 90] / [-180, 180] or not finite."""
    lat, lon = truth[:, 0], truth[:, 1]
    with np.errstate(invalid="ignore"):
        bad = ~np.isnan(truth).all(1) & ~((np.abs(lat) <= 90) & (np.abs(lon) <= 180))
    _first(errors, bad, "truth lat_deg / lon_deg out of range (expected -90..90 and -180..180 degrees)")


def _split_table_chunk(ch, path, cams, single, truth_cols, georef, off, vel=False):
    t, n = ch.table, ch.table.num_rows
    lines = ch.rows + off
    if ch.malformed:
        yield _chunk(path, "", None, [{"line": r + off, "error": f"malformed line ({why})"} for r, why in ch.malformed])
    if n == 0:
        return
    box = np.stack([_column(t, c, n) for c in BOX2D_COLUMNS], 1)
    truth = np.stack([_column(t, c, n) for c in truth_cols], 1)
    cov, partial = _pixel_cov(t, n)
    pre = _nan_values(t, BOX2D_COLUMNS + truth_cols + COV_COLUMNS + (TRUTH_VELOCITY_COLUMNS if vel else ()),
                      ch.pre_errors)
    errors = _table_errors(box, truth, partial, pre)
    if truth_cols == TRUTH_GEO_COLUMNS:
        _geo_range(truth, errors)
    time_s = _column(t, "timestamp_s", n)
    v_en = _velocity_errors(np.stack([_column(t, c, n) for c in TRUTH_VELOCITY_COLUMNS], 1), time_s, errors) \
        if vel else None
    ids = {k: _ids(t, k, n) for k in ("frame", "object_id", "class")}
    for k, sel in _camera_groups(t, n, single):
        entry = cams.get(k)
        err = [errors[i] for i in sel]
        if entry is None:
            why = "missing camera_id" if k is None else f"camera_id {k!r} not among the cameras given"
            err = [e if e is not None and e not in (NO_TRUTH, NO_DETECTION) else why for e in err]
            cam, bud, geo = None, None, None
        else:
            cam, bud, geo = entry
        tr = truth[sel]
        if truth_cols == TRUTH_GEO_COLUMNS and cam is not None:
            g = geo or georef
            if g is None or not g.has_origin:
                raise InputError("origin", f"camera {k!r}", "a geodetic origin (registry origin_lat_deg/"
                                 "origin_lon_deg or --origin-lat/--origin-lon): the truth is lat_deg, lon_deg")
            with np.errstate(invalid="ignore", over="ignore"):  # rows out of range are error rows already
                tr = g.from_wgs84(tr[:, 0], tr[:, 1])
        v_w = None
        if v_en is not None:  # east / north -> W by the camera's heading offset (none given: W is east / north)
            g = geo or georef
            v_w = v_en[sel] @ g.R_enu_world if g is not None else v_en[sel]  # a rotation, no origin
        yield LabelChunk(source=str(path), camera_key=f"camera:{k}" if k is not None else "camera", camera=cam,
                         line=lines[sel], frame=ids["frame"][sel], object_id=ids["object_id"][sel],
                         cls=ids["class"][sel], box_xyxy_px=box[sel], truth_xy_world_m=tr,
                         truth_z_m=np.full(len(sel), np.nan), yaw_world_rad=np.full(len(sel), np.nan), error=err,
                         cov_uv_px2=None if cov is None else cov[sel], budget=bud, time_s=time_s[sel],
                         truth_v_world_mps=v_w)


# ---------------------------------------------------------------------------------------------------
# A detector's own files + a truth table, paired by (frame, object_id)
# ---------------------------------------------------------------------------------------------------
def _truth_index(path, georef: GeoReference | None, chunk_rows: int):
    """``({(frame, object_id): [xy, line, used]}, error rows)`` of a truth table (frame, object_id, truth)."""
    reader = open_detections(path, chunk_rows=chunk_rows)
    cols = _truth_columns(reader.columns, str(path))
    missing = [c for c in ("frame", "object_id") if c not in reader.columns]
    if missing:
        raise InputError(f"{path}: columns", missing, "frame and object_id (the keys that pair the truth with "
                         "the detections)")
    if cols == TRUTH_GEO_COLUMNS and (georef is None or not georef.has_origin):
        raise InputError("origin", "missing", "--origin-lat/--origin-lon (the truth is lat_deg, lon_deg)")
    reader.select(cols)
    off = _line_of(reader.format)
    index: dict = {}
    bad: list = []
    for ch in reader:
        bad += [{"line": r + off, "error": f"malformed truth line ({why})"} for r, why in ch.malformed]
        t, n = ch.table, ch.table.num_rows
        xy = np.stack([_column(t, c, n) for c in cols], 1)
        if cols == TRUTH_GEO_COLUMNS and n:
            xy = georef.from_wgs84(xy[:, 0], xy[:, 1])
        frames, oids = _ids(t, "frame", n), _ids(t, "object_id", n)
        for i in range(n):
            line = int(ch.rows[i]) + off
            key = (frames[i], oids[i])
            why = ch.pre_errors[i] if ch.pre_errors is not None else None
            if why is None and (key[0] is None or key[1] is None):
                why = "truth row without frame or object_id"
            if why is None and not np.isfinite(xy[i]).all():
                why = "truth row without a finite truth point"
            if why is None and key in index:
                why = f"a second truth of frame {key[0]} object {key[1]!r} (the first is line {index[key][1]})"
            if why is not None:
                bad.append({"line": line, "frame": key[0], "object_id": key[1], "error": why})
            else:
                index[key] = [xy[i], line, False]
    return index, bad


def read_detections_with_truth(detections, truth, camera, *, format: str | None = None, class_names=None,
                               unknown_class: str = "error", georef: GeoReference | None = None,
                               chunk_rows: int = 131_072) -> Iterator[LabelChunk]:
    """A detector's own files (any format of :mod:`footprint_uq.batch.formats`) paired with a truth table.

    Parameters
    ----------
    detections : file or folder; ``format``, ``class_names``, ``unknown_class`` as
        :func:`footprint_uq.batch.formats.open_reader` (normalised boxes: the camera's image size)
    truth : CSV / JSON Lines / Parquet with ``frame``, ``object_id`` and ``x_m, y_m`` (world frame) or
        ``lat_deg, lon_deg`` (WGS84, with ``georef``)
    camera : Camera (one camera: every detection is seen by it)

    Yields :class:`LabelChunk` objects: the detections in input order (``line``: the detection's line in its
    file where the format has one, else its 0-based index), paired with the truth of the same ``(frame,
    object_id)`` (none: ``no truth``), then the truth rows no detection paired (``no detection``) and the
    truth rows that cannot be used (error rows with their line).
    """
    index, bad = _truth_index(truth, georef, chunk_rows)
    reader = open_reader(detections, format=format, chunk_rows=chunk_rows, class_names=class_names,
                         unknown_class=unknown_class, image_size_px=camera.image_size_px)
    if not all(c in reader.columns for c in BOX2D_COLUMNS):
        raise InputError(f"{detections}: columns", sorted(reader.columns)[:12], "the 2-D box columns "
                         f"{list(BOX2D_COLUMNS)}")
    reader.select(BOX2D_COLUMNS)
    for ch in reader:
        rows = [{"line": r, "error": f"malformed line ({why})"} for r, why in ch.malformed]
        t, n = ch.table, ch.table.num_rows
        box = np.stack([_column(t, c, n) for c in BOX2D_COLUMNS], 1)
        ids = {k: _ids(t, k, n) for k in ("frame", "object_id", "class", "line")}
        for i in range(n):
            key = (ids["frame"][i], ids["object_id"][i])
            hit = index.get(key) if key[1] is not None else None
            err = ch.pre_errors[i] if ch.pre_errors is not None else None
            row = {"line": ids["line"][i] if ids["line"][i] is not None else int(ch.rows[i]), "frame": key[0],
                   "object_id": key[1], "cls": ids["class"][i], "box": box[i],
                   "error": err if err is not None else (None if hit is not None else NO_TRUTH)}
            if hit is not None:
                row["truth"], hit[2] = hit[0], True
            rows.append(row)
        if rows:
            yield _chunk(detections, "camera", camera, rows)
    rest = [{"line": v[1], "frame": k[0], "object_id": k[1], "truth": v[0], "error": NO_DETECTION}
            for k, v in index.items() if not v[2]]
    if rest or bad:
        yield _chunk(truth, "camera", camera, sorted(rest + bad, key=lambda r: r["line"]))


# ---------------------------------------------------------------------------------------------------
# The numbers of every row, checked (every reader's chunks pass here: pairs.build_pairs)
# ---------------------------------------------------------------------------------------------------
def _first(out: list, mask: np.ndarray, reason) -> None:
    """``out[i] = reason`` (a str, or a callable of i) where ``mask`` and no reason yet."""
    for i in np.flatnonzero(mask):
        if out[i] is None:
            out[i] = reason(i) if callable(reason) else reason


def _box_checks(out: list, box: np.ndarray) -> None:
    given = ~np.isnan(box).all(1)
    with np.errstate(invalid="ignore"):
        _first(out, given & ~np.isfinite(box).all(1), "box not finite (a coordinate is inf or NaN)")
        _first(out, given & (np.abs(box) > MAX_BOX_PX).any(1),
               f"box out of range (a coordinate beyond {MAX_BOX_PX:g} px)")
        _first(out, given & ((box[:, 2] < box[:, 0]) | (box[:, 3] < box[:, 1])),
               "box inverted: expected u_min <= u_max and v_min <= v_max")


def _truth_checks(out: list, truth: np.ndarray, z: np.ndarray, yaw: np.ndarray, camera) -> None:
    given = ~np.isnan(truth).all(1)
    with np.errstate(invalid="ignore", over="ignore"):
        _first(out, given & ~np.isfinite(truth).all(1), "truth not finite (a coordinate is inf or NaN)")
        _first(out, given & (np.abs(truth) > MAX_COORD_M).any(1),
               f"truth out of range (a coordinate beyond {MAX_COORD_M:g} m)")
        if camera is not None:
            foot = np.asarray(camera.position_world_m, dtype=np.float64)[:2]
            far = np.hypot(truth[:, 0] - foot[0], truth[:, 1] - foot[1]) > MAX_TRUTH_RANGE_M
            _first(out, given & far, f"truth out of range (more than {MAX_TRUTH_RANGE_M:g} m from the camera)")
        _first(out, given & np.isinf(z), "truth height not finite")
        _first(out, given & (np.abs(z) > MAX_TRUTH_Z_M),
               f"truth height out of range (beyond {MAX_TRUTH_Z_M:g} m of the ground plane)")
        _first(out, given & np.isinf(yaw), "truth yaw not finite")


def _cov_checks(out: list, cov: np.ndarray) -> None:
    """The batch's tests of a detector pixel covariance (``footprint_uq.batch.process``), per row."""
    a, b, b2, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 0], cov[:, 1, 1]
    fin = np.isfinite(cov).all((1, 2))
    _first(out, ~fin, "pixel covariance not finite (cov_uu_px2, cov_uv_px2, cov_vv_px2)")
    with np.errstate(invalid="ignore", over="ignore"):
        scale = np.maximum(np.maximum(np.abs(a), np.abs(d)), np.maximum(np.abs(b), np.abs(b2)))
        lmin = 0.5 * (a + d) - np.hypot(0.5 * (a - d), b)
        _first(out, fin & ((a < 0) | (d < 0)), "pixel covariance with a negative variance (cov_uu_px2 or "
               "cov_vv_px2 < 0)")
        _first(out, fin & ~(lmin >= -PSD_TOL * scale), "pixel covariance not positive semi-definite "
               "(cov_uv_px2^2 > cov_uu_px2 cov_vv_px2)")
        _first(out, fin & (scale > MAX_PIXEL_VAR_PX2), f"pixel covariance out of range (entries above "
               f"{MAX_PIXEL_VAR_PX2:g} px^2)")


def row_problems(chunk: LabelChunk) -> list:
    """Per row of a chunk: why its numbers cannot make a pair (a str), or None.

    Every number a pair is made of is checked, whatever the reader: the box (finite, within
    :data:`MAX_BOX_PX`, not inverted), the truth (finite, within :data:`MAX_COORD_M` and within
    :data:`MAX_TRUTH_RANGE_M` of the camera's foot point; its height within :data:`MAX_TRUTH_Z_M`; its yaw
    finite), the detector pixel covariance (finite, variances >= 0, positive semi-definite, within the batch's
    ``MAX_PIXEL_VAR_PX2``).  NaN means "absent" (no detection, no truth, unknown height) and is no problem
    here: the readers decide what is absent.

    Returns
    -------
    list of (str or None), one per row
    """
    n = len(chunk)
    out: list = [None] * n
    box = np.asarray(chunk.box_xyxy_px, dtype=np.float64).reshape(n, 4)
    truth = np.asarray(chunk.truth_xy_world_m, dtype=np.float64).reshape(n, 2)
    _box_checks(out, box)
    _truth_checks(out, truth, np.asarray(chunk.truth_z_m, dtype=np.float64),
                  np.asarray(chunk.yaw_world_rad, dtype=np.float64), chunk.camera)
    if chunk.cov_uv_px2 is not None:
        _cov_checks(out, np.asarray(chunk.cov_uv_px2, dtype=np.float64).reshape(n, 2, 2))
    return out
