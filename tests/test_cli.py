"""The footprint-uq command line: outputs equal the API, files are written, bad input exits 2 in one line."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq import PanTiltCamera, ellipse_axes, propagate, status
from footprint_uq.cli.main import main
from footprint_uq.io import load_camera, save_camera
from footprint_uq.products.locate import CSV_KEYS, LOCATE_KEYS
from footprint_uq.products.maps import UncertaintyMap

CAM_KW = {"focal_px": 400.0, "image_size_px": (320, 240), "height_m": 7.5, "pan_deg": 200.0, "tilt_deg": 14.0,
          "roll_deg": -2.0, "position_m": (12.0, -4.0)}
PIXELS = [(160.0, 200.0), (10.5, 130.25), (300.0, 5.0)]  # the last one is above the horizon


@pytest.fixture(scope="module")
def camera_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("cam") / "camera.yaml"
    save_camera(PanTiltCamera(**CAM_KW), p)
    return p


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _pixel_args():
    out = []
    for u, v in PIXELS:
        out += ["--pixel", u, v]
    return out


def test_locate_json_equals_api(camera_file):
    r = run("locate", "--camera", camera_file, "--budget", "bw-cube1", *_pixel_args())
    assert r.exit_code == 0, r.output
    recs = json.loads(r.stdout)
    cam = load_camera(camera_file)
    est = propagate(cam, "bw-cube1", np.array(PIXELS))
    a, b, ang = ellipse_axes(est.cov_m2)
    assert est.valid.tolist() == [True, True, False]
    assert len(recs) == len(PIXELS)
    for i, rec in enumerate(recs):
        assert tuple(rec) == LOCATE_KEYS  # exactly these keys, in this order
        assert (rec["u_px"], rec["v_px"]) == PIXELS[i]
        assert rec["valid"] is bool(est.valid[i])
        if est.valid[i]:
            assert rec["reason"] is None
            assert [rec["x_m"], rec["y_m"]] == est.xy_world_m[i].tolist()
            assert rec["cov_m2"] == est.cov_m2[i].tolist()
            assert rec["sigma_major_m"] == a[i] and rec["sigma_minor_m"] == b[i]
            assert rec["orientation_deg"] == ang[i]
            assert rec["nonlinearity"] == est.nonlinearity[i] and rec["linear_ok"] is bool(est.linear_ok[i])
        else:
            assert rec["reason"] == status.REASONS[status.ABOVE_HORIZON]
            assert rec["x_m"] is None and rec["y_m"] is None and rec["sigma_major_m"] is None
            assert rec["nonlinearity"] is None and rec["linear_ok"] is False
            assert rec["cov_m2"] == [[None, None], [None, None]]


def test_locate_csv_equals_api(camera_file):
    r = run("locate", "--camera", camera_file, "--budget", "basler2", "--format", "csv", *_pixel_args())
    assert r.exit_code == 0, r.output
    rows = list(csv.reader(io.StringIO(r.stdout)))
    assert tuple(rows[0]) == CSV_KEYS
    assert len(rows) == 1 + len(PIXELS)
    est = propagate(load_camera(camera_file), "basler2", np.array(PIXELS))
    a, b, ang = ellipse_axes(est.cov_m2)
    for i, row in enumerate(rows[1:]):
        d = dict(zip(CSV_KEYS, row, strict=True))
        assert d["valid"] == ("true" if est.valid[i] else "false")
        if est.valid[i]:
            c = est.cov_m2[i]
            assert [float(d[k]) for k in ("x_m", "y_m")] == est.xy_world_m[i].tolist()
            assert [float(d[k]) for k in ("cov_xx_m2", "cov_xy_m2", "cov_yy_m2")] == [c[0, 0], c[0, 1], c[1, 1]]
            assert float(d["sigma_major_m"]) == a[i] and float(d["sigma_minor_m"]) == b[i]
            assert float(d["orientation_deg"]) == ang[i]
            assert float(d["nonlinearity"]) == est.nonlinearity[i]
            assert d["linear_ok"] == ("true" if est.linear_ok[i] else "false")
            assert d["reason"] == ""
        else:
            assert np.isnan(float(d["x_m"])) and np.isnan(float(d["cov_xx_m2"]))
            assert d["reason"] == status.REASONS[status.ABOVE_HORIZON]


def test_locate_linearity_flag_and_threshold(tmp_path):
    cam = tmp_path / "cam.yaml"
    save_camera(PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 20.0), cam)
    args = ("locate", "--camera", cam, "--pixel", 959.5, 800, "--pixel", 959.5, 60)
    r = run(*args, "--budget", "bw-cube1@deg")
    assert r.exit_code == 0, r.output
    near, far = json.loads(r.stdout)
    assert near["linear_ok"] is True and near["nonlinearity"] < 0.01
    assert far["linear_ok"] is False and far["nonlinearity"] > 0.5
    assert "#2" in r.stderr and "linearisation error" in r.stderr and "#1" not in r.stderr
    # as printed (1e-3 deg) the same pixel is linear; a threshold of 1e-9 flags both
    assert all(rec["linear_ok"] for rec in json.loads(run(*args, "--budget", "bw-cube1").stdout))
    r = run(*args, "--budget", "bw-cube1", "--linear-threshold", 1e-9)
    assert [rec["linear_ok"] for rec in json.loads(r.stdout)] == [False, False]
    r = run(*args, "--budget", "bw-cube1", "--linear-threshold", -1)
    assert r.exit_code == 2 and "linear_threshold" in r.output


def test_locate_confidence(camera_file):
    r = run("locate", "--camera", camera_file, "--budget", "basler1", "--pixel", 100, 180, "--confidence", 0.95)
    assert r.exit_code == 0, r.output
    (rec,) = json.loads(r.stdout)
    assert tuple(rec) == LOCATE_KEYS + ("confidence", "semi_major_m", "semi_minor_m")
    assert rec["confidence"] == 0.95
    assert rec["semi_major_m"] == pytest.approx(2.447746830680816 * rec["sigma_major_m"], rel=1e-14)
    assert rec["semi_minor_m"] == pytest.approx(2.447746830680816 * rec["sigma_minor_m"], rel=1e-14)


def test_locate_budget_file_and_outside_pixel_warning(camera_file, tmp_path):
    b = tmp_path / "budget.yaml"
    b.write_text("name: site\nheight_m: 0.1\npan_deg: 0.2\ntilt_deg: 0.2\nimaging_px: 0.5\n")
    r = run("locate", "--camera", camera_file, "--budget", b, "--pixel", 400, 200)
    assert r.exit_code == 0, r.output
    assert "outside the 320x240 image" in r.stderr
    (rec,) = json.loads(r.stdout)
    est = propagate(load_camera(camera_file), b, np.array([400.0, 200.0]))
    assert rec["cov_m2"] == est.cov_m2.tolist()


def test_map_writes_files(camera_file, tmp_path):
    out = tmp_path / "map"
    r = run("map", "--camera", camera_file, "--budget", "basler1", "--out", out, "--step-px", 8,
            "--max-range-m", 150)
    assert r.exit_code == 0, r.output
    for name in ("map.npz", "uncertainty_image.png", "uncertainty_ground.png", "gsd.png", "nonlinearity.png",
                 "summary.json"):
        p = out / name
        assert p.is_file() and p.stat().st_size > 1000, name
        if name.endswith(".png"):
            assert p.read_bytes()[:4] == b"\x89PNG"
    m = UncertaintyMap.load_npz(out / "map.npz")
    assert m.shape == (30, 40) and m.step_px == 8 and m.max_range_m == 150
    s = json.loads((out / "summary.json").read_text())
    assert s["budget"] == "basler1" and s["grid_shape"] == [30, 40]
    assert s["semi_major_m_median"] == pytest.approx(float(np.median(m.semi_major_m[m.valid])))
    assert s["camera"]["model"] == "pan-tilt"
    assert "median" in r.stdout
    # the linearity flag is on by default: layer in the npz, headline in the summary and on stdout
    assert m.nonlinearity is not None and m.linear_threshold == 0.05
    assert s["fraction_linear_ok"] == pytest.approx(float(m.linear_ok[m.valid].mean()))
    assert "linear_ok" in r.stdout
    r = run("map", "--camera", camera_file, "--budget", "basler1", "--out", tmp_path / "off", "--step-px", 8,
            "--no-linearity")
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "off" / "nonlinearity.png").exists()
    assert UncertaintyMap.load_npz(tmp_path / "off" / "map.npz").nonlinearity is None
    r = run("map", "--camera", camera_file, "--budget", "basler1", "--out", tmp_path / "bad", "--linear-threshold", -1)
    assert r.exit_code == 2 and "linear_threshold" in r.stderr


def test_presets_formats():
    r = run("presets")
    assert r.exit_code == 0
    for name in ("Basler1", "Basler2", "BW-Cube1", "BW-Cube2", "BW-Bullet1", "BW-Bullet2", "0.2768", "0.8484"):
        assert name in r.stdout
    rows = json.loads(run("presets", "--format", "json").stdout)
    assert [row["name"] for row in rows] == ["basler1", "basler2", "bw-cube1", "bw-cube2", "bw-bullet1",
                                            "bw-bullet2"]
    assert rows[0]["height_m"] == 0.1936 and rows[0]["pan_deg"] == pytest.approx(0.1524e-3)
    lines = run("presets", "--format", "csv").stdout.strip().splitlines()
    assert len(lines) == 7 and lines[0].startswith("name,focal_px")


def test_presets_angle_reading_and_axes():
    rows = json.loads(run("presets", "bw-cube1", "BW-Cube1@deg", "--format", "json").stdout)
    assert [row["name"] for row in rows] == ["bw-cube1", "bw-cube1@deg"]
    assert rows[0]["pan_deg"] == pytest.approx(0.8032e-3) and rows[1]["pan_deg"] == pytest.approx(0.8032)
    # Table 3: sigma X 0.4912 (north), sigma Y 0.1910 (east)
    assert rows[0]["x_m"] == 0.1910 and rows[0]["y_m"] == 0.4912
    text = run("presets", "basler1@deg").stdout
    assert "Basler1@deg" in text and "@deg" in run("presets", "--help").stdout
    r = run("presets", "basler1@rad")
    assert r.exit_code == 2 and "@deg" in r.output and "Traceback" not in r.output


def test_demo_writes_report(tmp_path):
    out = tmp_path / "demo"
    r = run("demo", "--out", out, "--step-px", 24)
    assert r.exit_code == 0, r.output
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 8
    assert "http://" not in html and "https://" not in html  # self-contained
    for name in ("Basler1", "BW-Bullet1", "BW-Cube1"):
        assert name in html
    # it opens with the camera view (also a file: the README's picture) and a one-sentence verdict, tables after
    assert (out / "camera_view.png").read_bytes()[:4] == b"\x89PNG"
    body = html[html.index("</h1>") + 5:].lstrip()
    assert body.startswith('<section class="lead"><p class="verdict">For 6 cars') and body.index("<table") > \
        body.index("</section>")
    assert "footprint-uq: demo: camera view [" in r.stderr  # a line per stage
    for sub in ("basler1", "bw-bullet1", "bw-cube1"):
        assert (out / sub / "map.npz").is_file() and (out / sub / "uncertainty_ground.png").is_file()
    # the left-turn case study runs too and is linked from the report (or, without its optional
    # dependencies, the report says why it was skipped)
    import importlib.util

    if importlib.util.find_spec("pandas") is not None:
        assert (out / "case-study" / "report.html").is_file()
        assert 'href="case-study/report.html"' in html
    else:
        assert "case study skipped: it needs the Python package &#x27;pandas&#x27;" in html
        assert "case study skipped" in r.stderr
    cam = load_camera(out / "camera.yaml")
    assert cam.image_size_px == (1920, 1080) and cam.height_m == 8.0 and cam.tilt_deg == pytest.approx(20.0)


# -- bad input ---------------------------------------------------------------------------------
GOOD_CAMERA = ("model: pan-tilt\nimage_size_px: [320, 240]\nfocal_px: 400\nheight_m: 7.5\npan_deg: 10\n"
               "tilt_deg: 14\n")

BAD_CAMERAS = {
    "missing key": (GOOD_CAMERA.replace("height_m: 7.5\n", ""), "height_m"),
    "unknown key": (GOOD_CAMERA + "lens_colour: blue\n", "lens_colour"),
    "wrong units": (GOOD_CAMERA.replace("focal_px: 400", "focal_mm: 4"), "focal_mm"),
    "zero focal": (GOOD_CAMERA.replace("focal_px: 400", "focal_px: 0"), "focal_px"),
    "negative height": (GOOD_CAMERA.replace("height_m: 7.5", "height_m: -3"), "height_m"),
    "NaN": (GOOD_CAMERA.replace("focal_px: 400", "focal_px: .nan"), "focal_px"),
    "not yaml": ("model: [pan-tilt\n", "camera.yaml"),
    "not a rotation": ("model: opencv\nimage_size_px: [320, 240]\nK: [[400, 0, 160], [0, 400, 120], [0, 0, 1]]\n"
                       "R: [[1, 0, 0], [0, 2, 0], [0, 0, 1]]\nt: [0, 0, 5]\n", "R"),
}

BAD_BUDGETS = {
    "non-PD covariance": ("covariance:\n  names: [x_m, y_m]\n  matrix: [[1.0, 2.0], [2.0, 1.0]]\n",
                          "covariance.matrix"),
    "unknown key": ("height_m: 0.1\nheigth_m: 0.2\n", "heigth_m"),
    "wrong units": ("height_mm: 100\n", "height_mm"),
    "NaN": ("height_m: .nan\n", "height_m"),
    "negative sigma": ("pan_deg: -0.1\n", "pan_deg"),
    "not yaml": ("height_m: [0.1\n", "budget.yaml"),
}


def _assert_one_line_error(r, field):
    assert r.exit_code == 2, (r.exit_code, r.output, r.exception)
    err = r.stderr
    assert "Traceback" not in r.output
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert err.startswith("footprint-uq: error: ")
    assert field in err, (field, err)
    assert r.stdout == ""


@pytest.mark.parametrize("case", sorted(BAD_CAMERAS))
def test_bad_camera_file(case, tmp_path):
    text, field = BAD_CAMERAS[case]
    p = tmp_path / "camera.yaml"
    p.write_text(text)
    for cmd in (["locate", "--pixel", 1, 2], ["map", "--out", tmp_path / "o"]):
        r = run(cmd[0], "--camera", p, "--budget", "basler1", *cmd[1:])
        _assert_one_line_error(r, field)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("case", sorted(BAD_BUDGETS))
def test_bad_budget_file(case, tmp_path, camera_file):
    text, field = BAD_BUDGETS[case]
    p = tmp_path / "budget.yaml"
    p.write_text(text)
    _assert_one_line_error(run("locate", "--camera", camera_file, "--budget", p, "--pixel", 1, 2), field)


@pytest.mark.parametrize("args, field", [
    (["--camera", "{missing}", "--budget", "basler1", "--pixel", 1, 2], "camera file"),
    (["--camera", "{dir}", "--budget", "basler1", "--pixel", 1, 2], "camera file"),
    (["--camera", "{cam}", "--budget", "no-such-preset", "--pixel", 1, 2], "budget"),
    (["--camera", "{cam}", "--budget", "basler1", "--pixel", "nan", 2], "--pixel"),
    (["--camera", "{cam}", "--budget", "basler1", "--pixel", "abc", 2], "--pixel"),
    (["--camera", "{cam}", "--budget", "basler1"], "--pixel"),
    (["--budget", "basler1", "--pixel", 1, 2], "--camera"),
    (["--camera", "{cam}", "--budget", "basler1", "--pixel", 1, 2, "--format", "xml"], "--format"),
    (["--camera", "{cam}", "--budget", "basler1", "--pixel", 1, 2, "--confidence", 1.5], "confidence"),
    (["--camera", "{cam}", "--budget", "basler1", "--pixel", 1, 2, "--bogus"], "--bogus"),
])
def test_bad_locate_options(args, field, tmp_path, camera_file):
    subs = {"{missing}": tmp_path / "nope.yaml", "{dir}": tmp_path, "{cam}": camera_file}
    _assert_one_line_error(run("locate", *[subs.get(a, a) if isinstance(a, str) else a for a in args]), field)


def test_bad_map_options(tmp_path, camera_file):
    _assert_one_line_error(run("map", "--camera", camera_file, "--budget", "basler1", "--out", tmp_path,
                               "--step-px", 0), "--step-px")
    _assert_one_line_error(run("map", "--camera", camera_file, "--budget", "basler1", "--out", tmp_path,
                               "--max-range-m", -5), "max_range_m")


def test_real_process_exit_status_and_no_traceback(tmp_path, camera_file):
    """The installed entry point behaves the same in a real process."""
    bad = tmp_path / "camera.yaml"
    bad.write_text(BAD_CAMERAS["zero focal"][0])
    cmd = [sys.executable, "-m", "footprint_uq.cli", "locate", "--camera", str(bad), "--budget", "basler1",
           "--pixel", "160", "200"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stdout == "" and p.stderr.count("\n") == 1 and "focal_px" in p.stderr and "Traceback" not in p.stderr
    cmd[5] = str(camera_file)
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)[0]["valid"] is True


def test_registry_loads_every_command_lazily():
    """One registry line per command; a command's module is imported when the command is looked up, not
    before (so that `presets` does not pay for matplotlib); the groups register their subcommands explicitly."""
    from footprint_uq.cli.calibrate import calibrate
    from footprint_uq.cli.carla import carla

    names = ["calibrate", "camera", "carla", "case-study", "convert", "demo", "fuse", "locate", "map", "objects",
             "plan", "presets", "serve", "validate", "warmup"]
    assert main.list_commands(None) == names
    for name in names:
        assert main.get_command(None, name).name == name
    assert sorted(calibrate.commands) == ["budget", "extrinsics", "gcp", "intrinsics", "motion", "synthetic"]
    assert sorted(carla.commands) == ["capture", "export"]
    code = ("import sys; from footprint_uq.cli.main import main; "
            "before = 'footprint_uq.viz.map_report' in sys.modules; main.get_command(None, 'presets'); "
            "mid = 'footprint_uq.viz.map_report' in sys.modules; main.get_command(None, 'map'); "
            "print(before, mid, 'footprint_uq.viz.map_report' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.stdout.split() == ["False", "False", "True"], p.stderr


def test_a_long_value_keeps_its_start_and_end_in_the_message():
    """A long path in a one-line error keeps its file name (the end), not only its first 77 characters."""
    from footprint_uq.errors import InputError

    path = "/tmp/" + "deep/" * 30 + "d.parquet"
    msg = str(InputError("detections", path, "a regular file"))
    assert "d.parquet'" in msg and "'/tmp/deep/" in msg and "..." in msg
    assert len(msg) < 160
