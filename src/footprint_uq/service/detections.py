"""A service frame's detections (a list of JSON objects) into columns, each bad detection its own error entry.

:func:`parse_detections` turns the ``detections`` list of one frame into :class:`FrameDetections`: the box
values ``(M, C)`` of the frame's box family, the detector's pixel covariances ``(M, 2, 2)``, the object ids,
classes and class confidences of the ``M`` good detections, their positions in the frame's list, and one
:class:`DetectionError` (index, field, reason) per bad detection.  One bad detection never costs the frame:
the others are processed and published, the bad one is named in the record's ``detection_errors``
(docs/service.md, "Bad detections").

The usual frame (every detection well-formed) is read field by field over all detections at C level
(``map`` over the dicts, one ``numpy.array`` per field) and checked on the set of its types; only a frame
with something wrong goes through the per-detection checks, which name the first bad field of each bad
detection.  The value checks the frame processor would make (box corners in order, 3-D sizes >= 0, pixel
covariances within :data:`~footprint_uq.products.detection_columns.MAX_PIXEL_VAR_PX2`) run here on the columns,
so that each bad box is found in one pass rather than by the processor's first-error exception; whether the
pixel covariances are positive semi-definite the processor checks in a compiled pass, and only a frame it
refuses gets :func:`check_values` (all of them at once).

The box family of a frame is that of its first detection with a complete box (2D, 3D or corners,
:mod:`footprint_uq.products.detection_columns`); a detection of another family, or with other columns (a 3-D
box with ``yaw_deg`` where the first has ``yaw_rad``, another corner count), is an error entry.

Integer class ids (YOLO / ultralytics ``cls``, COCO ``category_id``; an integral float such as ``2.0`` too)
are named through the service's names map (:class:`footprint_uq.io.class_names.ClassNames`, the one of the
batch too: ``serve --class-names coco|coco91|mot|FILE``); without a map the detection is an error entry, and so is
an id the map does not name unless the map's policy is ``unknown`` (``--unknown-class unknown``: the class
``"unknown"``) -- never a guessed class.
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass, field
from itertools import chain
from itertools import repeat as _repeat
from typing import NamedTuple

import numpy as np

from .._checks import cov2_faults
from ..errors import InputError
from ..io.class_names import ClassNames, class_id_of
from ..products.detection_columns import (
    BOX2D_COLUMNS,
    COV_COLUMNS,
    MAX_PIXEL_VAR_PX2,
    box_columns,
    detect_box_type,
)

__all__ = ["DetectionError", "FrameDetections", "FieldError", "parse_detections", "boxes2d_detections",
           "check_values", "finite_number", "NO_BOX_REASON"]

NO_BOX_REASON = ("no complete box: 2D (u_min_px, v_min_px, u_max_px, v_max_px), 3D (x_m, y_m, z_m, length_m, "
                 "width_m, height_m, yaw_rad|yaw_deg) or corners (u0_px, v0_px, ...), one family per frame")


class DetectionError(NamedTuple):
    """One bad detection of a frame: its position in the frame's list, the field and the one-line reason."""

    index: int
    #: e.g. ``"detections[3].u_max_px"``, or ``"detections[3]"`` for the detection as a whole
    field: str
    reason: str

    def as_dict(self) -> dict:
        return {"index": self.index, "field": self.field, "reason": self.reason}


class FieldError(Exception):
    """A field's fault: the field (``detections[3].u_max_px``, ``frame.timestamp_s``) and the one-line reason.  Inside
    this module the first fault of a detection (its error entry); :func:`finite_number` raises it for the frame's
    own fields too."""

    def __init__(self, field: str, reason: str):
        super().__init__(reason)
        self.field, self.reason = field, reason


