"""The edge service's per-frame work: one detector frame in, one output record out.

:class:`Service` is the embedding API used by both transports (stdin and MQTT, see
:mod:`footprint_uq.service.runner`).  ``Service(...).process_frame(frame)`` takes one frame
(a dict, or one JSON text line)::

    {"camera_id": "cam1", "frame": 42, "timestamp_s": 1714564800.033,
     "detections": [{"object_id": 7, "class": "car",
                     "u_min_px": 900, "v_min_px": 600, "u_max_px": 1000, "v_max_px": 700,
                     "cov_uu_px2": 4.0, "cov_uv_px2": 0.0, "cov_vv_px2": 9.0}]}       # covariance optional

with the box columns of the batch (docs/batch.md: 2D boxes ``u_min_px, v_min_px, u_max_px,
v_max_px``; 3D boxes ``x_m, y_m, z_m, length_m, width_m, height_m, yaw_rad|yaw_deg``; corners
``u0_px, v0_px, ...``; one family per frame) and returns either a **footprints record**
(``"type": "footprints"``: every object's centre, ``cov_m2``, ellipse, largest point, CPM and
J2735 fields, and the frame's CPM as JSON and UPER hex and SDSM as JSON) or an **error
record** (``"type": "error"`` with the ``field`` and the ``reason``).  It never raises on
bad input.  ``timestamp_s`` is Unix time in seconds (UTC): the CPM's ``TimestampIts`` and
the SDSM time stamp are derived from it.  The layout is documented in ``docs/service.md``.
"""

from __future__ import annotations

import json
import math
import re
import time
import zlib
from dataclasses import dataclass

import numpy as np

from ..batch import schema as S
from ..batch.fleet import load_registry
from ..errors import FootprintUQError, InputError
from ..products.footprints import CONTACT_MODES, V2X_FIELDS, FrameProcessor
from ..products.geo import GeoReference
from ..products.v2x import J2735_POSITION_CONFIDENCE_NAMES
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD, nonlinearity
from .messages.cpm import (
    CONFIDENCE_LEVEL_UNAVAILABLE,
    CPM_CLASSES,
    LATITUDE_UNAVAILABLE,
    LONGITUDE_UNAVAILABLE,
    build_cpm,
    coordinate_cm,
    encode_cpm_uper,
    timestamp_its_ms,
)
from .messages.sdsm import HEADING_UNAVAILABLE, SDSM_OBJECT_TYPES, SPEED_UNAVAILABLE, build_sdsm, offset_dm
from .messages.uper_cpm import class_bits, encode_cpm_uper_fast, perceived_object_container_uper

__all__ = ["Service", "CameraSetup", "error_record", "station_id_of", "RECORD_FOOTPRINTS", "RECORD_ERROR",
           "UPER_ENCODERS"]

UPER_ENCODERS = ("fast", "asn1tools")
#: most perceived objects in one CPM (``PerceivedObjects ::= SEQUENCE SIZE (0..255, ...)``); the SDSM follows
MAX_MESSAGE_OBJECTS = 255

RECORD_FOOTPRINTS = "footprints"
RECORD_ERROR = "error"
_CPM_INDEX = V2X_FIELDS.index("cpm_x_confidence")
_CPM_CLASS_BITS = {name: class_bits(c) for name, c in CPM_CLASSES.items()}
_J_POS = V2X_FIELDS.index("j2735_position_confidence")


def station_id_of(camera_id: str) -> int:
    """Default StationId of a camera: CRC-32 of its id (stable, documented; override with ``station_id``)."""
    return zlib.crc32(str(camera_id).encode("utf-8")) & 0xFFFFFFFF


def error_record(reason: str, *, field: str | None = None, camera_id=None, frame=None, source: str | None = None
                 ) -> dict:
    """An error record (one per rejected frame)."""
    return {"type": RECORD_ERROR, "camera_id": camera_id, "frame": frame, "field": field, "reason": str(reason),
            "source": source}


class _FrameError(Exception):
    def __init__(self, field: str | None, reason: str):
        super().__init__(reason)
        self.field = field
        self.reason = reason


@dataclass
class CameraSetup:
    """One camera of the service: its prepared processor, map tie and station id."""

    camera_id: str | None
    processor: FrameProcessor
    georef: GeoReference
    station_id: int


