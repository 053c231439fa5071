"""Extrinsic calibration against a LiDAR: board detection, PnP poses, variability, budget, CLI.

Synthetic ground truth (:mod:`footprint_uq.calibration.synthetic_lidar`): a camera and
a 128-beam / 45 deg LiDAR on a roof, the paper's 14x9 board (0.1 m squares, 5 cm
margins) on a stand at 3-8 m, ground plane.  Scanner at 1024 azimuth steps over a
160 deg window to keep the tests fast.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from footprint_uq.calibration import extrinsics as ex
from footprint_uq.calibration import lidar
from footprint_uq.calibration import synthetic_lidar as sl
from footprint_uq.calibration.boards import PAPER_BOARD
from footprint_uq.errors import InputError
from footprint_uq.uncertainty.budget import load_budget
from footprint_uq.uncertainty.propagation import propagate

SCANNER = sl.SpinningLidar(n_azimuth=1024, range_noise_m=0.02, azimuth_window_deg=(-80.0, 80.0))
TRUTH_KEYS = ex.POSE_NAMES


@pytest.fixture(scope="module")
def rig():
    cam, TL = sl.default_rig()
    poses = sl.sample_board_poses(cam, PAPER_BOARD, 8, T_world_lidar=TL, scanner=SCANNER, seed=11)
    return cam, TL, poses


@pytest.fixture(scope="module")
def campaign(rig):
    cam, TL, poses = rig
    return sl.make_lidar_campaign(camera=cam, T_world_lidar=TL, poses=poses, scanner=SCANNER, sigma_px=0.3, seed=1)


@pytest.fixture(scope="module")
def solved(campaign):
    pairs = [(f"f{k}", uv, cl) for k, (uv, cl) in enumerate(zip(campaign.corners_px, campaign.clouds, strict=True))]
    frames, plane = ex.frames_from_pairs(pairs, campaign.board)
    res = ex.calibrate_extrinsics(frames, campaign.camera, ground_plane=plane, bootstrap=100, seed=0)
    return frames, plane, res


def _truth(c):
    return np.array([c.truth[k] for k in TRUTH_KEYS])


# -- LiDAR side -------------------------------------------------------------------------------
def test_ground_frame_matches_truth(campaign, solved):
    _, plane, res = solved
    # the synthetic world is the ground frame the pipeline builds (origin below the LiDAR, x = LiDAR x)
    np.testing.assert_allclose(res.T_ground_lidar[:3, :3], campaign.T_world_lidar[:3, :3], atol=2e-4)
    np.testing.assert_allclose(res.T_ground_lidar[:3, 3], campaign.T_world_lidar[:3, 3], atol=3e-3)
    assert plane.rms_m < 0.03  # 2 cm range noise, mostly along the (steep) rays


def test_board_corners_recovered(campaign, solved):
    """3D corners from the rectangle fit within 2.5 cm RMS of the truth.

    Tolerance: scan lines are 3-5 cm apart on a board at 5-8 m, so each edge is seen
    up to one spacing inside the true edge; the fit uses the middle of the robust
    extents (errors of opposite edges cancel on average) and lands at 1-10 mm; 2.5 cm
    leaves room for the worst frame without letting a wrong grid placement
    (errors of 0.5-1 m) through.
    """
    frames, _, res = solved
    for k, f in enumerate(frames):
        assert f.ok, f.reason
        fp = res.frame_poses[k]
        err = np.sqrt(np.mean(np.sum((fp.xyz_m - campaign.corners_lidar_true[k]) ** 2, axis=1)))
        assert err < 0.025, (f.name, err)
        assert f.cloud_stats["n_read"] > 0


def test_detect_board_rejects_wall_and_reports_missing_board(rig):
    cam, TL, poses = rig
    wall = [((12.0, 0.0, 0.0), (1.0, 0.0, 0.0))]  # a wall 12 m east, facing the LiDAR
    cl = sl.simulate_scan(PAPER_BOARD, poses[0], TL, scanner=SCANNER, walls=wall, seed=3)
    g = lidar.fit_ground_plane(cl)
    det = lidar.detect_board(cl, PAPER_BOARD, ground=g)
    assert det.found and det.n_points > 300
    empty = sl.simulate_scan(PAPER_BOARD, poses[0], TL, scanner=SCANNER, walls=wall, seed=3, with_board=False)
    det = lidar.detect_board(empty, PAPER_BOARD, ground=g)
    assert not det.found and "no board-sized planar patch" in det.reason
    # no ground removal: the ground (one big plane and far-range ring arcs) is rejected by size
    det = lidar.detect_board(cl, PAPER_BOARD, ground=None)
    assert det.found and det.n_points > 300
    # a region that excludes the board
    det = lidar.detect_board(cl, PAPER_BOARD, ground=g, region="box:-5,-5,-1,0,5,5")
    assert not det.found


def test_nan_points_counted_and_ignored(rig, tmp_path):
    cam, TL, poses = rig
    cl = sl.simulate_scan(PAPER_BOARD, poses[1], TL, scanner=SCANNER, seed=4, no_return="nan")
    assert cl.n_nonfinite_dropped > 1000  # the sky
    from footprint_uq.calibration.pointclouds import read_point_cloud, write_pcd

    raw = np.full((len(cl) + 5, 3), np.nan)
    raw[:len(cl)] = cl.xyz_m
    p = write_pcd(tmp_path / "n.pcd", raw, data="binary", dtype="f8")
    back = read_point_cloud(p)
    assert back.n_nonfinite_dropped == 5 and len(back) == len(cl)
    det = lidar.detect_board(back, PAPER_BOARD, ground=lidar.fit_ground_plane(back))
    assert det.found


def test_region_parsing():
    b = lidar.parse_region("box:0,-1,-2,5,1,2")
    assert b.contains(np.array([[1.0, 0, 0], [6.0, 0, 0]])).tolist() == [True, False]
    s = lidar.parse_region("sphere:1,1,1,0.5")
    assert s.contains([1.2, 1, 1]) and not s.contains([2, 1, 1])
    for bad in ("box:1,2,3", "cube:1,2,3,4", "box:0,0,0,-1,1,1", "sphere:0,0,0,-1"):
        with pytest.raises(InputError):
            lidar.parse_region(bad)


# -- camera side and poses --------------------------------------------------------------------
def test_recovered_pose_matches_truth(campaign, solved):
    _, _, res = solved
    err = res.pose - _truth(campaign)
    sig = res.sigmas("bootstrap")
    assert np.all(np.abs(err) < 4 * sig + np.array([1e-3] * 3 + [0.01] * 3)), (err, sig)
    assert np.all(np.abs(err[:3]) < 0.03) and np.all(np.abs(err[3:]) < 0.3)
    assert res.frame_status == ["ok"] * 8
    # the grid placement was resolved: every chosen candidate reprojects to sub-pixel level
    assert all(res.frame_poses[k].rms_px < 1.0 for k in res.used)


def test_jacobian_is_the_gradient_of_the_cv2_solution(campaign, solved):
    """The LM optimum of OpenCV is a stationary point of the library's reprojection (J^T r = 0):
    cv2's pose conventions and pose_in_ground + general.project agree."""
    from footprint_uq.cameras import general

    _, _, res = solved
    X = np.concatenate([res.frame_poses[k].xyz_m[res.frame_poses[k].inliers] for k in res.used])
    U = np.concatenate([res.frame_poses[k].uv_px[res.frame_poses[k].inliers] for k in res.used])
    Xg = lidar.transform_points(res.T_ground_lidar, X)
    p = ex._params_from_pose(res.intrinsics, res.pose)
    pr = general.project(p, Xg, get_gradients=True)
    cols = [13, 14, 15, 16, 17, 18]
    J = pr.duv_dp[..., cols].reshape(-1, 6)
    r = (U - pr.uv_px).ravel()
    g = J.T @ r
    scale = np.sqrt(np.sum(J**2, axis=0)) * np.sqrt(np.sum(r**2))
    assert np.all(np.abs(g) < 1e-5 * scale), g / scale
    assert np.isclose(np.sqrt(np.mean(r**2) * 2), res.rms_px, rtol=1e-6)