@dataclass
class FrameDetections:
    """The good detections of one frame as columns, and the bad ones as error entries.

    Attributes
    ----------
    family : {"2d", "3d", "corners"} or None
        The frame's box family (None: no good detection).
    columns : tuple of str
        The box columns of ``boxes`` (:func:`~footprint_uq.products.detection_columns.box_columns`).
    boxes : ndarray (M, C)
        The box values (pixels, or metres and the yaw of 3-D boxes), finite.
    pixel_cov_px2 : ndarray (M, 2, 2) or None
        The detector's pixel covariance (zeros for detections without one); None when no detection has one.
    object_ids : list (M)
        ``object_id`` (int, str or None); absent: the detection's position in the frame's list.
    classes : list (M)
        The class name (str) or None; integer ids named through the names map.
    class_confidence : ndarray (M,) or None
        In [0, 1], NaN where absent; None when no detection has one.
    index : ndarray (M,) int64
        Position of each good detection in the frame's ``detections`` list.
    errors : list of DetectionError
        The bad detections, by position.
    int_ids : ndarray (M,) int64 or None
        ``object_ids`` as an array when the caller knows them all to be integers of 64 bits (the frame scanner's);
        None: not known (the record's writer then looks at the list).
    """

    family: str | None
    columns: tuple
    boxes: np.ndarray
    pixel_cov_px2: np.ndarray | None
    object_ids: list
    classes: list
    class_confidence: np.ndarray | None
    index: np.ndarray
    errors: list = field(default_factory=list)
    int_ids: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.object_ids)

    @property
    def yaw_rad(self) -> np.ndarray | None:
        """(M,) yaw of 3-D boxes in radians (None for other families)."""
        if self.family != "3d":
            return None
        yaw = self.boxes[:, 6]
        return yaw if self.columns[-1] == "yaw_rad" else np.deg2rad(yaw)

    def without(self, bad: np.ndarray, errors: list) -> FrameDetections:
        """These detections without the rows ``bad`` (bool (M,)), whose faults ``errors`` join the others."""
        keep = ~bad
        rows = np.flatnonzero(keep).tolist()
        return FrameDetections(
            self.family if rows else None, self.columns, self.boxes[keep],
            None if self.pixel_cov_px2 is None else self.pixel_cov_px2[keep], [self.object_ids[r] for r in rows],
            [self.classes[r] for r in rows],
            None if self.class_confidence is None else self.class_confidence[keep], self.index[keep],
            sorted(self.errors + errors), None if self.int_ids is None else self.int_ids[keep])


def parse_detections(dets: list, names: ClassNames | None = None) -> FrameDetections:
    """The ``detections`` list of a frame into :class:`FrameDetections` (see the module doc).

    Parameters
    ----------
    dets : list
        The frame's detections (JSON objects as dicts; anything else in the list is that entry's error).
    names : ClassNames, optional
        Integer class id -> name (without it an integer class is an error entry).
    """
    if not dets:
        return FrameDetections(None, (), np.zeros((0, 0)), None, [], [], None, np.zeros(0, np.int64))
    out = _fast(dets, names)
    if out is None:
        out = _slow(dets, names)
    return _value_checks(out)


def boxes2d_detections(boxes: np.ndarray, pixel_cov_px2: np.ndarray | None, object_ids: list, classes: list,
                       class_confidence: np.ndarray | None, int_ids: np.ndarray | None = None,
                       values_checked: bool = False) -> FrameDetections:
    """Well-formed 2-D box detections already in columns (:func:`.frame_scan.scan_frame`: every field of the
    right type, confidences in [0, 1]) into :class:`FrameDetections`, with :func:`parse_detections`' value checks
    (box corners in order, pixel covariances in range: each failing detection an error entry).

    Parameters
    ----------
    boxes : ndarray (M, 4)
        ``u_min_px, v_min_px, u_max_px, v_max_px``, finite.
    pixel_cov_px2 : ndarray (M, 2, 2) or None
    object_ids, classes : list (M)
    class_confidence : ndarray (M,) or None
        NaN where absent.
    int_ids : ndarray (M,) int64, optional
        ``object_ids`` as an array (every id an integer of 64 bits: the scanner's), kept in
        :attr:`FrameDetections.int_ids`.
    values_checked : bool
        The caller found every box's corners in order and every covariance entry in range already (the scanner's
        compiled pass): the value checks would mark nothing, and are skipped.
    """
    if len(object_ids) == 0:
        return FrameDetections(None, (), np.zeros((0, 0)), None, [], [], None, np.zeros(0, np.int64))
    found = FrameDetections("2d", BOX2D_COLUMNS, boxes, pixel_cov_px2, object_ids, classes, class_confidence,
                            np.arange(len(object_ids), dtype=np.int64), [], int_ids)
    return found if values_checked else _value_checks(found)


