"""Ground-control-point calibration: coverage of the reported covariance, real chessboard corners, the
intrinsics' covariance, degenerate input, the GCP table, the CLI outputs."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from footprint_uq import PanTiltCamera, load_budget, propagate
from footprint_uq import params as P
from footprint_uq.calibration import calibrate_intrinsics, parse_board
from footprint_uq.calibration.extrinsics import Intrinsics
from footprint_uq.calibration.gcp import GCPSet, _params_from_Rt, read_gcp_csv, run_gcp, solve_gcp
from footprint_uq.cameras import general
from footprint_uq.cli.main import main
from footprint_uq.errors import ConsistencyWarning, InputError
from footprint_uq.io import load_camera
from gcp_campaigns import SIZE, campaign, coverage

CHESS = Path(__file__).parent / "data" / "opencv-chessboard-right"
POSE = list(range(P.XM, P.ROLL + 1))


def _scene(seed=3, n=12, z_sigma=0.3):
    rng = np.random.default_rng(seed)
    cam = PanTiltCamera(focal_px=1400, image_size_px=SIZE, height_m=8.0, pan_deg=30, tilt_deg=20, roll_deg=1.0,
                        position_m=(5.0, -3.0))
    uv = np.column_stack([rng.uniform(80, 1840, n), rng.uniform(560, 1000, n)])
    xyz = np.column_stack([cam.backproject(uv).xy_world_m, rng.normal(0, z_sigma, n)])
    return cam, general.project(cam.params, xyz).uv_px, xyz


# ------------------------------------------------------------------------------------------ coverage
@pytest.mark.parametrize("known", [True, False], ids=["intrinsics", "focal"])
def test_coverage_200_campaigns(known):
    # 200 seeded campaigns: binomial sd of a 95 % rate is 1.5 % (pose) and 0.9 % (600 test pixels)
    pose, pix = coverage(200, known_intrinsics=known, seed=11)
    assert abs(pose - 0.95) <= 0.045, pose
    assert abs(pix - 0.95) <= 0.03, pix


@pytest.mark.slow
@pytest.mark.parametrize("known", [True, False], ids=["intrinsics", "focal"])
def test_coverage_1000_campaigns(known):
    pose, pix = coverage(1000, known_intrinsics=known, seed=0)
    assert abs(pose - 0.95) <= 0.02, pose
    assert abs(pix - 0.95) <= 0.02, pix


def test_covariance_matches_monte_carlo():
    # one camera, 300 seeded noisy re-surveys: the spread of the solved pose vs the reported covariance
    cam, uv, xyz = _scene()
    rng = np.random.default_rng(5)
    intr = Intrinsics(cam.K, np.zeros(5), SIZE)
    ests = []
    for _ in range(300):
        g = GCPSet(uv + rng.normal(0, 1.0, uv.shape), xyz + rng.normal(0, 0.05, xyz.shape), 1.0, 0.05)
        ests.append(solve_gcp(g, SIZE, intrinsics=intr, leave_one_out=False).params[POSE])
    ref = solve_gcp(GCPSet(uv, xyz, 1.0, 0.05), SIZE, intrinsics=intr, leave_one_out=False)
    sd_mc = np.std(ests, axis=0, ddof=1)
    sd_lin = ref.sigma_params()[POSE]
    # 300 samples: the sample sd is within ~8 % (2 sigma) of the truth
    np.testing.assert_allclose(sd_mc, sd_lin, rtol=0.12)
    np.testing.assert_allclose(np.mean(ests, axis=0), cam.params[POSE], atol=0.3 * sd_lin.max())


def test_intrinsics_covariance_propagation_matches_finite_differences():
    # noise-free points: perturbing fx/fy/cx/k1 moves the pose by G d_int (the covariance's sensitivity)
    cam, uv, xyz = _scene(z_sigma=0.0)
    base = Intrinsics(cam.K, np.zeros(5), SIZE)
    C_int = np.zeros((13, 13))
    C_int[[0, 1, 2, 5], [0, 1, 2, 5]] = [4.0, 4.0, 9.0, 1e-4]
    s0 = solve_gcp(GCPSet(uv, xyz, 1.0, 0.05), SIZE, intrinsics=base, intrinsics_cov=C_int, leave_one_out=False)
    s_plain = solve_gcp(GCPSet(uv, xyz, 1.0, 0.05), SIZE, intrinsics=base, leave_one_out=False)
    added = s0.cov_params - s_plain.cov_params
    # numerical G from re-solving with perturbed intrinsics (the pixels stay: the camera's K is wrong)
    G = np.zeros((6, 13))
    for j, h in ((0, 0.5), (1, 0.5), (2, 0.5), (5, 1e-3)):
        cols = []
        for sgn in (1, -1):
            K = cam.K.copy()
            d = np.zeros(5)
            if j == 0:
                K[0, 0] += sgn * h
            elif j == 1:
                K[1, 1] += sgn * h
            elif j == 2:
                K[0, 2] += sgn * h
            else:
                d[0] = sgn * h
            s = solve_gcp(GCPSet(uv, xyz, 1.0, 0.05), SIZE, intrinsics=Intrinsics(K, d, SIZE), leave_one_out=False)
            cols.append(s.params[POSE])
        G[:, j] = (cols[0] - cols[1]) / (2 * h)
    expected = G @ C_int @ G.T
    np.testing.assert_allclose(added[np.ix_(POSE, POSE)], expected, rtol=2e-3, atol=1e-6 * np.abs(expected).max())
    # and the cross-covariance pose / intrinsics and the intrinsics block itself
    np.testing.assert_allclose(added[np.ix_(POSE, range(13))], G @ C_int, rtol=2e-3, atol=1e-9)
    np.testing.assert_allclose(s0.cov_params[:13, :13], C_int, atol=1e-15)


# ------------------------------------------------------------------------------------------ real chessboard
@pytest.fixture(scope="module")
def chess_cal():
    return calibrate_intrinsics(CHESS, parse_board("9x6", 0.025), workers=1)


def test_chessboard_corners_as_gcps_recover_opencv_pose(chess_cal):
    cal = chess_cal
    M = np.diag([1.0, -1.0, -1.0])  # board frame (z into the board) -> a Z-up world with the camera above
    obj = parse_board("9x6", 0.025).object_points() @ M.T
    for label, uv, rv, tv in zip(cal.labels, cal.image_points_px, cal.rvecs, cal.tvecs, strict=True):
        p_ref = _params_from_Rt(cal.K, cal.dist, cv2.Rodrigues(rv)[0] @ M, tv)
        with pytest.warns(ConsistencyWarning) if label == "right05.jpg" else _no_warning():
            s = solve_gcp(GCPSet(uv, obj, cal.rms_px, 0.0), cal.image_size_px, intrinsics=cal, leave_one_out=False)
        d = s.params[POSE] - p_ref[POSE]
        C = s.cov_params[np.ix_(POSE, POSE)]
        # the same optimum as OpenCV's per-view pose, far inside the reported covariance
        assert d @ np.linalg.solve(C, d) < 1e-4, label
        assert np.abs(d[:3]).max() < 1e-6, label  # metres
        assert np.all(s.sigma_params()[POSE] > 0)


class _no_warning:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("error", ConsistencyWarning)

    def __exit__(self, *a):
        return self._w.__exit__(*a)


def test_chessboard_outlier_is_named(chess_cal):
    # right05 holds one ~3 px corner error: the solve names it
    cal = chess_cal
    k = cal.labels.index("right05.jpg")
    obj = parse_board("9x6", 0.025).object_points() @ np.diag([1.0, -1.0, -1.0])
    with pytest.warns(ConsistencyWarning, match=r"GCP 46: residual"):
        solve_gcp(GCPSet(cal.image_points_px[k], obj, 0.25, 0.0), cal.image_size_px, intrinsics=cal,
                  leave_one_out=False)


# ------------------------------------------------------------------------------------------ degenerate input
def test_degenerate_inputs_refused_with_the_cause():
    cam, uv, xyz = _scene()
    intr = Intrinsics(cam.K, np.zeros(5), SIZE)
    with pytest.raises(InputError, match="at least 4 points"):
        solve_gcp(GCPSet(uv[:3], xyz[:3], 1.0, 0.05), SIZE, intrinsics=intr)
    with pytest.raises(InputError, match="at least 6 points"):
        solve_gcp(GCPSet(uv[:5], xyz[:5], 1.0, 0.05), SIZE)
    line = np.column_stack([np.linspace(8, 20, 8), np.linspace(10, 30, 8), np.zeros(8)])
    uvl = general.project(cam.params, line).uv_px
    with pytest.raises(InputError, match="not all on one line"):
        solve_gcp(GCPSet(uvl, line, 1.0, 0.05), SIZE, intrinsics=intr)
    flipped = uv.copy()
    flipped[:, 0] = SIZE[0] - 1 - flipped[:, 0]  # mirror image: no proper camera above the ground sees it
    flat = xyz.copy()
    flat[:, 2] = 0.0
    with pytest.raises(InputError, match="below the ground plane|behind the camera"):
        solve_gcp(GCPSet(flipped, flat, 1.0, 0.05), SIZE, intrinsics=intr)
    with pytest.raises(InputError, match="no convergence"):
        solve_gcp(GCPSet(uv + 1.0, xyz, 1.0, 0.05), SIZE, intrinsics=intr, max_iter=1)
    bad = uv.copy()
    bad[2] = (2000.0, 10.0)
    with pytest.raises(InputError, match="point 3 pixel"):
        solve_gcp(GCPSet(bad, xyz, 1.0, 0.05), SIZE, intrinsics=intr)
    with pytest.raises(InputError, match="image size"):
        solve_gcp(GCPSet(uv, xyz, 1.0, 0.05), (1280, 720), intrinsics=intr)


# ------------------------------------------------------------------------------------------ GCP table
def _write_csv(path, header, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


@pytest.mark.parametrize("header,row,match", [
    (["u_px", "v_px", "x_m", "y_m", "height"], [1, 2, 3, 4, 5], "column: got 'height'"),
    (["u_px", "v_px", "x_m"], [1, 2, 3], "a column y_m"),
    (["u_px", "v_px", "x_m", "y_m", "lat_deg"], [1, 2, 3, 4, 5], "either x_m"),
    (["u_px", "v_px", "x_m", "y_m"], [1, "a", 3, 4], "row 2 v_px"),
    (["u_px", "v_px", "x_m", "y_m", "sigma_px"], [1, 2, 3, 4, -1], "row 2 sigma_px"),
    (["u_px", "v_px", "x_m", "y_m"], [1, 2, 3], "4 cells"),
])
def test_bad_tables_refused(tmp_path, header, row, match):
    p = _write_csv(tmp_path / "g.csv", header, [row])
    with pytest.raises(InputError, match=match):
        read_gcp_csv(p)


def test_lat_lon_table_gives_the_same_camera(tmp_path):
    pytest.importorskip("pyproj")
    from footprint_uq.products.geo import GeoReference

    cam, uv, xyz = _scene()
    geo = GeoReference(origin_lat_deg=48.1, origin_lon_deg=11.6)
    lat, lon = geo.to_wgs84(xyz[:, :2])
    pa = _write_csv(tmp_path / "xy.csv", ["u_px", "v_px", "x_m", "y_m", "z_m"], np.column_stack([uv, xyz]).tolist())
    pb = _write_csv(tmp_path / "ll.csv", ["u_px", "v_px", "lat_deg", "lon_deg", "alt_m"],
                    np.column_stack([uv, lat, lon, xyz[:, 2] + 520.0]).tolist())
    a = read_gcp_csv(pa)
    b = read_gcp_csv(pb, origin_lat_deg=48.1, origin_lon_deg=11.6, origin_alt_m=520.0)
    np.testing.assert_allclose(b.xyz_world_m, a.xyz_world_m, atol=1e-6)
    assert b.georef == {"origin_lat_deg": 48.1, "origin_lon_deg": 11.6, "origin_alt_m": 520.0}
    c = read_gcp_csv(pb)  # default origin: mean lat/lon, median altitude
    assert c.georef["origin_alt_m"] == pytest.approx(np.median(xyz[:, 2]) + 520.0)


# ------------------------------------------------------------------------------------------ outputs / CLI
def test_run_gcp_outputs_are_consistent(tmp_path):
    cam, uv, xyz = _scene()
    rng = np.random.default_rng(2)
    uvn, xyzn = uv + rng.normal(0, 1, uv.shape), xyz + rng.normal(0, 0.05, xyz.shape)
    pts = _write_csv(tmp_path / "g.csv", ["name", "u_px", "v_px", "x_m", "y_m", "z_m"],
                     [[f"P{i}", *a, *b] for i, (a, b) in enumerate(zip(uvn, xyzn, strict=True))])
    out = tmp_path / "out"
    res = run_gcp(pts, "1920x1080", out)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["budget.yaml", "camera.yaml", "gcp.png", "residuals.csv", "summary.html", "summary.json"]
    sol = res["solution"]
    cam2 = load_camera(out / "camera.yaml")
    np.testing.assert_allclose(cam2.params, sol.params, rtol=1e-12, atol=1e-12)
    bud = load_budget(out / "budget.yaml")
    np.testing.assert_allclose(bud.param_covariance(), sol.cov_params, rtol=1e-9, atol=1e-18)
    # the budget through the core gives the solve's own ground covariance
    uv_test = np.array([[900.0, 800.0], [300.0, 650.0]])
    est = propagate(cam2, bud, uv_test)
    _, cov = sol.ground_covariance_m2(uv_test)
    np.testing.assert_allclose(est.cov_m2, cov, rtol=1e-6)
    # leave-one-out column: an explicit re-solve without point 4
    rows = list(csv.DictReader(open(out / "residuals.csv")))
    assert len(rows) == len(uv) and rows[4]["loo_status"] == "ok"
    keep = np.arange(len(uv)) != 4
    s4 = solve_gcp(GCPSet(uvn[keep], xyzn[keep], 1.0, 0.05), SIZE, leave_one_out=False)
    pred = general.project(s4.params, xyzn[4]).uv_px
    np.testing.assert_allclose([float(rows[4]["loo_du_px"]), float(rows[4]["loo_dv_px"])], uvn[4] - pred, atol=1e-5)
    assert "focal_px" in (out / "summary.html").read_text()
    assert yaml.safe_load((out / "camera.yaml").read_text())["model"] == "opencv"


def test_cli_gcp(tmp_path):
    cam, uv, xyz = _scene()
    pts = _write_csv(tmp_path / "g.csv", ["u_px", "v_px", "x_m", "y_m", "z_m"], np.column_stack([uv, xyz]).tolist())
    intr = tmp_path / "intr.yaml"
    from footprint_uq import save_camera

    save_camera(cam.to_opencv() if hasattr(cam, "to_opencv") else cam, intr)
    img = np.full((SIZE[1], SIZE[0], 3), 128, np.uint8)
    cv2.imwrite(str(tmp_path / "photo.png"), img)
    r = CliRunner().invoke(main, ["calibrate", "gcp", "--points", str(pts), "--image-size", "1920x1080",
                                  "--intrinsics", str(intr), "--image", str(tmp_path / "photo.png"),
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    assert "height_m=8" in r.output
    assert not [p for p in (tmp_path / "o").iterdir() if p.name.startswith(".")]  # no temporary files left
    few = _write_csv(tmp_path / "few.csv", ["u_px", "v_px", "x_m", "y_m"], np.column_stack([uv, xyz[:, :2]])[:3])
    r = CliRunner().invoke(main, ["calibrate", "gcp", "--points", str(few), "--image-size", "1920x1080",
                                  "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2
    assert r.output.count("\n") == 1 and "at least 6 points" in r.output
    r = CliRunner().invoke(main, ["calibrate", "gcp", "--points", str(pts), "--image-size", "1920by1080",
                                  "--out", str(tmp_path / "o3")])
    assert r.exit_code == 2 and "--image-size" in r.output


def test_campaign_generator_is_seeded():
    a = campaign(np.random.default_rng(1), known_intrinsics=True)
    b = campaign(np.random.default_rng(1), known_intrinsics=True)
    np.testing.assert_array_equal(a[1].uv_px, b[1].uv_px)


def test_cli_gcp_with_the_intrinsics_budget(tmp_path):
    cam, uv, xyz = _scene()
    pts = _write_csv(tmp_path / "g.csv", ["u_px", "v_px", "x_m", "y_m", "z_m", "sigma_px"],
                     np.column_stack([uv, xyz, np.full(len(uv), 0.5)]).tolist())
    from footprint_uq import save_camera

    intr = save_camera(cam, tmp_path / "intr.yaml")
    (tmp_path / "ib.yaml").write_text("focal_px: 6.0\nprincipal_point_px: [4.0, 3.0]\n")
    args = ["calibrate", "gcp", "--points", str(pts), "--image-size", "1920x1080", "--intrinsics", str(intr)]
    r1 = CliRunner().invoke(main, args + ["--out", str(tmp_path / "a")])
    r2 = CliRunner().invoke(main, args + ["--intrinsics-budget", str(tmp_path / "ib.yaml"), "--out",
                                          str(tmp_path / "b")])
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
    a, b = load_budget(tmp_path / "a" / "budget.yaml"), load_budget(tmp_path / "b" / "budget.yaml")
    assert "cx_px" in b.covariance_names and "cx_px" not in a.covariance_names
    Ca, Cb = a.param_covariance(), b.param_covariance()
    assert Cb[P.FX, P.FX] == pytest.approx(36.0) and Cb[P.CY, P.CY] == pytest.approx(9.0)
    assert np.all(np.diag(Cb)[POSE] > np.diag(Ca)[POSE])  # the intrinsics' uncertainty widens the pose
    assert np.any(Cb[np.ix_(POSE, [P.FX, P.CX, P.CY])] != 0)  # and correlates with it
    r = CliRunner().invoke(main, ["calibrate", "gcp", "--points", str(pts), "--image-size", "1920x1080",
                                  "--intrinsics-budget", str(tmp_path / "ib.yaml"), "--out", str(tmp_path / "c")])
    assert r.exit_code == 2 and "--intrinsics too" in r.output
