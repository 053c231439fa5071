"""Record the paper's left-turn case study in a running CARLA simulator (``footprint-uq carla capture``).

:func:`record_left_turn` connects to a CARLA server, finds a junction with a left-turn
connection, places two cameras as in the paper (camera 1 on a corner pole looking along the
junction's diagonal, camera 2 across the junction facing the approaching vehicle), drives a
vehicle through the left turn on a scripted path (waypoints, physics off, synchronous mode:
deterministic) and writes a recording (``docs/carla-recording.md``,
:func:`footprint_uq.integrations.carla.bridge.write_recording`).

The geometry (:func:`plan_left_turn_geometry`, :func:`camera_poses_for_junction`,
:func:`resample_path`) needs no server.  The ``carla`` package is an optional extra: without it,
or without a reachable server, :func:`connect` raises :class:`CarlaUnavailable` with a one-line
reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import FootprintUQError
from ...scenario.intersection import Marking, RoadLayout
from .bridge import write_recording

__all__ = ["CarlaUnavailable", "CaptureOptions", "connect", "plan_left_turn_geometry", "camera_poses_for_junction",
           "resample_path", "road_layout", "capture_left_turn", "record_left_turn", "CAMERA_SIZE_PX", "CAMERA_FOVS_DEG"]

#: image size of the two recorded cameras
CAMERA_SIZE_PX = (1920, 1080)
#: horizontal field of view of camera 1 and camera 2, degrees
CAMERA_FOVS_DEG = (80.0, 90.0)
_DESCRIPTIONS = {"camera1": "junction corner, looking along the diagonal",
                 "camera2": "across the junction, facing the approaching vehicle"}


class CarlaUnavailable(FootprintUQError):
    """The carla package, the server or a usable junction is not available (the CLI exits with status 2)."""


@dataclass(frozen=True)
class CaptureOptions:
    """How the left turn is driven and recorded.

    Attributes
    ----------
    fps : float
        Frame rate (the simulator's fixed time step is ``1 / fps``).
    speed_mps : float
        Constant vehicle speed, m/s.
    lead_in_m, lead_out_m : float
        Path length before and after the junction connection, metres.
    vehicle_filter : str
        Blueprint filter of the vehicle (falls back to any four-wheeled vehicle).
    images_dir : path, optional
        Also save the two cameras' images here (one PNG per frame, per camera).
    """

    fps: float = 10.0
    speed_mps: float = 8.0
    lead_in_m: float = 35.0
    lead_out_m: float = 35.0
    vehicle_filter: str = "vehicle.lincoln.mkz*"
    images_dir: Path | None = None


def connect(host: str, port: int, timeout_s: float):
    """Connect to a CARLA server.

    Parameters
    ----------
    host : str
    port : int
        The server's RPC port.
    timeout_s : float
        Seconds to wait for the server.

    Returns
    -------
    tuple
        ``(carla module, client, world)``.

    Raises
    ------
    CarlaUnavailable
        The ``carla`` package is not installed, or no server answers in time.
    """
    try:
        import carla as carla_mod
    except ImportError as e:
        raise CarlaUnavailable(f"the 'carla' Python package is not installed ({e}); install the optional extra: "
                               "pip install 'footprint-uq[carla]'") from None
    try:
        client = carla_mod.Client(host, int(port))
        client.set_timeout(float(timeout_s))
        world = client.get_world()
    except RuntimeError as e:
        msg = " ".join(str(e).split())
        raise CarlaUnavailable(f"no CARLA server reachable at {host}:{port} within {timeout_s:g} s ({msg})") from None
    return carla_mod, client, world


# -- geometry that does not need a server (tested) ---------------------------------------------------
def _wrap_deg(a):
    return (np.asarray(a, dtype=float) + 180.0) % 360.0 - 180.0


def plan_left_turn_geometry(entry_yaw_deg: float, exit_yaw_deg: float, tol_deg: float = 25.0) -> bool:
    """Whether a junction connection from ``entry_yaw_deg`` to ``exit_yaw_deg`` (CARLA yaw) is a left turn.

    CARLA's yaw turns clockwise seen from above (left-handed frame), so a left turn
    *decreases* the yaw by about 90 degrees (within ``tol_deg``).
    """
    d = float(_wrap_deg(exit_yaw_deg - entry_yaw_deg))
    return abs(d + 90.0) <= tol_deg


def camera_poses_for_junction(centre_xy, half_size_m: float, entry_yaw_deg: float, *, setback_m: float = 2.0,
                              back_m: float = 12.0, ground_z_m: float = 0.0, heights_m=(8.0, 10.0),
                              pitch_deg=(-20.0, -20.0), camera2_turn_deg: float = 10.0) -> list[dict]:
    """CARLA poses ``{"location": (x, y, z), "rotation": (pitch, yaw, roll)}`` of the two cameras.

    In CARLA coordinates, for a vehicle entering the junction with yaw ``entry_yaw_deg``:
    camera 1 stands at the junction corner ahead and to the right of the entering driver
    and looks along the diagonal through the junction centre; camera 2 stands ``back_m``
    beyond the far corner on the driver's left, facing the approaching vehicle (turned
    ``camera2_turn_deg`` towards the exit side).  With the defaults these are the cameras of
    :func:`footprint_uq.scenario.cameras.default_camera_specs` for a junction of half size
    ``half_size_m`` (tested).
    """
    c = np.asarray(centre_xy, dtype=float)
    y = math.radians(entry_yaw_deg)
    d = np.array([math.cos(y), math.sin(y)])  # forward (CARLA)
    r = np.array([-math.sin(y), math.cos(y)])  # right of forward in CARLA's left-handed frame
    a = half_size_m + setback_m
    p1 = c + a * d + a * r
    v1 = c - p1
    p2 = c + (a + back_m) * d - a * r
    yaw1 = math.degrees(math.atan2(v1[1], v1[0]))
    yaw2 = float(_wrap_deg(entry_yaw_deg + 180.0 + camera2_turn_deg))
    out = []
    for p, yw, h, pitch in ((p1, yaw1, heights_m[0], pitch_deg[0]), (p2, yaw2, heights_m[1], pitch_deg[1])):
        out.append({"location": (float(p[0]), float(p[1]), float(ground_z_m + h)),
                    "rotation": (float(pitch), float(yw), 0.0)})
    return out


def resample_path(points, yaws, speed_mps: float, fps: float):
    """Positions and yaws at ``speed_mps`` and ``fps`` along a polyline.

    Parameters
    ----------
    points : array_like, shape (M, 3)
        The polyline (CARLA x, y, z).
    yaws : array_like, shape (M,)
        CARLA yaw at each point, degrees.
    speed_mps, fps : float

    Returns
    -------
    xyz : ndarray, shape (N, 3)
    yaw_deg : ndarray, shape (N,)
        Wrapped to [-180, 180).
    t_s : ndarray, shape (N,)
        Time of each sample.
    """
    P = np.asarray(points, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P[:, :2], axis=0), axis=1))])
    n = int(s[-1] / speed_mps * fps) + 1
    st = np.arange(n) * speed_mps / fps
    xyz = np.stack([np.interp(st, s, P[:, k]) for k in range(3)], -1)
    yw = np.unwrap(np.deg2rad(np.asarray(yaws, dtype=float)))
    yaw = np.rad2deg(np.interp(st, s, yw))
    return xyz, _wrap_deg(yaw), st / speed_mps


# -- the capture (needs a world: a server, or a stand-in in the tests) ---------------------------------------
def _find_left_turn(cm, cmap, lead_in_m: float, lead_out_m: float):
    """The first left-turn connection inside a junction with room before and after: ``(entry, exit)``."""
    for a, b in cmap.get_topology():
        if not a.is_junction or a.lane_type != cm.LaneType.Driving:
            continue
        if not plan_left_turn_geometry(a.transform.rotation.yaw, b.transform.rotation.yaw):
            continue
        if a.previous(max(lead_in_m, 1.0)) and b.next(max(lead_out_m, 1.0)):
            return a, b
    raise CarlaUnavailable(f"no junction with a left-turn connection found on map {cmap.name}")


def _waypoint_path(a, lead_in_m: float, lead_out_m: float) -> list:
    """Waypoints every metre: ``lead_in_m`` before ``a``, the connection through the junction, ``lead_out_m`` after."""
    back = []
    wp = a
    for _ in range(int(lead_in_m)):
        prev = wp.previous(1.0)
        if not prev:
            break
        wp = prev[0]
        back.append(wp)
    path = back[::-1] + [a]
    wp = a
    for _ in range(400):
        nxt = wp.next(1.0)
        if not nxt:
            break
        wp = nxt[0]
        path.append(wp)
        if not wp.is_junction:
            break
    for _ in range(int(lead_out_m)):
        nxt = wp.next(1.0)
        if not nxt:
            break
        wp = nxt[0]
        path.append(wp)
    return path


def _transform_record(tr) -> dict:
    return {"location": {"x": tr.location.x, "y": tr.location.y, "z": tr.location.z},
            "rotation": {"pitch": tr.rotation.pitch, "yaw": tr.rotation.yaw, "roll": tr.rotation.roll}}


def _spawn_vehicle(cm, world, lib, vehicle_filter: str, xyz0, yaw0, actors: list):
    bps = list(lib.filter(vehicle_filter)) or [v for v in lib.filter("vehicle.*")
                                               if v.has_attribute("number_of_wheels")
                                               and int(v.get_attribute("number_of_wheels")) == 4]
    if not bps:
        raise CarlaUnavailable("no four-wheeled vehicle blueprint on the server")
    start = cm.Transform(cm.Location(float(xyz0[0]), float(xyz0[1]), float(xyz0[2]) + 0.3),
                         cm.Rotation(yaw=float(yaw0)))
    vehicle = world.spawn_actor(bps[0], start)
    actors.append(vehicle)
    vehicle.set_simulate_physics(False)
    return vehicle


def _spawn_cameras(cm, world, lib, poses, images_dir, actors: list) -> dict:
    """The two RGB cameras at ``poses``: ``{name: (sensor, fov)}``; each spawned actor is appended to ``actors``."""
    cams = {}
    for i, (pose, fov) in enumerate(zip(poses, CAMERA_FOVS_DEG, strict=True), 1):
        bp = lib.find("sensor.camera.rgb")
        bp.set_attribute("image_size_x", str(CAMERA_SIZE_PX[0]))
        bp.set_attribute("image_size_y", str(CAMERA_SIZE_PX[1]))
        bp.set_attribute("fov", str(fov))
        tr = cm.Transform(cm.Location(*map(float, pose["location"])), cm.Rotation(*map(float, pose["rotation"])))
        sensor = world.spawn_actor(bp, tr)
        actors.append(sensor)
        if images_dir is not None:
            d = Path(images_dir) / f"camera{i}"
            d.mkdir(parents=True, exist_ok=True)
            sensor.listen(lambda img, d=d: img.save_to_disk(str(d / f"{img.frame:08d}.png")))
        cams[f"camera{i}"] = (sensor, fov)
    return cams


def _camera_records(cams: dict) -> dict:
    return {name: {"transform": _transform_record(sensor.get_transform()),
                   "attributes": {"image_size_x": CAMERA_SIZE_PX[0], "image_size_y": CAMERA_SIZE_PX[1], "fov": fov},
                   "description": _DESCRIPTIONS[name]}
            for name, (sensor, fov) in cams.items()}


def _drive(cm, world, vehicle, xyz, yaw) -> list[dict]:
    """Move the vehicle along the samples, one simulator tick each: the recording's frames."""
    frames = []
    bb = vehicle.bounding_box
    box = {"location": {"x": bb.location.x, "y": bb.location.y, "z": bb.location.z},
           "extent": {"x": bb.extent.x, "y": bb.extent.y, "z": bb.extent.z},
           "rotation": {"pitch": bb.rotation.pitch, "yaw": bb.rotation.yaw, "roll": bb.rotation.roll}}
    for k in range(len(xyz)):
        vehicle.set_transform(cm.Transform(cm.Location(*map(float, xyz[k])), cm.Rotation(yaw=float(yaw[k]))))
        frame_id = world.tick()
        snap = world.get_snapshot()
        frames.append({"frame": int(frame_id), "timestamp_s": float(snap.timestamp.elapsed_seconds),
                       "actors": [{"id": int(vehicle.id), "type_id": vehicle.type_id, "role": "ego",
                                   "transform": _transform_record(vehicle.get_transform()),
                                   "bounding_box": box}]})
    return frames


