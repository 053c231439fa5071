"""CARLA interoperability: coordinate conventions, cameras, 3-D boxes and recordings.

Pure numpy: nothing here imports ``carla`` (the tests compare against the real package
where it is installed; :mod:`footprint_uq.cli.carla` uses it to capture).

Conventions
-----------
CARLA (Unreal Engine) world: **left-handed**, x forward, y right, z up, metres.  Seen
from above with x pointing east, CARLA's y points *south*.  Our world frame W is
right-handed x east, y north, z up (``docs/conventions.md``), so::

    xyz_W = (x_carla, -y_carla, z_carla)          (S = diag(1, -1, 1), its own inverse)

``carla.Rotation(pitch, yaw, roll)`` in degrees; the local-to-world rotation is CARLA's
``Transform.get_matrix()`` (:func:`carla_rotation_matrix`): yaw about z (from x towards y,
i.e. clockwise seen from above), pitch positive nose-up, roll about the forward axis.
An actor's local frame is x forward, y right, z up.  A camera sensor looks along its
local +x; the OpenCV camera frame (x right, y down, z forward) is
``(y_local, -z_local, x_local)``.  Intrinsics of CARLA's pinhole camera:
``f = w / (2 tan(fov / 2))`` (fov = horizontal field of view), principal point
``(w / 2, h / 2)``, square pixels, no distortion (:func:`carla_intrinsics`).

So the standard CARLA recipe (``world_2_camera = inverse(camera transform)``, axis swap
``(x, y, z) -> (y, -z, x)``, ``K`` from the fov) and our camera model agree exactly when
the camera is built by :func:`camera_from_carla` (tested against ``carla``).

Boxes: a CARLA vehicle has a transform (location, rotation) and ``bounding_box`` with
``location`` (offset in the actor frame), ``extent`` (half sizes) and ``rotation``.  Our
3-D box ``(x, y, z, length, width, height, yaw_rad)`` (W, yaw counter-clockwise from
east) is the box centre converted to W, the full sizes ``2 * extent`` and
``yaw_rad = -radians(actor yaw + box yaw)`` (:func:`box_from_carla`).  Vehicle pitch and
roll are dropped (flat ground, as in the paper's model).

Recordings: JSON Lines, documented in ``docs/carla-recording.md``; written by
:func:`write_recording` (from a :class:`~footprint_uq.scenario.case_study.Scene` or by
``footprint-uq carla capture``) and read back into a Scene by :func:`read_recording`.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..._checks import as_float, as_points
from ...cameras.pantilt import PanTiltCamera
from ...cameras.rotation import pan_tilt_roll_from_R_W_C
from ...errors import ConfigError, InputError
from ...io.atomic import atomic_path
from ...scenario.case_study import Scene
from ...scenario.intersection import Marking, RoadLayout
from ...scenario.trajectory import segment_labels

__all__ = [
    "S_WORLD_CARLA", "A_LOCAL_CV", "RECORDING_FORMAT", "RECORDING_VERSION", "carla_rotation_matrix",
    "carla_transform_matrix", "rotation_from_matrix", "carla_to_world", "world_to_carla", "carla_intrinsics",
    "carla_recipe_project", "camera_from_carla", "camera_to_carla", "box_from_carla", "box_to_carla",
    "write_recording", "read_recording", "scene_to_recording",
]

#: CARLA world -> W (and back): flip y
S_WORLD_CARLA = np.diag([1.0, -1.0, 1.0])
#: OpenCV camera frame -> CARLA actor local frame: local = A @ cv
A_LOCAL_CV = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
RECORDING_FORMAT = "footprint-uq/carla-recording"
RECORDING_VERSION = 1


# -- rotations and transforms --------------------------------------------------------------------
def carla_rotation_matrix(pitch_deg, yaw_deg, roll_deg):
    """CARLA's local -> world rotation ``(..., 3, 3)`` (the 3x3 block of ``Transform.get_matrix()``)."""
    p, y, r = np.broadcast_arrays(*(np.deg2rad(np.asarray(a, dtype=np.float64)) for a in (pitch_deg, yaw_deg,
                                                                                            roll_deg)))
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    row0 = np.stack([cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr], -1)
    row1 = np.stack([cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr], -1)
    row2 = np.stack([sp, -cp * sr, cp * cr], -1)
    return np.stack([row0, row1, row2], -2)