# -- the usual frame: one pass per field over all detections ---------------------------------------------------
def _fast(dets: list, names: ClassNames | None) -> FrameDetections | None:
    """Every detection well-formed: the columns in one pass per field; None at the first sign of a bad one."""
    N = len(dets)
    if set(map(type, dets)) != _DICT_ONLY:
        return None
    keys = set().union(*dets)
    ids = _fast_ids(dets, keys)
    classes = _fast_classes(dets, keys, names)
    if ids is None or classes is None:
        return None
    class_p = None
    if "class_confidence" in keys:
        class_p = _fast_confidences(dets)
        if class_p is None:
            return None
    family, cols = _family_of(dets[0])
    if family is None:
        return None
    if family == "corners" and any(_corner_keys(d) != set(cols) for d in dets):
        return None
    X = _fast_boxes(dets, cols)
    if X is None:
        return None
    P = None
    if not keys.isdisjoint(COV_COLUMNS):
        P = _fast_cov(dets)
        if P is None:
            return None
    return FrameDetections(family, cols, X, P, ids, classes, class_p, np.arange(N, dtype=np.int64))


def _family_of(d: dict) -> tuple:
    """``(family, columns)`` of a detection's keys (``(None, ())`` without a complete box), remembered for the
    4096 first key layouts (a detector writes one or two: no call per frame)."""
    key = tuple(d)
    got = _FAMILIES.get(key)
    if got is None:
        family = detect_box_type(key)
        got = (family, box_columns(family, key) if family is not None else ())
        if len(_FAMILIES) < 4096:
            _FAMILIES[key] = got
    return got


_FAMILIES: dict = {}


def _fast_ids(dets: list, keys: set) -> list | None:
    if "object_id" not in keys:
        return list(range(len(dets)))
    try:
        ids = list(map(_GET_ID, dets))
    except KeyError:  # some without: the detection's index; an explicit null stays None
        ids = [d.get("object_id", i) for i, d in enumerate(dets)]
    return ids if set(map(type, ids)) <= _ID_TYPES else None


def _fast_classes(dets: list, keys: set, names: ClassNames | None) -> list | None:
    if "class" not in keys:
        return [None] * len(dets)
    classes = list(map(dict.get, dets, _repeat("class")))
    types = set(map(type, classes))
    if types <= _CLASS_TYPES:
        return classes
    if names is None or not types <= _CLASS_OR_ID_TYPES:
        return None
    named = [names.name_of(c) if type(c) is int else c for c in classes]
    return None if any(n is None and c is not None for n, c in zip(named, classes, strict=True)) else named


def _fast_confidences(dets: list) -> np.ndarray | None:
    cc = list(map(dict.get, dets, _repeat("class_confidence")))
    if not set(map(type, cc)) <= _CONF_TYPES:
        return None
    try:
        p = np.array(cc, dtype=np.float64)
    except OverflowError:
        return None
    fin = np.isfinite(p)
    if int(fin.sum()) != len(cc) - cc.count(None) or ((p[fin] < 0.0) | (p[fin] > 1.0)).any():
        return None
    return p


def _fast_boxes(dets: list, cols) -> np.ndarray | None:
    try:
        flat = list(chain.from_iterable(map(operator.itemgetter(*cols), dets)))
        if set(map(type, flat)) <= _NUMBER_TYPES:
            X = np.array(flat, dtype=np.float64).reshape(len(dets), len(cols))
            if np.isfinite(X).all():
                return X
    except (KeyError, TypeError, OverflowError):
        pass
    return None


def _fast_cov(dets: list) -> np.ndarray | None:
    """(N, 2, 2) pixel covariances when every detection has all three numbers (finite), else None."""
    try:
        vals = list(map(_GET_COV, dets))
    except KeyError:
        return None
    if not set(map(type, chain.from_iterable(vals))) <= _NUMBER_TYPES:
        return None
    try:
        c = np.array(vals, dtype=np.float64)
    except OverflowError:
        return None
    if not np.isfinite(c).all():
        return None
    return c[:, [0, 1, 1, 2]].reshape(-1, 2, 2)


# -- a frame with something wrong: detection by detection --------------------------------------------------------
class _Row(NamedTuple):
    object_id: object
    cls: str | None
    confidence: float
    box: list
    cov: tuple | None