def capture_left_turn(cm, world, out_file, options: CaptureOptions | None = None) -> dict:
    """Drive a left turn through a junction of ``world`` and write the recording.

    Parameters
    ----------
    cm : module
        The ``carla`` module (or a stand-in with the same types).
    world : carla.World
        The simulator's world; its settings are restored and every spawned actor destroyed
        on return, also after an error.
    out_file : path
        Recording to write (JSON Lines, ``docs/carla-recording.md``).
    options : CaptureOptions, optional
        Speed, frame rate, path lengths, vehicle, image output (default: ``CaptureOptions()``).

    Returns
    -------
    dict
        ``frames`` (number recorded), ``junction_id`` and ``map`` (the map's name).

    Raises
    ------
    CarlaUnavailable
        No junction with a left-turn connection, or no four-wheeled vehicle blueprint.
    """
    o = options if options is not None else CaptureOptions()
    cmap = world.get_map()
    a, _ = _find_left_turn(cm, cmap, o.lead_in_m, o.lead_out_m)
    junction = a.get_junction()
    path = _waypoint_path(a, o.lead_in_m, o.lead_out_m)
    pts = [(w.transform.location.x, w.transform.location.y, w.transform.location.z) for w in path]
    xyz, yaw, _ = resample_path(pts, [w.transform.rotation.yaw for w in path], o.speed_mps, o.fps)
    ground_z = float(np.median(np.asarray(pts)[:, 2]))
    jb = junction.bounding_box
    half = float(max(jb.extent.x, jb.extent.y))
    poses = camera_poses_for_junction((jb.location.x, jb.location.y), half, a.transform.rotation.yaw,
                                      ground_z_m=ground_z)
    original = world.get_settings()
    actors = []
    try:
        settings = world.get_settings()
        settings.synchronous_mode = True
        settings.fixed_delta_seconds = 1.0 / o.fps
        world.apply_settings(settings)
        lib = world.get_blueprint_library()
        vehicle = _spawn_vehicle(cm, world, lib, o.vehicle_filter, xyz[0], yaw[0], actors)
        cams = _spawn_cameras(cm, world, lib, poses, o.images_dir, actors)
        world.tick()
        cam_records = _camera_records(cams)
        frames = _drive(cm, world, vehicle, xyz, yaw)
        layout = road_layout(cmap, (jb.location.x, jb.location.y), radius_m=half + max(o.lead_in_m, o.lead_out_m) + 10,
                             junction_box=(jb.location.x - jb.extent.x, jb.location.y - jb.extent.y,
                                           jb.location.x + jb.extent.x, jb.location.y + jb.extent.y))
        write_recording(out_file, cameras=cam_records, frames=frames, layout=layout,
                        header={"source": "carla", "map": cmap.name, "junction_id": int(junction.id),
                                "ego_actor_id": int(vehicle.id), "ground_z_m": ground_z, "frame_rate_hz": o.fps})
        return {"frames": len(frames), "junction_id": int(junction.id), "map": cmap.name}
    finally:
        for act in actors[::-1]:
            if hasattr(act, "stop") and act.type_id.startswith("sensor."):
                act.stop()
            act.destroy()
        world.apply_settings(original)


