"""Synthetic checkerboards: pose campaigns, rendering geometry (exact corners), end-to-end calibration."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from footprint_uq.calibration import PAPER_BOARD, Checkerboard, calibrate_intrinsics, detect_corners
from footprint_uq.calibration.synthetic import (
    DEFAULT_CAMERA,
    SyntheticCamera,
    make_board_poses,
    noisy_corners,
    project_corners,
    render_board,
    write_campaign,
)
from footprint_uq.errors import InputError

CAM = DEFAULT_CAMERA.scaled(0.3)  # 576 x 360 px, same field of view and lens as the default camera
# a strongly distorting lens, to make the inverse mapping matter
FISHY = SyntheticCamera(300.0, 302.0, 290.0, 175.0, (576, 360), (-0.3, 0.12, 1e-3, -8e-4, -0.02))


def test_default_camera_and_scaling():
    assert DEFAULT_CAMERA.image_size_px == (1920, 1200)
    assert CAM.image_size_px == (576, 360)
    assert CAM.fx_px == pytest.approx(0.3 * DEFAULT_CAMERA.fx_px)
    # the same ray passes through the same (scaled) pixel position
    assert (CAM.cx_px + 0.5) / 0.3 - 0.5 == pytest.approx(DEFAULT_CAMERA.cx_px)
    with pytest.raises(InputError):
        SyntheticCamera(-1.0, 1.0, 0, 0, (10, 10))
    with pytest.raises(InputError):
        SyntheticCamera(1.0, 1.0, 0, 0, (10, 10), (0.1, 0.2))


def test_make_board_poses_cover_the_image():
    rv, tv = make_board_poses(CAM, PAPER_BOARD, 16, seed=2)
    assert rv.shape == (16, 3) and tv.shape == (16, 3)
    w, h = CAM.image_size_px
    centres = []
    for r, t in zip(rv, tv, strict=True):
        uv = project_corners(CAM, PAPER_BOARD, r, t)
        assert np.all((uv >= 0) & (uv <= [w - 1, h - 1]))
        R = cv2.Rodrigues(r)[0]
        assert t[2] > 0 and R[2, 2] > 0  # board in front, facing the camera
        # tilted out of fronto-parallel: Zhang's method needs non-parallel views
        c = R @ np.array([6.5 * PAPER_BOARD.square_m, 4 * PAPER_BOARD.square_m, 0]) + t
        ang = np.degrees(np.arccos(abs(R[:, 2] @ c) / np.linalg.norm(c)))
        assert ang < 70.0
        centres.append(uv.mean(0))
    centres = np.array(centres)
    # all four quadrants of the image hold board centres
    q = (centres[:, 0] > w / 2).astype(int) + 2 * (centres[:, 1] > h / 2)
    assert set(q) == {0, 1, 2, 3}
    # normals differ from view to view
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rv])
    assert np.degrees(np.arccos(np.clip(normals @ normals.T, -1, 1))).max() > 20
    # seeded
    rv2, tv2 = make_board_poses(CAM, PAPER_BOARD, 16, seed=2)
    np.testing.assert_array_equal(rv, rv2)
    rv3, _ = make_board_poses(CAM, PAPER_BOARD, 16, seed=3)
    assert not np.allclose(rv, rv3)


def test_make_board_poses_bad_input():
    with pytest.raises(InputError):
        make_board_poses(CAM, PAPER_BOARD, 2)
    with pytest.raises(InputError):
        make_board_poses(CAM, PAPER_BOARD, 5, fill=(0.5, 1.2))
    tiny = SyntheticCamera(30.0, 30.0, 9.5, 9.5, (20, 20))
    with pytest.raises(InputError, match="fits"):
        make_board_poses(tiny, PAPER_BOARD, 3, fill=(0.9, 0.95), margin_px=8)


@pytest.mark.parametrize("cam", [CAM, FISHY], ids=["default-lens", "strong-distortion"])
def test_render_geometry_is_the_lens_model(cam):
    """Square centres, margin and background land where cv2.projectPoints says (no blur, no noise)."""
    board = Checkerboard(14, 9, 0.1, 0.05)
    rv, tv = make_board_poses(cam, board, 3, seed=1)
    for r, t in zip(rv, tv, strict=True):
        img, corners = render_board(cam, board, r, t, supersample=3, blur_sigma_px=0, noise_sigma_dn=0,
                                    black_dn=20, white_dn=230, background_dn=100)
        assert img.shape == (360, 576) and img.dtype == np.uint8
        np.testing.assert_allclose(corners, project_corners(cam, board, r, t))
        s = board.square_m
        i, j = np.meshgrid(np.arange(-1, 14), np.arange(-1, 9))
        pts = np.stack([(i.ravel() + 0.5) * s, (j.ravel() + 0.5) * s, np.zeros(i.size)], -1)
        uv = project_corners(cam, board, r, t, pts)
        px = img[np.rint(uv[:, 1]).astype(int), np.rint(uv[:, 0]).astype(int)]
        expect = np.where((i.ravel() + 1 + j.ravel() + 1) % 2 == 0, 20, 230)
        np.testing.assert_array_equal(px, expect)
        # the white margin, halfway between the squares and the board's edge, and the background beyond
        margin = project_corners(cam, board, r, t, np.array([[-s - 0.025, 4 * s, 0], [14 * s + 0.025, 4 * s, 0]]))
        assert np.all(img[np.rint(margin[:, 1]).astype(int), np.rint(margin[:, 0]).astype(int)] == 230)
        assert img[0, 0] == 100 or img[-1, -1] == 100


def test_detected_corners_match_the_ground_truth():
    rv, tv = make_board_poses(CAM, PAPER_BOARD, 4, seed=6)
    rng = np.random.default_rng(0)
    errs = []
    for r, t in zip(rv, tv, strict=True):
        img, truth = render_board(CAM, PAPER_BOARD, r, t, supersample=3, blur_sigma_px=0.6, noise_sigma_dn=2.0,
                                  seed=rng)
        c, method = detect_corners(img, PAPER_BOARD)
        assert c is not None and method
        if np.linalg.norm(c[0] - truth[0]) > np.linalg.norm(c[0] - truth[-1]):
            c = c[::-1]
        errs.append(c - truth)
    e = np.concatenate(errs)
    # sub-pixel detection on 8-bit, blurred, noisy renders: a few hundredths of a pixel
    assert np.sqrt(np.mean(e**2)) < 0.1
    assert np.abs(e).max() < 0.4
    assert np.all(np.abs(e.mean(0)) < 0.02)  # no systematic offset (pixel-centre convention consistent)


def test_noise_and_seed():
    rv, tv = make_board_poses(CAM, PAPER_BOARD, 3, seed=0)
    exact = noisy_corners(CAM, PAPER_BOARD, rv, tv, 0.0)
    for c, r, t in zip(exact, rv, tv, strict=True):
        np.testing.assert_array_equal(c, project_corners(CAM, PAPER_BOARD, r, t))
    noisy = noisy_corners(CAM, PAPER_BOARD, rv, tv, 0.5, seed=1)
    d = np.concatenate([a - b for a, b in zip(noisy, exact, strict=True)])
    assert d.std() == pytest.approx(0.5, rel=0.1)
    img1, _ = render_board(CAM, PAPER_BOARD, rv[0], tv[0], supersample=2, seed=5)
    img2, _ = render_board(CAM, PAPER_BOARD, rv[0], tv[0], supersample=2, seed=5)
    np.testing.assert_array_equal(img1, img2)
    with pytest.raises(InputError):
        render_board(CAM, PAPER_BOARD, rv[0], tv[0], supersample=0)
    with pytest.raises(InputError):
        render_board(CAM, PAPER_BOARD, rv[0], tv[0], noise_sigma_dn=-1)


def test_rendered_campaign_end_to_end(tmp_path):
    """Render 12 views of the paper's 14x9 board, detect, calibrate: the truth is recovered.

    Tolerance: 4 OpenCV standard deviations per parameter.  The corner errors of a real
    detector on rendered images are not exactly independent and identically distributed
    (small position-dependent biases from blur and 8-bit quantisation), so the first-order
    sigmas are only approximately right; 4 sigma keeps the test meaningful (a wrong pixel
    convention, a lens-model mismatch or a rendering bug of 0.5 px shifts cx/cy or k1 by far more).
    """
    write_campaign(tmp_path, CAM, PAPER_BOARD, 12, seed=5, supersample=3)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert len(truth["frames"]) == 12
    np.testing.assert_allclose(truth["camera"]["K"], CAM.K)
    cal = calibrate_intrinsics(tmp_path, PAPER_BOARD, workers=1)
    assert len(cal.labels) == 12
    err_in_sigma = (cal.values - CAM.values) / cal.std_opencv
    assert np.all(np.abs(err_in_sigma) < 4), err_in_sigma
    assert abs(cal.K[0, 2] - CAM.cx_px) < 0.5 and abs(cal.K[1, 2] - CAM.cy_px) < 0.5
    assert cal.rms_px < 0.15
    # the recovered board poses are the true ones
    for lab, r, t in zip(cal.labels, cal.rvecs, cal.tvecs, strict=True):
        fr = next(f for f in truth["frames"] if f["image"] == lab)
        Rt = cv2.Rodrigues(np.array(fr["rvec"]))[0]
        Re = cv2.Rodrigues(r)[0]
        # the detector may number the corners from the other end: compare up to the board's 180 deg turn
        flip = np.diag([-1.0, -1.0, 1.0])
        c_true = Rt @ np.array([6.5 * 0.1, 4 * 0.1, 0]) + np.array(fr["tvec"])
        c_est = Re @ np.array([6.5 * 0.1, 4 * 0.1, 0]) + t
        assert np.linalg.norm(c_true - c_est) < 0.01 * np.linalg.norm(c_true)
        ang = min(np.degrees(np.arccos(np.clip((np.trace(Rt.T @ Re) - 1) / 2, -1, 1))),
                  np.degrees(np.arccos(np.clip((np.trace((Rt @ flip).T @ Re) - 1) / 2, -1, 1))))
        assert ang < 0.5


def test_simulate_campaigns_planning_table():
    from footprint_uq.calibration.synthetic import simulate_campaigns

    r = simulate_campaigns(CAM, PAPER_BOARD, 8, corner_noise_px=0.2, n_campaigns=6, bootstrap=5, seed=1)
    assert r["scatter"].shape == (9,) and r["opencv"].shape == (9,) and r["bootstrap"].shape == (9,)
    np.testing.assert_allclose(r["truth"], CAM.values)
    assert np.all(np.abs(r["mean"] - r["truth"]) < 5 * r["opencv"])
    assert set(r["paper"]) == {"scatter", "opencv", "bootstrap"}
    assert r["paper"]["opencv"]["sigma_f_px"] == pytest.approx(np.hypot(*r["opencv"][:2]))
    # more corner noise -> proportionally larger error sizes (first-order theory: linear in the noise)
    r2 = simulate_campaigns(CAM, PAPER_BOARD, 8, corner_noise_px=0.4, n_campaigns=6, seed=1)
    np.testing.assert_allclose(r2["opencv"] / r["opencv"], 2.0, rtol=0.25)
    with pytest.raises(InputError):
        simulate_campaigns(CAM, PAPER_BOARD, 8, n_campaigns=1)


def test_cli_synthetic_then_intrinsics(tmp_path):
    from click.testing import CliRunner

    from footprint_uq.cli.calibrate import calibrate
    from footprint_uq.cli.main import FootprintUQGroup

    cli = FootprintUQGroup(name="footprint-uq", commands={"calibrate": calibrate})
    syn = tmp_path / "syn"
    r = CliRunner().invoke(cli, ["calibrate", "synthetic", "--out", str(syn), "--views", "6", "--scale", "0.3",
                                 "--supersample", "2", "--plan", "3", "--plan-bootstrap", "5", "--seed", "4"])
    assert r.exit_code == 0, r.output
    assert len(list(syn.glob("board_*.png"))) == 6
    plan = json.loads((syn / "plan.json").read_text())
    assert plan["n_views"] == 6 and len(plan["scatter"]) == 9 and "sigma_f_px" in plan["paper"]["opencv"]
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["calibrate", "intrinsics", str(syn), "--board", "14x9", "--square-m", "0.1",
                                 "--out", str(out), "--workers", "1", "--quiet"])
    assert r.exit_code == 0, r.output
    summ = json.loads((out / "summary.json").read_text())
    assert summ["frames"]["used"] == 6
    assert abs(summ["intrinsics"]["fx_px"] - CAM.fx_px) < 5 * summ["std"]["opencv"]["fx_px"]
    r = CliRunner().invoke(cli, ["calibrate", "synthetic", "--out", str(tmp_path / "x"), "--camera",
                                 str(tmp_path / "missing.yaml")])
    assert r.exit_code == 2