def _slow(dets: list, names: ClassNames | None) -> FrameDetections:
    """Each detection checked on its own; the frame's family is its first complete detection's."""
    family = cols = None
    for d in dets:
        if type(d) is dict and (family := detect_box_type(d.keys())) is not None:
            cols = box_columns(family, d.keys())
            break
    rows, index, errors = [], [], []
    for i, d in enumerate(dets):
        try:
            rows.append(_one(d, i, names, family, cols))
            index.append(i)
        except FieldError as e:
            errors.append(DetectionError(i, e.field, e.reason))
    M = len(rows)
    P = None
    if any(r.cov is not None for r in rows):
        P = np.zeros((M, 2, 2))
        for k, r in enumerate(rows):
            if r.cov is not None:
                uu, uv, vv = r.cov
                P[k] = ((uu, uv), (uv, vv))
    class_p = None
    if any(r.confidence == r.confidence for r in rows):  # (NaN: absent)
        class_p = np.array([r.confidence for r in rows], dtype=np.float64)
    boxes = np.array([r.box for r in rows], dtype=np.float64).reshape(M, len(cols or ()))
    return FrameDetections(family if M else None, cols or (), boxes, P, [r.object_id for r in rows],
                           [r.cls for r in rows], class_p, np.array(index, dtype=np.int64), errors)


def _one(d, i: int, names: ClassNames | None, family: str | None, cols) -> _Row:
    """Detection ``i`` checked: its fields, or :class:`FieldError` naming its first fault."""
    where = f"detections[{i}]"
    if type(d) is not dict:
        raise FieldError(where, f"detection {i} is not a JSON object")
    oid = _object_id(d.get("object_id", i), where)
    cls = _class(d.get("class"), where, names)
    p = d.get("class_confidence")
    if p is not None:
        p = finite_number(d, "class_confidence", where)
        if not 0.0 <= p <= 1.0:
            raise FieldError(f"{where}.class_confidence", f"class_confidence {p} not in [0, 1]")
    own = detect_box_type(d.keys())
    if own is None:
        raise FieldError(where, NO_BOX_REASON)
    if own != family:
        raise FieldError(where, f"detection {i} is a {own} box in a frame of {family} boxes (one family per frame: "
                                "the first complete detection's)")
    if family == "corners":
        _check_corners(d, i, cols)
    elif box_columns(family, d.keys()) != cols:
        raise FieldError(where, f"detection {i} gives its yaw as {box_columns(family, d.keys())[-1]}, the frame's "
                                f"first box as {cols[-1]}: one yaw column per frame")
    box = [finite_number(d, c, where) for c in cols]
    return _Row(oid, cls, math.nan if p is None else p, box, _cov(d, where))


def _object_id(oid, where: str):
    if type(oid) in _ID_TYPES:
        return oid
    if isinstance(oid, str):
        return str(oid)
    if isinstance(oid, (int, np.integer)) and not isinstance(oid, (bool, np.bool_)):
        return int(oid)  # numpy integers from embedding code: their Python value
    raise FieldError(f"{where}.object_id", f"object_id is not a string or integer: {oid!r}")


def _class(cls, where: str, names: ClassNames | None) -> str | None:
    if cls is None or type(cls) is str:
        return cls
    if isinstance(cls, str):
        return str(cls)
    cid = class_id_of(cls)
    if cid is None:
        raise FieldError(f"{where}.class", f"class is not a name or an integer class id: {cls!r}")
    if names is None:
        raise FieldError(f"{where}.class", f"class {cls!r} is an integer class id and the service has no names "
                                           "map (serve --class-names coco|FILE)")
    name, reason = names.lookup(cid)
    if name is None:
        raise FieldError(f"{where}.class", reason)
    return name


def finite_number(d: dict, key: str, where: str) -> float:
    """``d[key]`` as a finite float (bool is not a number); :class:`FieldError` ``<where>.<key>`` otherwise."""
    v = d.get(key)
    if v is None:
        raise FieldError(f"{where}.{key}", f"missing field {key}")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise FieldError(f"{where}.{key}", f"field {key} is not a number: {v!r}")
    if not math.isfinite(v):
        raise FieldError(f"{where}.{key}", f"field {key} is not finite: {v!r}")
    return float(v)


def _cov(d: dict, where: str) -> tuple | None:
    """All three covariance entries or none (absent or null)."""
    present = [c for c in COV_COLUMNS if d.get(c) is not None]
    if not present:
        return None
    if len(present) != 3:
        missing = next(c for c in COV_COLUMNS if c not in present)
        raise FieldError(f"{where}.{missing}", f"incomplete pixel covariance: {missing} missing (give cov_uu_px2, "
                                               "cov_uv_px2, cov_vv_px2 or none)")
    return tuple(finite_number(d, c, where) for c in COV_COLUMNS)


def _corner_keys(d: dict) -> set:
    return {k for k in d if _CORNER_KEY.match(k)}