def _nan_none(values: list) -> list:
    return [v if v == v else None for v in values]  # NaN != NaN


def _finite_number(d: dict, key: str, where: str) -> float:
    v = d.get(key)
    if v is None:
        raise _FrameError(f"{where}.{key}", f"missing field {key}")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _FrameError(f"{where}.{key}", f"field {key} is not a number: {v!r}")
    if not math.isfinite(v):
        raise _FrameError(f"{where}.{key}", f"field {key} is not finite: {v!r}")
    return float(v)


class Service:
    """Detections in, positions with uncertainty and V2X messages out, one frame at a time.

    Parameters
    ----------
    camera : Camera, optional
        The one camera (with ``budget``); or give ``registry``.
    budget : ErrorBudget, preset name, path or mapping
        The camera's error budget (with ``registry``: the default for entries without one).
    registry : path or dict camera_id -> RegistryEntry, optional
        Many cameras (the batch registry format, :func:`footprint_uq.batch.fleet.load_registry`);
        a frame's ``camera_id`` selects its camera.
    camera_id : str, optional
        With one camera: the id it answers to (frames with another id are errors); None
        accepts any id (the frames come from that camera).
    heading_offset_deg : float
        Compass bearing of the world +y axis (V2X fields, CPM/SDSM east/north offsets);
        registry entries may override it.
    origin_lat_deg, origin_lon_deg : float, optional
        WGS84 position of the world origin: objects get ``lat_deg``/``lon_deg`` and the
        messages' reference position is the origin (otherwise it is "unavailable").
    confidence : float
        Probability of the ``semi_major_m``/``semi_minor_m`` ellipse (default 0.95).
    contact : {"bottom-centre", "bottom-corners"}
        Ground contact of 2D boxes.
    allow_outside_image : bool
        See :func:`footprint_uq.products.footprints.footprints_from_corners`.
    station_id : int, optional
        StationId of the messages (one camera); default :func:`station_id_of` of the camera id.
    messages : bool
        Build the CPM, its UPER encoding and the SDSM (default True).
    uper_encoder : {"fast", "asn1tools"}
        ``asn1tools`` encodes the CPM with asn1tools from the subset module (about 6 ms for 100
        objects); ``fast`` (default) writes the same bytes directly
        (:mod:`~footprint_uq.service.messages.uper_cpm`, checked bit for bit against asn1tools by
        the tests) in a fraction of that.
    linearity : bool
        Add per object ``nonlinearity`` -- the largest predicted relative error of the linear
        1-sigma semi-major axis over its usable ground-contact points
        (:func:`footprint_uq.uncertainty.propagation.nonlinearity`; for 2D boxes with the bottom-centre contact
        that point is the centre itself) -- and ``linear_ok`` (``nonlinearity <= linear_threshold``).
        Off by default: it costs about 1.7 ms per 100 points (numpy), more than the rest of a frame.
    linear_threshold : float, optional
        Threshold of ``linear_ok`` (default :data:`footprint_uq.uncertainty.propagation.DEFAULT_LINEAR_THRESHOLD`).
    warm_up : bool
        Run each camera once on a dummy frame so that the compiled kernels are loaded
        before the first real frame (default True).
    """

    def __init__(self, camera=None, budget=None, *, registry=None, camera_id: str | None = None,
                 heading_offset_deg: float = 0.0, origin_lat_deg: float | None = None,
                 origin_lon_deg: float | None = None, confidence: float = 0.95, contact: str = "bottom-centre",
                 allow_outside_image: bool = False, station_id: int | None = None, messages: bool = True,
                 uper_encoder: str = "fast", linearity: bool = False, linear_threshold: float | None = None,
                 warm_up: bool = True):
        if (camera is None) == (registry is None):
            raise InputError("camera/registry", "both" if camera is not None else "neither",
                             "exactly one of a camera (with a budget) or a registry")
        if contact not in CONTACT_MODES:
            raise InputError("contact", contact, f"one of {CONTACT_MODES}")
        self.contact = contact
        self.confidence = float(confidence)
        if not 0.0 < self.confidence < 1.0:
            raise InputError("confidence", confidence, "a probability in (0, 1)")
        self._k = chi2_scale(self.confidence)
        self.messages = bool(messages)
        if uper_encoder not in UPER_ENCODERS:
            raise InputError("uper_encoder", uper_encoder, f"one of {UPER_ENCODERS}")
        self.uper_encoder = uper_encoder
        self._encode = encode_cpm_uper if uper_encoder == "asn1tools" else encode_cpm_uper_fast
        self.cameras: dict[str | None, CameraSetup] = {}
        if camera is not None:
            if budget is None:
                raise InputError("budget", None, "an error budget (preset, file or ErrorBudget) for the camera")
            geo = GeoReference(heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat_deg,
                               origin_lon_deg=origin_lon_deg)
            sid = station_id if station_id is not None else station_id_of(camera_id or "camera")
            self.cameras[camera_id] = CameraSetup(camera_id, self._processor(camera, budget, geo, allow_outside_image),
                                                  geo, int(sid))
        else:

            entries = registry if isinstance(registry, dict) else load_registry(registry, budget=budget)
            for cid, e in entries.items():
                geo = GeoReference(
                    heading_offset_deg=heading_offset_deg if e.heading_offset_deg is None else e.heading_offset_deg,
                    origin_lat_deg=origin_lat_deg if e.origin_lat_deg is None else e.origin_lat_deg,
                    origin_lon_deg=origin_lon_deg if e.origin_lon_deg is None else e.origin_lon_deg)
                self.cameras[str(cid)] = CameraSetup(str(cid), self._processor(e.camera, e.budget, geo,
                                                                               allow_outside_image),
                                                     geo, station_id_of(cid))
        self._single = camera is not None
        self._omitted = 0
        self._pixel_cov = None

        self.linearity = bool(linearity)
        self.linear_threshold = DEFAULT_LINEAR_THRESHOLD if linear_threshold is None else float(linear_threshold)
        if not self.linear_threshold > 0:
            raise InputError("linear_threshold", linear_threshold, "a relative error > 0 (e.g. 0.05)")
        if warm_up:
            self.warm_up()

    @staticmethod
    def _processor(camera, budget, geo: GeoReference, allow_outside_image: bool) -> FrameProcessor:
        return FrameProcessor(camera, budget, heading_offset_deg=geo.heading_offset_deg,
                              allow_outside_image=allow_outside_image, joint_cov=False)

    @property
    def camera_ids(self) -> list:
        return list(self.cameras)

    def warm_up(self) -> None:
        """Load the compiled kernels (and pyproj, with an origin) once, before the first frame."""
        for setup in self.cameras.values():
            cam = setup.processor.camera
            w, h = cam.image_size_px
            setup.processor.corners(np.array([[[0.5 * w, 0.9 * h]]]))
            setup.processor.boxes3d(np.zeros((0, 7)))
            if setup.georef.has_origin:
                setup.georef.to_wgs84(np.zeros((1, 2)))
            if self.messages:
                self._encode(build_cpm(setup.station_id, 0, []))

    # -- one frame ------------------------------------------------------------------------------------
    def process_frame(self, frame, *, source: str | None = None) -> dict:
        """One frame (dict or JSON text) -> a footprints record or an error record (never raises on bad input).

        ``source`` (e.g. ``"stdin line 7"``, ``"mqtt detections/cam1"``) is copied into error records.
        """
        t0 = time.perf_counter()
        camera_id = frame_no = None
        try:
            if isinstance(frame, (bytes, bytearray, memoryview)):
                try:
                    frame = bytes(frame).decode("utf-8")
                except UnicodeDecodeError as e:
                    raise _FrameError(None, f"frame is not UTF-8 text: {e}") from None
            if isinstance(frame, str):
                try:
                    frame = json.loads(frame)
                except json.JSONDecodeError as e:
                    raise _FrameError(None, f"invalid JSON: {e}") from None
            if not isinstance(frame, dict):
                raise _FrameError(None, f"frame is not a JSON object: {type(frame).__name__}")
            camera_id = frame.get("camera_id")
            frame_no = frame.get("frame")
            return self._process(frame, t0)
        except _FrameError as e:
            return error_record(e.reason, field=e.field, camera_id=_jsonable(camera_id), frame=_jsonable(frame_no),
                                source=source)
        except FootprintUQError as e:
            return error_record(str(e), field=getattr(e, "field", None), camera_id=_jsonable(camera_id),
                                frame=_jsonable(frame_no), source=source)

    def _setup(self, camera_id) -> CameraSetup:
        if camera_id is not None and not isinstance(camera_id, str):
            raise _FrameError("camera_id", f"camera_id is not a string: {camera_id!r}")
        if self._single:
            (key, setup), = self.cameras.items()
            if key is not None and camera_id != key:
                raise _FrameError("camera_id", f"camera_id {camera_id!r} is not this service's camera {key!r}")
            return setup
        if camera_id is None:
            raise _FrameError("camera_id", "missing field camera_id (needed with a registry)")
        setup = self.cameras.get(camera_id)
        if setup is None:
            raise _FrameError("camera_id", f"camera_id {camera_id!r} not in the registry")
        return setup

    def _process(self, frame: dict, t0: float) -> dict:
        camera_id = frame.get("camera_id")
        setup = self._setup(camera_id)
        fno = frame.get("frame")
        if fno is None:
            raise _FrameError("frame", "missing field frame")
        if isinstance(fno, bool) or not isinstance(fno, int):
            raise _FrameError("frame", f"field frame is not an integer: {fno!r}")
        ts = _finite_number(frame, "timestamp_s", "frame")
        dets = frame.get("detections")
        if not isinstance(dets, list):
            raise _FrameError("detections", f"field detections is not a list: {type(dets).__name__}")
        ref_ms = timestamp_its_ms(ts) if self.messages else None
        est, ids, classes, class_conf = self._footprints(setup, dets)
        t1 = time.perf_counter()
        objects, pos, sobj = self._objects(setup, est, ids, classes, class_conf)
        t2 = time.perf_counter()
        cpm, cpm_hex, sdsm = self._messages(setup, pos, sobj, int(fno), ts, ref_ms) if self.messages else (None,) * 3
        rec = {"type": RECORD_FOOTPRINTS, "camera_id": camera_id, "frame": fno, "timestamp_s": ts,
               "station_id": setup.station_id, "heading_offset_deg": setup.georef.heading_offset_deg,
               "confidence": self.confidence, "n_objects": len(objects), "objects": objects}
        if self.messages:
            rec.update(cpm=cpm, cpm_uper_hex=cpm_hex, sdsm=sdsm)
            if self._omitted:  # said, never silent: objects with a centre that did not fit in the messages
                rec["objects_not_in_messages"] = self._omitted
        t3 = time.perf_counter()
        rec["processing_us"] = {"footprints": round(1e6 * (t1 - t0), 1), "records": round(1e6 * (t2 - t1), 1),
                                "messages": round(1e6 * (t3 - t2), 1), "total": round(1e6 * (t3 - t0), 1)}
        return rec

    def _footprints(self, setup: CameraSetup, dets: list):
        N = len(dets)
        for i, d in enumerate(dets):
            if type(d) is not dict:
                raise _FrameError(f"detections[{i}]", f"detection {i} is not a JSON object")
        # one pass per field; the per-detection checks only name the first bad value
        ids = [d.get("object_id", i) for i, d in enumerate(dets)]
        for i, oid in enumerate(ids):
            if type(oid) not in _ID_TYPES:  # numpy scalars from embedding code are taken as their Python value
                if isinstance(oid, str):
                    ids[i] = str(oid)
                elif isinstance(oid, (int, np.integer)) and not isinstance(oid, (bool, np.bool_)):
                    ids[i] = int(oid)
                else:
                    raise _FrameError(f"detections[{i}].object_id", f"object_id is not a string or integer: {oid!r}")
        classes = [d.get("class") for d in dets]
        for i, cls in enumerate(classes):
            if cls is not None and type(cls) is not str:
                if not isinstance(cls, str):
                    raise _FrameError(f"detections[{i}].class", f"class is not a string: {cls!r}")
                classes[i] = str(cls)
        class_conf = [d.get("class_confidence") for d in dets]
        for i, cc in enumerate(class_conf):
            if cc is not None:
                cc = class_conf[i] = _finite_number(dets[i], "class_confidence", f"detections[{i}]")
                if not 0.0 <= cc <= 1.0:
                    raise _FrameError(f"detections[{i}].class_confidence", f"class_confidence {cc} not in [0, 1]")
        proc = setup.processor
        if N == 0:
            return proc.corners(np.zeros((0, 1, 2))), ids, classes, class_conf
        family = S.detect_box_type(dets[0].keys())
        if family is None:
            raise _FrameError("detections[0]", "no complete box: 2D (u_min_px, v_min_px, u_max_px, v_max_px), 3D "
                                               "(x_m, y_m, z_m, length_m, width_m, height_m, yaw_rad|yaw_deg) or "
                                               "corners (u0_px, v0_px, ...), one family per frame")
        cols = S.box_columns(family, dets[0].keys())
        X = _box_array(dets, cols)
        P = None
        for i, d in enumerate(dets):
            where = f"detections[{i}]"
            if "cov_uu_px2" not in d and "cov_uv_px2" not in d and "cov_vv_px2" not in d:
                continue
            present = [c for c in S.COV_COLUMNS if d.get(c) is not None]
            if present:
                if len(present) != 3:
                    missing = [c for c in S.COV_COLUMNS if c not in present]
                    raise _FrameError(f"{where}.{missing[0]}", f"incomplete pixel covariance: {missing[0]} missing "
                                                               "(give cov_uu_px2, cov_uv_px2, cov_vv_px2 or none)")
                uu, uv, vv = (_finite_number(d, c, where) for c in S.COV_COLUMNS)
                if P is None:
                    P = np.zeros((N, 2, 2))
                P[i] = ((uu, uv), (uv, vv))
        try:
            if family == "2d":
                est = proc.boxes2d(X, contact=self.contact, pixel_cov_px2=P)
            elif family == "3d":
                est = proc.boxes3d(X, yaw_unit="deg" if cols[-1] == "yaw_deg" else "rad", pixel_cov_px2=P)
            else:
                est = proc.corners(X.reshape(N, -1, 2), pixel_cov_px2=P)
        except InputError as e:
            raise _FrameError(_detection_field(e.field), str(e)) from None
        self._pixel_cov = P
        return est, ids, classes, class_conf

    def _linearity(self, setup: CameraSetup, est):
        """Per object: the largest predicted relative error of the linear 1-sigma semi-major axis over its
        usable ground-contact points (:func:`footprint_uq.uncertainty.propagation.nonlinearity`, with the detector's
        pixel covariance) and ``linear_ok`` = that <= the threshold (False where nothing is usable)."""

        uv = est.corners_px
        N, K = uv.shape[:2]
        P = self._pixel_cov
        Pk = None if P is None else np.broadcast_to(P[:, None], (N, K, 2, 2)).reshape(N * K, 2, 2)
        proc = setup.processor
        with np.errstate(invalid="ignore"):
            nl = nonlinearity(proc.camera, proc.budget, uv.reshape(N * K, 2), pixel_cov_px2=Pk).reshape(N, K)
        usable = est.corner_usable & np.isfinite(nl)
        worst = np.where(usable.any(1), np.max(np.where(usable, nl, -np.inf), axis=1), np.nan)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(worst) & (worst <= self.linear_threshold)
        return worst, ok

    def _objects(self, setup, est, ids, classes, class_conf):
        N = len(ids)
        geo = setup.georef
        centre = est.centre_xy_world_m
        cov = est.centre_cov_m2
        a, b, ori = ellipse_axes(cov)
        valid = est.centre_valid.tolist()
        li = est.largest_index.tolist()
        reasons = est.centre_reason_text() if N else []
        codes = est.v2x_codes.tolist()
        x, y = _nan_none(centre[:, 0].tolist()), _nan_none(centre[:, 1].tolist())
        cxx, cxy, cyy = (_nan_none(v.tolist()) for v in (cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]))
        a_l, b_l, o_l = _nan_none(a.tolist()), _nan_none(b.tolist()), _nan_none(ori.tolist())
        ka, kb = _nan_none((self._k * a).tolist()), _nan_none((self._k * b).tolist())
        lsemi = _nan_none(est.largest_semi_major_m.tolist())
        lx, ly = (_nan_none(v.tolist()) for v in (est.largest_xy_world_m[:, 0], est.largest_xy_world_m[:, 1]))
        en = geo.world_to_enu(centre) if N else np.zeros((0, 2))
        if self.messages:
            ex_cm, ny_cm = coordinate_cm(en[:, 0]).tolist(), coordinate_cm(en[:, 1]).tolist()
            ex_dm, ny_dm = offset_dm(en[:, 0]).tolist(), offset_dm(en[:, 1]).tolist()
        if geo.has_origin and N:
            lat, lon = (_nan_none(v.tolist()) for v in geo.to_wgs84(centre))
        linear = nonlin = None
        if self.linearity and N:
            nonlin, linear = self._linearity(setup, est)
        if all(valid):
            status, reason = [S.STATUS_OK] * N, ["ok"] * N
        else:
            status = [S.STATUS_OK if ok else (S.STATUS_PARTIAL if j >= 0 else S.STATUS_ERROR)
                      for ok, j in zip(valid, li, strict=True)]
            reason = ["ok" if ok else f"no centre: {r}" for ok, r in zip(valid, reasons, strict=True)]
        keys = ["object_id", "class", "status", "reason", "x_m", "y_m", "cov_m2", "sigma_major_m", "sigma_minor_m",
                "orientation_deg", "semi_major_m", "semi_minor_m", "largest_index", "largest_sigma_major_m",
                "largest_x_m", "largest_y_m", *V2X_FIELDS]
        columns = [ids, classes, status, reason, x, y,
                   [[[p, q], [q, r]] for p, q, r in zip(cxx, cxy, cyy, strict=True)],
                   a_l, b_l, o_l, ka, kb, li, lsemi, lx, ly, *est.v2x_codes.T.tolist()]
        if geo.has_origin:
            keys += ["lat_deg", "lon_deg"]
            columns += [lat, lon] if N else [[], []]
        if linear is not None:
            keys += ["nonlinearity", "linear_ok"]
            columns += [_nan_none(nonlin.tolist()), linear.tolist()]
        pos = sobj = None
        if self.messages:
            ok_all = [i for i in range(N) if valid[i]]
            ok_idx = ok_all[:MAX_MESSAGE_OBJECTS]  # a CPM carries at most 255 perceived objects
            self._omitted = len(ok_all) - len(ok_idx)
            msg_ids = [None] * N
            for i in ok_idx:
                msg_ids[i] = _message_object_id(ids[i], i)
            keys.append("message_object_id")  # None: not in the CPM / SDSM (no centre, or beyond 255)
            columns.append(msg_ids)
            pos = self._message_columns(ok_idx, msg_ids, classes, class_conf, codes, ex_cm, ny_cm, ex_dm, ny_dm)
        objects = [dict(zip(keys, row, strict=True)) for row in zip(*columns, strict=True)]
        return objects, pos, sobj

    @staticmethod
    def _message_columns(ok_idx, msg_ids, classes, class_conf, codes, ex_cm, ny_cm, ex_dm, ny_dm) -> dict:
        """The per-object columns of the messages (objects with a centre, at most 255)."""
        oid = [msg_ids[i] for i in ok_idx]
        cls = [classes[i] for i in ok_idx]
        cc = [class_conf[i] for i in ok_idx]
        low = [c.lower() if c else None for c in cls]
        cpm_class = [CPM_CLASSES.get(c) if c else None for c in low]
        level = [CONFIDENCE_LEVEL_UNAVAILABLE if p is None else max(1, math.ceil(100.0 * p - 1e-9)) for p in cc]
        return {"objectId": oid, "class": cls, "cpm_class": cpm_class, "level": level,
                "class_bits": [_CPM_CLASS_BITS.get(c) if c else None for c in low],
                "class_pct": [0 if p is None else int(round(100.0 * p)) for p in cc],
                "x_cm": [ex_cm[i] for i in ok_idx], "y_cm": [ny_cm[i] for i in ok_idx],
                "x_conf": [codes[i][_CPM_INDEX] for i in ok_idx], "y_conf": [codes[i][_CPM_INDEX + 1] for i in ok_idx],
                "corr": [codes[i][_CPM_INDEX + 2] for i in ok_idx], "pos_conf": [codes[i][_J_POS] for i in ok_idx],
                "x_dm": [ex_dm[i] for i in ok_idx], "y_dm": [ny_dm[i] for i in ok_idx]}

    def _messages(self, setup, m: dict, sobj, fno: int, ts: float, ref_ms):
        geo = setup.georef
        # the JSON forms of perceived_object() / sdsm_object(), written inline (the per-frame hot path)
        pos = [{"objectId": o, "measurementDeltaTime": 0,
                "position": {"xCoordinate": {"value": x, "confidence": cx},
                             "yCoordinate": {"value": y, "confidence": cy}}}
               for o, x, y, cx, cy in zip(m["objectId"], m["x_cm"], m["y_cm"], m["x_conf"], m["y_conf"], strict=True)]
        for po, r, c, lv in zip(pos, m["corr"], m["cpm_class"], m["level"], strict=True):
            if r != 101:
                po["lowerTriangularCorrelationMatrices"] = [
                    {"componentsIncludedIntheMatrix": ["xPosition", "yPosition"], "matrix": [[r]]}]
            if c is not None:
                po["classification"] = [{"objectClass": c, "confidence": lv}]
        sobj = [{"detObjCommon": {
            "objType": SDSM_OBJECT_TYPES.get(c.lower(), "unknown") if c else "unknown", "objTypeCfd": pct,
            "objectID": o, "measurementTime": 0, "timeConfidence": "unavailable", "pos": {"offsetX": x, "offsetY": y},
            "posConfidence": {"pos": J2735_POSITION_CONFIDENCE_NAMES[pc], "elevation": "unavailable"},
            "speed": SPEED_UNAVAILABLE, "speedConfidence": "unavailable", "heading": HEADING_UNAVAILABLE,
            "headingConf": "unavailable"}}
            for o, x, y, pc, c, pct in zip(m["objectId"], m["x_dm"], m["y_dm"], m["pos_conf"], m["class"],
                                           m["class_pct"], strict=True)]
        lat_e7 = lon_e7 = None
        if geo.has_origin:
            lat_e7, lon_e7 = round(geo.origin_lat_deg * 1e7), round(geo.origin_lon_deg * 1e7)
        cpm = build_cpm(setup.station_id, ref_ms, pos,
                        latitude=LATITUDE_UNAVAILABLE if lat_e7 is None else lat_e7,
                        longitude=LONGITUDE_UNAVAILABLE if lon_e7 is None else lon_e7)
        if self.uper_encoder == "fast":
            container = perceived_object_container_uper(
                m["objectId"], m["x_cm"], m["x_conf"], m["y_cm"], m["y_conf"], m["corr"],
                [None if c is None else (c, lv) for c, lv in zip(m["class_bits"], m["level"], strict=True)])
            cpm_hex = encode_cpm_uper_fast(cpm, perceived_objects_uper=container).hex()
        else:
            cpm_hex = self._encode(cpm).hex()
        # J3224's DetectedObjectList has 1..256 entries: a frame without objects has no SDSM (null)
        sdsm = None if not sobj else build_sdsm(setup.station_id, fno, ts, sobj,
                          **({} if lat_e7 is None else {"lat_1e7deg": lat_e7, "lon_1e7deg": lon_e7}))
        return cpm, cpm_hex, sdsm


