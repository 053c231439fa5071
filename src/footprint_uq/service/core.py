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

import functools
import json
import re
import threading
import time
import zlib
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import orjson

from .._checks import as_float
from ..errors import FootprintUQError, InputError
from ..fast.footprint_kernels import OBJ_ROW
from ..io.class_names import UNKNOWN_POLICIES, ClassNames, load_class_names
from ..io.registry import load_registry
from ..products import detection_columns as S
from ..products.footprint_estimate import centre_reason_texts
from ..products.footprints import CONTACT_MODES, V2X_FIELDS, V2X_POLICIES, FrameProcessor
from ..products.geo import GeoReference
from ..products.v2x import J2735_POSITION_CONFIDENCE_NAMES
from ..tracking import TrackerConfig
from ..tracking.camera_tracker import CameraTracker
from ..tracking.classes import ClassTracks
from ..tracking.consistency import DEFAULT_WINDOW_S, NisMonitor, health_section
from ..tracking.contact_slide import ContactSlide
from ..uncertainty.ellipse import chi2_scale
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD
from .detections import (
    DetectionError,
    FieldError,
    FrameDetections,
    boxes2d_detections,
    check_values,
    finite_number,
    parse_detections,
)
from .frame_kernels import LeanCpm, cm_dm, lean_cpm_constants, lean_cpm_uper, plain_cpm_uper, worst_usable
from .frame_scan import ScannedFrame, scan_frame
from .jsonrows import Table, compact_objects_json
from .messages.asn1_cpm import DEFAULT_CDD
from .messages.cpm import (
    CONFIDENCE_LEVEL_UNAVAILABLE,
    CPM_CLASS_OF,
    LATITUDE_UNAVAILABLE,
    LONGITUDE_UNAVAILABLE,
    build_cpm,
    check_cdd,
    encode_cpm_uper,
    object_class_json,
    timestamp_its_ms,
)
from .messages.ids import MessageIdMap
from .messages.motion import (
    HEADING_CONFIDENCE_NAMES,
    SDSM_HEADING_UNAVAILABLE,
    SDSM_SPEED_UNAVAILABLE,
    SPEED_CONFIDENCE_NAMES,
    ObjectMotion,
    coded,
    codes_pass,
    motion_codes,
    motion_rows,
)
from .messages.sdsm import SDSM_OBJECT_TYPES, build_sdsm
from .messages.uper_cpm import (
    CpmUperWriter,
    class_bits,
    encode_cpm_uper_fast,
    perceived_object_container_uper_arrays,
)

__all__ = ["Service", "CameraSetup", "FrameOutput", "error_record", "station_id_of", "RECORD_FOOTPRINTS",
           "RECORD_ERROR", "UPER_ENCODERS", "RECORD_LAYOUTS", "COMPACT_OBJECT_FIELDS", "MAX_FRAME_DETECTIONS"]

UPER_ENCODERS = ("fast", "asn1tools")
#: the record layouts (``Service(record=...)``, ``serve --record``)
RECORD_LAYOUTS = ("full", "compact")
#: per object in a compact record (with ``tracks``: the last four too); the full record has these and more
COMPACT_OBJECT_FIELDS = ("object_id", "class", "status", "reason", "x_m", "y_m", "cov_m2", "message_object_id",
                         "track_id", "v_east_mps", "v_north_mps", "cov_v_m2ps2")
#: most perceived objects in one CPM (``PerceivedObjects ::= SEQUENCE SIZE (0..255, ...)``); the SDSM follows
MAX_MESSAGE_OBJECTS = 255
#: most detections one frame may hold (``Service(max_frame_detections=...)``); a frame with more is one error
#: record, refused before any parsing.  40 CPMs' worth: a detector's frame holds tens to hundreds; 100,000
#: detections (16 MB of JSON, over the transports' 4 MiB --max-frame-bytes) took 4 s and an 82 MB record
MAX_FRAME_DETECTIONS = 10_000

RECORD_FOOTPRINTS = "footprints"
#: the dummy frames' time of :meth:`Service.warm_up` (a valid TimestampIts: 2023-11-14)
_WARM_TIME_S = 1.7e9
RECORD_ERROR = "error"
_CPM_INDEX = V2X_FIELDS.index("cpm_x_confidence")
_J_POS = V2X_FIELDS.index("j2735_position_confidence")
#: rows of FootprintEstimate.object_rows: the centre's 1-sigma ellipse
_ROW_SMAJ, _ROW_SMIN, _ROW_ORI = (OBJ_ROW[k] for k in ("sigma_major_m", "sigma_minor_m", "orientation_deg"))


def station_id_of(camera_id: str) -> int:
    """Default StationId of a camera: CRC-32 of its id (stable, documented; override with ``station_id``)."""
    return zlib.crc32(str(camera_id).encode("utf-8")) & 0xFFFFFFFF


def error_record(reason: str, *, field: str | None = None, camera_id=None, frame=None, source: str | None = None
                 ) -> dict:
    """An error record (one per rejected frame)."""
    return {"type": RECORD_ERROR, "camera_id": camera_id, "frame": frame, "field": field, "reason": str(reason),
            "source": source}


class FrameOutput(NamedTuple):
    """One frame's output as the transports send it (:meth:`Service.process_frame_json`)."""

    #: the record as JSON text (UTF-8)
    data: bytes
    #: ``"footprints"`` or ``"error"``
    type: str
    camera_id: object
    #: ``processing_us["total"]`` of a footprints record (None for an error record)
    processing_us: float | None
    #: an error record as a dict (None for a footprints record: parse ``data``)
    record: dict | None
    #: a footprints record's bad detections (its ``detection_errors``: each one's index and reason)
    n_detection_errors: int = 0
    #: ``record="compact"``: the frame's CPM, UPER-encoded (bytes for a V2X stack; the record says its length);
    #: None for a full record (its CPM is in the record) or without messages
    cpm_uper: bytes | None = None


#: ``_made(T, (every field in order))``: the NamedTuple ``T`` without its Python-level ``__new__`` (~0.15 us less a
#: call; the lean frame's outputs)
_made = tuple.__new__


def _parse_frame_text(text) -> object:
    """A frame's JSON text (bytes or str) parsed by orjson, as the MQTT path does (strict JSON: no NaN literals,
    integers within 64 bits); bytes that are not UTF-8 or text that is not JSON -> a frame error."""
    if isinstance(text, memoryview):
        text = bytes(text)
    try:
        return orjson.loads(text)
    except orjson.JSONDecodeError as e:
        if isinstance(text, (bytes, bytearray)):
            try:
                bytes(text).decode("utf-8")
            except UnicodeDecodeError as u:
                raise _FrameError(None, f"frame is not UTF-8 text: {u}") from None
        raise _FrameError(None, f"invalid JSON: {e}") from None


#: a frame given as its JSON text (:meth:`Service.process_frame_json`)
_TEXT_TYPES = (bytes, bytearray, memoryview, str)


def _scan_text(text) -> ScannedFrame | None:
    """:func:`.frame_scan.scan_frame` of a frame's text (bytes-like or str); None: not the common layout (or a str
    that is not valid Unicode), for the general path."""
    if isinstance(text, str):
        try:
            text = text.encode("utf-8")
        except UnicodeEncodeError:
            return None
    return scan_frame(text)


def _dumps_error(rec: dict) -> bytes:
    try:
        return orjson.dumps(rec)
    except orjson.JSONEncodeError:  # text that is not valid Unicode (an embedding caller's str): escaped
        return json.dumps(rec, ensure_ascii=True, separators=(",", ":")).encode("ascii")


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
    #: the reference position of the messages (0.1 microdegree; "unavailable" without an origin)
    lat_1e7deg: int | None = None
    lon_1e7deg: int | None = None
    #: the fixed part of its CPMs' UPER encoding
    uper: CpmUperWriter | None = None
    #: its tracker (``tracks=True``): the tracks by object_id with a motion model per class, their NIS check
    #: (docs/motion-fit.md) and the 2-D boxes' sliding-contact term, one call per frame (tracking/camera_tracker.py)
    tracker: CameraTracker | None = None
    #: object_id -> the messages' object id (unique per message, stable across frames; messages/ids.py)
    ids: MessageIdMap = field(default_factory=MessageIdMap)
    #: the tracker's output of the camera's latest frame (``tracks=True``; read by :attr:`Service.on_tracked`)
    last_tracks: object = None
    #: the constants of its lean frame's CPM call (:func:`.frame_kernels.lean_cpm_uper`), packed once by the
    #: service (None: not a lean service, or numpy's world -> ENU product not matched here: the numpy path)
    lean_cpm: LeanCpm | None = None
    #: camera_id -> the constant texts of its compact record's head (:func:`_lean_head`; at most 64 ids)
    head_texts: dict = field(default_factory=dict, repr=False)

    #: the map tie's constants, read once (a frame calls no method of the GeoReference but ``to_wgs84``)
    has_origin: bool = False
    enu_origin_m: np.ndarray | None = None
    enu_rotation_t: np.ndarray | None = None

    @property
    def tracks(self) -> ClassTracks | None:
        """The tracker's tracks (one frame at a time: :attr:`tracks_lock`)."""
        return None if self.tracker is None else self.tracker.tracks

    @property
    def tracks_lock(self) -> threading.Lock | None:
        return None if self.tracker is None else self.tracker.lock

    @property
    def nis(self) -> NisMonitor | None:
        """The NIS of the tracks per class over a window (under :attr:`tracks_lock`; None: no check)."""
        return None if self.tracker is None else self.tracker.nis

    @property
    def slide(self) -> ContactSlide | None:
        """The velocity term of 2-D boxes' sliding contact (tracking/contact_slide.py)."""
        return None if self.tracker is None else self.tracker.slide

    def __post_init__(self):
        geo = self.georef
        self.has_origin = geo.has_origin
        self.enu_origin_m, self.enu_rotation_t = np.asarray(geo.origin_world_m), geo.R_enu_world.T
        self._message_origin()

    def world_to_enu(self, xy_world_m: np.ndarray) -> np.ndarray:
        """:meth:`~footprint_uq.products.geo.GeoReference.world_to_enu` of checked ``(N, 2)`` world points (the same
        operations on the constants read once)."""
        return (xy_world_m - self.enu_origin_m) @ self.enu_rotation_t

    def _message_origin(self) -> None:
        geo = self.georef
        if geo.has_origin:
            self.lat_1e7deg, self.lon_1e7deg = round(geo.origin_lat_deg * 1e7), round(geo.origin_lon_deg * 1e7)
        self.uper = CpmUperWriter(self.station_id, latitude=LATITUDE_UNAVAILABLE if self.lat_1e7deg is None else
                                  self.lat_1e7deg, longitude=LONGITUDE_UNAVAILABLE if self.lon_1e7deg is None else
                                  self.lon_1e7deg)


