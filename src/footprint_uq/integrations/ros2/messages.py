"""One frame's footprints as ROS 2 messages: ``vision_msgs/msg/Detection3DArray`` and ``visualization_msgs/msg/
MarkerArray`` (rosbags message objects; :mod:`.bag_writer` serialises and records them).

Conventions (docs/integrations.md "ROS 2 bags and Foxglove", docs/conventions.md "ROS 2 messages"):

* ``header.frame_id`` is the world frame W (x east, y north, z up, metres: REP 103's ENU), by default ``"map"``
  (REP 105's world-fixed frame); ``header.stamp`` is ``timestamp_s`` (Unix time, UTC) in sec / nanosec;
* each object is one ``Detection3D``: ``id`` the object id, ``results[0].hypothesis`` its class and score,
  ``results[0].pose`` a ``geometry_msgs/PoseWithCovariance`` at the footprint centre ``(x_m, y_m, ground_z_m)``,
  identity orientation, whose 6x6 covariance (row-major, axes x, y, z, rotation about x, y, z) holds the
  footprint's 2x2 ``cov_m2`` in its x/y block and :data:`UNKNOWN_VARIANCE` on the four other diagonal
  entries (not estimated: "unknown" as REP 103/105 consumers read it, e.g. robot_localization), zeros
  elsewhere; ``bbox`` is centred on the same point with size 0 (a footprint has no box);
* the MarkerArray starts with a ``DELETEALL`` marker (no stale ellipse of an earlier frame), then per object a
  flat ``CYLINDER`` whose ``scale.x`` / ``scale.y`` are the full axes ``2 * ellipse_axes(cov, 0.95)`` and whose
  orientation turns x onto the major axis (yaw = ``orientation_deg``), and a ``TEXT_VIEW_FACING`` marker with
  the object id above it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...uncertainty.ellipse import ellipse_axes
from .types import zero_fields

__all__ = ["UNKNOWN_VARIANCE", "ELLIPSE_CONFIDENCE", "FrameFootprints", "pose_covariance_6x6", "stamp",
           "detection3d_array", "ellipse_marker_array", "yaw_quaternion"]

#: the variance (m^2 for z, rad^2 for the rotations) of the axes a ground footprint does not estimate
UNKNOWN_VARIANCE = 1.0e6
#: the probability of the ellipses drawn (MarkerArray, Foxglove scene)
ELLIPSE_CONFIDENCE = 0.95
#: thickness of the drawn ellipse discs (m) and height of the id labels above the ground (m)
DISC_HEIGHT_M = 0.05
LABEL_HEIGHT_M = 1.5


@dataclass
class FrameFootprints:
    """The footprints of one frame that have a centre (what the bag records).

    Attributes
    ----------
    stamp_ns : int                  header.stamp, ns since the Unix epoch
    frame_id : str                  the world frame's name (header.frame_id)
    object_ids : list of str, (n,)  Detection3D.id (the input's object_id, else the input row number)
    classes : list of str, (n,)     hypothesis.class_id ("" when the input has no class)
    scores : (n,) float64           hypothesis.score (NaN when the input has none)
    xy_world_m : (n, 2) float64     footprint centres in W
    cov_m2 : (n, 2, 2) float64      their covariances
    ground_z_m : float              the ground plane's height in W (z of the poses)
    """

    stamp_ns: int
    frame_id: str
    object_ids: list
    classes: list
    scores: np.ndarray
    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    ground_z_m: float = 0.0


def pose_covariance_6x6(cov_m2) -> np.ndarray:
    """``(..., 2, 2)`` ground covariances -> ``(..., 36)`` row-major PoseWithCovariance covariances (x, y block
    from ``cov_m2``; z and the three rotations :data:`UNKNOWN_VARIANCE`; zeros elsewhere)."""
    c = np.asarray(cov_m2, dtype=np.float64)
    out = np.zeros(c.shape[:-2] + (6, 6))
    out[..., :2, :2] = c
    for k in range(2, 6):
        out[..., k, k] = UNKNOWN_VARIANCE
    return out.reshape(c.shape[:-2] + (36,))


def stamp(ts, stamp_ns: int):
    """A ``builtin_interfaces/msg/Time`` of ``stamp_ns`` (>= 0)."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)


def yaw_quaternion(yaw_rad) -> np.ndarray:
    """``(...,)`` yaw (about +z, counter-clockwise from +x) -> ``(..., 4)`` quaternions (x, y, z, w)."""
    h = 0.5 * np.asarray(yaw_rad, dtype=np.float64)
    z = np.zeros_like(h)
    return np.stack([z, z, np.sin(h), np.cos(h)], axis=-1)


def _header(ts, f: FrameFootprints):
    return ts.types["std_msgs/msg/Header"](stamp=stamp(ts, f.stamp_ns), frame_id=f.frame_id)


def _pose(ts, x: float, y: float, z: float, q=(0.0, 0.0, 0.0, 1.0)):
    T = ts.types
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))