def _check_corners(d: dict, i: int, cols) -> None:
    """Detection ``i`` of a corners frame has the corner columns of the first one (no more, no fewer)."""
    want, have = set(cols), _corner_keys(d)
    if have != want:
        extra = sorted(have - want)
        name = extra[0] if extra else sorted(want - have)[0]
        raise FieldError(f"detections[{i}].{name}", f"detection {i} has {len(have) // 2} corners ({len(have)} corner "
                                                    f"columns), the frame's first box has {len(want) // 2}: one corner "
                                                    "count per frame")


# -- the values the frame processor would refuse, every row at once -----------------------------------------------
def _value_checks(f: FrameDetections, psd: bool = False) -> FrameDetections:
    """Box corners in order (2D), sizes >= 0 (3D), pixel covariances in range (and, with ``psd``, positive
    semi-definite; the processor checks that itself in a compiled pass, :func:`check_values`): each failing
    detection an error entry (its first fault), found on the columns in one pass."""
    M = len(f)
    if M == 0:
        return f
    X, P = f.boxes, f.pixel_cov_px2
    if f.family == "2d" and not psd and not ((X[:, 0] > X[:, 2]) | (X[:, 1] > X[:, 3])).any() and \
            (P is None or not (np.abs(P) > MAX_PIXEL_VAR_PX2).any()):
        return f  # the usual frame: nothing to mark
    bad = np.zeros(M, bool)
    errors: list = []

    def mark(rows: np.ndarray, field_of, reason_of) -> None:
        for r in np.flatnonzero(rows & ~bad).tolist():
            i = int(f.index[r])
            errors.append(DetectionError(i, field_of(i, r), reason_of(r)))
        bad[rows] = True

    if f.family == "2d":
        mark((X[:, 0] > X[:, 2]) | (X[:, 1] > X[:, 3]), lambda i, r: f"detections[{i}]",
             lambda r: str(InputError(_EXPECT_2D_FIELD, X[r].tolist(), _EXPECT_2D)))
    elif f.family == "3d":
        mark((X[:, 3:6] < 0.0).any(axis=1), lambda i, r: f"detections[{i}]",
             lambda r: str(InputError("length_m, width_m, height_m", X[r, 3:6].tolist(), "sizes >= 0")))
    if P is not None:
        big = np.abs(P) > MAX_PIXEL_VAR_PX2
        first = np.array([0, 1, 2])[np.argmax(big.reshape(M, 4)[:, [0, 1, 3]], axis=1)]
        mark(big.any(axis=(1, 2)), lambda i, r: f"detections[{i}].{COV_COLUMNS[first[r]]}",
             lambda r: f"pixel covariance out of range: {COV_COLUMNS[first[r]]} "
                       f"{float(P[r].reshape(4)[[0, 1, 3][first[r]]]):g} (entries up to {MAX_PIXEL_VAR_PX2:g} px^2)")
        if psd:
            with np.errstate(invalid="ignore", over="ignore"):  # (entries beyond the limit: marked above already)
                _, neg, w_min = cov2_faults(P)
            mark(neg, lambda i, r: f"detections[{i}]",
                 lambda r: str(InputError("pixel covariance", f"min eigenvalue {w_min[r]:.3g}",
                                          "a positive semi-definite covariance matrix")))
    return f.without(bad, errors) if errors else f


def check_values(found: FrameDetections) -> FrameDetections:
    """Every value check of :func:`parse_detections` and the pixel covariances positive semi-definite, each
    failing detection an error entry: for a frame the processor refused (its own compiled check finds the first
    covariance that is not; this finds them all, so that the frame is run once more, not once per bad one)."""
    return _value_checks(found, psd=True)


_EXPECT_2D_FIELD = ", ".join(BOX2D_COLUMNS)
_EXPECT_2D = "u_min <= u_max and v_min <= v_max"
_CORNER_KEY = re.compile(r"^[uv]\d+_px$")
_DICT_ONLY = {dict}
_ID_TYPES = {int, str, type(None)}
_CLASS_TYPES = {str, type(None)}
_CLASS_OR_ID_TYPES = {str, int, type(None)}
_NUMBER_TYPES = {int, float}  # (bool is not int here: type() is exact)
_CONF_TYPES = {int, float, type(None)}
_GET_ID = operator.itemgetter("object_id")
_GET_COV = operator.itemgetter(*COV_COLUMNS)
