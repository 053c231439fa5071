"""Scenario generator: intersection geometry, left-turn path, sampled frames, cameras, config."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq.errors import ConfigError, InputError
from footprint_uq.products.footprints import box3d_bottom_corners
from footprint_uq.scenario import (
    CameraSpec,
    CaseStudyConfig,
    Intersection,
    Vehicle,
    box_corners,
    build_scene,
    default_camera_specs,
    focal_from_hfov,
    hfov_from_focal,
    left_turn_path,
    load_config,
    sample_trajectory,
)
from footprint_uq.scenario.trajectory import segment_labels


def _shoelace(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


# -- intersection ------------------------------------------------------------------------------
def test_road_polygon_area_square_corners_hand_checked():
    inter = Intersection(lanes_per_direction=2, lane_width_m=3.5, arm_length_m=45.0, curb_radius_m=0.0)
    h, L = 7.0, 52.0
    # cross = two strips 2L x 2h minus the doubly counted centre square
    assert _shoelace(inter.road_polygon()) == pytest.approx(2 * (2 * L * 2 * h) - (2 * h) ** 2, rel=1e-12)


def test_road_polygon_area_rounded_corners():
    inter = Intersection(curb_radius_m=4.0)
    h, L, r = inter.half_width_m, inter.extent_m, 4.0
    exact = 2 * (2 * L * 2 * h) - (2 * h) ** 2 + 4 * (r * r - np.pi * r * r / 4)
    poly = inter.road_polygon(n_arc=200)
    assert _shoelace(poly) == pytest.approx(exact, rel=1e-4)
    assert _shoelace(poly) > 0  # counter-clockwise


@pytest.mark.parametrize("lanes,width", [(1, 3.0), (2, 3.5), (3, 3.25)])
def test_lane_centre_lines_and_markings(lanes, width):
    inter = Intersection(lanes_per_direction=lanes, lane_width_m=width)
    h = lanes * width
    # northbound lanes (incoming from the south) are east of the centre line: right-hand traffic
    for k in range(lanes):
        p, d = inter.lane_centre_line("south", k, incoming=True)
        np.testing.assert_allclose(p, [(k + 0.5) * width, -h], atol=1e-12)
        np.testing.assert_allclose(d, [0.0, 1.0], atol=1e-12)
        p, d = inter.lane_centre_line("west", k, incoming=False)  # westbound, north of the centre line
        np.testing.assert_allclose(p, [-h, (k + 0.5) * width], atol=1e-12)
        np.testing.assert_allclose(d, [-1.0, 0.0], atol=1e-12)
    marks = inter.markings()
    kinds = [m.kind for m in marks]
    assert kinds.count("stop") == 4 and kinds.count("centre") == 4 and kinds.count("edge") == 8
    assert kinds.count("lane") == 4 * 2 * (lanes - 1)
    stop_south = [m for m in marks if m.kind == "stop" and m.xy_world_m[0, 1] < 0 and m.xy_world_m[0, 0] == 0]
    assert len(stop_south) == 1
    np.testing.assert_allclose(stop_south[0].xy_world_m, [[0, -h - 1.5], [h, -h - 1.5]], atol=1e-12)
    lay = inter.layout()
    assert lay.lane_width_m == width and lay.junction_box_m == (-h, -h, h, h)


def test_layout_dict_round_trip():
    lay = Intersection().layout()
    from footprint_uq.scenario import RoadLayout

    back = RoadLayout.from_dict(lay.to_dict())
    assert len(back.markings) == len(lay.markings)
    np.testing.assert_array_equal(back.road_polygons[0], lay.road_polygons[0])


@pytest.mark.parametrize("kw", [{"lanes_per_direction": 0}, {"lanes_per_direction": 1.5}, {"lane_width_m": -1},
                                {"arm_length_m": float("nan")}])
def test_intersection_bad_input(kw):
    with pytest.raises(ConfigError):
        Intersection(**kw)


def test_lane_and_arm_bad_input():
    inter = Intersection()
    with pytest.raises(ConfigError, match="lane"):
        inter.lane_centre_line("south", 2, True)
    with pytest.raises(ConfigError, match="arm"):
        inter.lane_centre_line("up", 0, True)
    with pytest.raises(ConfigError, match="intersection.lanes"):
        Intersection.from_dict({"lanes": 2})


# -- path and trajectory ------------------------------------------------------------------------
def test_default_turn_radius_hand_checked():
    # lane centres at 1.75 m, box half size 7 m: the arc from the box edge to the box edge
    path = left_turn_path(Intersection())
    assert path.radius_m == pytest.approx(8.75)
    np.testing.assert_allclose(path.arc_centre_m, [-7.0, -7.0])
    xy, yaw, seg = path.pose(np.array(path.breakpoints_m))
    np.testing.assert_allclose(xy, [[1.75, -7.0], [-7.0, 1.75]], atol=1e-12)
    np.testing.assert_allclose(np.exp(1j * yaw), np.exp(1j * np.array([np.pi / 2, np.pi])), atol=1e-12)


@pytest.mark.parametrize("approach", ["south", "north", "east", "west"])
def test_path_continuous_and_tangent(approach):
    inter = Intersection(lanes_per_direction=3)
    path = left_turn_path(inter, approach=approach, entry_lane=1, exit_lane=2, lead_in_m=20, lead_out_m=25)
    s = np.linspace(0.0, path.length_m, 4001)
    xy, yaw, seg = path.pose(s)
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    np.testing.assert_allclose(step, s[1] - s[0], rtol=1e-6)  # unit speed: arc-length parametrised
    tangent = np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0]))
    mid_yaw = np.angle(np.exp(1j * yaw[:-1]) + np.exp(1j * yaw[1:]))
    # exact on straights and arcs (a chord of a circle has the mid-arc heading); O(ds^2 / R) where a
    # step straddles a breakpoint
    assert np.max(np.abs(np.angle(np.exp(1j * (tangent - mid_yaw))))) < 2e-4
    # a left turn: heading increases by exactly 90 degrees
    turn = np.unwrap(yaw)
    assert turn[-1] - turn[0] == pytest.approx(np.pi / 2, abs=1e-12)
    assert set(np.unique(seg)) == {0, 1, 2}
    # the arc stays inside the junction box
    h = inter.half_width_m
    assert np.all(np.abs(xy[seg == 1]) <= h + 1e-9)


def test_path_bad_input():
    path = left_turn_path(Intersection())
    with pytest.raises(InputError):
        path.pose(path.length_m + 1.0)
    with pytest.raises(InputError):
        left_turn_path(Intersection(), lead_in_m=-1)


def test_sample_trajectory_spacing_and_boxes():
    veh = Vehicle(4.5, 1.8, 1.4)
    path = left_turn_path(Intersection())
    tr = sample_trajectory(path, veh, speed_mps=5.0, frame_rate_hz=20.0)
    assert len(tr) == int(np.floor(path.length_m / 5.0 * 20.0)) + 1
    np.testing.assert_allclose(np.diff(tr.t_s), 0.05)
    np.testing.assert_allclose(np.diff(tr.s_m), 0.25, rtol=1e-12)
    np.testing.assert_allclose(tr.boxes_world[:, 2:6], np.broadcast_to([0.7, 4.5, 1.8, 1.4], (len(tr), 4)))
    assert tr.boxes_world.shape == (len(tr), 7)
    lab = segment_labels(tr.boxes_world[:, 6], tol_deg=1e-6)
    np.testing.assert_array_equal(lab[tr.segment != 1], tr.segment[tr.segment != 1])


def test_box_corners_match_footprint_order():
    rng = np.random.default_rng(3)
    b = np.column_stack([rng.normal(0, 10, (5, 3)), rng.uniform(1, 5, (5, 3)), rng.uniform(-3, 3, 5)])
    c = box_corners(b)
    assert c.shape == (5, 8, 3)
    b[:, 2] = b[:, 5] / 2  # bottom on the ground
    np.testing.assert_allclose(box_corners(b)[:, :4], box3d_bottom_corners(b), atol=1e-12)
    # top face straight above the bottom one
    np.testing.assert_allclose(c[:, 4:, :2], c[:, :4, :2])
    np.testing.assert_allclose(c[:, 4:, 2] - c[:, :4, 2], b[:, 5:6].repeat(4, 1))
    with pytest.raises(InputError):
        box_corners(np.zeros((3, 6)))


# -- cameras ---------------------------------------------------------------------------------------
def test_focal_hfov_hand_checked():
    assert focal_from_hfov(90.0, 1920) == pytest.approx(960.0)
    assert hfov_from_focal(focal_from_hfov(77.3, 1920), 1920) == pytest.approx(77.3)


def test_default_cameras_look_like_roadside_installations():
    specs = default_camera_specs()
    assert [s.name for s in specs] == ["camera1", "camera2"]
    for s in specs:
        assert 6 <= s.height_m <= 10 and 15 <= s.tilt_deg <= 30
        assert tuple(s.image_size_px) == (1920, 1080)
        assert 70 <= s.hfov_deg <= 90
        cam = s.build()
        # the intersection centre is in view
        pr = cam.project([0.0, 0.0, 0.0])
        assert pr.valid and cam.in_image(pr.uv_px)
        assert cam.principal_point_px == (960.0, 540.0)
    # camera 1 looks along the diagonal (south-west) from the north-east corner
    assert specs[0].pan_deg == 225.0 and specs[0].position_m[0] > 0 and specs[0].position_m[1] > 0


def test_scene_every_frame_in_view_of_camera1():
    scene = build_scene()
    cam = scene.cameras["camera1"]
    c = box_corners(scene.boxes_world)
    pr = cam.project(c)
    assert np.all(pr.valid) and np.all(cam.in_image(pr.uv_px))


def test_camera_spec_bad_input():
    with pytest.raises(ConfigError, match="zoom"):
        CameraSpec.from_dict({"name": "c", "zoom": 2})
    with pytest.raises(ConfigError, match="name"):
        CameraSpec.from_dict({"height_m": 8})
    with pytest.raises(InputError, match="height_m"):
        CameraSpec.from_dict({"name": "c", "height_m": -3})


# -- config ------------------------------------------------------------------------------------------
def test_config_file_round_trip(tmp_path):
    import yaml

    cfg = CaseStudyConfig.from_dict({"intersection": {"lanes_per_direction": 3, "lane_width_m": 3.25},
                                     "trajectory": {"speed_mps": 6.0, "frame_rate_hz": 5.0,
                                                    "turn_speed_mps": None},
                                     "camera_types": ["basler1", "bw-cube1"]})
    p = tmp_path / "cs.yaml"
    p.write_text(yaml.safe_dump(cfg.to_dict()))
    back = load_config(p)
    assert back.intersection == cfg.intersection
    assert back.trajectory == cfg.trajectory
    assert [c.name for c in back.cameras] == ["camera1", "camera2"]
    assert back.cameras[0].position_m == pytest.approx((11.75, 11.75))
    assert list(back.camera_types) == ["basler1", "bw-cube1"]
    scene = build_scene(back)
    assert len(scene) == int(np.floor(left_turn_path(back.intersection).length_m / 6.0 * 5.0)) + 1


@pytest.mark.parametrize("d,field", [({"intersecton": {}}, "intersecton"), ({"trajectory": {"speed": 3}}, "speed"),
                                     ({"camera_types": ["nikon"]}, "nikon"), ({"confidence": 1.5}, "confidence"),
                                     ({"cameras": []}, "cameras"), ({"heatmap": {"step_m": 0}}, "step_m")])
def test_config_bad_input(d, field):
    with pytest.raises(ConfigError, match=field):
        CaseStudyConfig.from_dict(d)


def test_speed_profile_brakes_turns_and_accelerates():
    """Default: 8 m/s on the straights, 4.5 m/s through the arc, 2 m/s^2 braking and accelerating."""
    from footprint_uq.scenario.trajectory import speed_profile

    path = left_turn_path(Intersection())
    s0, s1 = path.breakpoints_m
    v = speed_profile(path, [0.0, s0 - 1.0, s0, 0.5 * (s0 + s1), s1, s1 + 1.0, path.length_m], speed_mps=8.0,
                      turn_speed_mps=4.5, accel_mps2=2.0)
    np.testing.assert_allclose(v[[0, -1]], 8.0)
    np.testing.assert_allclose(v[2:5], 4.5)
    np.testing.assert_allclose(v[[1, 5]], np.sqrt(4.5**2 + 2 * 2.0 * 1.0))
    tr = sample_trajectory(path, speed_mps=8.0, frame_rate_hz=10.0, turn_speed_mps=4.5, accel_mps2=2.0)
    # the frames follow the profile: displacement per frame = speed x 0.1 s (to the profile's change in 0.1 s)
    step = np.diff(tr.s_m)
    np.testing.assert_allclose(step, 0.1 * 0.5 * (tr.speed_mps[1:] + tr.speed_mps[:-1]), atol=0.2 * 0.1 * 0.1 * 2)
    turn = tr.segment == 1
    assert np.allclose(tr.speed_mps[turn], 4.5)
    # lateral acceleration in the turn v^2 / R = 2.3 m/s^2 (the old constant 8 m/s gave 7.3 m/s^2)
    assert 4.5**2 / path.radius_m == pytest.approx(2.314, abs=1e-3)
    # default scene: the same profile
    scene = build_scene(CaseStudyConfig())
    np.testing.assert_allclose(scene.extra["speed_mps"], tr.speed_mps)
    with pytest.raises(InputError, match="turn_speed_mps"):
        sample_trajectory(path, turn_speed_mps=-1.0)