def _frame_number(frame: dict, key: str) -> float:
    """A frame's own number field (``timestamp_s``), finite; a frame error otherwise."""
    try:
        return finite_number(frame, key, "frame")
    except FieldError as e:
        raise _FrameError(e.field, e.reason) from None


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
    cpm_cdd : {"2.2.1", "2.1.1"}
        The ETSI-ITS-CDD release of the CPM (:data:`~footprint_uq.service.messages.asn1_cpm.CDD_RELEASES`;
        default the newest): a receiver decodes only the release it compiled (docs/service.md).
    v2x_policy : {"sampled", "unavailable", "linear"}
        What the V2X fields (the CPM's confidences and correlation, the J2735 fields) encode where an object's
        centre is not ``linear_ok`` (far objects): :data:`footprint_uq.products.footprints.V2X_POLICIES`,
        docs/uncertainty-model.md; each object's record says which (``v2x_source``, ``v2x_cov_m2``).
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
    tracks : bool
        Track each camera's objects by ``object_id`` across frames (:mod:`footprint_uq.tracking`) and add their
        motion to every object: ``track_id``, ``v_east_mps``, ``v_north_mps``, ``cov_v_m2ps2``, ``speed_mps``,
        ``sigma_speed_mps``, ``heading_deg``, ``sigma_heading_deg``, ``yaw_deg``, ``sigma_yaw_deg``, ``age_s``
        (null where unknown; docs/service.md).  Frames of a camera must then come in time order.
    tracker : TrackerConfig, optional
        The tracker's options (timeout, gate, acceleration noise); a camera budget's ``motion`` section sets the
        motion model per class over it (docs/motion-fit.md).
    class_names : "coco", "coco91", "mot", path, list, mapping or ClassNames, optional
        Names of integer class ids (``"class": 2``): a built-in map or a names file (data.yaml, JSON, one name per
        line), the one names map of the package (:class:`footprint_uq.io.class_names.ClassNames`).  Without it an
        integer class is that detection's error entry (the frame's other detections go on).
    unknown_class : {"error", "unknown"}, optional
        With ``class_names``: an id the map does not name is that detection's error entry, or the class
        ``"unknown"`` (default: a given ClassNames' own policy, else ``"error"``).
    record : {"full", "compact"}
        The record's layout: ``full`` (default) every field, the CPM as JSON and UPER hex, the SDSM; ``compact``
        the fields of :data:`COMPACT_OBJECT_FIELDS` per object and, without the CPM JSON and the SDSM, the CPM's
        UPER bytes beside the record (:attr:`FrameOutput.cpm_uper`; ``serve --output mqtt`` publishes them on
        ``<prefix>/<camera_id>/cpm``).  docs/service.md, "Lean records on the wire".
    consistency_window_s : float
        With tracks: the window of the on-line NIS check of the motion model per camera and class
        (:class:`~footprint_uq.tracking.consistency.NisMonitor`, :meth:`motion_health`); 0: no check.
    max_frame_detections : int
        Most detections of one frame (default :data:`MAX_FRAME_DETECTIONS`); a frame with more is refused
        with one error record (field ``detections``) before it is parsed.
    """

    #: write the compact record (tracked or not) and the untracked frame's CPM from the columns in compiled passes
    #: (:meth:`_compact_objects`); False: the general writers, the same bytes (the tests' reference path)
    _columnar = True

    def __init__(self, camera=None, budget=None, *, registry=None, camera_id: str | None = None,
                 heading_offset_deg: float = 0.0, origin_lat_deg: float | None = None,
                 origin_lon_deg: float | None = None, confidence: float = 0.95, contact: str = "bottom-centre",
                 allow_outside_image: bool = False, station_id: int | None = None, messages: bool = True,
                 uper_encoder: str = "fast", linearity: bool = False, linear_threshold: float | None = None,
                 warm_up: bool = True, cpm_cdd: str = DEFAULT_CDD, v2x_policy: str = "sampled",
                 tracks: bool = False, tracker: TrackerConfig | None = None,
                 class_names: str | ClassNames | None = None, unknown_class: str | None = None,
                 record: str = "full", consistency_window_s: float = DEFAULT_WINDOW_S,
                 max_frame_detections: int = MAX_FRAME_DETECTIONS):
        if (camera is None) == (registry is None):
            raise InputError("camera/registry", "both" if camera is not None else "neither",
                             "exactly one of a camera (with a budget) or a registry")
        if contact not in CONTACT_MODES:
            raise InputError("contact", contact, f"one of {CONTACT_MODES}")
        self.contact = contact
        if isinstance(max_frame_detections, bool) or not isinstance(max_frame_detections, int) or \
                max_frame_detections < 1:
            raise InputError("max_frame_detections", max_frame_detections, "an integer >= 1")
        self.max_frame_detections = max_frame_detections
        self.confidence = float(confidence)
        if not 0.0 < self.confidence < 1.0:
            raise InputError("confidence", confidence, "a probability in (0, 1)")
        self._k = chi2_scale(self.confidence)
        self.messages = bool(messages)
        if uper_encoder not in UPER_ENCODERS:
            raise InputError("uper_encoder", uper_encoder, f"one of {UPER_ENCODERS}")
        self.uper_encoder = uper_encoder
        self.cpm_cdd = check_cdd(cpm_cdd)
        if v2x_policy not in V2X_POLICIES:
            raise InputError("v2x_policy", v2x_policy, f"one of {V2X_POLICIES}")
        self.v2x_policy = v2x_policy
        self._encode = functools.partial(encode_cpm_uper if uper_encoder == "asn1tools" else encode_cpm_uper_fast,
                                         cdd=self.cpm_cdd)
        self._cls = _class_tables(self.cpm_cdd)
        self.class_names = None if class_names is None else load_class_names(class_names, unknown=unknown_class)
        if class_names is None and unknown_class not in (None, *UNKNOWN_POLICIES):
            raise InputError("unknown_class", unknown_class, f"one of {UNKNOWN_POLICIES}")
        if record not in RECORD_LAYOUTS:
            raise InputError("record", record, f"one of {RECORD_LAYOUTS}")
        self.record = record
        #: frames of 2-D boxes take :meth:`_lean_frame` (the columns alone, one compiled call for the positions;
        #: tracked too, unless :attr:`on_tracked` asks for the estimate: :meth:`_takes_lean`)
        self._lean = record == "compact" and uper_encoder == "fast"
        self.cameras: dict[str | None, CameraSetup] = self._camera_setups(
            camera, budget, registry, camera_id, station_id, allow_outside_image,
            dict(heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat_deg, origin_lon_deg=origin_lon_deg))
        #: the one camera's ``(id, CameraSetup)`` (None: a registry)
        self._single = next(iter(self.cameras.items())) if camera is not None else None
        if self._lean and self.messages:  # (the lean frame's CPM: each camera's constants packed once)
            cls = self._cls
            for setup in self.cameras.values():
                setup.lean_cpm = lean_cpm_constants(setup.uper, self.cpm_cdd, setup.enu_origin_m, setup.enu_rotation_t,
                                                    _CPM_INDEX, cls.bits_value, cls.bits_width)
        self.tracks = bool(tracks)
        if self.tracks:
            cfg = tracker or TrackerConfig()
            window_s = as_float("consistency_window_s", consistency_window_s, nonnegative=True)
            for setup in self.cameras.values():
                proc = setup.processor
                proc.shared_jacobian = True
                setup.tracker = CameraTracker.for_camera(  # (the budget's motion section: docs/motion-fit.md)
                    proc.camera, proc.budget, cfg, window_s=window_s,
                    heading_offset_deg=setup.georef.heading_offset_deg)
                if warm_up:
                    setup.tracker.warm_up()

        #: called after each tracked frame as ``on_tracked(camera_id, frame, timestamp_s, TrackOutput, estimate,
        #: FrameDetections)`` (the CP service of ``serve --cp-service``: :mod:`.cp_serve`); None: nothing.  Set, the
        #: tracked frames take the general path (it forms the estimate; :meth:`_takes_lean`)
        self.on_tracked = None
        self.linearity = bool(linearity)
        self.linear_threshold = DEFAULT_LINEAR_THRESHOLD if linear_threshold is None else float(linear_threshold)
        if not self.linear_threshold > 0:
            raise InputError("linear_threshold", linear_threshold, "a relative error > 0 (e.g. 0.05)")
        if warm_up:
            self.warm_up()

    def _camera_setups(self, camera, budget, registry, camera_id, station_id, allow_outside_image: bool,
                       tie: dict) -> dict:
        """camera id -> :class:`CameraSetup`: the one camera (``tie``: the service's map-tie options), or the
        registry's (each entry's heading offset and origin where it gives them, else ``tie``'s)."""
        if camera is not None:
            if budget is None:
                raise InputError("budget", None, "an error budget (preset, file or ErrorBudget) for the camera")
            geo = GeoReference(**tie)
            sid = station_id if station_id is not None else station_id_of(camera_id or "camera")
            return {camera_id: CameraSetup(camera_id, self._processor(camera, budget, geo, allow_outside_image),
                                           geo, int(sid))}
        setups = {}
        entries = registry if isinstance(registry, dict) else load_registry(registry, budget=budget)
        for cid, e in entries.items():
            geo = GeoReference(**{k: v if getattr(e, k) is None else getattr(e, k) for k, v in tie.items()})
            setups[str(cid)] = CameraSetup(str(cid), self._processor(e.camera, e.budget, geo, allow_outside_image),
                                           geo, station_id_of(cid))
        return setups

    def _processor(self, camera, budget, geo: GeoReference, allow_outside_image: bool) -> FrameProcessor:
        return FrameProcessor(camera, budget, heading_offset_deg=geo.heading_offset_deg,
                              allow_outside_image=allow_outside_image, joint_cov=False, v2x_policy=self.v2x_policy)

    def motion_health(self) -> tuple[dict | None, list[str]]:
        """The health record's ``motion_consistency`` entry (:func:`~footprint_uq.tracking.consistency.
        health_section`; None without tracks or check) and one log line per camera and class newly found
        inconsistent (docs/motion-fit.md)."""
        cams, bad, lines = {}, [], []
        for cid, setup in self.cameras.items():
            if setup.nis is None:
                continue
            with setup.tracks_lock:
                sec = health_section({cid: setup.nis})
                news = setup.nis.new_flags()
            cams.update(sec["cameras"])
            bad += sec["inconsistent"]
            lines += [f"motion model inconsistent: camera {cid}, class {c or '(no class)'}: mean NIS / 2 = "
                      f"{r['nis_ratio']:.3f} over {r['n_updates']} updates (p = {r['p_value']:.2g}): the traffic is "
                      f"{'more agitated' if r['nis_ratio'] > 1 else 'calmer'} than the motion model" for c, r in news]
        return ({"cameras": cams, "inconsistent": bad} if cams else None), lines

    @property
    def camera_ids(self) -> list:
        return list(self.cameras)

    def warm_up(self) -> None:
        """Load the compiled kernels (and pyproj, with an origin) once, before the first frame."""
        for setup in self.cameras.values():  # (the per-frame kernels: by _warm_frames' frames)
            if setup.georef.has_origin:
                setup.georef.to_wgs84(np.zeros((1, 2)))
            if self.messages:
                self._encode(build_cpm(setup.station_id, 0, []))
        self._warm_frames()
        # the compiled writers (JSON rows, UPER container): loaded from numba's cache or compiled now
        t = Table(1)
        t.json([b'{"a":', t.column(np.zeros(1)), t.when(np.ones(1, bool), b',"b":', t.column(["x"])), b"}"])
        one = np.ones(1, np.int64)
        perceived_object_container_uper_arrays(one, one, one, one, one, one, one, one, one, cdd=self.cpm_cdd)
        if self.record == "compact":  # (its compiled passes: _compact_objects, _plain_cpm_uper)
            compact_objects_json(one, 0 * one, [b"null"], 0 * one, [b""], np.zeros((5, 1)), one)
            cls = self._cls
            for setup in self.cameras.values():
                plain_cpm_uper(setup.uper, 0, np.zeros((1, 2)), 0 * one, None, one, np.ones((7, 1), np.int32), 0,
                               0 * one, 0 * one, cls.bits_value, cls.bits_width, cdd=self.cpm_cdd)
                if setup.lean_cpm is not None:  # (the lean frame's: untracked and tracked, one signature)
                    for motion in (None, np.ones((14, 1), np.int64)):
                        lean_cpm_uper(setup.lean_cpm, 0, np.zeros((5, 1)), 0 * one, None, one,
                                      np.ones((7, 1), np.int32), 0 * one, 0 * one, motion)
        cm_dm(np.zeros((1, 2)), np.zeros(1, np.int64))
        scan_frame(b'{"camera_id":"c","frame":0,"timestamp_s":0,"detections":[{"object_id":1,"class":"car",'
                   b'"u_min_px":1,"v_min_px":1.5,"u_max_px":2,"v_max_px":3}]}')

    def _warm_frames(self) -> None:
        """Two dummy frames of 2D boxes and two of 3D boxes through the whole path of each camera (records,
        messages, motion), on scratch tracks and message ids: every kernel a frame calls is loaded before the
        first real frame (one left cold cost that frame ~20 ms from the cache, ~1 s after an install, and a
        burst of cameras behind it was dropped).  The camera's state is left as it was."""
        for cid, setup in self.cameras.items():
            w, h = setup.processor.camera.image_size_px
            box2d = {"u_min_px": 0.45 * w, "v_min_px": 0.8 * h, "u_max_px": 0.55 * w, "v_max_px": 0.9 * h}
            xy = setup.processor.corners(np.array([[[0.5 * w, 0.85 * h]]])).centre_xy_world_m[0]
            x, y = (float(v) for v in (xy if np.isfinite(xy).all() else (0.0, 0.0)))
            box3d = {"x_m": x, "y_m": y, "z_m": 0.0, "length_m": 4.0, "width_m": 2.0, "height_m": 1.5, "yaw_rad": 0.0}
            saved = setup.tracker, setup.ids
            try:
                for box in (box2d, box3d):
                    setup.ids = MessageIdMap()
                    if saved[0] is not None:
                        setup.tracker = saved[0].fresh()
                    for k in range(2):
                        dets = [{"object_id": j, "class": "car", **box} for j in range(2)]
                        try:
                            self._process({"camera_id": cid, "frame": k, "timestamp_s": _WARM_TIME_S + 0.1 * k,
                                           "detections": dets}, time.perf_counter())
                        except (_FrameError, FootprintUQError):  # (a camera that cannot see the dummy box: the
                            pass  # kernels ran all the same; real frames report their own errors)
            finally:
                setup.tracker, setup.ids = saved
            if self._lean:  # (the frames above are dicts: the lean path's kernel is loaded here)
                setup.processor.boxes2d_columns(np.array([[box2d[k] for k in S.BOX2D_COLUMNS]]), contact=self.contact,
                                                value_rows=10 if self.tracks else 5)

    # -- one frame ------------------------------------------------------------------------------------
    def process_frame(self, frame, *, source: str | None = None) -> dict:
        """One frame (dict or JSON text) -> a footprints record or an error record (never raises on bad input).

        ``source`` (e.g. ``"stdin line 7"``, ``"mqtt detections/cam1"``) is copied into error records.
        The record is :meth:`process_frame_json`'s text, parsed.
        """
        out = self.process_frame_json(frame, source=source)
        return out.record if out.record is not None else orjson.loads(out.data)

    def process_frame_json(self, frame, *, source: str | None = None) -> FrameOutput:
        """:meth:`process_frame` as the JSON text the transports send (a :class:`FrameOutput`).

        The footprints record is written as text directly from the frame's arrays, without building the
        per-object dicts: the bytes orjson writes for :meth:`process_frame`'s record, in a fraction of the time.
        ``frame``: a dict, the frame's JSON text (bytes or str: a frame in the common layout is read straight into
        columns by :func:`.frame_scan.scan_frame`, any other parsed in full) or a
        :class:`~.frame_scan.ScannedFrame` a transport has read already.
        """
        t0 = time.perf_counter()
        camera_id = frame_no = None
        try:
            # the common layout, read by one compiled pass (frame_scan); a transport may have read it already
            if type(frame) is bytes:
                scanned = scan_frame(frame)
            elif isinstance(frame, ScannedFrame):
                scanned = frame
            else:
                scanned = _scan_text(frame) if isinstance(frame, _TEXT_TYPES) else None
            if scanned is not None:
                camera_id, frame_no = scanned.camera_id, scanned.frame
                return self._process_scanned(scanned, t0)
            if isinstance(frame, _TEXT_TYPES):
                frame = _parse_frame_text(frame)
            if not isinstance(frame, dict):
                raise _FrameError(None, f"frame is not a JSON object: {type(frame).__name__}")
            camera_id = frame.get("camera_id")
            frame_no = frame.get("frame")
            try:
                return self._process(frame, t0)
            except orjson.JSONEncodeError as e:  # e.g. a lone surrogate in a string of an embedding caller's dict
                raise _FrameError(None, f"text that cannot be written as JSON: {e}") from None
        except _FrameError as e:
            rec = error_record(e.reason, field=e.field, camera_id=_jsonable(camera_id), frame=_jsonable(frame_no),
                               source=source)
        except FootprintUQError as e:
            rec = error_record(str(e), field=getattr(e, "field", None), camera_id=_jsonable(camera_id),
                               frame=_jsonable(frame_no), source=source)
        return FrameOutput(_dumps_error(rec), RECORD_ERROR, rec["camera_id"], None, rec)

    def _setup(self, camera_id) -> CameraSetup:
        if camera_id is not None and not isinstance(camera_id, str):
            raise _FrameError("camera_id", f"camera_id is not a string: {camera_id!r}")
        if self._single is not None:
            key, setup = self._single
            if key is not None and camera_id != key:
                raise _FrameError("camera_id", f"camera_id {camera_id!r} is not this service's camera {key!r}")
            return setup
        if camera_id is None:
            raise _FrameError("camera_id", "missing field camera_id (needed with a registry)")
        setup = self.cameras.get(camera_id)
        if setup is None:
            raise _FrameError("camera_id", f"camera_id {camera_id!r} not in the registry")
        return setup

    def _process(self, frame: dict, t0: float) -> FrameOutput:
        camera_id = frame.get("camera_id")
        setup = self._setup(camera_id)
        fno = frame.get("frame")
        if fno is None:
            raise _FrameError("frame", "missing field frame")
        if isinstance(fno, bool) or not isinstance(fno, int):
            raise _FrameError("frame", f"field frame is not an integer: {fno!r}")
        ts = _frame_number(frame, "timestamp_s")
        dets = frame.get("detections")
        if not isinstance(dets, list):
            raise _FrameError("detections", f"field detections is not a list: {type(dets).__name__}")
        if len(dets) > self.max_frame_detections:  # the frame size limit: one error record, nothing parsed
            raise _FrameError("detections", f"{len(dets)} detections in one frame, more than the frame limit of "
                              f"{self.max_frame_detections} (split the frame)")
        return self._frame(setup, camera_id, fno, ts, parse_detections(dets, self.class_names), t0)

    def _process_scanned(self, scanned: ScannedFrame, t0: float) -> FrameOutput:
        """A frame read by :func:`.frame_scan.scan_frame` (its fields of the right types already): the same checks
        and record as :meth:`_process`."""
        setup = self._setup(scanned.camera_id)
        n = len(scanned.int_ids)
        if n > self.max_frame_detections:
            raise _FrameError("detections", f"{n} detections in one frame, more than the frame limit of "
                              f"{self.max_frame_detections} (split the frame)")
        if scanned.values_checked and n and self._takes_lean():
            # (nothing for the value checks: the columns go to the lean path as they are)
            ts = scanned.timestamp_s
            out = self._lean_frame(setup, scanned.camera_id, scanned.frame, ts,
                                   timestamp_its_ms(ts) if self.messages else None, scanned, scanned.int_ids, (), t0)
            if out is not None:
                return out
            return self._frame(setup, scanned.camera_id, scanned.frame, ts, boxes2d_detections(
                scanned.boxes, scanned.pixel_cov_px2, scanned.object_ids, scanned.classes, scanned.class_confidence,
                scanned.int_ids, True), t0, lean=False)
        found = boxes2d_detections(scanned.boxes, scanned.pixel_cov_px2, scanned.object_ids, scanned.classes,
                                   scanned.class_confidence, scanned.int_ids, scanned.values_checked)
        return self._frame(setup, scanned.camera_id, scanned.frame, scanned.timestamp_s, found, t0)

    def _frame(self, setup: CameraSetup, camera_id, fno: int, ts: float, found: FrameDetections, t0: float,
               lean: bool = True) -> FrameOutput:
        """The record of a frame whose fields are checked and whose detections are in columns (``lean``: by
        :meth:`_lean_frame` where it takes the frame; False: it declined it already)."""
        ref_ms = timestamp_its_ms(ts) if self.messages else None
        if lean and found.family == "2d" and self._takes_lean():
            int_ids = found.int_ids if found.int_ids is not None else _int_ids(found.object_ids)
            out = None if int_ids is None else self._lean_frame(setup, camera_id, fno, ts, ref_ms, found, int_ids,
                                                                found.errors, t0)
            if out is not None:
                return out
        est, found = self._footprints(setup, found)
        ids, classes = found.object_ids, found.classes
        motion = self._motion(setup, est, ids, classes, ts, found.yaw_rad, found.family) if self.tracks else None
        if self.on_tracked is not None and motion is not None:
            self.on_tracked(camera_id, fno, ts, setup.last_tracks, est, found)
        return self._records(setup, camera_id, fno, ts, ref_ms, found, est, motion, t0)

    def _takes_lean(self) -> bool:
        """Whether a frame of 2-D boxes goes to :meth:`_lean_frame` first (compact records, the fast UPER
        encoder, the columnar writers; tracked: no :attr:`on_tracked`, which takes the estimate)."""
        return self._lean and self._columnar and (self.on_tracked is None or not self.tracks)

    def _records(self, setup: CameraSetup, camera_id, fno: int, ts: float, ref_ms: int | None,
                 found: FrameDetections, est, motion, t0: float) -> FrameOutput:
        """:meth:`_frame`'s record (and CPM) of the frame's estimate ``est`` and its tracker's ``motion``
        (:meth:`_motion`; None: untracked) by the general writers (the compact ones where they take it)."""
        ids, classes, class_p = found.object_ids, found.classes, found.class_confidence
        t1 = time.perf_counter()
        compact = self.record == "compact"
        # the compact record: its objects (with the motion when tracked) from the columns in one compiled pass, and
        # the untracked frame's CPM in another
        co = self._compact_objects(setup, est, ids, classes, ts, motion, found.int_ids) if compact else None
        if co is None:
            objects, ok_idx, msg_ids = self._objects_json(setup, est, ids, classes, ts, motion)
        else:
            objects, ok_idx, msg_ids = co.text, co.ok_idx, co.msg_ids
        t2 = time.perf_counter()
        head = {"type": RECORD_FOOTPRINTS, **({"record": "compact"} if compact else {}), "camera_id": camera_id,
                "frame": fno, "timestamp_s": ts, "station_id": setup.station_id,
                "heading_offset_deg": setup.georef.heading_offset_deg,
                **({} if compact else {"confidence": self.confidence}), "n_objects": len(ids),
                "detection_errors": [e.as_dict() for e in found.errors]}
        if self.messages:
            head["cpm_cdd"] = self.cpm_cdd
        parts = [orjson.dumps(head)[:-1], b',"objects":', objects]
        cpm_uper = None
        if self.messages:
            # motion: the tracker's motion of the frame's objects (None: the messages carry no motion)
            om = None if motion is None else motion[1]
            if compact and self.uper_encoder == "fast":  # the CPM's bytes only (on their own topic)
                cpm_uper = None if co is None else self._plain_cpm_uper(setup, est, class_p, co, ref_ms, om)
                if cpm_uper is None:  # (tracked, or a value out of range: the general writer names it)
                    cpm_uper = self._cpm_uper(setup, self._message_columns(setup, est, classes, class_p, ok_idx,
                                                                           om), msg_ids, ref_ms)
            else:
                cpm, cpm_uper, sdsm = self._messages_json(setup, est, classes, class_p, ok_idx, msg_ids, int(fno),
                                                          ts, ref_ms, motion=om)
            if compact:
                parts += [b',"cpm_uper_bytes":', b"%d" % len(cpm_uper)]
            else:
                parts += [b',"cpm":', *cpm, b',"cpm_uper_hex":"', cpm_uper.hex().encode(), b'","sdsm":', *sdsm]
                cpm_uper = None  # (in the record)
            omitted = int(np.count_nonzero(est.centre_valid)) - len(ok_idx)
            if omitted:  # said, never silent: objects with a centre that did not fit in the messages
                parts += [b',"objects_not_in_messages":', b"%d" % omitted]
        t3 = time.perf_counter()
        total = round(1e6 * (t3 - t0), 1)
        # (orjson's text of these rounded floats: one decimal, as "%.1f" writes them below 1e15)
        parts.append(b',"processing_us":{"footprints":%.1f,"records":%.1f,"messages":%.1f,"total":%.1f}}' % (
            1e6 * (t1 - t0), 1e6 * (t2 - t1), 1e6 * (t3 - t2), total))
        return FrameOutput(b"".join(parts), RECORD_FOOTPRINTS, camera_id, total, None, len(found.errors), cpm_uper)

    def _lean_frame(self, setup: CameraSetup, camera_id, fno: int, ts: float, ref_ms: int | None, found,
                    int_ids: np.ndarray, errors, t0: float) -> FrameOutput | None:
        """:meth:`_frame`'s record of a compact frame of 2-D boxes with integer ids, by the columns alone:
        :meth:`~footprint_uq.products.frame_processor.FrameProcessor.boxes2d_columns` (one compiled call), with
        tracks the tracker's step on its centre columns (:meth:`_step_tracks`), then :meth:`_lean_records` -- no
        estimate, the same bytes and tracks (``tests/test_service_columnar.py``, ``tests/test_frame_columns.py``).
        ``found``: the detections' columns (a :class:`.detections.FrameDetections` of 2-D boxes, or the
        :class:`.frame_scan.ScannedFrame` itself when its values are checked), ``int_ids`` its ids as int64 (every
        ``object_id`` an integer of 64 bits), ``errors`` its bad detections.  None: a frame for :meth:`_frame`'s
        general path (the processor declines it -- a covariance it refuses, an overflow, a centre the V2X policy
        samples -- or, untracked, a value out of the CPM's range, which the general writer names).  A tracked
        frame is never declined after the tracker's step: the general writers then finish it (:meth:`_records`
        with the estimate formed again by ``boxes2d``: the same numbers), the tracks stepped once."""
        cols = setup.processor.boxes2d_columns(found.boxes, found.pixel_cov_px2, contact=self.contact,
                                               value_rows=10 if self.tracks else 5)
        if cols is None:
            return None
        motion = None
        if self.tracks:
            # (the ids as int64 when every one is such an integer: the tracks' compiled id look-up)
            motion = self._step_tracks(setup, cols.centre_xy_world_m, cols.centre_cov_m2, cols.centre_shared_m,
                                       found.object_ids if int_ids is None else int_ids, found.classes, ts, None,
                                       True)
        t1 = time.perf_counter()
        out = None if motion is not None and not _motion_values(cols.values, motion) else \
            self._lean_records(setup, camera_id, fno, ts, ref_ms, found, int_ids, errors, cols, motion, t0, t1)
        if out is None and motion is not None:  # (after the step: the general writers finish the frame)
            if isinstance(found, ScannedFrame):
                found = boxes2d_detections(found.boxes, found.pixel_cov_px2, found.object_ids, found.classes,
                                           found.class_confidence, int_ids, True)
            est = setup.processor.boxes2d(found.boxes, contact=self.contact, pixel_cov_px2=found.pixel_cov_px2,
                                          boxes_checked=True)
            return self._records(setup, camera_id, fno, ts, ref_ms, found, est, motion, t0)
        return out

    def _lean_records(self, setup: CameraSetup, camera_id, fno: int, ts: float, ref_ms: int | None, found,
                      int_ids: np.ndarray, errors, cols, motion, t0: float, t1: float) -> FrameOutput | None:
        """:meth:`_lean_frame`'s record and UPER CPM from the columns ``cols`` (a :class:`~footprint_uq.products.
        frame_processor.FrameColumns`; tracked: its ``values`` rows 5-9 the motion's, ``motion`` the tracker's
        ``(track_id, ObjectMotion)``) by :meth:`_compact_text` and :meth:`_lean_cpm`, its head by :func:`_lean_head`.
        None: a value out of the CPM's range (the general writer names it)."""
        N = len(int_ids)
        all_valid = cols.n_valid == N
        valid = None if all_valid else cols.centre_reason == 0
        status = None if all_valid else _compact_status_of(valid, cols.largest_index, centre_reason_texts(
            cols.centre_reason, cols.centre_bad_corner, cols.n_corners))
        tid = None if motion is None else np.asarray(motion[0], dtype=np.int64)
        # (the classes as _class_index gives them: the scanner's own columns, no list of classes made)
        class_idx, distinct = (found.class_index, found.distinct_classes) if type(found) is ScannedFrame else \
            _class_index(found.classes)
        co = self._compact_text(setup, int_ids, class_idx, distinct, ts, cols.values, valid, all_valid, status, tid)
        t2 = time.perf_counter()
        tail = b""
        cpm_uper = None
        if self.messages:
            cpm_uper = self._lean_cpm(setup, ref_ms, found.class_confidence, cols, co, motion, N)
            if cpm_uper is None:  # (a value out of range: the general path's writer names it)
                return None
            omitted = cols.n_valid - len(co.ok_idx)
            # (objects_not_in_messages: said, never silent: objects with a centre that did not fit in the messages)
            tail = b',"cpm_uper_bytes":%d' % len(cpm_uper) if not omitted else \
                b',"cpm_uper_bytes":%d,"objects_not_in_messages":%d' % (len(cpm_uper), omitted)
        head = _lean_head(setup, camera_id, fno, ts, N, errors, self.cpm_cdd if self.messages else None)
        t3 = time.perf_counter()
        # (orjson's text of the rounded floats: one decimal, as "%.1f" writes them below 1e15; the total's text read
        # back is round(total, 1): tests/test_service_lean_cpm.py)
        total_text = b"%.1f" % (1e6 * (t3 - t0))
        # (joined: the objects' text copied once -- a "%s" of it copies it twice)
        data = b"".join((head, b',"objects":', co.text, b'%s,"processing_us":{"footprints":%.1f,"records":%.1f,'
                         b'"messages":%.1f,"total":%s}}' % (tail, 1e6 * (t1 - t0), 1e6 * (t2 - t1), 1e6 * (t3 - t2),
                                                            total_text)))
        return _made(FrameOutput, (data, RECORD_FOOTPRINTS, camera_id, float(total_text), None, len(errors), cpm_uper))

    def _lean_cpm(self, setup: CameraSetup, ref_ms: int, class_p, cols, co: _CompactObjects, motion,
                  N: int) -> bytes | None:
        """:meth:`_lean_records`' UPER CPM of the objects ``co.ok_idx`` from the columns ``cols`` (``motion``: the
        tracker's; None: untracked): :func:`.frame_kernels.lean_cpm_uper` (one compiled call, the world -> ENU
        transform inside) where it takes the frame, else :func:`.frame_kernels.plain_cpm_uper` on numpy's ENU
        columns -- the same bytes.  None: a value out of range (the general writer names it)."""
        # (tracked: the message's objects' motion codes in one compiled call, as _plain_cpm_uper)
        mc = None if motion is None else motion_rows(motion[1], N, None if len(co.ok_idx) == N else co.ok_idx)
        crow = co.class_rows
        if setup.lean_cpm is not None:
            out = lean_cpm_uper(setup.lean_cpm, ref_ms, cols.values, co.ok_idx, class_p, co.msg_ids, cols.v2x_rows,
                                co.class_idx, crow, mc)
            if out is not None:
                return out
        cls = self._cls  # (declined, or no lean constants: the call before, which also names what it declines)
        return plain_cpm_uper(setup.uper, ref_ms, setup.world_to_enu(cols.values[:2].T), co.ok_idx, class_p,
                              co.msg_ids, cols.v2x_rows, _CPM_INDEX, co.class_idx, crow, cls.bits_value,
                              cls.bits_width, cdd=self.cpm_cdd, motion=mc)

    def _footprints(self, setup: CameraSetup, found: FrameDetections) -> tuple:
        """The camera's kernel over the frame's good detections (in columns: :func:`.detections.parse_detections`,
        each bad one an error entry): ``(estimate, FrameDetections)``.

        A frame the processor refuses (a pixel covariance that is not positive semi-definite: its compiled check)
        is checked in full (:func:`.detections.check_values`: every bad detection an error entry) and run again;
        a value refused beyond those checks (none is known) costs that detection, not the frame: it joins the
        error entries and the kernel runs again without it."""
        proc = setup.processor
        checked = False
        while True:
            if found.family is None:
                return proc.corners(np.zeros((0, 1, 2))), found
            X, P = found.boxes, found.pixel_cov_px2
            try:
                if found.family == "2d":
                    return proc.boxes2d(X, contact=self.contact, pixel_cov_px2=P, boxes_checked=True), found
                if found.family == "3d":
                    return proc.boxes3d(X, yaw_unit="deg" if found.columns[-1] == "yaw_deg" else "rad",
                                        pixel_cov_px2=P), found
                return proc.corners(X.reshape(len(found), -1, 2), pixel_cov_px2=P), found
            except InputError as e:
                if not checked:  # every covariance that is not PSD, at once (the processor names the first)
                    found, checked = check_values(found), True
                    continue
                m = re.search(r"\[(\d+)", e.field or "")
                if m is None or int(m.group(1)) >= len(found):
                    raise _FrameError("detections", str(e)) from None
                r = int(m.group(1))
                bad = np.zeros(len(found), bool)
                bad[r] = True
                i = int(found.index[r])
                found = found.without(bad, [DetectionError(i, f"detections[{i}]", str(e))])

    def _linearity(self, est):
        """Per object: the largest predicted relative error of the linear 1-sigma semi-major axis over its
        usable ground-contact points (:func:`footprint_uq.uncertainty.propagation.nonlinearity`, with the detector's
        pixel covariance) and ``linear_ok`` = that <= the threshold (False where nothing is usable).

        The points' values are the fused kernel's (``est.corners_nonlinearity``: the frame processor computes
        them for the V2X policy anyway; ``tests/test_service.py`` holds them to the library's function), not a
        second numpy pass over the frame (~1.7 ms per 100 objects)."""
        worst, ok = np.empty(len(est)), np.empty(len(est), np.bool_)
        worst_usable(est.corners_nonlinearity, est.corner_usable, self.linear_threshold, worst, ok)
        return worst, ok

    def _motion(self, setup: CameraSetup, est, ids: list, classes: list, ts: float, yaw_rad: np.ndarray | None,
                family: str | None = None):
        """The frame's objects through the camera's tracker, one call (:meth:`~footprint_uq.tracking.
        camera_tracker.CameraTracker.step_frame`: step, NIS check, slide term, motion): ``(track_id (N,),
        ObjectMotion)``; ``yaw_rad``: the 3-D boxes' yaw (None for other boxes); 2-D boxes (``family``) add their
        sliding contact's velocity term."""
        return self._step_tracks(setup, est.centre_xy_world_m, est.centre_cov_m2, est.centre_shared_m, ids,
                                 classes, ts, yaw_rad, family == "2d")

    def _step_tracks(self, setup: CameraSetup, xy_world_m: np.ndarray, cov_m2: np.ndarray,
                     shared_m: np.ndarray | None, ids: list | np.ndarray, classes: list, ts: float,
                     yaw_rad: np.ndarray | None, contact_2d: bool) -> tuple:
        """:meth:`_motion` of the centres' columns ``xy_world_m`` (N, 2) m, ``cov_m2`` (N, 2, 2) m^2 and
        ``shared_m`` (N, 2, r) (an estimate's, or the lean frame's :class:`~footprint_uq.products.frame_processor.
        FrameColumns`): ``(track_id (N,), ObjectMotion)``."""
        # (with messages: the motion fields -- object_motion's, to the bit -- and the messages' codes in one
        # compiled call, the codes kept for the frame's motion_rows; without, no codes are computed)
        motion_pass = codes_pass(len(ids)) if self.messages else None
        f = setup.tracker.step_frame(ts, ids, classes, xy_world_m, cov_m2, shared_m, yaw_rad=yaw_rad,
                                     contact_2d=contact_2d, motion_pass=motion_pass)
        # what the CP service fuses (on_tracked): the tracks with the sliding contact's velocity term
        setup.last_tracks = f.tracks
        return f.track_id, f.motion if motion_pass is None else coded(f.motion, motion_pass)

    def _objects_json(self, setup: CameraSetup, est, ids: list, classes: list, ts: float = 0.0,
                      motion=None) -> tuple[bytes, np.ndarray, list]:
        """The ``objects`` list of the record as JSON text, written column-wise (:class:`.jsonrows.Table`); and
        the indices of the objects in the messages (with a centre, at most 255) and their ``message_object_id``.
        ``record="compact"``: the fields of :data:`COMPACT_OBJECT_FIELDS` only."""
        N = len(ids)
        cov = est.centre_cov_m2
        valid = est.centre_valid
        centre = est.centre_xy_world_m
        t = Table(N)
        compact = self.record == "compact"
        x, y, cxx, cxy, cyy = t.columns(np.array([centre[:, 0], centre[:, 1], cov[:, 0, 0], cov[:, 0, 1],
                                                  cov[:, 1, 1]]))
        layout = [b'{"object_id":', t.column(ids), b',"class":', t.column(classes), *_status_layout(t, est, compact),
                  b',"x_m":', x, b',"y_m":', y, b',"cov_m2":[[', cxx, b",", cxy, b"],[", cxy, b",", cyy, b"]]"]
        if not compact:
            layout += self._full_object_layout(setup, t, est, cxx, cxy, cyy)
        if motion is not None:
            layout += _motion_object_layout(t, motion, compact)
        ok_idx = msg_ids = None
        if self.messages:
            ok_idx, msg_ids, ids_layout = _message_id_layout(t, setup, ids, valid, ts)
            layout += ids_layout
        layout.append(b"}")
        return t.json_buffer(layout), ok_idx, msg_ids

    def _compact_objects(self, setup: CameraSetup, est, ids: list, classes: list, ts: float, motion=None,
                         int_ids: np.ndarray | None = None) -> _CompactObjects | None:
        """The compact record's ``objects`` by :func:`.jsonrows.compact_objects_json` (one compiled pass;
        :meth:`_objects_json` writes the same bytes with its general layout), and the message ids as
        :meth:`_objects_json` assigns them.  ``motion``: the tracker's ``(track_id (N,), ObjectMotion)`` (None:
        untracked).  None: not this path's frame (no objects, an ``object_id`` that is not an integer of 64 bits,
        motion not in float64, or :attr:`_columnar` off: the reference path of the tests).  ``int_ids``: ``ids`` as
        int64 when the caller knows them all to be such integers (:attr:`.detections.FrameDetections.int_ids`)."""
        if not self._columnar or len(ids) == 0:
            return None
        id_arr = int_ids if int_ids is not None else _int_ids(ids)
        values = None if id_arr is None else _compact_values(est, motion)
        if values is None:
            return None
        valid = est.centre_valid
        all_valid = bool(valid.all())
        status = None if all_valid else _compact_status(est)
        tid = None if motion is None else np.asarray(motion[0], dtype=np.int64)
        class_idx, distinct = _class_index(classes)
        return self._compact_text(setup, id_arr, class_idx, distinct, ts, values, valid, all_valid, status, tid)

    def _compact_text(self, setup: CameraSetup, id_arr: np.ndarray, class_idx: np.ndarray | None, distinct: list,
                      ts: float, values: np.ndarray, valid: np.ndarray | None, all_valid: bool,
                      status: tuple | None, tid: np.ndarray | None) -> _CompactObjects:
        """:meth:`_compact_objects` from the columns: ``id_arr`` (N,) int64 the object ids, ``class_idx`` (N,) int64
        each object's entry among the frame's ``distinct`` classes (None: one class; :func:`_class_index`),
        ``values`` (5 or 10, N) the record's floats, ``valid`` (N,) the centres found (``all_valid``: every one),
        ``status`` :func:`_compact_status`'s pair (None: all ok), ``tid`` the track ids (None: untracked); the
        message ids assigned here (with ``messages``).  ``valid`` is read only when not ``all_valid`` (None then)."""
        N = len(id_arr)
        zeros, first_rows = _KEPT_ROWS.get(N) or _kept_rows(N)  # (the look-up inline: the usual frame's sizes)
        if class_idx is None:
            class_idx = zeros
        status_idx, status_texts = (zeros, [_STATUS_ALL_OK_COMPACT]) if status is None else status
        ok_idx = msg_ids = mid = None
        if self.messages:  # (as _message_id_layout: the objects with a centre, at most 255)
            ok_idx = first_rows if all_valid else np.flatnonzero(valid)[:MAX_MESSAGE_OBJECTS]
            msg_ids = mid = setup.ids.assign(None, ok_idx, ts, int_ids=id_arr)
            if len(ok_idx) < N:
                mid = np.full(N, -1, np.int64)
                mid[ok_idx] = msg_ids
        class_texts, class_rows = _CLASS_CONSTS.get(tuple(distinct)) or _class_consts(distinct)
        text = compact_objects_json(id_arr, class_idx, class_texts, status_idx, status_texts, values, mid, tid)
        return _made(_CompactObjects, (text, ok_idx, msg_ids, class_idx, class_rows))

    def _plain_cpm_uper(self, setup: CameraSetup, est, class_p, co: _CompactObjects, ref_ms: int,
                        motion: ObjectMotion | None = None) -> bytes | None:
        """The UPER CPM of a compact frame's objects ``co.ok_idx`` by :func:`.frame_kernels.plain_cpm_uper` (their
        cm, confidence levels, container and the message in one compiled call); the bytes of :meth:`_cpm_uper`.
        ``motion``: the tracker's motion of all the frame's objects (None: untracked).  None: a value out of
        range (the general writer then names it)."""
        cls = self._cls
        n = est.centre_valid.shape[0]  # (not len(est): a call back up into products/, bench/frame_walk.py)
        # the message's objects' motion codes in one compiled call, straight from the motion's columns (no copy)
        mc = None if motion is None else motion_rows(motion, n, None if len(co.ok_idx) == n else co.ok_idx)
        return plain_cpm_uper(setup.uper, ref_ms, setup.world_to_enu(est.centre_xy_world_m), co.ok_idx, class_p,
                              co.msg_ids, np.ascontiguousarray(est.v2x_codes.T, dtype=np.int32), _CPM_INDEX,
                              co.class_idx, co.class_rows, cls.bits_value, cls.bits_width,
                              cdd=self.cpm_cdd, motion=mc)

    def _full_object_layout(self, setup: CameraSetup, t: Table, est, cxx, cxy, cyy) -> list:
        """The full record's object fields after ``cov_m2``: ellipses, largest point, V2X fields and their source,
        the WGS84 position (with an origin), the linearity flag (``linearity``)."""
        rows = est.object_rows  # (every FrameProcessor estimate has them: the kernel's or the reference's)
        a, b, ori = rows[_ROW_SMAJ], rows[_ROW_SMIN], rows[_ROW_ORI]  # the centre's ellipse, as ellipse_axes
        sa, sb, so, ka, kb, ls, lx, ly = t.columns(np.array([
            a, b, ori, self._k * a, self._k * b, est.largest_semi_major_m, est.largest_xy_world_m[:, 0],
            est.largest_xy_world_m[:, 1]]))
        layout = [b',"sigma_major_m":', sa, b',"sigma_minor_m":', sb, b',"orientation_deg":', so,
                  b',"semi_major_m":', ka, b',"semi_minor_m":', kb, b',"largest_index":', t.column(est.largest_index),
                  b',"largest_sigma_major_m":', ls, b',"largest_x_m":', lx, b',"largest_y_m":', ly]
        for key, col in zip(_V2X_KEYS, t.columns(est.v2x_codes.T), strict=True):
            layout += [key, col]
        layout += _v2x_source_layout(t, est, cxx, cxy, cyy)
        if setup.has_origin:
            N = len(est)
            lat, lon = setup.georef.to_wgs84(est.centre_xy_world_m) if N else (np.zeros(0), np.zeros(0))
            layout += [b',"lat_deg":', t.column(lat), b',"lon_deg":', t.column(lon)]
        if self.linearity:
            nonlin, linear = self._linearity(est) if len(est) else (np.zeros(0), np.zeros(0, bool))
            layout += [b',"nonlinearity":', t.column(nonlin), b',"linear_ok":', t.column(linear)]
        return layout

    def _message_columns(self, setup: CameraSetup, est, classes: list, class_p, ok_idx: np.ndarray,
                         motion: ObjectMotion | None) -> _MessageColumns:
        """The columns of the CPM / SDSM objects ``ok_idx`` (:class:`_MessageColumns`)."""
        N, m = len(classes), len(ok_idx)
        en = setup.world_to_enu(est.centre_xy_world_m) if N else np.zeros((0, 2))
        x_cm, y_cm, x_dm, y_dm = cm_dm(en, ok_idx)
        if N and classes.count(classes[0]) == N:  # one class for the frame (or none): one look-up
            crow = np.full(m, _CLASS_ROWS[classes[0]], np.intp)
        else:
            crow = np.fromiter(map(_CLASS_ROWS.__getitem__, classes), np.intp, N)[ok_idx]
        mc = None if motion is None else motion_codes(motion if m == N else motion.take(ok_idx), m)  # (sorted rows)
        level, p = _confidence_levels(class_p, ok_idx)
        return _MessageColumns(m, x_cm, y_cm, x_dm, y_dm, est.v2x_codes[ok_idx], crow, level, p, mc)

    def _cpm_uper(self, setup: CameraSetup, c: _MessageColumns, msg_ids: np.ndarray, ref_ms: int) -> bytes:
        """The UPER CPM of the message columns, by the compiled column writer (``uper_encoder="fast"``)."""
        cls = self._cls
        codes = c.codes
        container = perceived_object_container_uper_arrays(
            msg_ids, c.x_cm, codes[:, _CPM_INDEX], c.y_cm, codes[:, _CPM_INDEX + 1], codes[:, _CPM_INDEX + 2],
            cls.bits_value[c.crow], cls.bits_width[c.crow], c.level, cdd=self.cpm_cdd, motion=c.mc)
        return setup.uper.encode(ref_ms, container)

    def _messages_json(self, setup: CameraSetup, est, classes: list, class_p, ok_idx: np.ndarray,
                       msg_ids: np.ndarray, fno: int, ts: float, ref_ms: int, motion: ObjectMotion | None = None
                       ) -> tuple[tuple, bytes, tuple]:
        """The CPM (JSON text, as pieces to join), its UPER encoding (bytes) and the SDSM (JSON text as pieces,
        ``null`` without objects) of the objects ``ok_idx``, written column-wise; UPER by the compiled column
        writer.  ``motion``: the :class:`~.messages.motion.ObjectMotion` of all the frame's objects (None: no
        motion is sent)."""
        c = self._message_columns(setup, est, classes, class_p, ok_idx, motion)
        m, codes, crow, mc = c.m, c.codes, c.crow, c.mc
        cls = self._cls
        t = Table(m)
        oid = t.column(msg_ids)
        if c.class_p is None:
            lv, pct = b"%d" % CONFIDENCE_LEVEL_UNAVAILABLE, b"0"
        else:
            lv = t.column(c.level)
            pct = t.column(np.where(np.isnan(c.class_p), 0.0, np.rint(100.0 * c.class_p)).astype(np.int64))
        corr = codes[:, _CPM_INDEX + 2]
        cx, cy, xv, yv, r = t.columns(np.array([codes[:, _CPM_INDEX], codes[:, _CPM_INDEX + 1], c.x_cm, c.y_cm, corr],
                                               dtype=np.int64))
        vel, age = _motion_layout(t, mc)
        po = t.json_buffer([b'{"objectId":', oid, b',"measurementDeltaTime":0,"position":{"xCoordinate":{"value":', xv,
                     b',"confidence":', cx, b'},"yCoordinate":{"value":', yv, b',"confidence":', cy, b"}}", *vel,
                     t.when(corr != 101, _CORR_OPEN, r, _CORR_CLOSE), *age,
                     t.when(cls.bits_width[crow] > 0, b',"classification":[{"objectClass":',
                            t.column(cls.object_json[crow].tolist()), b',"confidence":', lv, b"}]"),
                     b"}"])
        lat_e7, lon_e7 = setup.lat_1e7deg, setup.lon_1e7deg
        cpm = build_cpm(setup.station_id, ref_ms, [],
                        latitude=LATITUDE_UNAVAILABLE if lat_e7 is None else lat_e7,
                        longitude=LONGITUDE_UNAVAILABLE if lon_e7 is None else lon_e7)
        cpm["payload"]["cpmContainers"][1]["containerData"]["numberOfPerceivedObjects"] = m
        cpm_json = _splice(orjson.dumps(cpm), b'"perceivedObjects":[]', po)  # (pieces of the text)
        if self.uper_encoder == "fast":
            cpm_uper = self._cpm_uper(setup, c, msg_ids, ref_ms)
        else:
            cpm_uper = self._encode(orjson.loads(b"".join(cpm_json)))
        # J3224's DetectedObjectList has 1..256 entries: a frame without objects has no SDSM (null)
        if m == 0:
            return cpm_json, cpm_uper, (b"null",)
        xd, yd = t.columns(np.array([c.x_dm, c.y_dm]))
        if mc is None:
            tail = [_SDSM_TAIL_NO_MOTION]
        else:
            sp, hd = t.columns(np.array([mc.sdsm_speed, mc.sdsm_heading]))
            tail = [_SDSM_SPEED, sp, b',"speedConfidence":', t.column(_SPEED_CONF[mc.sdsm_speed_conf].tolist()),
                    b',"heading":', hd, b',"headingConf":', t.column(_HEADING_CONF[mc.sdsm_heading_conf].tolist()),
                    b"}}"]
        objs = t.json_buffer([b'{"detObjCommon":{"objType":', t.column(_SDSM_TYPE[crow].tolist()),
                              b',"objTypeCfd":', pct, b',"objectID":', oid, _SDSM_AFTER_ID, xd, b',"offsetY":', yd,
                              b'},"posConfidence":{"pos":', t.column(_POS_NAMES[codes[:, _J_POS]].tolist()), *tail])
        sdsm = build_sdsm(setup.station_id, fno, ts, [],
                          **({} if lat_e7 is None else {"lat_1e7deg": lat_e7, "lon_1e7deg": lon_e7}))
        return cpm_json, cpm_uper, _splice(orjson.dumps(sdsm), b'"objects":[]', objs)


class _CompactObjects(NamedTuple):
    """An untracked compact record's objects (:meth:`Service._compact_objects`): their JSON text, the rows in the
    messages and their message ids (None without messages), each row's class among the frame's distinct
    classes and those classes' rows of the class tables (:func:`_class_rows_of`)."""

    text: object
    ok_idx: np.ndarray | None
    msg_ids: np.ndarray | None
    class_idx: np.ndarray
    class_rows: np.ndarray


class _MessageColumns(NamedTuple):
    """The CPM / SDSM objects of a frame as columns (m rows): positions (CPM cm, SDSM dm, east / north), the V2X
    codes (m, 7), class rows of the class tables, CPM confidence levels, class confidences (None: none given) and
    the motion codes (None: no motion)."""

    m: int
    x_cm: np.ndarray
    y_cm: np.ndarray
    x_dm: np.ndarray
    y_dm: np.ndarray
    codes: np.ndarray
    crow: np.ndarray
    level: np.ndarray
    class_p: np.ndarray | None
    mc: object


def _status_layout(t: Table, est, compact: bool) -> list:
    """``status`` and ``reason`` of every object (compact: ``reason`` only where the status is not ``ok``)."""
    valid = est.centre_valid
    if valid.all():
        return [_STATUS_ALL_OK_COMPACT if compact else _STATUS_ALL_OK]
    li = est.largest_index.tolist()
    reasons = est.centre_reason_text()
    status = t.column([S.STATUS_OK if ok else (S.STATUS_PARTIAL if j >= 0 else S.STATUS_ERROR)
                       for ok, j in zip(valid.tolist(), li, strict=True)])
    if compact:
        return [b',"status":', status, t.when(~valid, b',"reason":', t.column([
            "" if ok else f"no centre: {r}" for ok, r in zip(valid.tolist(), reasons, strict=True)]))]
    return [b',"status":', status, b',"reason":', t.column(["ok" if ok else f"no centre: {r}"
                                                           for ok, r in zip(valid.tolist(), reasons, strict=True)])]


def _confidence_levels(class_p: np.ndarray | None, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The CPM ConfidenceLevel (int64) of the objects ``rows`` from their class confidences (NaN or none given:
    unavailable), and those confidences (None: none given)."""
    if class_p is None:
        return np.full(len(rows), CONFIDENCE_LEVEL_UNAVAILABLE, np.int64), None
    p = class_p[rows]
    return np.where(np.isnan(p), CONFIDENCE_LEVEL_UNAVAILABLE, np.maximum(1.0, np.ceil(100.0 * p - 1e-9))
                    ).astype(np.int64), p


def _compact_status(est) -> tuple[np.ndarray, list]:
    """A compact record's ``status`` (and ``reason`` where it is not ``ok``) texts: each object's entry among the
    frame's distinct ones and those texts (:func:`_status_layout`'s bytes)."""
    return _compact_status_of(est.centre_valid, est.largest_index, est.centre_reason_text())


def _compact_status_of(valid: np.ndarray, largest_index: np.ndarray, reasons) -> tuple[np.ndarray, list]:
    """:func:`_compact_status` of the columns: ``valid`` (N,) bool, ``largest_index`` (N,) and the centres'
    reason texts (:func:`~footprint_uq.products.footprint_estimate.centre_reason_texts`)."""
    seen: dict = {}
    idx = np.empty(len(valid), np.int64)
    for r, (ok, j, why) in enumerate(zip(valid.tolist(), largest_index.tolist(), reasons, strict=True)):
        text = _STATUS_ALL_OK_COMPACT if ok else b',"status":%s,"reason":%s' % (
            orjson.dumps(S.STATUS_PARTIAL if j >= 0 else S.STATUS_ERROR), orjson.dumps(f"no centre: {why}"))
        idx[r] = seen.setdefault(text, len(seen))
    return idx, list(seen)


def _class_index(classes: list) -> tuple[np.ndarray | None, list]:
    """Each object's entry (int64; None: one class for the frame, every entry 0) among the frame's distinct
    ``classes`` (str or None, in order of first appearance) and those classes (as the scanner's
    :attr:`.frame_scan.ScannedFrame.class_index` and ``distinct_classes``)."""
    N = len(classes)
    if classes.count(classes[0]) == N:  # one class for the frame (or none): one entry
        return None, [classes[0]]
    first: dict = {}
    class_idx = np.fromiter((first.setdefault(c, len(first)) for c in classes), np.int64, N)
    return class_idx, list(first)


#: the 64-bit integers orjson writes (a frame number beyond them: its error, by the dict's text)
_INT_MIN, _UINT_MAX = -(1 << 63), (1 << 64) - 1


def _lean_head(setup: CameraSetup, camera_id, fno: int, ts: float, n_objects: int, errors, cdd: str | None) -> bytes:
    """The compact record's head up to its ``objects`` (without the closing brace): ``orjson.dumps`` of the dict
    ``{"type": "footprints", "record": "compact", "camera_id", "frame", "timestamp_s", "station_id",
    "heading_offset_deg", "n_objects", "detection_errors"[, "cpm_cdd"]}`` to the byte, its constant texts kept per
    camera and ``camera_id`` (``setup.head_texts``), the frame's values written in (floats and errors by orjson).
    ``cdd``: None without messages (no ``cpm_cdd``)."""
    if type(fno) is not int or not _INT_MIN <= fno <= _UINT_MAX:  # (orjson's error or text: the dict's)
        head = {"type": RECORD_FOOTPRINTS, "record": "compact", "camera_id": camera_id, "frame": fno,
                "timestamp_s": ts, "station_id": setup.station_id,
                "heading_offset_deg": setup.georef.heading_offset_deg, "n_objects": n_objects,
                "detection_errors": [e.as_dict() for e in errors]}
        if cdd is not None:
            head["cpm_cdd"] = cdd
        return orjson.dumps(head)[:-1]
    texts = setup.head_texts.get(camera_id)
    if texts is None:
        texts = (b'{"type":%s,"record":"compact","camera_id":%s,"frame":' % (
            orjson.dumps(RECORD_FOOTPRINTS), orjson.dumps(camera_id)),
            b',"station_id":%s,"heading_offset_deg":%s,"n_objects":' % (
            orjson.dumps(setup.station_id), orjson.dumps(setup.georef.heading_offset_deg)),
            b"" if cdd is None else b',"cpm_cdd":%s' % orjson.dumps(cdd))
        if len(setup.head_texts) >= 64:  # (a single camera answers to any id: a few are kept)
            setup.head_texts.clear()
        setup.head_texts[camera_id] = texts
    a, b, c = texts
    return b'%s%d,"timestamp_s":%s%s%d,"detection_errors":%s%s' % (
        a, fno, orjson.dumps(ts), b, n_objects, orjson.dumps([e.as_dict() for e in errors]) if errors else b"[]", c)


def _int_ids(ids: list) -> np.ndarray | None:
    """``ids`` as int64 when every one is an integer (not a bool) of 64 bits, else None."""
    if set(map(type, ids)) != _INT_ONLY:
        return None
    try:
        return np.array(ids, dtype=np.int64)
    except OverflowError:  # (beyond int64: JSON allows up to 2**64 - 1)
        return None


_KEPT_ROWS: dict = {}


def _kept_rows(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` int64 zeros and the rows ``0 .. min(n, 255) - 1`` (int64), made once per ``n`` (at most 1024 sizes kept)
    and shared by the frames: read only, by the compiled writers and the message ids (the class and status
    entries of a uniform frame; the messages' rows of a frame whose centres are all found).
    ``tests/test_service_columnar.py`` checks that frames leave them as they are."""
    kept = _KEPT_ROWS.get(n)
    if kept is None:
        if len(_KEPT_ROWS) >= 1024:
            _KEPT_ROWS.clear()
        kept = _KEPT_ROWS[n] = (np.zeros(n, np.int64), np.arange(min(n, MAX_MESSAGE_OBJECTS), dtype=np.int64))
    return kept


_CLASS_CONSTS: dict = {}


def _class_consts(distinct: list) -> tuple[list, np.ndarray]:
    """The JSON texts of a frame's distinct classes and their class-table rows (:func:`_class_rows_of`), kept for
    the next frames (at most 256 lists)."""
    key = tuple(distinct)
    kept = _CLASS_CONSTS.get(key)
    if kept is None:
        kept = ([orjson.dumps(c) for c in distinct], _class_rows_of(distinct))
        if len(_CLASS_CONSTS) >= 256:
            _CLASS_CONSTS.clear()
        _CLASS_CONSTS[key] = kept
    return kept


def _compact_values(est, motion) -> np.ndarray | None:
    """The compact record's float columns: centre and covariance ``(5, N)`` (m, m^2), with ``motion`` also the
    velocity and its covariance ``(10, N)`` (m/s, m^2/s^2), written row by row into one array (no list of ten
    strided views stacked).  None: a motion column not in float64 (the general writer's text of it would
    differ)."""
    centre, cov = est.centre_xy_world_m, est.centre_cov_m2
    n = centre.shape[0]
    out = np.empty((5 if motion is None else 10, n))
    out[0:2] = centre.T
    c = cov.reshape(n, 4)  # (xx, xy, yx, yy)
    out[2], out[3], out[4] = c[:, 0], c[:, 1], c[:, 3]
    if motion is not None and not _motion_values(out, motion):
        return None
    return out


def _motion_values(out: np.ndarray, motion) -> bool:
    """Rows 5-9 of the compact record's float columns ``out`` (10, N): the velocity (m/s) and its covariance
    (m^2/s^2) of the tracker's ``motion`` ``(track_id, ObjectMotion)``, copied.  False (``out`` not written): a
    motion column not in float64 (the general writer's text of it would differ)."""
    m = motion[1]
    ve, vn, cv = m.v_east_mps, m.v_north_mps, m.cov_v_m2ps2
    try:
        f8 = ve.dtype == _F8 and vn.dtype == _F8 and cv.dtype == _F8
    except AttributeError:  # (not arrays: as numpy reads them)
        f8 = all(np.asarray(a).dtype == _F8 for a in (ve, vn, cv))
    if not f8:
        return False
    out[5], out[6] = ve, vn
    d = np.asarray(cv).reshape(out.shape[1], 4)
    out[7], out[8], out[9] = d[:, 0], d[:, 1], d[:, 3]
    return True


_F8 = np.dtype(np.float64)


def _motion_object_layout(t: Table, motion, compact: bool) -> list:
    """The motion fields of every object (null where unknown: no track, no velocity yet, heading sigma
    unavailable, ...); compact: ``track_id``, the velocity and its covariance."""
    tid, m = motion
    tracked = tid >= 0
    rows = [m.v_east_mps, m.v_north_mps, m.cov_v_m2ps2[:, 0, 0], m.cov_v_m2ps2[:, 0, 1], m.cov_v_m2ps2[:, 1, 1]]
    if not compact:  # (a compact record formats only the five columns it writes)
        rows += [m.speed_mps, m.sigma_speed_mps, m.heading_deg, m.sigma_heading_deg, m.yaw_deg, m.sigma_yaw_deg,
                 m.age_s]
    ve, vn, c00, c01, c11, *more = t.columns(np.array(rows))
    layout = [b',"track_id":', t.when(tracked, t.column(tid)), t.when(~tracked, b"null"),
              b',"v_east_mps":', ve, b',"v_north_mps":', vn, b',"cov_v_m2ps2":[[', c00, b",", c01, b"],[",
              c01, b",", c11, b"]]"]
    if not compact:
        sp, ssp, hd, shd, yw, syw, age = more
        layout += [b',"speed_mps":', sp, b',"sigma_speed_mps":', ssp, b',"heading_deg":', hd,
                   b',"sigma_heading_deg":', shd, b',"yaw_deg":', yw, b',"sigma_yaw_deg":', syw, b',"age_s":', age]
    return layout


def _message_id_layout(t: Table, setup: CameraSetup, ids: list, valid: np.ndarray, ts: float) -> tuple:
    """``(ok_idx, msg_ids, layout)``: the objects in the messages (with a centre, at most 255), their message ids
    (stable per object_id) and the ``message_object_id`` field (null: not in the CPM / SDSM)."""
    N = len(ids)
    ok_idx = np.flatnonzero(valid)[:MAX_MESSAGE_OBJECTS]  # a CPM carries at most 255 perceived objects
    msg_ids = setup.ids.assign(ids, ok_idx, ts)
    if len(ok_idx) == N:
        return ok_idx, msg_ids, [b',"message_object_id":', t.column(msg_ids)]
    col = np.zeros(N, np.int64)
    col[ok_idx] = msg_ids
    sent = np.zeros(N, bool)
    sent[ok_idx] = True
    return ok_idx, msg_ids, [b',"message_object_id":', t.when(sent, t.column(col)), t.when(~sent, b"null")]


def _motion_layout(t: Table, mc) -> tuple[list, list]:
    """The CPM JSON pieces of ``velocity`` and ``angles`` (after the position) and of ``objectAge`` (after the
    correlation matrix) of :class:`~.messages.motion.MotionCodes` (none without motion)."""
    if mc is None:
        return [], []
    vx, vxc, vy, vyc, z, zc, age = t.columns(np.array([mc.vx, mc.vx_conf, mc.vy, mc.vy_conf, mc.yaw, mc.yaw_conf,
                                                        mc.age_ms], dtype=np.int64))
    vel = [t.when(mc.has_velocity, b',"velocity":{"cartesianVelocity":{"xVelocity":{"value":', vx,
                  b',"confidence":', vxc, b'},"yVelocity":{"value":', vy, b',"confidence":', vyc, b"}}}"),
           t.when(mc.has_yaw, b',"angles":{"zAngle":{"value":', z, b',"confidence":', zc, b"}}")]
    return vel, [t.when(mc.has_age, b',"objectAge":', age)]


def _splice(doc: bytes, empty_list: bytes, items) -> tuple:
    """``doc`` with its (only) ``"key":[]`` replaced by ``"key":<items>``, as three pieces for the record's one
    final join (``items``: bytes or :meth:`.jsonrows.Table.json_buffer`'s array)."""
    i = doc.rindex(empty_list) + len(empty_list) - 2
    return doc[:i], items, doc[i + 2:]


def _v2x_source_layout(t: Table, est, cxx, cxy, cyy) -> list:
    """``v2x_source`` and ``v2x_cov_m2`` of every object: which covariance its V2X fields encode (the policy of
    docs/uncertainty-model.md) -- ``cov_m2`` itself ("linear"), a sampled one ("sampled") or none ("unavailable",
    null) -- so that every CPM / J2735 field is ``footprint_uq.products.v2x`` of a covariance in the record."""
    src = est.v2x_source
    names = _V2X_SOURCE_NAMES[src]
    if est.v2x_cov_m2 is not None:
        c = est.v2x_cov_m2
        cxx, cxy, cyy = t.columns(np.array([c[:, 0, 0], c[:, 0, 1], c[:, 1, 1]]))
    has = src != _V2X_UNAVAILABLE
    return [b',"v2x_source":', t.column(names.tolist()), b',"v2x_cov_m2":',
            t.when(has, b"[[", cxx, b",", cxy, b"],[", cxy, b",", cyy, b"]]"), t.when(~has, b"null")]


def _class_rows():
    """The distinct (CPM class spec, SDSM objType) of the detector classes, and lower-case class -> row."""
    results, row_of = [], {}

    def row(spec, sdsm):
        key = (spec, sdsm)
        if key not in results:
            results.append(key)
        return results.index(key)

    default = row(None, "unknown")
    for low in sorted(set(CPM_CLASS_OF) | set(SDSM_OBJECT_TYPES)):
        row_of[low] = row(CPM_CLASS_OF.get(low), SDSM_OBJECT_TYPES.get(low, "unknown"))
    return results, row_of, default


_CLASS_RESULTS, _ROW_OF_LOWER, _DEFAULT_CLASS_ROW = _class_rows()
_SDSM_TYPE = np.array([t for _, t in _CLASS_RESULTS], dtype=object)
_POS_NAMES = np.array(J2735_POSITION_CONFIDENCE_NAMES, dtype=object)


class _ClassTables(NamedTuple):
    """Per row of the class tables, in one CDD release: the CPM ObjectClass (JSON; None: no classification) and
    its class bits for the UPER writer (width 0: none)."""

    object_json: np.ndarray
    bits_value: np.ndarray
    bits_width: np.ndarray


@functools.cache
def _class_tables(cdd: str) -> _ClassTables:
    objs = [None if spec is None else object_class_json(spec, cdd) for spec, _ in _CLASS_RESULTS]
    bits = [(0, 0) if o is None else class_bits(o, cdd) for o in objs]
    return _ClassTables(np.array(objs, dtype=object), np.array([v for v, _ in bits], dtype=np.int64),
                        np.array([w for _, w in bits], dtype=np.int64))


class _ClassRowCache(dict):
    """Detector class (str or None) -> row of the class tables; remembers at most 4096 class strings."""

    def __missing__(self, c):
        r = _ROW_OF_LOWER.get(c.lower(), _DEFAULT_CLASS_ROW) if c else _DEFAULT_CLASS_ROW
        if len(self) < 4096:
            self[c] = r
        return r


_CLASS_ROWS = _ClassRowCache()
_CLASS_ROW_ARRAYS: dict = {}


def _class_rows_of(classes: list) -> np.ndarray:
    """The class-table rows (int64) of a frame's distinct ``classes`` (str or None), kept for the next frames
    (at most 256 class lists: a detector's frames repeat a few)."""
    key = tuple(classes)
    rows = _CLASS_ROW_ARRAYS.get(key)
    if rows is None:
        rows = np.array([_CLASS_ROWS[c] for c in classes], np.int64)
        if len(_CLASS_ROW_ARRAYS) >= 256:
            _CLASS_ROW_ARRAYS.clear()
        _CLASS_ROW_ARRAYS[key] = rows
    return rows
_CORR_OPEN = b',"lowerTriangularCorrelationMatrices":[{"componentsIncludedIntheMatrix":["xPosition","yPosition"],' \
             b'"matrix":[['
_CORR_CLOSE = b"]]}]"
_SDSM_AFTER_ID = b',"measurementTime":0,"timeConfidence":"unavailable","pos":{"offsetX":'
_SDSM_TAIL_NO_MOTION = (b',"elevation":"unavailable"},"speed":%d,"speedConfidence":"unavailable","heading":%d,'
                        b'"headingConf":"unavailable"}}' % (SDSM_SPEED_UNAVAILABLE, SDSM_HEADING_UNAVAILABLE))
_SDSM_SPEED = b',"elevation":"unavailable"},"speed":'
_SPEED_CONF = np.array(SPEED_CONFIDENCE_NAMES, dtype=object)
_HEADING_CONF = np.array(HEADING_CONFIDENCE_NAMES, dtype=object)
_V2X_SOURCE_NAMES = np.array(["linear", "sampled", "unavailable"], dtype=object)  # FootprintEstimate.v2x_source
_V2X_UNAVAILABLE = 2
_STATUS_ALL_OK = b',"status":%s,"reason":"ok"' % orjson.dumps(S.STATUS_OK)
_STATUS_ALL_OK_COMPACT = b',"status":%s' % orjson.dumps(S.STATUS_OK)
_INT_ONLY = {int}  # (bool is not int here: type() is exact)
_V2X_KEYS = [b',"%s":' % k.encode() for k in V2X_FIELDS]
def _jsonable(v):
    return v if v is None or isinstance(v, (str, int, float, bool)) else repr(v)