def test_sigmas_match_scatter_over_campaigns(rig):
    """Reported standard deviations vs the scatter of the estimates over 30 synthetic campaigns.

    Pixel noise only (0.5 px), exact 3D corners, same 8 board poses: the first-order
    (Jacobian) sigma of the joint pose and of the single-frame poses must match the
    scatter, and the bootstrap over 8 frames must too.  Tolerances: the sample std of
    30 estimates has a relative standard error of 1/sqrt(2*29) = 13 %, so the
    Jacobian ratio must lie in [0.7, 1.4] (~ +-2.7 sigma); the bootstrap over only 8
    frames is biased low (sqrt(7/8)) and itself noisy, hence [0.6, 1.5] on its
    campaign-averaged value.
    """
    cam, TL, poses = rig
    est, jac, boot, frame_est, frame_jac = [], [], [], [], []
    est_m, jac_m, boot_m = [], [], []
    T_lw = np.linalg.inv(TL)
    for s in range(30):
        frames = []
        rng = np.random.default_rng(1000 + s)
        for k, T in enumerate(poses):
            uv, _ = sl.image_corners(cam, PAPER_BOARD, T, sigma_px=0.5, seed=rng)
            X = sl.board_corners_world(PAPER_BOARD, T) @ T_lw[:3, :3].T + T_lw[:3, 3]
            frames.append(ex.FrameData(f"f{k}", uv, [X]))
        res = ex.calibrate_extrinsics(frames, cam, T_ground_lidar=TL, bootstrap=40, seed=s)
        est.append(res.pose)
        jac.append(res.sigmas("jacobian"))
        boot.append(res.sigmas("bootstrap"))
        frame_est.append(res.per_frame[0])
        frame_jac.append(np.sqrt(np.diag(res.cov_jacobian_frames[0])))
        res = ex.calibrate_extrinsics(frames, cam, T_ground_lidar=TL, bootstrap=40, seed=s, estimator="mean")
        est_m.append(res.pose)
        jac_m.append(res.sigmas("jacobian"))
        boot_m.append(res.sigmas("bootstrap"))
    est, frame_est = np.array(est), np.array(frame_est)
    scatter = est.std(axis=0, ddof=1)
    r_jac = np.mean(jac, axis=0) / scatter
    r_boot = np.mean(boot, axis=0) / scatter
    r_frame = np.mean(frame_jac, axis=0) / frame_est.std(axis=0, ddof=1)
    assert np.all((r_jac > 0.7) & (r_jac < 1.4)), r_jac
    assert np.all((r_boot > 0.6) & (r_boot < 1.5)), r_boot
    assert np.all((r_frame > 0.7) & (r_frame < 1.4)), r_frame
    scatter_m = np.std(est_m, axis=0, ddof=1)
    assert np.all((np.mean(jac_m, axis=0) / scatter_m > 0.7) & (np.mean(jac_m, axis=0) / scatter_m < 1.4))
    assert np.all((np.mean(boot_m, axis=0) / scatter_m > 0.6) & (np.mean(boot_m, axis=0) / scatter_m < 1.5))
    assert np.all(scatter < scatter_m)  # with pixel noise only the joint fit beats the mean of single frames
    truth = np.array([sl.default_rig()[0].position_world_m[0], sl.default_rig()[0].position_world_m[1], 1.75, 91, 4,
                      0.5])
    assert np.all(np.abs(est.mean(axis=0) - truth) < 3 * scatter / np.sqrt(30) + 1e-9)