_NUMBER_TYPES = (int, float)
_ID_TYPES = (int, str, type(None))


def _box_array(dets: list, cols) -> np.ndarray:
    """The (N, len(cols)) box values; a frame with a missing, non-numeric or non-finite value -> _FrameError."""
    try:
        rows = [[d[c] for c in cols] for d in dets]
        if all(type(v) in _NUMBER_TYPES for r in rows for v in r):  # (bool is not int here: type() is exact)
            X = np.array(rows, dtype=np.float64)
            if np.isfinite(X).all():
                return X
    except (KeyError, TypeError, OverflowError):
        pass
    X = np.empty((len(dets), len(cols)))
    for i, d in enumerate(dets):  # the slow path names the first bad field
        X[i] = [_finite_number(d, c, f"detections[{i}]") for c in cols]
    return X


def _message_object_id(object_id, index: int) -> int:
    """Identifier2B of an object: its id if it is an integer in 0..65535, else CRC-32 of its text mod 65536."""
    if type(object_id) is int and 0 <= object_id <= 65535:
        return object_id
    if isinstance(object_id, str) and object_id.isdigit() and int(object_id) <= 65535:
        return int(object_id)
    text = str(index) if object_id is None else str(object_id)
    return zlib.crc32(text.encode("utf-8")) & 0xFFFF


def _detection_field(field: str) -> str:
    # "boxes_px[3]" / "boxes_world[3] (...)" / "pixel_cov_px2" -> "detections[3]"

    m = re.search(r"\[(\d+)\]", field or "")
    return f"detections[{m.group(1)}]" if m else "detections"


def _jsonable(v):
    return v if v is None or isinstance(v, (str, int, float, bool)) else repr(v)
