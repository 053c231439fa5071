"""CARLA conventions vs our camera model (against the real ``carla`` package where installed),
recordings (round trip through our own scenario), and the ``carla`` CLI failing fast."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import warnings

import numpy as np
import pytest

from footprint_uq.errors import ConfigError, InputError
from footprint_uq.integrations.carla.bridge import (
    box_from_carla,
    box_to_carla,
    camera_from_carla,
    camera_to_carla,
    carla_intrinsics,
    carla_recipe_project,
    carla_rotation_matrix,
    carla_to_world,
    carla_transform_matrix,
    read_recording,
    rotation_from_matrix,
    scene_to_recording,
    world_to_carla,
)
from footprint_uq.products.footprints import box3d_bottom_corners
from footprint_uq.scenario import CaseStudyConfig, analyse, build_scene

SIZE = (1920, 1080)


def _random_poses(rng, n):
    loc = np.column_stack([rng.uniform(-80, 80, (n, 2)), rng.uniform(3, 12, n)])
    rot = np.column_stack([rng.uniform(-45, -5, n), rng.uniform(-180, 180, n), rng.uniform(-8, 8, n)])
    return loc, rot


def _points(rng, n=300):
    return np.column_stack([rng.uniform(-100, 100, (n, 2)), rng.uniform(0, 4, n)])


# -- pure numpy ------------------------------------------------------------------------------------
def test_rotation_matrix_hand_checked_and_inverse():
    # yaw 90: forward (local x) points along CARLA +y (south in W)
    R = carla_rotation_matrix(0.0, 90.0, 0.0)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # pitch 30 (nose up): forward gains +z
    R = carla_rotation_matrix(30.0, 0.0, 0.0)
    np.testing.assert_allclose(R @ [1, 0, 0], [np.cos(np.pi / 6), 0, 0.5], atol=1e-15)
    rng = np.random.default_rng(0)
    _, rot = _random_poses(rng, 50)
    R = carla_rotation_matrix(rot[:, 0], rot[:, 1], rot[:, 2])
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
    np.testing.assert_allclose(rotation_from_matrix(R), rot, atol=1e-10)


def test_world_conversion_flips_y():
    np.testing.assert_array_equal(carla_to_world([1.0, 2.0, 3.0]), [1.0, -2.0, 3.0])
    x = np.random.default_rng(1).normal(size=(7, 3))
    np.testing.assert_array_equal(world_to_carla(carla_to_world(x)), x)


def test_intrinsics_hand_checked():
    K = carla_intrinsics((1920, 1080), 90.0)
    np.testing.assert_allclose(K, [[960, 0, 960], [0, 960, 540], [0, 0, 1]], rtol=1e-14)
    with pytest.raises(InputError, match="fov"):
        carla_intrinsics((1920, 1080), 180.0)


def test_our_camera_equals_numpy_recipe():
    rng = np.random.default_rng(2)
    loc, rot = _random_poses(rng, 10)
    for i in range(10):
        fov = rng.uniform(50, 100)
        cam = camera_from_carla(loc[i], rot[i], SIZE, fov)
        X = _points(rng)
        uv_ref, depth = carla_recipe_project(X, loc[i], rot[i], SIZE, fov)
        pr = cam.project(carla_to_world(X))
        front = depth > 0.1
        assert front.sum() > 20
        np.testing.assert_allclose(pr.uv_px[front], uv_ref[front], rtol=0, atol=1e-7)
        assert not np.any(pr.valid[depth <= 0])  # behind the camera: invalid
        # and back: ground points back-projected land where they were
        g = X.copy()
        g[:, 2] = 0.0
        uvg, dg = carla_recipe_project(g, loc[i], rot[i], SIZE, fov)
        ok = (dg > 1.0) & cam.in_image(uvg)
        bp = cam.backproject(uvg[ok])
        np.testing.assert_allclose(bp.xy_world_m, carla_to_world(g[ok])[:, :2], atol=1e-7)


def test_camera_to_carla_round_trip():
    rng = np.random.default_rng(3)
    loc, rot = _random_poses(rng, 10)
    for i in range(10):
        cam = camera_from_carla(loc[i], rot[i], SIZE, 75.0, ground_z_m=0.4)
        back = camera_to_carla(cam)
        np.testing.assert_allclose([back["location"][k] for k in "xyz"], loc[i], atol=1e-9)
        np.testing.assert_allclose([back["rotation"][k] for k in ("pitch", "yaw", "roll")], rot[i], atol=1e-9)
        assert back["attributes"] == {"image_size_x": 1920, "image_size_y": 1080,
                                      "fov": pytest.approx(75.0, abs=1e-9)}


def test_camera_to_carla_rejects_what_carla_cannot_represent():
    from footprint_uq import PanTiltCamera

    with pytest.raises(InputError, match="principal_point"):
        camera_to_carla(PanTiltCamera(1000, SIZE, 8, 10, 20))  # principal point (w-1)/2 by default
    with pytest.raises(InputError, match="location"):
        camera_from_carla((0, 0, 0.2), (0, 0, 0), SIZE, 90, ground_z_m=0.5)


def test_box_conversion_hand_checked():
    # actor at CARLA (10, 5, 0) facing CARLA +y (yaw 90, i.e. south), box centre 0.7 m up
    b = box_from_carla([10.0, 5.0, 0.0], [0.0, 90.0, 0.0], [0.0, 0.0, 0.7], [2.4, 0.95, 0.7])
    np.testing.assert_allclose(b, [10.0, -5.0, 0.7, 4.8, 1.9, 1.4, -np.pi / 2], atol=1e-12)
    # the box offset is in the actor frame: 0.5 m forward of a south-facing actor is 0.5 m further south
    b = box_from_carla([10.0, 5.0, 0.0], [0.0, 90.0, 0.0], [0.5, 0.0, 0.7], [2.4, 0.95, 0.7])
    np.testing.assert_allclose(b[:2], [10.0, -5.5], atol=1e-12)
    rng = np.random.default_rng(4)
    boxes = np.column_stack([rng.normal(0, 20, (6, 2)), rng.uniform(0.5, 1, 6), rng.uniform(3, 5, 6),
                             rng.uniform(1.5, 2, 6), rng.uniform(1.2, 2, 6), rng.uniform(-3, 3, 6)])
    loc, rot, ext = box_to_carla(boxes)
    np.testing.assert_allclose(box_from_carla(loc, rot, np.zeros(3), ext), boxes, atol=1e-12)
    with pytest.raises(InputError):
        box_from_carla([0, 0, 0], [0, 0, 0], [0, 0, 0], [1, -1, 1])


# -- against the real carla package ----------------------------------------------------------------------
def test_matrices_equal_carla():
    carla = pytest.importorskip("carla")
    rng = np.random.default_rng(5)
    loc, rot = _random_poses(rng, 20)
    for i in range(20):
        t = carla.Transform(carla.Location(*map(float, loc[i])), carla.Rotation(*map(float, rot[i])))
        M = np.array(t.get_matrix())
        np.testing.assert_allclose(carla_transform_matrix(loc[i], rot[i]), M, atol=2e-5)  # carla is float32
        Mi = np.array(t.get_inverse_matrix())
        np.testing.assert_allclose(np.linalg.inv(carla_transform_matrix(loc[i], rot[i])), Mi, atol=2e-5)
        v = t.transform(carla.Location(1.5, -2.0, 0.5))
        np.testing.assert_allclose([v.x, v.y, v.z], M[:3, :3] @ [1.5, -2.0, 0.5] + loc[i], atol=1e-4)


def test_projection_equals_carla_recipe():
    """A world point through our model = CARLA's recipe with CARLA's own inverse matrix."""
    carla = pytest.importorskip("carla")
    rng = np.random.default_rng(6)
    loc, rot = _random_poses(rng, 10)
    n_checked = 0
    for i in range(10):
        fov = float(rng.uniform(60, 100))
        t = carla.Transform(carla.Location(*map(float, loc[i])), carla.Rotation(*map(float, rot[i])))
        world_2_camera = np.array(t.get_inverse_matrix())
        cam = camera_from_carla(loc[i], rot[i], SIZE, fov)
        X = _points(rng)
        # the recipe, step by step as in CARLA's examples
        pc = (world_2_camera @ np.column_stack([X, np.ones(len(X))]).T)[:3]
        pc = np.array([pc[1], -pc[2], pc[0]])
        K = np.identity(3)
        K[0, 0] = K[1, 1] = SIZE[0] / (2.0 * np.tan(fov * np.pi / 360.0))
        K[0, 2], K[1, 2] = SIZE[0] / 2.0, SIZE[1] / 2.0
        q = K @ pc
        uv_ref = (q[:2] / q[2]).T
        pr = cam.project(carla_to_world(X))
        ok = (pc[2] > 5.0) & cam.in_image(uv_ref)
        n_checked += ok.sum()
        # carla's matrices are float32: ~1e-7 relative on 100 m coordinates
        np.testing.assert_allclose(pr.uv_px[ok], uv_ref[ok], rtol=0, atol=2e-3)
    assert n_checked > 100


def test_bounding_box_vertices_equal_carla():
    carla = pytest.importorskip("carla")
    rng = np.random.default_rng(7)
    for _ in range(10):
        loc = [float(v) for v in rng.normal(0, 30, 3)]
        yaw = float(rng.uniform(-180, 180))
        t = carla.Transform(carla.Location(*loc), carla.Rotation(0.0, yaw, 0.0))
        bl = [float(v) for v in (rng.normal(0, 0.3), rng.normal(0, 0.1), rng.uniform(0.5, 0.9))]
        ext = [float(v) for v in rng.uniform([1.8, 0.8, 0.6], [2.6, 1.1, 0.9])]
        bb = carla.BoundingBox(carla.Location(*bl), carla.Vector3D(*ext))
        verts = np.array([[v.x, v.y, v.z] for v in bb.get_world_vertices(t)])
        box = box_from_carla(loc, [0.0, yaw, 0.0], bl, ext)
        ours = box3d_bottom_corners(box[None], bottom_on_ground=False)[0]
        theirs = carla_to_world(verts)
        bottom = theirs[np.argsort(theirs[:, 2])[:4]]
        # same four points (as sets)
        d = np.linalg.norm(ours[:, None, :] - bottom[None, :, :], axis=-1)
        assert np.all(d.min(1) < 1e-4) and np.all(d.min(0) < 1e-4)


# -- recordings ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    scene = build_scene()
    p = tmp_path_factory.mktemp("rec") / "scene.jsonl"
    scene_to_recording(scene, p)
    return scene, p


def test_recording_round_trip(recording):
    scene, p = recording
    back = read_recording(p)
    np.testing.assert_allclose(back.boxes_world, scene.boxes_world, atol=1e-12)
    np.testing.assert_array_equal(back.segment, scene.segment)
    np.testing.assert_allclose(back.t_s, scene.t_s)
    for name, cam in scene.cameras.items():
        c2 = back.cameras[name]
        np.testing.assert_allclose(c2.R_world_cam, cam.R_world_cam, atol=1e-12)
        np.testing.assert_allclose(c2.position_world_m, cam.position_world_m, atol=1e-12)
        np.testing.assert_allclose(c2.K, cam.K, rtol=1e-12)
    assert len(back.layout.markings) == len(scene.layout.markings)
    assert back.layout.junction_box_m == pytest.approx(scene.layout.junction_box_m)
    a, b = analyse(scene, ["basler1", "bw-cube1"]), analyse(back, ["basler1", "bw-cube1"])
    num = a.table.select_dtypes("number").columns
    np.testing.assert_allclose(b.table[num].to_numpy(float), a.table[num].to_numpy(float), rtol=1e-8, atol=1e-9)
    assert [s["holds"] for s in a.statements()] == [s["holds"] for s in b.statements()]


def test_recording_format(recording):
    _, p = recording
    lines = [json.loads(s) for s in p.read_text().splitlines()]
    assert lines[0]["type"] == "header" and lines[0]["format"] == "footprint-uq/carla-recording"
    assert [r["type"] for r in lines[1:4]] == ["camera", "camera", "road"]
    fr = lines[4]
    assert fr["type"] == "frame" and set(fr["actors"][0]) >= {"id", "transform", "bounding_box"}
    assert set(fr["actors"][0]["bounding_box"]["extent"]) == {"x", "y", "z"}


def test_recording_without_road_and_segments(tmp_path, recording):
    _, p = recording
    lines = [json.loads(s) for s in p.read_text().splitlines()]
    out = tmp_path / "bare.jsonl"
    kept = [r for r in lines if r["type"] != "road"]
    for r in kept:
        r.pop("segment", None)
    out.write_text("\n".join(json.dumps(r) for r in kept) + "\n")
    sc = read_recording(out)
    assert sc.layout.markings == [] and set(np.unique(sc.segment)) == {0, 1, 2}
    # without a junction box the turn frames stand in for "in the intersection"
    res = analyse(sc, ["basler1"])
    assert all(np.isfinite(s["value_m"]) for s in res.lane_width_statements())
    assert [s["holds"] for s in res.statements()] == [s["holds"] for s in analyse(build_scene(), ["basler1"])
                                                      .statements()]


def test_recording_bad_lines_reported_and_skipped(tmp_path, recording):
    _, p = recording
    text = p.read_text().splitlines()
    text[6] = '{"type": "frame", "frame": 3'  # truncated JSON
    bad = json.loads(text[8])
    del bad["actors"][0]["bounding_box"]
    text[8] = json.dumps(bad)
    out = tmp_path / "bad.jsonl"
    out.write_text("\n".join(text) + "\n")
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        sc = read_recording(out)
    msgs = [str(x.message) for x in w]
    assert any("bad.jsonl:7:" in m for m in msgs) and any("bad.jsonl:9:" in m for m in msgs)
    assert len(sc) == len(text) - 4 - 2


def test_recording_bad_header(tmp_path):
    p = tmp_path / "x.jsonl"
    p.write_text('{"type": "frame"}\n')
    with pytest.raises(ConfigError, match="header"):
        read_recording(p)
    p.write_text(json.dumps({"type": "header", "format": "footprint-uq/carla-recording", "version": 1}) + "\n")
    with pytest.raises(ConfigError, match="camera"):
        read_recording(p)


# -- geometry of the capture command, without a server ---------------------------------------------------------
def test_capture_camera_poses_match_the_generator():
    from footprint_uq.integrations.carla.capture import camera_poses_for_junction, plan_left_turn_geometry
    from footprint_uq.scenario import Intersection, default_camera_specs

    inter = Intersection()
    # entering northwards in W = CARLA yaw -90; a left turn then heads west = CARLA yaw 180
    assert plan_left_turn_geometry(-90.0, 180.0) and not plan_left_turn_geometry(-90.0, 0.0)
    poses = camera_poses_for_junction((0.0, 0.0), inter.half_width_m, -90.0)
    for pose, spec, fov in zip(poses, default_camera_specs(inter), (80.0, 90.0), strict=True):
        cam = camera_from_carla(pose["location"], pose["rotation"], SIZE, fov)
        ref = spec.build()
        np.testing.assert_allclose(cam.position_world_m, ref.position_world_m, atol=1e-9)
        assert np.mod(cam.pan_deg - ref.pan_deg, 360.0) == pytest.approx(0.0, abs=1e-9)
        assert cam.tilt_deg == pytest.approx(ref.tilt_deg) and cam.K[0, 0] == pytest.approx(ref.K[0, 0])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


_RUN = "import sys; from footprint_uq.cli.main import main; main(sys.argv[1:])"


def test_capture_fails_fast_without_server(tmp_path):
    pytest.importorskip("carla")
    out = tmp_path / "rec.jsonl"
    p = subprocess.run([sys.executable, "-c", _RUN, "carla", "capture", "--host", "127.0.0.1", "--port",
                        str(_free_port()), "--out", str(out), "--timeout", "1"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "no CARLA server reachable at 127.0.0.1" in lines[0]
    assert not out.exists()


def test_capture_fails_fast_without_carla_package(tmp_path):
    code = "import sys; sys.modules['carla'] = None; " + _RUN
    p = subprocess.run([sys.executable, "-c", code, "carla", "capture", "--out", str(tmp_path / "r.jsonl"),
                        "--timeout", "1"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "'carla' Python package is not installed" in lines[0]


def test_export_command_writes_the_generator_scene(tmp_path):
    from click.testing import CliRunner

    from footprint_uq.cli.main import main

    rec = tmp_path / "ours.jsonl"
    res = CliRunner().invoke(main, ["carla", "export", "--out", str(rec)])
    assert res.exit_code == 0, res.output
    sc = read_recording(rec)
    ref = build_scene()
    np.testing.assert_allclose(sc.boxes_world, ref.boxes_world, atol=1e-12)
    assert "recording ours.jsonl" in sc.source


# -- the capture procedure against a scripted stand-in for a CARLA world -----------------------------------------
class _FakeWorld:
    """Just enough of carla.World/Map/Waypoint for :func:`capture_left_turn`: one lane along our generator's
    left-turn path (CARLA coordinates), a junction over the arc, blueprints and actors that store transforms."""

    def __init__(self, cm, path, fps):
        self.cm, self.path, self.frame, self.dt = cm, path, 100, 1.0 / fps
        self.settings = type("S", (), {"synchronous_mode": False, "fixed_delta_seconds": None})()
        self.actors, self.destroyed, self.applied = [], [], []
        world = self

        class WP:
            def __init__(self, s):
                self.s = float(s)
                xy, yaw, seg = path.pose(self.s)
                self.is_junction = bool(seg == 1)
                self.lane_type = cm.LaneType.Driving
                self.transform = cm.Transform(cm.Location(float(xy[0]), float(-xy[1]), 0.0),
                                              cm.Rotation(0.0, float(-np.rad2deg(yaw)), 0.0))
                self.road_id, self.section_id, self.lane_id, self.lane_width = 1, 0, -1, 3.5

            def next(self, d):
                return [WP(self.s + d)] if self.s + d <= path.length_m else []

            def previous(self, d):
                return [WP(self.s - d)] if self.s - d >= 0 else []

            def get_junction(self):
                bb = cm.BoundingBox(cm.Location(0.0, 0.0, 0.0), cm.Vector3D(7.0, 7.0, 1.0))
                return type("J", (), {"id": 7, "bounding_box": bb})()

        class Map:
            name = "FakeTown"

            def get_topology(self):
                s0, s1 = path.breakpoints_m
                return [(WP(s0 - 20.0), WP(s0)), (WP(s0 + 1e-9), WP(s1))]

            def generate_waypoints(self, d):
                return [WP(s) for s in np.arange(0.0, path.length_m, d)]

        class BP:
            def __init__(self, id_):
                self.id, self.attrs = id_, {}

            def set_attribute(self, k, v):
                self.attrs[k] = v

            def has_attribute(self, k):
                return k == "number_of_wheels"

            def get_attribute(self, k):
                return "4"

        class Lib:
            def filter(self, pattern):
                return [BP("vehicle.fake.car")] if pattern.startswith("vehicle") else []

            def find(self, id_):
                return BP(id_)

        class Actor:
            def __init__(self, bp, tr):
                self.type_id, self.tr, self.id = bp.id, tr, len(world.actors) + 1
                self.bounding_box = cm.BoundingBox(cm.Location(0.0, 0.0, 0.75), cm.Vector3D(2.4, 0.95, 0.75))

            def set_simulate_physics(self, on):
                self.physics = on

            def set_transform(self, tr):
                self.tr = tr

            def get_transform(self):
                return self.tr

            def listen(self, cb):
                self.cb = cb

            def stop(self):
                pass

            def destroy(self):
                world.destroyed.append(self.id)

        self._map, self._lib, self._Actor = Map(), Lib(), Actor

    def get_map(self):
        return self._map

    def get_settings(self):
        return self.settings

    def apply_settings(self, s):
        self.applied.append((s.synchronous_mode, s.fixed_delta_seconds))

    def get_blueprint_library(self):
        return self._lib

    def spawn_actor(self, bp, tr):
        a = self._Actor(bp, tr)
        self.actors.append(a)
        return a

    def tick(self):
        self.frame += 1
        return self.frame

    def get_snapshot(self):
        ts = type("T", (), {"elapsed_seconds": (self.frame - 101) * self.dt})()
        return type("Snap", (), {"timestamp": ts})()


def test_capture_procedure_on_a_scripted_world(tmp_path):
    cm = pytest.importorskip("carla")
    from footprint_uq.integrations.carla.capture import CaptureOptions, capture_left_turn
    from footprint_uq.scenario import Intersection, default_camera_specs, left_turn_path

    path = left_turn_path(Intersection())
    world = _FakeWorld(cm, path, fps=10.0)
    out = tmp_path / "cap.jsonl"
    info = capture_left_turn(cm, world, out, CaptureOptions(fps=10.0, speed_mps=8.0, lead_in_m=35.0, lead_out_m=35.0,
                                                            vehicle_filter="vehicle.*", images_dir=None))
    assert info["junction_id"] == 7 and info["map"] == "FakeTown"
    # actors destroyed, settings restored
    assert sorted(world.destroyed) == [1, 2, 3] and world.applied[0] == (True, 0.1)
    sc = read_recording(out)
    assert sc.source.startswith("carla")
    # the capture drives at a constant speed: compare with the generator at constant speed
    ref = build_scene(CaseStudyConfig.from_dict({"trajectory": {"turn_speed_mps": None}}))
    for name, spec in zip(("camera1", "camera2"), default_camera_specs(), strict=True):
        cam, want = sc.cameras[name], spec.build()
        np.testing.assert_allclose(cam.R_world_cam, want.R_world_cam, atol=1e-6)  # carla stores float32
        np.testing.assert_allclose(cam.position_world_m, want.position_world_m, atol=1e-5)
    # the recorded path follows the generator's (1 m waypoints, linear interpolation: < 2 cm off the arc)
    n = min(len(sc), len(ref))
    assert abs(len(sc) - len(ref)) <= 1
    d = np.linalg.norm(sc.boxes_world[:n, :2] - ref.boxes_world[:n, :2], axis=1)
    assert d.max() < 0.05
    np.testing.assert_allclose(sc.boxes_world[:, 3:6], np.broadcast_to([4.8, 1.9, 1.5], (len(sc), 3)), atol=1e-6)
    assert set(np.unique(sc.segment)) == {0, 1, 2}
    # the layout has lane strips and the junction box, and the analysis gives the generator's verdicts
    assert sc.layout.road_polygons and sc.layout.junction_box_m == pytest.approx((-7.0, -7.0, 7.0, 7.0))
    a = analyse(sc, ["basler1"])
    b = analyse(ref, ["basler1"])
    assert [s["holds"] for s in a.statements()] == [s["holds"] for s in b.statements()]
