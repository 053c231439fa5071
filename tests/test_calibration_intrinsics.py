"""Intrinsic calibration: real OpenCV sample images, synthetic statistics, maps, outputs, bad input, CLI, pipeline."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq import OpenCVCamera, load_budget, propagate
from footprint_uq.calibration import (
    INTRINSIC_NAMES,
    PAPER_BOARD,
    Checkerboard,
    calibrate_corners,
    calibrate_intrinsics,
    coverage_map,
    detect_frames,
    error_asymmetry,
    expand_inputs,
    paper_sigmas,
    parse_board,
    reprojection_error_map,
)
from footprint_uq.calibration.synthetic import DEFAULT_CAMERA, make_board_poses, noisy_corners
from footprint_uq.errors import InputError

DATA = Path(__file__).parent / "data" / "opencv-chessboard-right"
BOARD = parse_board("9x6", 0.025)


@pytest.fixture(scope="module")
def real_cal():
    return calibrate_intrinsics(DATA, BOARD, workers=1)


# ------------------------------------------------------------------------------------------ real images
def test_real_images_match_opencv_run_directly(real_cal):
    cal = real_cal
    assert len(cal.detections) == 13 and all(d.found for d in cal.detections)
    assert len(cal.labels) == 13 and cal.image_size_px == (640, 480)
    obj = [BOARD.object_points().astype(np.float32)] * 13
    ips = [c.astype(np.float32).reshape(-1, 1, 2) for c in cal.image_points_px]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, d, _rv, _tv, sdi, _sde, pve = cv2.calibrateCameraExtended(obj, ips, (640, 480), None, None,
                                                                       criteria=crit)
    # same solver, same data: OpenCV's Levenberg-Marquardt stops at its own eps, and runs in different
    # processes/thread counts reproduce K to ~5e-9 relative (1e-6 px), far below sigma (~0.3 px)
    np.testing.assert_allclose(cal.K, K, rtol=1e-7)
    # the distortion vector to the same 1e-7, relative to its scale: a small coefficient (p2 ~ 6e-4) alone
    # moved by 8e-7 of itself (4.6e-10 absolute) between two runs in one clean-clone CI run
    dref = d.ravel()[:5]
    np.testing.assert_allclose(cal.dist, dref, rtol=1e-7, atol=1e-7 * np.abs(dref).max())
    np.testing.assert_allclose(cal.std_opencv, sdi.ravel()[:9], rtol=1e-6)
    np.testing.assert_allclose(cal.per_view_rms_px, pve.ravel(), rtol=1e-6)
    assert cal.rms_px == pytest.approx(rms, rel=1e-9)
    assert cal.opencv_version == cv2.__version__
    # our own first-order covariance reproduces OpenCV's standard deviations (same dof convention, 2N - p)
    np.testing.assert_allclose(cal.std_jacobian, cal.std_opencv, rtol=1e-4)
    # plausibility pins for OpenCV's sample camera: a 640x480 camera with ~60 deg horizontal field of view
    # and strong barrel distortion (a plain OpenCV pipeline with a fixed 11x11 sub-pixel window gives fx 542)
    assert 530 < cal.K[0, 0] < 545 and 530 < cal.K[1, 1] < 545
    assert 310 < cal.K[0, 2] < 340 and 235 < cal.K[1, 2] < 260
    assert -0.33 < cal.dist[0] < -0.25
    # residuals are detected - reprojected: their RMS is OpenCV's per-view error
    for r, e in zip(cal.residuals_px, cal.per_view_rms_px, strict=True):
        assert np.sqrt(np.mean(np.sum(r**2, -1))) == pytest.approx(e, rel=1e-5)  # OpenCV sums in float32


def test_real_frame_filter_drops_the_bad_frame(real_cal):
    # right05 holds one ~3 px corner error (mean 0.39 px); every other view is below 0.21 px
    means = dict(zip(real_cal.labels, real_cal.per_view_mean_px, strict=True))
    assert max(means, key=means.get) == "right05.jpg"
    cal = calibrate_intrinsics(DATA, BOARD, workers=1, max_mean_reproj_px=0.3)
    assert [d["label"] for d in cal.dropped][0] == "right05.jpg"
    assert cal.dropped[0]["round"] == 0 and cal.dropped[0]["mean_error_px"] > 0.3
    assert "right05.jpg" not in cal.labels
    assert len(cal.rounds) >= 2 and cal.rounds[-1].dropped == []
    assert np.all(cal.per_view_mean_px <= 0.3)
    assert cal.rms_px < real_cal.rms_px
    rows = {r["label"]: r for r in cal.frames_table()}
    assert rows["right05.jpg"]["used"] is False and rows["right05.jpg"]["dropped_round"] == 0
    assert "0.3" in rows["right05.jpg"]["reason"]
    # capped rounds: a warning, and the result is solved on the frames left (arrays consistent)
    with pytest.warns(RuntimeWarning, match="did not settle"):
        capped = calibrate_corners(real_cal.image_points_px, BOARD, (640, 480), labels=real_cal.labels,
                                   max_mean_reproj_px=0.3, max_rounds=1)
    assert "right05.jpg" not in capped.labels
    assert len(capped.labels) == len(capped.rvecs) == len(capped.residuals_px) == len(capped.per_view_rms_px) == 12
    # a threshold nothing meets -> clear error naming the threshold
    with pytest.raises(InputError, match="max_mean_reproj_px"):
        calibrate_corners(real_cal.image_points_px, BOARD, (640, 480), max_mean_reproj_px=0.05)


def test_real_maps(real_cal):
    cal = real_cal
    cov = cal.coverage(5.0)
    assert cov.count.shape == (96, 128) and cov.n_boards == 13
    assert cov.count.max() <= 13
    # the rasterised hull area matches the polygon areas (cells are counted by their centre)
    area = sum(cv2.contourArea(cv2.convexHull(c.astype(np.float32))) for c in cal.image_points_px)
    assert cov.count.sum() * 25.0 == pytest.approx(area, rel=0.03)
    # every board's centre cell is covered, the image's top-right corner never is (no board there)
    for c in cal.image_points_px:
        u, v = c.mean(0)
        assert cov.count[int((v + 0.5) // 5), int((u + 0.5) // 5)] >= 1
    assert cov.count[:10, -20:].sum() == 0
    # the squares' outline is larger than the inner corners' hull
    assert cal.coverage(5.0, hull="squares").count.sum() > cov.count.sum()
    em = cal.error_map(5.0)
    assert em.count.sum() == 13 * 54
    # corner-weighted mean of the cell means is the overall mean error
    allerr = np.concatenate([np.linalg.norm(r, axis=-1) for r in cal.residuals_px])
    ok = em.count > 0
    assert np.sum(em.mean_error_px[ok] * em.count[ok]) / em.count.sum() == pytest.approx(allerr.mean(), rel=1e-9)
    assert np.isnan(em.mean_error_px[~ok]).all()
    # the worst cell holds right05's bad corner near (102, 112) px
    s = em.summary()
    assert s["max_cell_mean_error_px"] > 2.0
    assert abs(s["max_cell_centre_px"][0] - 102) < 5 and abs(s["max_cell_centre_px"][1] - 112) < 5
    a = cal.asymmetry()
    assert 0 <= a["reflection_index"] <= 1 and a["reflection_pairs"] > 10
    assert -1 <= a["left_right"] <= 1 and -1 <= a["top_bottom"] <= 1


def test_maps_on_hand_built_input():
    # one square board 100x100 px: 20x20 cells of 5 px
    sq = np.array([[50.0, 50.0], [149.999, 50.0], [149.999, 149.999], [50.0, 149.999]])
    cov = coverage_map([sq, sq + 50.0], (300, 200), 5.0)
    assert cov.count.shape == (40, 60)
    assert cov.count.max() == 2 and cov.count.sum() == 800
    assert cov.count[20, 20] == 2 and cov.count[12, 12] == 1 and cov.count[5, 5] == 0
    # error map: two corners in one cell, one in another
    pts = np.array([[1.0, 1.0], [3.0, 2.0], [12.0, 1.0]])
    res = np.array([[0.3, 0.4], [0.0, -1.0], [2.0, 0.0]])
    em = reprojection_error_map(pts, res, (20, 10), 5.0)
    assert em.mean_error_px[0, 0] == pytest.approx(0.75) and em.count[0, 0] == 2
    assert em.mean_error_px[0, 2] == pytest.approx(2.0)
    np.testing.assert_allclose(em.mean_residual_px[0, 0], [0.15, -0.3])
    assert np.isnan(em.mean_error_px[1, 1])
    with pytest.raises(InputError):
        reprojection_error_map(pts, res[:2], (20, 10), 5.0)


def test_asymmetry_detects_one_sided_error():
    rng = np.random.default_rng(3)
    pts = rng.uniform([0, 0], [640, 480], size=(4000, 2))
    iid = rng.normal(0, 0.1, size=(4000, 2))
    sym = error_asymmetry(pts, iid, (320, 240), (640, 480), n_permutations=100)
    assert abs(sym["left_right"]) < 0.05 and abs(sym["top_bottom"]) < 0.05
    assert sym["reflection_index"] < sym["reflection_index_null_p95"] * 1.2
    # a systematic error on the right side only (not point-symmetric)
    extra = np.where(pts[:, :1] > 320, [[0.4, 0.0]], [[0.0, 0.0]])
    asym = error_asymmetry(pts, iid + extra, (320, 240), (640, 480), n_permutations=100)
    assert asym["left_right"] > 0.4
    assert asym["reflection_index"] > asym["reflection_index_null_p95"]
    assert asym["reflection_p_value"] < 0.05
    assert asym["residual_coherence"] > sym["residual_coherence"]


# ------------------------------------------------------------------------------------------ statistics
def test_paper_sigma_f_is_root_sum_square():
    row = paper_sigmas([0.1992, 0.1923, 0.1713, 0.1314, 5e-4, 0.0019, 3e-5, 5e-5, 0.0002])
    # the paper's Basler1 row prints 0.2768: sqrt(0.1992^2 + 0.1923^2) = 0.27688, truncated
    assert abs(row["sigma_f_px"] - 0.2768) < 1e-4
    assert row["sigma_c_px"] == 0.1713 and row["sigma_r_px"] == 0.1314
    with pytest.raises(InputError):
        paper_sigmas([1, 2, 3])


def test_synthetic_truth_and_opencv_sigmas_match_scatter():
    """Injected Gaussian corner noise (0.2 px per coordinate) on 15 exact board views, 50 campaigns.

    The recovered intrinsics are unbiased (mean within 4 standard errors of the truth), the
    residual-based noise estimate recovers 0.2 px, and OpenCV's reported standard deviations
    match the scatter over campaigns: with 50 campaigns a sample standard deviation is uncertain
    by 1/sqrt(2*49) = 10 %, so each parameter's ratio must lie in [0.7, 1.4] (3-4 standard errors),
    and the median over the nine parameters in [0.85, 1.18] -- tight enough to catch a sqrt(2)
    convention error (ratio 0.71 or 1.41).
    """
    cam = DEFAULT_CAMERA.scaled(0.4)
    rv, tv = make_board_poses(cam, PAPER_BOARD, 15, seed=3)
    rng = np.random.default_rng(7)
    M, sig = 50, 0.2
    vals, stds, sigs = [], [], []
    for _ in range(M):
        cal = calibrate_corners(noisy_corners(cam, PAPER_BOARD, rv, tv, sig, seed=rng), PAPER_BOARD,
                                cam.image_size_px)
        vals.append(cal.values)
        stds.append(cal.std_opencv)
        sigs.append(cal.corner_sigma_px)
    vals, stds = np.array(vals), np.array(stds)
    scatter = vals.std(0, ddof=1)
    reported = np.sqrt(np.mean(stds**2, 0))
    bias_in_se = (vals.mean(0) - cam.values) / (scatter / np.sqrt(M))
    assert np.all(np.abs(bias_in_se) < 4), dict(zip(INTRINSIC_NAMES, bias_in_se, strict=True))
    ratio = scatter / reported
    assert np.all((ratio > 0.7) & (ratio < 1.4)), dict(zip(INTRINSIC_NAMES, ratio, strict=True))
    assert 0.85 < np.median(ratio) < 1.18
    assert np.mean(sigs) == pytest.approx(sig, rel=0.03)


def test_synthetic_covariance_and_bootstrap():
    cam = DEFAULT_CAMERA.scaled(0.4)
    rv, tv = make_board_poses(cam, PAPER_BOARD, 12, seed=4)
    cs = noisy_corners(cam, PAPER_BOARD, rv, tv, 0.2, seed=11)
    cal = calibrate_corners(cs, PAPER_BOARD, cam.image_size_px, bootstrap=24, seed=2)
    np.testing.assert_allclose(cal.std_jacobian, cal.std_opencv, rtol=1e-4)
    w = np.linalg.eigvalsh(cal.cov_jacobian)
    assert w.min() > 0
    corr = cal.cov_jacobian[0, 1] / np.sqrt(cal.cov_jacobian[0, 0] * cal.cov_jacobian[1, 1])
    assert corr > 0.5  # fx and fy move together
    b = cal.bootstrap
    assert b.samples.shape == (24, 9) and b.n_failed == 0
    # iid noise: bootstrap over views and first-order sigmas agree within a factor 1.6 (24 resamples, 12 views)
    ratio = b.std / cal.std_opencv
    assert 1 / 1.6 < np.median(ratio) < 1.6
    # seeded and independent of the number of processes (resamples are drawn up front)
    again = calibrate_corners(cs, PAPER_BOARD, cam.image_size_px, bootstrap=24, seed=2, workers=2)
    # (OpenCV's thread count changes summation order: agreement to 1e-3 of the scatter, not bit for bit)
    assert np.all(np.abs(again.bootstrap.samples - b.samples) < 1e-3 * b.std)
    other = calibrate_corners(cs, PAPER_BOARD, cam.image_size_px, bootstrap=24, seed=3)
    assert not np.allclose(other.bootstrap.samples, b.samples)
    s = cal.summary()
    assert "comparison" in s and "verdict" in s["comparison"]
    assert set(s["paper_table"]) >= {"opencv", "jacobian", "bootstrap"}
    # budget from the bootstrap, and the 'max' of all sources
    bb = cal.to_budget("bootstrap")
    assert bb.focal_px == pytest.approx(math.hypot(b.std[0], b.std[1]))
    bm = cal.to_budget("max")
    assert bm.focal_px >= max(bb.focal_px, cal.to_budget().focal_px) - 1e-12


# ------------------------------------------------------------------------------------------ outputs
def test_save_outputs_and_budget_roundtrip(real_cal, tmp_path):
    files = real_cal.save(tmp_path, grid_px=5.0)
    for name in ("camera.yaml", "intrinsics.yaml", "budget.yaml", "summary.json", "report.md", "frames.csv",
                 "maps.npz", "coverage.png", "reprojection_error.png", "asymmetry.png", "view_errors.png",
                 "sigmas.png", "report.html"):
        assert (tmp_path / name).is_file() and name in files
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 5 and "sigma_f_px" in html
    b = load_budget(tmp_path / "budget.yaml")
    s = real_cal.std_opencv
    assert b.focal_px == pytest.approx(math.hypot(s[0], s[1]), rel=1e-12)
    assert b.principal_point_px == pytest.approx((s[2], s[3]), rel=1e-12)
    assert b.distortion == pytest.approx(tuple(s[4:9]), rel=1e-12)
    assert b.height_m == 0 and b.pan_deg == 0
    fs = cv2.FileStorage(str(tmp_path / "camera.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), real_cal.K, rtol=1e-12)
    np.testing.assert_allclose(fs.getNode("distortion_coefficients").mat().ravel(), real_cal.dist, rtol=1e-12)
    assert int(fs.getNode("image_width").real()) == 640
    fs.release()
    summ = json.loads((tmp_path / "summary.json").read_text())
    assert summ["opencv_version"] == cv2.__version__
    assert summ["frames"]["used"] == 13
    assert summ["paper_table"]["opencv"]["sigma_f_px"] == pytest.approx(math.hypot(s[0], s[1]))
    m = np.load(tmp_path / "maps.npz")
    assert m["coverage_count"].shape == (96, 128) and m["mean_error_px"].shape == (96, 128)
    assert int(m["corner_count"].sum()) == 13 * 54
    import yaml

    intr = yaml.safe_load((tmp_path / "intrinsics.yaml").read_text())
    assert intr["model"] == "opencv" and intr["image_size_px"] == [640, 480]
    np.testing.assert_allclose(intr["K"], real_cal.K, rtol=1e-15)
    # the OpenCV file is read by the core's reader, given a pose
    from footprint_uq.io import load_camera, load_intrinsics

    cam = load_camera(tmp_path / "camera.yaml", pose={"height_m": 6.0, "pan_deg": 0.0, "tilt_deg": 20.0})
    np.testing.assert_allclose(cam.K, real_cal.K, rtol=1e-12)
    K, dist, size = load_intrinsics(tmp_path / "camera.yaml")
    np.testing.assert_allclose(K, real_cal.K, rtol=1e-12)
    np.testing.assert_allclose(dist, real_cal.dist, rtol=1e-12)
    assert tuple(size) == (640, 480)
    # full covariance: correlations from the Jacobian, scaled to the OpenCV sigmas
    bf = real_cal.to_budget(full_covariance=True)
    C = bf.param_covariance()
    from footprint_uq.params import param_index

    idx = param_index(INTRINSIC_NAMES)
    np.testing.assert_allclose(np.sqrt(np.diag(C[np.ix_(idx, idx)])), s, rtol=1e-9)


def test_calibrate_budget_propagate_pipeline(real_cal, tmp_path):
    """calibrate -> budget.yaml -> load_budget -> propagate on a camera with the calibrated intrinsics."""
    real_cal.save(tmp_path, figures=False)
    budget = load_budget(str(tmp_path / "budget.yaml"))
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # looking north, horizontal
    tilt = np.radians(25.0)
    Rt = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    R = Rt @ R
    C = np.array([0.0, 0.0, 6.0])
    cam = OpenCVCamera(real_cal.K, real_cal.dist, R, -R @ C, real_cal.image_size_px)
    uv = np.array([[320.0, 400.0], [100.0, 300.0], [600.0, 450.0]])
    est = propagate(cam, budget, uv)
    assert est.valid.all()
    assert np.all(np.isfinite(est.cov_m2))
    assert np.all(np.linalg.eigvalsh(est.cov_m2) > 0)
    # intrinsic-only budget: doubling every sigma quadruples the covariance
    est2 = propagate(cam, budget.scaled(2.0), uv)
    np.testing.assert_allclose(est2.cov_m2, 4 * est.cov_m2, rtol=1e-9)
    # and the calibrated intrinsics' uncertainty is a few centimetres at ~10 m, not metres
    assert np.sqrt(np.linalg.eigvalsh(est.cov_m2)).max() < 1.0
    # the same through the CLI: footprint-uq locate --camera (calibrated K, dist + pose) --budget budget.yaml
    from footprint_uq.cli.main import main
    from footprint_uq.io import save_camera

    save_camera(cam, tmp_path / "cam.yaml")
    r = CliRunner().invoke(main, ["locate", "--camera", str(tmp_path / "cam.yaml"), "--budget",
                                  str(tmp_path / "budget.yaml"), "--pixel", "320", "400", "--format", "json"])
    assert r.exit_code == 0, r.output
    rec = json.loads(r.stdout)[0]
    # a budget of intrinsics only is named as such: on stderr and in the record (issue 24)
    assert "extrinsic" in r.stderr and rec["budget_missing_terms"]
    np.testing.assert_allclose(rec["cov_m2"], est.cov_m2[0], rtol=1e-6, atol=1e-12)


# ------------------------------------------------------------------------------------------ bad input
def test_unreadable_and_missing_images_are_reported_not_fatal(tmp_path):
    for f in sorted(DATA.glob("*.jpg"))[:4]:
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "broken.jpg").write_bytes(b"not an image at all")
    cal = calibrate_intrinsics([tmp_path, str(tmp_path / "missing.png"), str(tmp_path / "nomatch_*.png")], BOARD,
                               workers=1)
    reasons = {d.label: d.reason for d in cal.detections if not d.found}
    assert "unreadable" in reasons["broken.jpg"]
    assert "file not found" in reasons["missing.png"]
    assert "file not found" in reasons["nomatch_*.png"]
    assert len(cal.labels) == 4
    rows = {r["label"]: r for r in cal.frames_table()}
    assert rows["broken.jpg"]["found"] is False and rows["right01.jpg"]["used"] is True


def test_wrong_board_size_lists_frames_and_fails_clearly():
    dets = detect_frames(sorted(DATA.glob("*.jpg"))[:3], "10x7", workers=1, progress=False, method="classic")
    assert [d.found for d in dets] == [False] * 3
    assert all("no board found (10x7" in d.reason for d in dets)
    with pytest.raises(InputError, match="no board found"):
        calibrate_intrinsics(sorted(DATA.glob("*.jpg"))[:3], "10x7", workers=1, method="classic")


def test_too_few_frames_and_bad_arguments():
    with pytest.raises(InputError, match="at least 3 views"):
        calibrate_intrinsics(sorted(DATA.glob("*.jpg"))[:2], BOARD, workers=1)
    with pytest.raises(InputError, match="board"):
        parse_board("9by6")
    with pytest.raises(InputError):
        Checkerboard(1, 6)
    with pytest.raises(InputError):
        parse_board("9x6", square_m=-1)
    with pytest.raises(InputError, match="corners"):
        calibrate_corners([np.zeros((50, 2))] * 3, BOARD, (640, 480))
    with pytest.raises(InputError, match="finite"):
        calibrate_corners([np.full((54, 2), np.nan)] * 3, BOARD, (640, 480))
    with pytest.raises(InputError, match="min_views"):
        calibrate_corners([np.zeros((54, 2))] * 3, BOARD, (640, 480), min_views=2)
    with pytest.raises(InputError, match="video_step"):
        expand_inputs([str(DATA)], video_step=0)


def test_image_size_mismatch_is_reported(tmp_path):
    for f in sorted(DATA.glob("*.jpg"))[:4]:
        shutil.copy(f, tmp_path / f.name)
    big = cv2.resize(cv2.imread(str(DATA / "right06.jpg")), (800, 600))
    cv2.imwrite(str(tmp_path / "right99_big.png"), big)
    with pytest.warns(RuntimeWarning, match="1 of 5 frames left out: their image size differs"):  # said aloud
        cal = calibrate_intrinsics(tmp_path, BOARD, workers=1)
    det = {d.label: d for d in cal.detections}
    assert det["right99_big.png"].found is False and "differs" in det["right99_big.png"].reason
    assert len(cal.labels) == 4 and cal.image_size_px == (640, 480)


def test_video_input_with_frame_step(tmp_path):
    path = tmp_path / "calib.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5, (640, 480), isColor=False)
    assert w.isOpened()
    files = sorted(DATA.glob("*.jpg"))[:8]
    for f in files:
        w.write(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE))
    w.release()
    dets = detect_frames([path], BOARD, video_step=2, workers=2, progress=False)
    assert [d.source.frame_index for d in dets] == [0, 2, 4, 6]
    assert dets[1].label == "calib.avi#frame=2"
    assert all(d.found for d in dets)
    # parallel detection equals serial detection
    serial = detect_frames([path], BOARD, video_step=2, workers=1, progress=False)
    for a, b in zip(dets, serial, strict=True):
        np.testing.assert_array_equal(a.corners_px, b.corners_px)


# ------------------------------------------------------------------------------------------ CLI
def _cli():
    from footprint_uq.cli.calibrate import calibrate
    from footprint_uq.cli.main import FootprintUQGroup

    return FootprintUQGroup(name="footprint-uq", commands={"calibrate": calibrate})


def test_cli_intrinsics(tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(_cli(), ["calibrate", "intrinsics", str(DATA / "right0*.jpg"), "--board", "9x6",
                                    "--square-m", "0.025", "--out", str(out), "--max-mean-reproj-px", "0.3",
                                    "--bootstrap", "10", "--workers", "1", "--grid-px", "10", "--quiet"])
    assert r.exit_code == 0, r.output
    assert "dropped" in r.output and "sigma (bootstrap" in r.output
    summ = json.loads((out / "summary.json").read_text())
    assert summ["frames"]["input"] == 9 and summ["filter"]["dropped"][0]["label"] == "right05.jpg"
    assert summ["maps"]["coverage"]["cell_px"] == 10.0
    assert np.load(out / "maps.npz")["coverage_count"].shape == (48, 64)
    load_budget(out / "budget.yaml")


def test_cli_errors_exit_2(tmp_path):
    out = tmp_path / "o"
    r = CliRunner().invoke(_cli(), ["calibrate", "intrinsics", str(DATA / "right0[1-4].jpg"), "--board", "10x7",
                                    "--square-m", "0.025", "--out", str(out), "--workers", "1", "--quiet",
                                    "--method", "classic"])
    assert r.exit_code == 2
    assert "no board found" in r.output
    assert (out / "frames.csv").read_text().count("no board found") == 4
    r = CliRunner().invoke(_cli(), ["calibrate", "intrinsics", str(DATA), "--board", "9by6", "--square-m", "0.025",
                                    "--out", str(out)])
    assert r.exit_code == 2 and "COLSxROWS" in r.output
    r = CliRunner().invoke(_cli(), ["calibrate", "intrinsics", str(DATA), "--board", "9x6", "--square-m", "0.025",
                                    "--out", str(out), "--budget-source", "bootstrap"])
    assert r.exit_code == 2 and "--bootstrap" in r.output