def carla_transform_matrix(location_m, rotation_deg) -> np.ndarray:
    """4x4 local -> CARLA-world matrix ``(..., 4, 4)`` of ``location (x, y, z)`` and ``rotation (pitch, yaw, roll)``."""
    loc = as_points("location_m", location_m, 3)
    rot = as_points("rotation_deg", rotation_deg, 3)
    R = carla_rotation_matrix(rot[..., 0], rot[..., 1], rot[..., 2])
    lead = np.broadcast_shapes(loc.shape[:-1], R.shape[:-2])
    T = np.zeros(lead + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = loc
    T[..., 3, 3] = 1.0
    return T


def rotation_from_matrix(R) -> np.ndarray:
    """``(pitch, yaw, roll)`` degrees ``(..., 3)`` of a CARLA local -> world rotation (inverse of
    :func:`carla_rotation_matrix`; at pitch = +-90 deg the roll is set to 0)."""
    R = np.asarray(R, dtype=np.float64)
    sp = np.clip(R[..., 2, 0], -1.0, 1.0)
    pitch = np.arcsin(sp)
    gimbal = np.abs(sp) > 1.0 - 1e-12
    yaw = np.where(gimbal, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    roll = np.where(gimbal, 0.0, np.arctan2(-R[..., 2, 1], R[..., 2, 2]))
    return np.rad2deg(np.stack([pitch, yaw, roll], -1))


def carla_to_world(xyz_carla) -> np.ndarray:
    """CARLA world points ``(..., 3)`` -> W (x east, y north, z up)."""
    return as_points("xyz_carla", xyz_carla, 3) * np.array([1.0, -1.0, 1.0])


def world_to_carla(xyz_world_m) -> np.ndarray:
    """W points ``(..., 3)`` -> CARLA world."""
    return as_points("xyz_world_m", xyz_world_m, 3) * np.array([1.0, -1.0, 1.0])


def carla_intrinsics(image_size_px, fov_deg) -> np.ndarray:
    """CARLA camera matrix K (3, 3): ``f = w / (2 tan(fov/2))``, principal point ``(w/2, h/2)``."""
    w, h = _image_size(image_size_px)
    fov = as_float("fov_deg", fov_deg)
    if not 0 < fov < 180:
        raise InputError("fov_deg", fov_deg, "a horizontal field of view in (0, 180) degrees")
    f = w / (2.0 * np.tan(np.deg2rad(fov) / 2.0))
    return np.array([[f, 0.0, w / 2.0], [0.0, f, h / 2.0], [0.0, 0.0, 1.0]])


def _image_size(image_size_px) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in image_size_px)
    except (TypeError, ValueError):
        raise InputError("image_size_px", image_size_px, "[width, height] in pixels") from None
    if w <= 0 or h <= 0:
        raise InputError("image_size_px", image_size_px, "two positive integers [width, height]")
    return w, h


def carla_recipe_project(points_carla, location_m, rotation_deg, image_size_px, fov_deg,
                         world_2_camera=None) -> tuple[np.ndarray, np.ndarray]:
    """The standard CARLA projection recipe, in numpy: ``(uv_px (..., 2), depth_m (...))``.

    ``world_2_camera`` = inverse of the camera's transform (pass CARLA's own
    ``get_inverse_matrix()`` to test against it; default: computed here), then the axis swap
    ``(x, y, z) -> (y, -z, x)`` and ``K`` from the fov.  ``depth_m`` is the distance along the
    boresight (points with depth <= 0 are behind the camera).
    """
    X = as_points("points_carla", points_carla, 3)
    if world_2_camera is None:
        world_2_camera = np.linalg.inv(carla_transform_matrix(location_m, rotation_deg))
    M = np.asarray(world_2_camera, dtype=np.float64)
    pc = X @ M[:3, :3].T + M[:3, 3]
    cv = np.stack([pc[..., 1], -pc[..., 2], pc[..., 0]], -1)
    K = carla_intrinsics(image_size_px, fov_deg)
    q = cv @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = q[..., :2] / q[..., 2:3]
    return uv, cv[..., 2]


# -- cameras ----------------------------------------------------------------------------------------
def camera_from_carla(location_m, rotation_deg, image_size_px, fov_deg, *, ground_z_m: float = 0.0) -> PanTiltCamera:
    """Our camera for a CARLA camera sensor.

    Parameters
    ----------
    location_m : (x, y, z) CARLA world, metres
    rotation_deg : (pitch, yaw, roll) CARLA, degrees
    image_size_px : (image_size_x, image_size_y)
    fov_deg : float  the sensor's ``fov`` attribute (horizontal)
    ground_z_m : float  CARLA z of the (flat) ground

    Returns
    -------
    PanTiltCamera
        Height ``z - ground_z_m``, pan/tilt/roll of the same rotation, principal point
        ``(w/2, h/2)``, ``ground_z_m`` set, so ``camera.project(carla_to_world(X))`` equals
        :func:`carla_recipe_project` for every CARLA point ``X``.
    """
    loc = np.asarray(as_points("location_m", location_m, 3), dtype=np.float64).reshape(3)
    rot = np.asarray(as_points("rotation_deg", rotation_deg, 3), dtype=np.float64).reshape(3)
    w, h = _image_size(image_size_px)
    K = carla_intrinsics((w, h), fov_deg)
    gz = as_float("ground_z_m", ground_z_m)
    R_W_C = S_WORLD_CARLA @ carla_rotation_matrix(*rot) @ A_LOCAL_CV
    pan, tilt, roll = (float(np.rad2deg(a)) for a in pan_tilt_roll_from_R_W_C(R_W_C))
    height = loc[2] - gz
    if not height > 0:
        raise InputError("location_m[2]", float(loc[2]), f"a camera above the ground (ground_z_m = {gz})")
    return PanTiltCamera(K[0, 0], (w, h), height, pan, tilt, roll, position_m=(loc[0], -loc[1]),
                         principal_point_px=(K[0, 2], K[1, 2]), ground_z_m=gz)


def camera_to_carla(camera) -> dict:
    """CARLA placement of one of our cameras: ``{"location": {x,y,z}, "rotation": {pitch,yaw,roll},
    "attributes": {image_size_x, image_size_y, fov}}``.

    CARLA cameras have square pixels, a centred principal point and no distortion; other
    cameras raise :class:`~footprint_uq.errors.InputError`.
    """
    K = camera.K
    w, h = camera.image_size_px
    if abs(K[0, 0] - K[1, 1]) > 1e-9 * K[0, 0] or abs(K[0, 1]) > 1e-12:
        raise InputError("camera K", K.tolist(), "square pixels (fx = fy, no skew) to be placed in CARLA")
    if abs(K[0, 2] - w / 2) > 1e-6 or abs(K[1, 2] - h / 2) > 1e-6:
        raise InputError("camera principal_point_px", (K[0, 2], K[1, 2]),
                         f"the image centre ({w / 2}, {h / 2}) to be placed in CARLA")
    if np.any(camera.dist != 0):
        raise InputError("camera distortion", camera.dist.tolist(), "no distortion to be placed in CARLA")
    M = S_WORLD_CARLA @ camera.R_world_cam @ A_LOCAL_CV.T
    pitch, yaw, roll = (float(v) for v in rotation_from_matrix(M))
    x, y, z = (float(v) for v in world_to_carla(camera.position_world_m))
    fov = float(np.rad2deg(2.0 * np.arctan(w / (2.0 * K[0, 0]))))
    return {"location": {"x": x, "y": y, "z": z}, "rotation": {"pitch": pitch, "yaw": yaw, "roll": roll},
            "attributes": {"image_size_x": int(w), "image_size_y": int(h), "fov": fov}}


# -- boxes -----------------------------------------------------------------------------------------------
def box_from_carla(actor_location_m, actor_rotation_deg, bb_location_m, bb_extent_m, bb_rotation_deg=(0, 0, 0)):
    """Our 3-D boxes ``(..., 7)`` from CARLA actor transforms and bounding boxes (see module doc)."""
    loc = as_points("actor_location_m", actor_location_m, 3)
    rot = as_points("actor_rotation_deg", actor_rotation_deg, 3)
    bl = as_points("bb_location_m", bb_location_m, 3)
    ext = as_points("bb_extent_m", bb_extent_m, 3)
    br = as_points("bb_rotation_deg", bb_rotation_deg, 3)
    if np.any(ext < 0):
        raise InputError("bb_extent_m", ext.tolist(), "half sizes >= 0")
    R = carla_rotation_matrix(rot[..., 0], rot[..., 1], rot[..., 2])
    centre = np.einsum("...ij,...j->...i", R, bl) + loc
    c = carla_to_world(centre)
    yaw = -np.deg2rad(rot[..., 1] + br[..., 1])
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    lead = np.broadcast_shapes(c.shape[:-1], ext.shape[:-1], yaw.shape)
    return np.concatenate([np.broadcast_to(c, lead + (3,)), np.broadcast_to(2 * ext, lead + (3,)),
                           np.broadcast_to(yaw, lead)[..., None]], -1)


def box_to_carla(boxes_world) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`box_from_carla` for a box at the actor origin:
    ``(actor_location (..., 3), actor_rotation (..., 3), extent (..., 3))``, box offset 0."""
    b = as_points("boxes_world", boxes_world, 7)
    loc = world_to_carla(b[..., :3])
    yaw = -np.rad2deg(b[..., 6])
    rot = np.stack([np.zeros_like(yaw), yaw, np.zeros_like(yaw)], -1)
    return loc, rot, b[..., 3:6] / 2


# -- recordings --------------------------------------------------------------------------------------------
def _vec(d, keys, where):
    try:
        return [float(d[k]) for k in keys]
    except (KeyError, TypeError, ValueError):
        raise ConfigError(where, d, f"a mapping with numeric {', '.join(keys)}") from None


def _xy_to_carla(xy):
    a = np.asarray(xy, dtype=np.float64)
    return np.stack([a[..., 0], -a[..., 1]], -1)


def write_recording(path, *, cameras: dict, frames, layout=None, header: dict | None = None) -> Path:
    """Write a recording (JSON Lines, CARLA coordinates; ``docs/carla-recording.md``).

    Parameters
    ----------
    path : str or Path
    cameras : dict name -> camera record ``{"transform": {...}, "attributes": {...}}`` or one of our
        cameras (converted with :func:`camera_to_carla`)
    frames : iterable of dict ``{"frame", "timestamp_s", "actors": [actor records], optional "segment"}``
    layout : RoadLayout, optional  (written in CARLA coordinates)
    header : dict, optional  extra header fields (``source``, ``map``, ``ego_actor_id``, ``ground_z_m``, ...)
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    head = {"type": "header", "format": RECORDING_FORMAT, "version": RECORDING_VERSION, "coordinates": "carla",
            "units": {"length": "m", "angle": "deg", "time": "s"}}
    head.update(header or {})
    with atomic_path(p) as tmp, tmp.open("w", encoding="utf-8") as f:
        f.write(json.dumps(head) + "\n")
        for name, cam in cameras.items():
            rec = cam if isinstance(cam, dict) else camera_to_carla(cam)
            out = {"type": "camera", "name": str(name),
                   "transform": rec.get("transform") or {"location": rec["location"], "rotation": rec["rotation"]},
                   "attributes": rec["attributes"]}
            if rec.get("description"):
                out["description"] = rec["description"]
            f.write(json.dumps(out) + "\n")
        if layout is not None:
            road = {"type": "road", "lane_width_m": layout.lane_width_m,
                    "road_polygons": [_xy_to_carla(pg).tolist() for pg in layout.road_polygons],
                    "markings": [{"kind": m.kind, "points": _xy_to_carla(m.xy_world_m).tolist(), "dashed": m.dashed,
                                  "width_m": m.width_m} for m in layout.markings]}
            if layout.junction_box_m is not None:
                x0, y0, x1, y1 = layout.junction_box_m
                road["junction_box"] = [x0, -y1, x1, -y0]
            f.write(json.dumps(road) + "\n")
        for fr in frames:
            f.write(json.dumps({"type": "frame", **fr}) + "\n")
    return p


def scene_to_recording(scene, path) -> Path:
    """Write a :class:`~footprint_uq.scenario.case_study.Scene` (one vehicle) as a recording."""
    loc, rot, ext = box_to_carla(scene.boxes_world)
    frames = []
    seg_names = ("entry", "turn", "exit")
    for i in range(len(scene)):
        frames.append({"frame": int(scene.frame[i]), "timestamp_s": float(scene.t_s[i]),
                       "segment": seg_names[int(scene.segment[i])],
                       "actors": [{"id": 1, "type_id": "vehicle.footprint_uq.box", "role": "ego",
                                   "transform": {"location": dict(zip("xyz", loc[i].tolist(), strict=True)),
                                                 "rotation": dict(zip(("pitch", "yaw", "roll"), rot[i].tolist(),
                                                                      strict=True))},
                                   "bounding_box": {"location": {"x": 0.0, "y": 0.0, "z": 0.0},
                                                    "extent": dict(zip("xyz", ext[i].tolist(), strict=True)),
                                                    "rotation": {"pitch": 0.0, "yaw": 0.0, "roll": 0.0}}}]})
    cams = {}
    for name, cam in scene.cameras.items():
        rec = camera_to_carla(cam)
        rec["description"] = scene.camera_settings.get(name, {}).get("description", "")
        cams[name] = rec
    gz = {float(c.ground_z_m) for c in scene.cameras.values()}
    return write_recording(path, cameras=cams, frames=frames, layout=scene.layout,
                           header={"source": scene.source, "ego_actor_id": 1,
                                   "ground_z_m": gz.pop() if len(gz) == 1 else 0.0})


def _check_header(rec, kind, where: str) -> None:
    """A recording's first record must be its header, of this format and a version this reader knows."""
    if kind != "header" or rec.get("format") != RECORDING_FORMAT:
        raise ConfigError(where, kind, f"a header record with format {RECORDING_FORMAT!r}")
    if int(rec.get("version", 0)) > RECORDING_VERSION:
        raise ConfigError(f"{where}: version", rec.get("version"), f"<= {RECORDING_VERSION}")
    if rec.get("coordinates", "carla") != "carla":
        raise ConfigError(f"{where}: coordinates", rec.get("coordinates"), "'carla'")


def _read_records(p: Path) -> tuple[dict, dict, tuple | None, list]:
    """The records of a recording: ``(header, {camera: (rec, where)}, (road, where) or None, [(frame, where)])``."""
    header = None
    cams_raw: dict = {}
    road = None
    frames = []
    with p.open(encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            if not line.strip():
                continue
            where = f"{p.name}:{lineno}"
            try:
                rec = json.loads(line)
            except json.JSONDecodeError as e:
                if header is None:
                    raise ConfigError(where, line[:60], f"a JSON header record ({e.msg})") from None
                warnings.warn(f"{where}: not valid JSON ({e.msg}); line skipped", stacklevel=3)
                continue
            kind = rec.get("type") if isinstance(rec, dict) else None
            if header is None:
                _check_header(rec, kind, where)
                header = rec
            elif kind == "camera":
                name = str(rec.get("name", f"camera{len(cams_raw) + 1}"))
                if name in cams_raw:
                    raise ConfigError(f"{where}: name", name, "a unique camera name")
                cams_raw[name] = (rec, where)
            elif kind == "road":
                road = (rec, where)
            elif kind == "frame":
                frames.append((rec, where))
            else:
                warnings.warn(f"{where}: unknown record type {kind!r}; line skipped", stacklevel=3)
    if header is None:
        raise ConfigError(p.name, "empty file", "a recording starting with a header record")
    if not cams_raw:
        raise ConfigError(p.name, "no camera records", "at least one camera record")
    return header, cams_raw, road, frames


def _cameras_from_records(cams_raw: dict, gz: float) -> tuple[dict, dict]:
    """``({name: Camera}, {name: settings})`` from the camera records (ground at CARLA z ``gz`` m)."""
    cameras, settings = {}, {}
    for name, (rec, where) in cams_raw.items():
        tr = rec.get("transform") or {}
        at = rec.get("attributes") or {}
        loc = _vec(tr.get("location"), "xyz", f"{where}: transform.location")
        rot = _vec(tr.get("rotation"), ("pitch", "yaw", "roll"), f"{where}: transform.rotation")
        try:
            size = (int(at["image_size_x"]), int(at["image_size_y"]))
            fov = float(at["fov"])
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"{where}: attributes", at, "image_size_x, image_size_y and fov") from None
        cameras[name] = camera_from_carla(loc, rot, size, fov, ground_z_m=gz)
        settings[name] = {"description": rec.get("description", ""), "carla_location": loc, "carla_rotation": rot,
                          "fov_deg": fov}
    return cameras, settings


def _road_layout(road: tuple | None, header: dict) -> RoadLayout:
    """The road record as a :class:`RoadLayout` in W (empty layout if the recording has none)."""
    if road is None:
        return RoadLayout([], [], float(header.get("lane_width_m", 3.5)), None)
    rec, where = road
    try:
        return RoadLayout(
            [np.asarray(_xy_to_carla(np.asarray(pg, dtype=np.float64))) for pg in rec.get("road_polygons", [])],
            [Marking(str(m.get("kind", "lane")), _xy_to_carla(np.asarray(m["points"], dtype=np.float64)),
                     bool(m.get("dashed", False)), float(m.get("width_m", 0.15))) for m in rec.get("markings", [])],
            as_float("lane_width_m", rec.get("lane_width_m", 3.5), positive=True),
            None if rec.get("junction_box") is None else
            (float(rec["junction_box"][0]), -float(rec["junction_box"][3]), float(rec["junction_box"][2]),
             -float(rec["junction_box"][1])))
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise ConfigError(f"{where}: road", type(e).__name__, "road_polygons, markings (kind, points) and "
                                                              "lane_width_m as documented") from None


def _vehicle_box(a: dict, where: str) -> np.ndarray:
    """The vehicle's 3-D box in W from an actor record (transform and bounding box)."""
    bb = a["bounding_box"]
    return box_from_carla(_vec(a["transform"]["location"], "xyz", f"{where}: transform.location"),
                          _vec(a["transform"]["rotation"], ("pitch", "yaw", "roll"), f"{where}: transform.rotation"),
                          _vec(bb.get("location", {"x": 0, "y": 0, "z": 0}), "xyz", f"{where}: bb.location"),
                          _vec(bb["extent"], "xyz", f"{where}: bounding_box.extent"),
                          _vec(bb.get("rotation", {"pitch": 0, "yaw": 0, "roll": 0}), ("pitch", "yaw", "roll"),
                               f"{where}: bounding_box.rotation"))


def _vehicle_rows(frames: list, want) -> list[tuple]:
    """``[(frame, timestamp_s, box, segment)]`` of the vehicle ``want`` (None: the ego, or the only actor).

    Frames without a unique vehicle or with a malformed record are skipped with a warning.
    """
    rows = []
    for rec, where in frames:
        try:
            actors = rec["actors"]
            if want is not None:
                cand = [a for a in actors if a.get("id") == want]
            else:
                cand = [a for a in actors if a.get("role") == "ego"] or (actors if len(actors) == 1 else [])
            if len(cand) != 1:
                warnings.warn(f"{where}: frame {rec.get('frame')} has no unique vehicle "
                              f"(actor_id={want}); frame skipped", stacklevel=3)
                continue
            box = _vehicle_box(cand[0], where)
            rows.append((int(rec["frame"]), float(rec["timestamp_s"]), box, rec.get("segment")))
        except (KeyError, TypeError, ValueError, InputError) as e:
            warnings.warn(f"{where}: malformed frame record ({type(e).__name__}: {e}); frame skipped", stacklevel=3)
    return rows


def read_recording(path, *, actor_id: int | None = None, ground_z_m: float | None = None):
    """Read a recording into a :class:`~footprint_uq.scenario.case_study.Scene` (W coordinates).

    The vehicle is ``actor_id``, else the header's ``ego_actor_id``, else the actor with
    ``"role": "ego"``, else the only actor.  A malformed frame line is reported as a warning
    naming its line number and skipped; a malformed header, camera or road record raises
    :class:`~footprint_uq.errors.ConfigError`.
    """

    p = Path(path)
    if not p.exists():
        raise ConfigError("recording", str(path), "an existing JSON Lines recording")
    header, cams_raw, road, frames = _read_records(p)
    gz = float(header.get("ground_z_m", 0.0)) if ground_z_m is None else float(ground_z_m)
    cameras, settings = _cameras_from_records(cams_raw, gz)
    layout = _road_layout(road, header)
    want = actor_id if actor_id is not None else header.get("ego_actor_id")
    rows = _vehicle_rows(frames, want)
    if not rows:
        raise ConfigError(p.name, "no usable frame records", "frames with the vehicle's transform and bounding box")
    rows.sort(key=lambda r: r[1])
    frame = np.array([r[0] for r in rows])
    t = np.array([r[1] for r in rows])
    boxes = np.stack([r[2] for r in rows])
    segs = [r[3] for r in rows]
    names = ("entry", "turn", "exit")
    if all(s in names for s in segs):
        segment = np.array([names.index(s) for s in segs], dtype=np.int8)
    else:
        segment = segment_labels(boxes[:, 6])
    source = str(header.get("source", "carla recording"))
    return Scene(layout, cameras, frame, t, boxes, segment, source=f"{source} (recording {p.name})",
                 camera_settings=settings, extra={"header": header})
