"""``footprint-uq carla ...``: record the case study in a running CARLA simulator, export our scenario.

* ``carla capture --host H --port P --out FILE``: connects to a CARLA server, finds a
  junction with a left-turn connection, places two cameras as in the paper (camera 1 on a
  corner pole looking along the junction's diagonal, camera 2 across the junction facing
  the approaching vehicle), drives a vehicle through the left turn on a scripted path
  (waypoints, physics off, synchronous mode: deterministic) and writes a recording
  (``docs/carla-recording.md``).  Analyse it with ``footprint-uq case-study --recording FILE``.
* ``carla export --out FILE``: our own generated scenario as a recording (same format).

Without the ``carla`` package, or without a reachable server, ``capture`` fails fast with
one line on stderr and exit status 2.
"""

from __future__ import annotations

import math
from pathlib import Path

import click
import numpy as np

__all__ = ["carla", "CarlaUnavailable", "connect", "plan_left_turn_geometry", "camera_poses_for_junction"]


class CarlaUnavailable(click.ClickException):
    """The carla package or the server is not available (exit status 2)."""

    exit_code = 2


def connect(host: str, port: int, timeout_s: float):
    """``(carla module, client, world)``; raises :class:`CarlaUnavailable` with a one-line reason."""
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
    """True if a junction connection from ``entry_yaw_deg`` to ``exit_yaw_deg`` (CARLA yaw) is a left turn.

    CARLA's yaw turns clockwise seen from above (left-handed frame), so a left turn
    *decreases* the yaw by about 90 degrees.
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


def _resample_path(points, yaws, speed_mps, fps):
    """Positions/yaws at ``speed_mps`` and ``fps`` along a polyline ``(M, 3)``."""
    P = np.asarray(points, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P[:, :2], axis=0), axis=1))])
    n = int(s[-1] / speed_mps * fps) + 1
    st = np.arange(n) * speed_mps / fps
    xyz = np.stack([np.interp(st, s, P[:, k]) for k in range(3)], -1)
    yw = np.unwrap(np.deg2rad(np.asarray(yaws, dtype=float)))
    yaw = np.rad2deg(np.interp(st, s, yw))
    return xyz, _wrap_deg(yaw), st / speed_mps


# -- the commands -------------------------------------------------------------------------------------------
@click.group("carla")
def carla():
    """CARLA simulator: capture the case study, export our scenario (docs/carla-recording.md)."""


@carla.command("capture")
@click.option("--host", default="127.0.0.1", show_default=True, help="CARLA server host.")
@click.option("--port", default=2000, show_default=True, type=click.IntRange(1, 65535), help="CARLA RPC port.")
@click.option("--out", "out_file", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording to write (JSON Lines).")
@click.option("--timeout", "timeout_s", default=5.0, show_default=True, type=click.FloatRange(0.1, 600),
              help="Seconds to wait for the server.")
@click.option("--map", "map_name", default=None, help="Load this map first (e.g. Town03); default: the current one.")
@click.option("--fps", default=10.0, show_default=True, type=click.FloatRange(1, 100), help="Frame rate.")
@click.option("--speed", "speed_mps", default=8.0, show_default=True, type=click.FloatRange(0.5, 40),
              help="Vehicle speed, m/s.")
@click.option("--lead-in", "lead_in_m", default=35.0, show_default=True, type=click.FloatRange(0, 200))
@click.option("--lead-out", "lead_out_m", default=35.0, show_default=True, type=click.FloatRange(0, 200))
@click.option("--vehicle", "vehicle_filter", default="vehicle.lincoln.mkz*", show_default=True,
              help="Blueprint filter of the vehicle (falls back to any four-wheeled vehicle).")
@click.option("--images", "images_dir", default=None, type=click.Path(file_okay=False, path_type=Path),
              help="Also save the two cameras' images here (PNG per frame).")
def capture(host, port, out_file, timeout_s, map_name, fps, speed_mps, lead_in_m, lead_out_m, vehicle_filter,
            images_dir):
    """Drive a left turn through a junction in CARLA and record cameras and vehicle boxes."""
    cm, client, world = connect(host, port, timeout_s)
    if map_name:
        world = client.load_world(map_name)
    rec = _capture(cm, world, out_file, fps=fps, speed_mps=speed_mps, lead_in_m=lead_in_m, lead_out_m=lead_out_m,
                   vehicle_filter=vehicle_filter, images_dir=images_dir)
    click.echo(f"recorded {rec['frames']} frames of a left turn at junction {rec['junction_id']} "
               f"({rec['map']}) to {out_file}")


def _capture(cm, world, out_file, *, fps, speed_mps, lead_in_m, lead_out_m, vehicle_filter, images_dir):
    from ..integrations.carla.bridge import write_recording

    cmap = world.get_map()
    # a left-turn connection inside a junction, with room before and after
    choice = None
    for a, b in cmap.get_topology():
        if not a.is_junction or a.lane_type != cm.LaneType.Driving:
            continue
        if not plan_left_turn_geometry(a.transform.rotation.yaw, b.transform.rotation.yaw):
            continue
        before = a.previous(max(lead_in_m, 1.0))
        after = b.next(max(lead_out_m, 1.0))
        if before and after:
            choice = (a, b)
            break
    if choice is None:
        raise CarlaUnavailable(f"no junction with a left-turn connection found on map {cmap.name}")
    a, b = choice
    junction = a.get_junction()
    # path: lead-in, the connection, lead-out (1 m steps)
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
    pts = [(w.transform.location.x, w.transform.location.y, w.transform.location.z) for w in path]
    yaws = [w.transform.rotation.yaw for w in path]
    xyz, yaw, t = _resample_path(pts, yaws, speed_mps, fps)
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
        settings.fixed_delta_seconds = 1.0 / fps
        world.apply_settings(settings)
        lib = world.get_blueprint_library()
        bps = list(lib.filter(vehicle_filter)) or [v for v in lib.filter("vehicle.*")
                                                   if v.has_attribute("number_of_wheels")
                                                   and int(v.get_attribute("number_of_wheels")) == 4]
        if not bps:
            raise CarlaUnavailable("no four-wheeled vehicle blueprint on the server")
        start = cm.Transform(cm.Location(float(xyz[0][0]), float(xyz[0][1]), float(xyz[0][2]) + 0.3),
                             cm.Rotation(yaw=float(yaw[0])))
        vehicle = world.spawn_actor(bps[0], start)
        actors.append(vehicle)
        vehicle.set_simulate_physics(False)
        cams = {}
        size = (1920, 1080)
        for i, (pose, fov) in enumerate(zip(poses, (80.0, 90.0), strict=True), 1):
            bp = lib.find("sensor.camera.rgb")
            bp.set_attribute("image_size_x", str(size[0]))
            bp.set_attribute("image_size_y", str(size[1]))
            bp.set_attribute("fov", str(fov))
            tr = cm.Transform(cm.Location(*map(float, pose["location"])), cm.Rotation(*map(float, pose["rotation"])))
            sensor = world.spawn_actor(bp, tr)
            actors.append(sensor)
            if images_dir is not None:
                d = Path(images_dir) / f"camera{i}"
                d.mkdir(parents=True, exist_ok=True)
                sensor.listen(lambda img, d=d: img.save_to_disk(str(d / f"{img.frame:08d}.png")))
            cams[f"camera{i}"] = (sensor, fov)
        world.tick()
        cam_records = {}
        for name, (sensor, fov) in cams.items():
            tr = sensor.get_transform()
            cam_records[name] = {
                "transform": {"location": {"x": tr.location.x, "y": tr.location.y, "z": tr.location.z},
                              "rotation": {"pitch": tr.rotation.pitch, "yaw": tr.rotation.yaw,
                                           "roll": tr.rotation.roll}},
                "attributes": {"image_size_x": size[0], "image_size_y": size[1], "fov": fov},
                "description": ("junction corner, looking along the diagonal" if name == "camera1" else
                                "across the junction, facing the approaching vehicle")}
        frames = []
        bb = vehicle.bounding_box
        for k in range(len(t)):
            vehicle.set_transform(cm.Transform(cm.Location(*map(float, xyz[k])), cm.Rotation(yaw=float(yaw[k]))))
            frame_id = world.tick()
            snap = world.get_snapshot()
            tr = vehicle.get_transform()
            frames.append({"frame": int(frame_id), "timestamp_s": float(snap.timestamp.elapsed_seconds),
                           "actors": [{"id": int(vehicle.id), "type_id": vehicle.type_id, "role": "ego",
                                       "transform": {"location": {"x": tr.location.x, "y": tr.location.y,
                                                                  "z": tr.location.z},
                                                     "rotation": {"pitch": tr.rotation.pitch, "yaw": tr.rotation.yaw,
                                                                  "roll": tr.rotation.roll}},
                                       "bounding_box": {"location": {"x": bb.location.x, "y": bb.location.y,
                                                                     "z": bb.location.z},
                                                        "extent": {"x": bb.extent.x, "y": bb.extent.y,
                                                                   "z": bb.extent.z},
                                                        "rotation": {"pitch": bb.rotation.pitch,
                                                                     "yaw": bb.rotation.yaw,
                                                                     "roll": bb.rotation.roll}}}]})
        layout = _road_layout(cmap, (jb.location.x, jb.location.y), radius_m=half + max(lead_in_m, lead_out_m) + 10,
                              junction_box=(jb.location.x - jb.extent.x, jb.location.y - jb.extent.y,
                                            jb.location.x + jb.extent.x, jb.location.y + jb.extent.y))
        write_recording(out_file, cameras=cam_records, frames=frames, layout=layout,
                        header={"source": "carla", "map": cmap.name, "junction_id": int(junction.id),
                                "ego_actor_id": int(vehicle.id), "ground_z_m": ground_z, "frame_rate_hz": fps})
        return {"frames": len(frames), "junction_id": int(junction.id), "map": cmap.name}
    finally:
        for act in actors[::-1]:
            if hasattr(act, "stop") and act.type_id.startswith("sensor."):
                act.stop()
            act.destroy()
        world.apply_settings(original)


def _road_layout(cmap, centre_xy, *, radius_m, junction_box):
    """Lane strips (polygons) and lane edges (markings) near the junction, in W (for drawing)."""
    from ..scenario.intersection import Marking, RoadLayout

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


@carla.command("export")
@click.option("--out", "out_file", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording to write (JSON Lines).")
@click.option("--config", "config", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Scenario settings (docs/case-study.md); default: the paper-like set-up.")
def export(out_file, config):
    """Write our generated left-turn scenario as a recording (CARLA coordinates)."""
    from ..integrations.carla.bridge import scene_to_recording
    from ..scenario.case_study import CaseStudyConfig, build_scene, load_config

    cfg = load_config(config) if config else CaseStudyConfig()
    scene = build_scene(cfg)
    scene_to_recording(scene, out_file)
    click.echo(f"wrote {len(scene)} frames, {len(scene.cameras)} cameras to {out_file}")
