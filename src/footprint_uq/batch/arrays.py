"""Detections held in Python: a supervision ``Detections`` or plain ``(N, 4)`` xyxy arrays -> footprints.

:func:`detections_table` turns arrays (boxes, class ids or names, scores, track ids) into the canonical
detection table (:mod:`footprint_uq.batch.schema`) and the per-row errors; :func:`supervision_table` does
the same for a ``supervision.Detections`` (``xyxy``, ``confidence``, ``class_id``, ``tracker_id``,
``data["class_name"]``; read by attribute, so the ``supervision`` package is not imported here);
:func:`footprints_from_xyxy` and :func:`footprints_from_supervision` run the batch on them
(:func:`footprint_uq.batch.process.process_table`).

Class ids go through a names map (:class:`~footprint_uq.io.class_names.ClassNames`; default COCO's 80,
the map of a COCO-trained detector); an id without a name is that detection's error row (or the class
``"unknown"`` with ``unknown_class="unknown"``), never the frame's.  Boxes of detectors are continuous
coordinates in which the image spans ``[0, W]`` (``box_coordinates="image-edges"``, the default: shifted
by -0.5 px to the project's pixel centres, docs/conventions.md section 2); ``"pixel-centres"`` takes them
as they are.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from ..errors import InputError
from ..io.class_names import ClassNames
from . import schema as S
from .formats import EDGE_SHIFT_PX
from .process import process_table

__all__ = ["BOX_COORDINATES", "detections_table", "supervision_table", "footprints_from_xyxy",
           "footprints_from_supervision"]

BOX_COORDINATES = ("image-edges", "pixel-centres")


def _per_row(name: str, values, n: int, kind: str) -> np.ndarray | None:
    """``values`` as an ``(n,)`` array (None stays None); ``kind``: "int", "float" or "object"."""
    if values is None:
        return None
    a = np.asarray(values)
    if a.shape != (n,):
        raise InputError(name, f"shape {a.shape}", f"one value per box ({n},)")
    if kind == "int":
        if a.dtype.kind not in "iu":
            raise InputError(name, f"dtype {a.dtype}", "integer class ids")
        return a.astype(np.int64)
    if kind == "float":
        if a.dtype.kind not in "iuf":
            raise InputError(name, f"dtype {a.dtype}", "numbers")
        return a.astype(np.float64)
    return a.astype(object)


def detections_table(xyxy_px, *, class_id=None, class_name=None, class_names=None, unknown_class: str = "error",
                     score=None, object_id=None, frame=None, timestamp_s=None, camera_id=None,
                     box_coordinates: str = "image-edges") -> tuple[pa.Table, list | None]:
    """The canonical detection table of ``N`` boxes.

    Parameters
    ----------
    xyxy_px : (N, 4) float    boxes ``x_min, y_min, x_max, y_max`` in pixels
    class_id : (N,) int, optional        class ids, named through ``class_names``
    class_name : (N,) str, optional      class names (win over ``class_id`` where given)
    class_names : names map of the ids (:meth:`ClassNames.load`: ``"coco"`` (default), a file, a list, a mapping)
    unknown_class : ``"error"`` or ``"unknown"``: an id without a name
    score : (N,) float, optional         detector confidences
    object_id : (N,), optional           track ids (text in the table; None / negative: no id)
    frame : int, optional; timestamp_s : float, optional; camera_id : str, optional   the same for every row
    box_coordinates : ``"image-edges"`` (detectors: the image spans [0, W]) or ``"pixel-centres"``

    Returns
    -------
    table : pyarrow.Table    the id columns given and ``u_min_px, v_min_px, u_max_px, v_max_px``
    pre_errors : list (N,) of str or None, or None    the rows that are errors and why
    """
    box = np.asarray(xyxy_px, dtype=np.float64)
    if box.ndim != 2 or box.shape[1] != 4:
        raise InputError("xyxy_px", f"shape {box.shape}", "boxes of shape (N, 4): x_min, y_min, x_max, y_max")
    if box_coordinates not in BOX_COORDINATES:
        raise InputError("box_coordinates", box_coordinates, f"one of {BOX_COORDINATES}")
    n = box.shape[0]
    if box_coordinates == "image-edges":
        box = box - EDGE_SHIFT_PX
    cid = _per_row("class_id", class_id, n, "int")
    cname = _per_row("class_name", class_name, n, "object")
    cols: dict = {}
    pre: list = [None] * n
    if frame is not None:
        cols["frame"] = pa.array(np.full(n, int(frame), dtype=np.int64))
    if timestamp_s is not None:
        cols["timestamp_s"] = pa.array(np.full(n, float(timestamp_s)))
    if camera_id is not None:
        cols["camera_id"] = pa.array([str(camera_id)] * n, pa.string())
    oid = _per_row("object_id", object_id, n, "object")
    if oid is not None:
        cols["object_id"] = pa.array([_id_text(v) for v in oid], pa.string())
    if cid is not None or cname is not None:
        cols["class"] = pa.array(_classes(cid, cname, class_names, unknown_class, pre, n), pa.string())
    sc = _per_row("score", score, n, "float")
    if sc is not None:
        cols["score"] = pa.array(sc)
    for j, c in enumerate(S.BOX2D_COLUMNS):
        cols[c] = pa.array(box[:, j])
    return pa.table(cols), (pre if any(p is not None for p in pre) else None)


def _id_text(v) -> str | None:
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return None
    if isinstance(v, int | np.integer) and v < 0:
        return None
    return str(v.item() if hasattr(v, "item") else v)


def _classes(cid, cname, class_names, unknown_class, pre, n) -> list:
    names = ClassNames.load("coco" if class_names is None else class_names, unknown=unknown_class)
    out = []
    for i in range(n):
        given = None if cname is None else cname[i]
        if given is not None and str(given) != "":
            out.append(str(given))
            continue
        if cid is None:
            out.append(None)
            continue
        name, err = names.lookup(int(cid[i]))
        out.append(name)
        pre[i] = err
    return out


def supervision_table(detections, *, frame=None, timestamp_s=None, camera_id=None, class_names=None,
                      unknown_class: str = "error", box_coordinates: str = "image-edges"
                      ) -> tuple[pa.Table, list | None]:
    """:func:`detections_table` of a ``supervision.Detections`` (``xyxy``, ``confidence``, ``class_id``,
    ``tracker_id``, ``data["class_name"]``; any object with these attributes)."""
    try:
        xyxy = detections.xyxy
    except AttributeError:
        raise InputError("detections", type(detections).__name__, "a supervision Detections (xyxy, confidence, "
                         "class_id, tracker_id, data)") from None
    data = getattr(detections, "data", None) or {}
    return detections_table(xyxy, class_id=getattr(detections, "class_id", None), class_name=data.get("class_name"),
                            class_names=class_names, unknown_class=unknown_class,
                            score=getattr(detections, "confidence", None),
                            object_id=getattr(detections, "tracker_id", None), frame=frame, timestamp_s=timestamp_s,
                            camera_id=camera_id, box_coordinates=box_coordinates)


def footprints_from_xyxy(camera, budget, xyxy_px, *, class_id=None, class_name=None, class_names=None,
                         unknown_class: str = "error", score=None, object_id=None, frame=None, timestamp_s=None,
                         camera_id=None, box_coordinates: str = "image-edges", **options) -> pa.Table:
    """Footprints of ``(N, 4)`` xyxy boxes: :func:`detections_table`, then
    :func:`~footprint_uq.batch.process.process_table` (``**options``: its keyword arguments, e.g.
    ``confidence``, ``contact``).  One output row per box, in order; bad boxes are error rows."""
    table, pre = detections_table(xyxy_px, class_id=class_id, class_name=class_name, class_names=class_names,
                                  unknown_class=unknown_class, score=score, object_id=object_id, frame=frame,
                                  timestamp_s=timestamp_s, camera_id=camera_id, box_coordinates=box_coordinates)
    return process_table(camera, budget, table, pre_errors=pre, box_type="2d", **options)


def footprints_from_supervision(camera, budget, detections, *, frame=None, timestamp_s=None, camera_id=None,
                                class_names=None, unknown_class: str = "error",
                                box_coordinates: str = "image-edges", **options) -> pa.Table:
    """Footprints of a ``supervision.Detections`` (one frame): :func:`supervision_table`, then
    :func:`~footprint_uq.batch.process.process_table`.

    Examples
    --------
    >>> import supervision as sv
    >>> dets = sv.Detections.from_ultralytics(model(image)[0])
    >>> out = footprints_from_supervision(camera, "basler1", dets, frame=17, confidence=0.95)
    >>> out.select(["object_id", "class", "x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2"])
    """
    table, pre = supervision_table(detections, frame=frame, timestamp_s=timestamp_s, camera_id=camera_id,
                                   class_names=class_names, unknown_class=unknown_class,
                                   box_coordinates=box_coordinates)
    return process_table(camera, budget, table, pre_errors=pre, box_type="2d", **options)