def test_lidar_campaigns_bootstrap_covers_the_error(rig):
    """With LiDAR board fits (2 cm range noise) the per-frame corner errors are shared by
    all corners of a frame: the bootstrap over frames sees them, the Jacobian does not.
    Over 4 campaigns x 6 parameters the errors normalised by the bootstrap sigma have an
    RMS near 1 (accepted in [0.4, 2.2]: 24 correlated values), and the Jacobian sigma is
    the smaller one."""
    cam, TL, poses = rig
    z, jac_over_boot = [], []
    for s in range(4):
        c = sl.make_lidar_campaign(camera=cam, T_world_lidar=TL, poses=poses, scanner=SCANNER, sigma_px=0.3,
                                   seed=50 + s)
        pairs = [(f"f{k}", uv, cl) for k, (uv, cl) in enumerate(zip(c.corners_px, c.clouds, strict=True))]
        frames, plane = ex.frames_from_pairs(pairs, c.board, seed=s)
        res = ex.calibrate_extrinsics(frames, cam, ground_plane=plane, bootstrap=60, seed=s)
        z.append((res.pose - _truth(c)) / res.sigmas("bootstrap"))
        jac_over_boot.append(res.sigmas("jacobian") / res.sigmas("bootstrap"))
    rms_z = float(np.sqrt(np.mean(np.square(z))))
    assert 0.4 < rms_z < 2.2, np.array(z)
    assert np.all(np.mean(jac_over_boot, axis=0) < 0.8)