def detection3d_array(ts, f: FrameFootprints):
    """The frame's ``vision_msgs/msg/Detection3DArray`` (module docstring: what each field holds)."""
    T = ts.types
    header = _header(ts, f)
    cov36 = pose_covariance_6x6(f.cov_m2)
    xy = np.asarray(f.xy_world_m, dtype=np.float64).tolist()
    scores = np.asarray(f.scores, dtype=np.float64).tolist()
    size0 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    dets = []
    for i, (x, y) in enumerate(xy):
        pose = _pose(ts, x, y, f.ground_z_m)
        hyp = T["vision_msgs/msg/ObjectHypothesis"](class_id=f.classes[i], score=scores[i])
        res = T["vision_msgs/msg/ObjectHypothesisWithPose"](
            hypothesis=hyp, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36[i]))
        dets.append(T["vision_msgs/msg/Detection3D"](
            header=header, results=[res], bbox=T["vision_msgs/msg/BoundingBox3D"](center=pose, size=size0),
            id=f.object_ids[i]))
    return T["vision_msgs/msg/Detection3DArray"](header=header, detections=dets)


def ellipse_marker_array(ts, f: FrameFootprints, *, ns: str = "footprints"):
    """The frame's ``visualization_msgs/msg/MarkerArray``: DELETEALL, then per object a flat CYLINDER (the
    :data:`ELLIPSE_CONFIDENCE` ellipse: ``scale.x = 2 a``, ``scale.y = 2 b``, yaw = orientation) in namespace
    ``ns + "/ellipses"`` and a TEXT_VIEW_FACING label (the object id) in ``ns + "/ids"``; marker id = the
    object's index in the frame."""
    T = ts.types
    Marker = T["visualization_msgs/msg/Marker"]
    header = _header(ts, f)
    zero = zero_fields(ts, "visualization_msgs/msg/Marker")  # shared by this array's markers (never changed)
    markers = [Marker(**{**zero, "header": header, "ns": ns, "action": Marker.DELETEALL})]
    a, b, ori = ellipse_axes(f.cov_m2, confidence=ELLIPSE_CONFIDENCE)
    q = yaw_quaternion(np.radians(ori)).tolist()
    a, b = a.tolist(), b.tolist()
    Vector3 = T["geometry_msgs/msg/Vector3"]
    label_scale = Vector3(x=0.0, y=0.0, z=0.8)
    xy = np.asarray(f.xy_world_m, dtype=np.float64).tolist()
    z = f.ground_z_m
    color = T["std_msgs/msg/ColorRGBA"](r=1.0, g=0.55, b=0.0, a=0.5)
    white = T["std_msgs/msg/ColorRGBA"](r=1.0, g=1.0, b=1.0, a=1.0)
    for i, (x, y) in enumerate(xy):
        markers.append(Marker(**{
            **zero, "header": header, "ns": f"{ns}/ellipses", "id": i, "type": Marker.CYLINDER, "action": Marker.ADD,
            "pose": _pose(ts, x, y, z + 0.5 * DISC_HEIGHT_M, q[i]),
            "scale": Vector3(x=2.0 * a[i], y=2.0 * b[i], z=DISC_HEIGHT_M), "color": color}))
        markers.append(Marker(**{
            **zero, "header": header, "ns": f"{ns}/ids", "id": i, "type": Marker.TEXT_VIEW_FACING,
            "action": Marker.ADD, "pose": _pose(ts, x, y, z + LABEL_HEIGHT_M), "scale": label_scale, "color": white,
            "text": f.object_ids[i]}))
    return T["visualization_msgs/msg/MarkerArray"](markers=markers)
