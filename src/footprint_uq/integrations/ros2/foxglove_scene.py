"""One frame's footprints (and the camera) as a Foxglove ``SceneUpdate`` (foxglove-sdk's schema, protobuf).

Foxglove's 3D panel draws SceneUpdate entities without a plugin.  Per frame one SceneUpdate: a deletion of
every earlier entity (type ALL, at the frame's time), then

* per object an entity ``object/<index>`` (metadata ``object_id``, ``class``): a flat cylinder, the
  :data:`~.messages.ELLIPSE_CONFIDENCE` ellipse (size = the full axes ``2 * ellipse_axes(cov, 0.95)``, yaw = the
  major axis' ``orientation_deg``), and a billboard text with the object id 1.5 m above the ground;
* with a camera, an entity ``camera``: an arrow from the camera centre along its boresight, the image's
  frustum as lines to 2 m along the boresight (pinhole ``K``; the lens distortion is not drawn) and the label
  "camera".

Every entity is in ``frame_id`` (the world frame W, ENU, like the ROS messages) at the frame's time.
"""

from __future__ import annotations

import functools

import numpy as np

from ...errors import ConfigError
from ...uncertainty.ellipse import ellipse_axes
from .messages import DISC_HEIGHT_M, ELLIPSE_CONFIDENCE, LABEL_HEIGHT_M, FrameFootprints, yaw_quaternion
from .types import EXTRA

__all__ = ["scene_schema", "scene_update", "camera_entity", "quaternion_x_to"]

#: depth of the drawn frustum (m)
FRUSTUM_DEPTH_M = 2.0
_ORANGE = (1.0, 0.55, 0.0, 0.5)
_WHITE = (1.0, 1.0, 1.0, 1.0)
_CYAN = (0.2, 0.8, 1.0, 1.0)


@functools.cache
def _fm():
    """foxglove-sdk's message classes (``foxglove.messages``; the optional extra ``ros``)."""
    try:
        from foxglove import messages
    except ImportError as e:
        raise ConfigError("--foxglove", f"{e.name} not installed", EXTRA) from None
    return messages


def scene_schema():
    """foxglove-sdk's schema of the messages (name ``foxglove.SceneUpdate``, encoding ``protobuf``)."""
    return _fm().SceneUpdate.get_schema()


def _color(rgba):
    return _fm().Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _timestamp(stamp_ns: int):
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return _fm().Timestamp(sec=sec, nsec=nsec)


def _pose(xyz, q=(0.0, 0.0, 0.0, 1.0)):
    fm = _fm()
    return fm.Pose(position=fm.Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                   orientation=fm.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def quaternion_x_to(direction) -> np.ndarray:
    """The quaternion (x, y, z, w) of the shortest rotation taking +x onto ``direction`` (3,) (any length > 0)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    x = np.array([1.0, 0.0, 0.0])
    c = float(x @ d)
    if c < -1.0 + 1e-12:  # opposite: half a turn about z
        return np.array([0.0, 0.0, 1.0, 0.0])
    v = np.cross(x, d)
    q = np.array([v[0], v[1], v[2], 1.0 + c])
    return q / np.linalg.norm(q)


def camera_entity(camera, stamp_ns: int, frame_id: str):
    """The camera as an entity ``camera`` (a ``SceneEntity``): boresight arrow, frustum lines (pinhole K), label."""
    fm = _fm()
    T = np.asarray(camera.T_world_cam, dtype=np.float64)
    R, c = T[:3, :3], T[:3, 3]
    w, h = camera.image_size_px
    Kinv = np.linalg.inv(np.asarray(camera.K, dtype=np.float64))
    corners = np.array([[0.0, 0.0, 1.0], [w, 0.0, 1.0], [w, h, 1.0], [0.0, h, 1.0]]) @ Kinv.T
    far = c + (FRUSTUM_DEPTH_M * corners / corners[:, 2:3]) @ R.T
    pts = [fm.Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in np.vstack([c[None], far])]
    apex = pts[0]
    segs = [p for k in range(4) for p in (apex, pts[1 + k])] + \
           [p for k in range(4) for p in (pts[1 + k], pts[1 + (k + 1) % 4])]
    cyan = _color(_CYAN)
    arrow = fm.ArrowPrimitive(pose=_pose(c, quaternion_x_to(R[:, 2])), shaft_length=FRUSTUM_DEPTH_M,
                              shaft_diameter=0.05, head_length=0.3, head_diameter=0.15, color=cyan)
    lines = fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList, pose=_pose((0.0, 0.0, 0.0)), thickness=2.0,
                             scale_invariant=True, points=segs, color=cyan)
    text = fm.TextPrimitive(pose=_pose(c + np.array([0.0, 0.0, 0.5])), billboard=True, font_size=14.0,
                            scale_invariant=True, color=cyan, text="camera")
    return fm.SceneEntity(timestamp=_timestamp(stamp_ns), frame_id=frame_id, id="camera", arrows=[arrow],
                          lines=[lines], texts=[text])


def scene_update(f: FrameFootprints, camera=None):
    """The frame's ``SceneUpdate`` (module docstring: what it holds)."""
    fm = _fm()
    orange, white = _color(_ORANGE), _color(_WHITE)
    t = _timestamp(f.stamp_ns)
    a, b, ori = ellipse_axes(f.cov_m2, confidence=ELLIPSE_CONFIDENCE)
    q = yaw_quaternion(np.radians(ori))
    xy = np.asarray(f.xy_world_m, dtype=np.float64)
    z = f.ground_z_m
    entities = []
    for i in range(xy.shape[0]):
        cyl = fm.CylinderPrimitive(pose=_pose((xy[i, 0], xy[i, 1], z + 0.5 * DISC_HEIGHT_M), q[i]),
                                   size=fm.Vector3(x=2.0 * float(a[i]), y=2.0 * float(b[i]), z=DISC_HEIGHT_M),
                                   bottom_scale=1.0, top_scale=1.0, color=orange)
        text = fm.TextPrimitive(pose=_pose((xy[i, 0], xy[i, 1], z + LABEL_HEIGHT_M)), billboard=True,
                                font_size=14.0, scale_invariant=True, color=white, text=f.object_ids[i])
        entities.append(fm.SceneEntity(
            timestamp=t, frame_id=f.frame_id, id=f"object/{i}", cylinders=[cyl], texts=[text],
            metadata=[fm.KeyValuePair(key="object_id", value=f.object_ids[i]),
                      fm.KeyValuePair(key="class", value=f.classes[i])]))
    if camera is not None:
        entities.append(camera_entity(camera, f.stamp_ns, f.frame_id))
    return fm.SceneUpdate(deletions=[fm.SceneEntityDeletion(timestamp=t, type=fm.SceneEntityDeletionType.All)],
                          entities=entities)