# -- failures ---------------------------------------------------------------------------------
def test_frame_without_board_is_reported_and_others_go_on(campaign, rig):
    cam, TL, poses = rig
    clouds = list(campaign.clouds)
    clouds[2] = sl.simulate_scan(PAPER_BOARD, poses[2], TL, scanner=SCANNER, seed=9, with_board=False)
    pairs = [(f"f{k}", uv, cl) for k, (uv, cl) in enumerate(zip(campaign.corners_px, clouds, strict=True))]
    pairs.append(("lonely", None, clouds[0]))  # no image side
    frames, plane = ex.frames_from_pairs(pairs, campaign.board)
    res = ex.calibrate_extrinsics(frames, cam, ground_plane=plane, bootstrap=0)
    assert res.frame_status[2].startswith("no board in the cloud")
    assert res.frame_status[8] == "no image or corners file for this frame"
    assert len(res.used) == 7 and res.cov_bootstrap is None
    s = res.summary()
    assert s["frames"][2]["status"].startswith("no board") and s["sigma"]["bootstrap"] is None
    with pytest.raises(InputError, match="budget_from"):
        res.budget("bootstrap")
    assert np.all(np.abs(res.pose - _truth(campaign))[:3] < 0.03)
    # the paper's frame filter: frames above a reprojection threshold are dropped and reported
    thr = float(np.median([res.frame_poses[k].rms_px for k in res.used]))
    res2 = ex.calibrate_extrinsics(frames, cam, ground_plane=plane, bootstrap=0, max_frame_rms_px=thr)
    dropped = [s for s in res2.frame_status if s.startswith("reprojection RMS")]
    assert len(dropped) == sum(res.frame_poses[k].rms_px > thr for k in res.used) >= 3
    assert all(res2.frame_poses[k].rms_px <= thr for k in res2.used)


def test_too_few_frames(campaign):
    frames = [ex.FrameData(f"f{k}", uv, [X]) for k, (uv, X) in
              enumerate(zip(campaign.corners_px[:2], campaign.corners_lidar_true[:2], strict=True))]
    frames.append(ex.FrameData("bad", None, [], False, "no board found in the image"))
    with pytest.raises(InputError, match="at least 3 frames.*bad: no board found in the image"):
        ex.calibrate_extrinsics(frames, campaign.camera, T_ground_lidar=campaign.T_world_lidar)


def test_correspondence_csv_round_trip_and_bad_rows(campaign, tmp_path):
    frames = [ex.FrameData(f"f{k}", uv, [X]) for k, (uv, X) in
              enumerate(zip(campaign.corners_px, campaign.corners_lidar_true, strict=True))]
    p = ex.write_correspondences_csv(tmp_path / "c.csv", frames)
    back = ex.read_correspondences_csv(p)
    assert [f.name for f in back] == [f.name for f in frames]
    np.testing.assert_array_equal(back[3].xyz_candidates[0], frames[3].xyz_candidates[0])
    lines = p.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[4], "nan")  # a NaN u in frame f0 (file row 6)
    p.write_text("\n".join(lines) + "\n")
    back = ex.read_correspondences_csv(p)
    assert not back[0].ok and "rows [6]" in back[0].reason and all(f.ok for f in back[1:])
    res = ex.calibrate_extrinsics(back, campaign.camera, T_ground_lidar=campaign.T_world_lidar, bootstrap=0)
    assert res.frame_status[0].startswith("non-numeric") and len(res.used) == 7
    (tmp_path / "h.csv").write_text("frame,X,Y,u,v\n")
    with pytest.raises(InputError, match="frame, X, Y, Z, u, v"):
        ex.read_correspondences_csv(tmp_path / "h.csv")


def test_pose_conversion_round_trip():
    rng = np.random.default_rng(5)
    T = np.eye(4)
    T[:3, :3] = sl.rot_xyz(1.0, -2.0, 30.0)
    T[:3, 3] = (0.3, -0.2, 1.9)
    for _ in range(5):
        p = np.array([*rng.uniform(-2, 2, 2), rng.uniform(1, 8), rng.uniform(-179, 179), rng.uniform(-60, 60),
                      rng.uniform(-30, 30)])
        rv, tv = ex._rt_from_pose(p, T)
        np.testing.assert_allclose(ex.pose_in_ground(rv, tv, T), p, atol=1e-9)


def test_bad_inputs():
    with pytest.raises(InputError, match="ground transform"):
        ex.load_transform(np.eye(3))
    with pytest.raises(InputError, match="rigid"):
        ex.load_transform(np.diag([2.0, 1, 1, 1]))
    with pytest.raises(InputError, match="intrinsics"):
        ex.load_intrinsics(object())
    with pytest.raises(InputError, match="ground"):
        ex.calibrate_extrinsics([], ex.Intrinsics(np.eye(3), np.zeros(5), (10, 10)), ground="sky")
    with pytest.raises(InputError, match="estimator"):
        ex.calibrate_extrinsics([], ex.Intrinsics(np.eye(3), np.zeros(5), (10, 10)), estimator="median")