def road_layout(cmap, centre_xy, *, radius_m: float, junction_box) -> RoadLayout:
    """Lane strips (polygons) and lane edges (markings) of a CARLA map near a junction, in W (for drawing).

    Parameters
    ----------
    cmap : carla.Map
    centre_xy : (float, float)
        Junction centre, CARLA coordinates.
    radius_m : float
        Waypoints farther than this from the centre are left out.
    junction_box : (x0, y0, x1, y1)
        The junction's bounding box, CARLA coordinates.

    Returns
    -------
    RoadLayout
        In the world frame W (CARLA's y flipped).
    """
    c = np.asarray(centre_xy, dtype=float)
    groups: dict = {}
    widths = []
    for wp in cmap.generate_waypoints(2.0):
        loc = wp.transform.location
        if np.hypot(loc.x - c[0], loc.y - c[1]) > radius_m:
            continue
        rv = wp.transform.get_right_vector()
        hw = wp.lane_width / 2
        widths.append(wp.lane_width)
        key = (wp.road_id, wp.section_id, wp.lane_id)
        groups.setdefault(key, []).append((wp.s, (loc.x - rv.x * hw, loc.y - rv.y * hw),
                                           (loc.x + rv.x * hw, loc.y + rv.y * hw)))
    polys, marks = [], []
    for items in groups.values():
        if len(items) < 2:
            continue
        items.sort(key=lambda it: it[0])
        left = np.array([it[1] for it in items]) * [1.0, -1.0]  # CARLA -> W
        right = np.array([it[2] for it in items]) * [1.0, -1.0]
        polys.append(np.vstack([left, right[::-1]]))
        marks.append(Marking("lane", left, False, 0.12))
        marks.append(Marking("lane", right, False, 0.12))
    x0, y0, x1, y1 = junction_box
    return RoadLayout(polys, marks, float(np.median(widths)) if widths else 3.5, (x0, -y1, x1, -y0))


def record_left_turn(host: str, port: int, out_file, *, timeout_s: float = 5.0, map_name: str | None = None,
                     options: CaptureOptions | None = None) -> dict:
    """Connect to a CARLA server, optionally load a map, and capture the left turn (:func:`capture_left_turn`).

    Parameters
    ----------
    host : str
    port : int
    out_file : path
        Recording to write.
    timeout_s : float
        Seconds to wait for the server.
    map_name : str, optional
        Load this map first (e.g. ``"Town03"``); default the current one.
    options : CaptureOptions, optional

    Returns
    -------
    dict
        As :func:`capture_left_turn`.

    Raises
    ------
    CarlaUnavailable
        No ``carla`` package, no server, no usable junction or vehicle.
    """
    cm, client, world = connect(host, port, timeout_s)
    if map_name:
        world = client.load_world(map_name)
    return capture_left_turn(cm, world, out_file, options)