# -- budget, pipeline, CLI ----------------------------------------------------------------------
def test_budget_feeds_propagate(solved, tmp_path):
    _, _, res = solved
    import yaml

    for src in ("per_frame", "bootstrap", "jacobian"):
        b = res.budget(src)
        p = tmp_path / f"{src}.yaml"
        p.write_text(yaml.safe_dump(b.to_dict()))
        bl = load_budget(str(p))
        S = bl.param_covariance()
        np.testing.assert_allclose(np.sqrt(S[[13, 14, 15], [13, 14, 15]]), res.sigmas(src)[:3], rtol=1e-12)
        np.testing.assert_allclose(np.rad2deg(np.sqrt(S[[16, 17, 18], [16, 17, 18]])), res.sigmas(src)[3:],
                                   rtol=1e-12)
    cam = res.camera()
    uv = np.array([[960.0, 900.0], [400.0, 1000.0]])
    est = propagate(cam, load_budget(str(tmp_path / "per_frame.yaml")), uv)
    assert np.all(est.valid) and np.all(np.linalg.eigvalsh(est.cov_m2) > 0)
    sd = res.budget("per_frame", correlations=False)
    assert sd.covariance_matrix is None and sd.height_m == pytest.approx(res.sigmas("per_frame")[2])


def test_cli_end_to_end(campaign, tmp_path):
    from click.testing import CliRunner

    from footprint_uq.cli.calibrate import calibrate

    d = campaign.write(tmp_path / "pairs")
    args = ["extrinsics", "--pairs", str(d), "--camera", str(d / "camera.yaml"), "--board", "14x9",
            "--square-m", "0.1", "--margin-m", "0.05", "--bootstrap", "30", "--out", str(tmp_path / "out")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = CliRunner().invoke(calibrate, args)
    assert r.exit_code == 0, (r.output, r.exception)
    out = tmp_path / "out"
    for f in ("budget.yaml", "camera.yaml", "summary.json", "frames.csv", "board_poses.png", "pose_spread.png"):
        assert (out / f).exists(), f
    s = json.loads((out / "summary.json").read_text())
    assert s["n_used"] == 8 and set(s["sigma"]) == {"per_frame", "bootstrap", "jacobian"}
    b = load_budget(str(out / "budget.yaml"))
    assert b.height_m > 0 and b.pan_deg > 0
    from footprint_uq.io import load_camera

    cam = load_camera(out / "camera.yaml")
    assert abs(cam.height_m - 1.75) < 0.03 and abs(cam.pan_deg - 91.0) < 0.3
    # correspondences CSV input with a ground transform file
    np.save(tmp_path / "T.npy", campaign.T_world_lidar)
    r = CliRunner().invoke(calibrate, ["extrinsics", "--pairs", str(out / "correspondences.csv"), "--camera",
                                       str(d / "camera.yaml"), "--board", "14x9", "--square-m", "0.1",
                                       "--ground", str(tmp_path / "T.npy"), "--bootstrap", "0", "--estimator", "mean",
                                       "--out", str(tmp_path / "out2")])
    assert r.exit_code == 0, (r.output, r.exception)
    r = CliRunner().invoke(calibrate, ["extrinsics", "--pairs", str(out / "correspondences.csv"), "--camera",
                                       str(d / "camera.yaml"), "--board", "14x9", "--square-m", "0.1",
                                       "--out", str(tmp_path / "out3")])
    assert r.exit_code != 0 and isinstance(r.exception, InputError)


def test_same_board_poses_as_the_synthetic_images():
    """The LiDAR scans can be taken at the board poses of the synthetic image campaign; the image corners of
    :func:`image_corners` (library camera model) equal those of the renderer's ``project_corners`` (cv2)."""
    from footprint_uq.calibration import synthetic as sy

    cam, TL = sl.default_rig(intrinsics=sy.DEFAULT_CAMERA)
    rv, tv = sy.make_board_poses(sy.DEFAULT_CAMERA, PAPER_BOARD, n=5, seed=0)
    poses = sl.poses_from_camera(cam, rv, tv)
    for k, T in enumerate(poses):
        uv, ok = sl.image_corners(cam, PAPER_BOARD, T)
        assert ok
        np.testing.assert_allclose(uv, sy.project_corners(sy.DEFAULT_CAMERA, PAPER_BOARD, rv[k], tv[k]), atol=1e-9)
    c = sl.make_lidar_campaign(camera=cam, T_world_lidar=TL, poses=poses, scanner=SCANNER, sigma_px=0.2, seed=2)
    pairs = [(f"f{k}", uv, cl) for k, (uv, cl) in enumerate(zip(c.corners_px, c.clouds, strict=True))]
    frames, plane = ex.frames_from_pairs(pairs, c.board)
    res = ex.calibrate_extrinsics(frames, sy.DEFAULT_CAMERA, ground_plane=plane, bootstrap=0, estimator="mean")
    # these poses were made for the camera only: boards close and low in the image fall partly below the
    # LiDAR's field of view (+-22.5 deg against the camera's +-30 deg); such frames are reported, not used
    assert len(res.used) >= 3
    for k in set(range(5)) - set(res.used):
        assert res.frame_status[k].startswith("no board in the cloud: no board-sized planar patch (patch of")
    err = res.pose - _truth(c)
    # 3 boards at ~2 m, where the LiDAR's per-frame board-fit errors (~6 mm) dominate the 0.2 px pixel noise:
    # the mean of the single-frame poses (the joint fit compromises between frames whose 3D corners disagree)
    assert np.all(np.abs(err) < 3 * res.sigmas("per_frame")), (err, res.sigmas("per_frame"))
    assert np.all(np.abs(err[:3]) < 0.05) and np.all(np.abs(err[3:]) < 0.5), err


def test_rendered_images_and_pcd_pairs_through_the_cli(tmp_path):
    """Real-format inputs: rendered PNG images (the intrinsic helper's renderer, detected by the 2D corner
    detector) paired with binary_compressed PCD scans, and an intrinsics-only camera file (no pose)."""
    import cv2
    import yaml
    from click.testing import CliRunner

    from footprint_uq.calibration import synthetic as sy
    from footprint_uq.calibration.pointclouds import write_pcd
    from footprint_uq.cli.calibrate import calibrate

    scam = sy.DEFAULT_CAMERA.scaled(0.5)
    # the LiDAR pitched down 12 deg so that it sees the low, close boards of an intrinsic campaign too
    cam, TL = sl.default_rig(intrinsics=scam, lidar_pitch_deg=12.0)
    rv, tv = sy.make_board_poses(scam, PAPER_BOARD, n=4, seed=1)
    c = sl.make_lidar_campaign(camera=cam, T_world_lidar=TL, poses=sl.poses_from_camera(cam, rv, tv),
                               scanner=SCANNER, seed=2)
    d = tmp_path / "pairs"
    d.mkdir()
    for k in range(4):
        img, _ = sy.render_board(scam, PAPER_BOARD, rv[k], tv[k], supersample=2, seed=k)
        cv2.imwrite(str(d / f"f{k}.png"), img)
        write_pcd(d / f"f{k}.pcd", c.clouds[k].xyz_m, {"intensity": c.clouds[k].fields["intensity"]},
                  data="binary_compressed")
    (d / "f9.pcd").write_bytes(b"VERSION 0.7\nFIELDS x y z\n")  # a broken cloud, and no image for it
    intr = {"model": "opencv", "image_size_px": list(scam.image_size_px), "K": scam.K.tolist(),
            "dist": list(scam.dist)}
    (tmp_path / "intrinsics.yaml").write_text(yaml.safe_dump(intr))
    args = ["extrinsics", "--pairs", str(d), "--camera", str(tmp_path / "intrinsics.yaml"), "--board", "14x9",
            "--square-m", "0.1", "--margin-m", "0.05", "--bootstrap", "20", "--estimator", "mean",
            "--out", str(tmp_path / "out")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = CliRunner().invoke(calibrate, args)
    assert r.exit_code == 0, (r.output, r.exception)
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["n_used"] == 4 and s["frames"][4]["status"].startswith("unreadable point cloud")
    assert s["frames"][4]["status"].endswith("also: no image or corners file for this frame")
    for fr in s["frames"][:4]:
        assert fr["rms_px"] < 0.2  # rendered corners, sub-pixel detection
    err = np.array([s["pose"][k] for k in TRUTH_KEYS]) - _truth(c)
    assert np.all(np.abs(err[:3]) < 0.06) and np.all(np.abs(err[3:]) < 0.5), err
