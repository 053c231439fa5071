"""The case-study report opened in headless Chromium: loads without errors, every figure displayed.

The pages are checked with the probe of tests/browser_probe.py (a checking script in a copy, ``--dump-dom``).
A screenshot is kept in the test's directory (``tmp_path``; set ``FOOTPRINT_UQ_TEST_OUT`` to keep it elsewhere).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from browser_probe import assert_leads_with_figure_and_verdict, keep_screenshot, need_chromium, probe, run_chromium

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    need_chromium()
    from footprint_uq.scenario import CaseStudyConfig
    from footprint_uq.viz.case_study_run import run_case_study

    out = tmp_path_factory.mktemp("report")
    cfg = CaseStudyConfig.from_dict({"trajectory": {"frame_rate_hz": 2.0}, "heatmap": {"step_m": 4.0}})
    paths = run_case_study(out, config=cfg, dpi=60)
    return paths


def test_report_loads_and_every_figure_is_displayed(report, tmp_path):
    html = report["report"].read_text(encoding="utf-8")
    n_fig = len(report["figures"])
    res = probe(html, tmp_path)
    assert res["errors"] == []
    assert res["n_img"] == n_fig + 1 == 11  # the first camera's view twice: leading the page and in its section
    for i, img in enumerate(res["imgs"]):
        assert img["complete"] and img["w"] > 100 and img["h"] > 100, (i, img)
        assert img["shown_w"] > 100, (i, img)  # laid out, not hidden
    assert res["title"].startswith("Left-turn case study")
    assert res["h2"] >= 4


def test_probe_detects_a_broken_figure(report, tmp_path):
    """Negative control: the same check flags a figure that does not decode."""
    html = report["report"].read_text(encoding="utf-8")
    i = html.index("data:image/png;base64,") + len("data:image/png;base64,")
    broken = html[:i] + "AAAA" + html[i + 40:]
    res = probe(broken, tmp_path)
    assert res["imgs"][0]["w"] == 0 and all(img["w"] > 0 for img in res["imgs"][1:])
    assert res["n_img"] == len(report["figures"]) + 1
    assert len(res["errors"]) == 1


def test_report_screenshot_kept(report, tmp_path):
    keep = Path(os.environ.get("FOOTPRINT_UQ_TEST_OUT", tmp_path))
    keep.mkdir(parents=True, exist_ok=True)
    shot = keep / "report_screenshot.png"
    p = run_chromium([f"--screenshot={shot}", "--window-size=1200,2400", "--hide-scrollbars",
              report["report"].as_uri()], tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000


# -- every HTML page the project writes: no horizontal overflow, every image loaded (issue 24) ----------------------
def _layout(html: str, tmp_path) -> dict:
    """Open ``html`` at 1200 px (scrollbars hidden) with the probe: overflowing elements, images."""
    return probe(html, tmp_path, hide_scrollbars=True)


def _assert_laid_out(res: dict, n_img_min: int):
    assert res["errors"] == []
    assert res["scroll_w"] <= res["view_w"], res["wide"]  # no horizontal overflow of the page
    assert res["wide"] == []
    assert res["scrolled"] == []  # nor a table hidden in a scrolling box (the statements table was, 1912 px wide)
    assert len(res["imgs"]) >= n_img_min
    bad = [i for i in res["imgs"] if not (i["complete"] and i["w"] > 0)]
    assert bad == []  # every image decoded


@pytest.fixture(scope="module")
def pages(report, tmp_path_factory):
    """Every kind of HTML page the project writes, small: the case study (the module's report), the demo, an
    intrinsic calibration and a ground-control-point solve."""
    from click.testing import CliRunner

    from footprint_uq.cli.main import main
    from footprint_uq.viz.demo import write_demo

    out = tmp_path_factory.mktemp("pages")
    found = {"case study": (report["report"], 10)}
    found["demo"] = (write_demo(out / "demo", step_px=48, case_study=False), 8)
    images = Path(__file__).parent / "data" / "opencv-chessboard-right"
    r = CliRunner().invoke(main, ["calibrate", "intrinsics", str(images), "--board", "9x6", "--square-m", "0.025",
                                  "--out", str(out / "cal"), "--quiet", "--workers", "1"])
    assert r.exit_code == 0, r.output
    found["intrinsic calibration"] = (out / "cal" / "report.html", 3)
    found["ground control points"] = (_gcp_page(out / "gcp"), 1)
    return found


def _gcp_page(out: Path) -> Path:
    import numpy as np

    from footprint_uq import PanTiltCamera
    from footprint_uq.calibration.gcp_run import run_gcp

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    xy = np.array([[x, y] for x in (-6.0, 0.0, 6.0) for y in (15.0, 25.0, 40.0)])
    xyz = np.c_[xy @ np.array([[np.cos(0.52), -np.sin(0.52)], [np.sin(0.52), np.cos(0.52)]]), np.zeros(len(xy))]
    uv = cam.project(xyz).uv_px + np.random.default_rng(1).normal(0, 0.5, (len(xy), 2))
    out.mkdir(parents=True, exist_ok=True)
    pts = out.parent / "gcp.csv"
    pts.write_text("u_px,v_px,x_m,y_m,z_m\n" + "".join(f"{a},{b},{c},{d},{e}\n" for (a, b), (c, d, e)
                                                     in zip(uv, xyz, strict=True)))
    run_gcp(pts, "1920x1080", out)
    return out / "summary.html"


@pytest.mark.parametrize("kind", ["case study", "demo", "intrinsic calibration", "ground control points"])
def test_every_page_fits_the_window_and_every_image_loads(pages, kind, tmp_path):
    path, n_img = pages[kind]
    _assert_laid_out(_layout(path.read_text(encoding="utf-8"), tmp_path), n_img)


@pytest.mark.parametrize("kind", ["case study", "demo", "intrinsic calibration", "ground control points"])
def test_reports_lead_with_their_figure_and_verdict(pages, kind, tmp_path):
    path, _ = pages[kind]
    html = path.read_text(encoding="utf-8")
    assert_leads_with_figure_and_verdict(_layout(html, tmp_path))
    keep_screenshot(path, f"report_{kind}", tmp_path)
    if kind == "case study":  # PASS and FAIL are explained before the first verdict is listed
        assert html.index("How to read the verdicts") < html.index("<strong>FAIL</strong>") < html.index("<td><b>")
    # negative control: the same page with a table moved in front of the lead fails the check
    moved = html.replace("<section class=\"lead\">", "<table><tr><td>x</td></tr></table><section class=\"lead\">", 1)
    with pytest.raises(AssertionError):
        assert_leads_with_figure_and_verdict(_layout(moved, tmp_path))


def test_demo_map_legends_say_what_they_draw(pages):
    """The demo's maps: the sky and the masked ground beyond the range are told apart; a linearity map with
    nothing to show (all linear_ok) is one sentence, not an empty image."""
    from footprint_uq.io import camera_from_dict
    from footprint_uq.products.maps import uncertainty_map
    from footprint_uq.viz.demo import DEMO_CAMERA
    from footprint_uq.viz.maps import _invalid_handles  # noqa: PLC2701 - the legend's entries themselves

    m = uncertainty_map(camera_from_dict(dict(DEMO_CAMERA)), "basler1", 48, max_range_m=120.0)
    labels = [h.get_label() for h in _invalid_handles(m)]
    assert labels[0].startswith("above the horizon") and labels[1].startswith("ground beyond 120 m")
    colours = [h.get_facecolor() for h in _invalid_handles(m)]
    assert colours[0] != colours[1]
    html = pages["demo"][0].read_text(encoding="utf-8")
    if m.summary()["fraction_linear_ok"] == 1.0:
        assert "every valid pixel is <code>linear_ok</code>" in html and "Linearity flag: predicted" not in html


def test_layout_probe_detects_overflow_and_a_broken_image(pages, tmp_path):
    """Negative control: a table that cannot wrap and an image that does not decode are both flagged."""
    html = pages["demo"][0].read_text(encoding="utf-8")
    wide = html.replace("<h2>", '<table><tr><td style="white-space:nowrap">' + "x" * 400 + "</td></tr></table><h2>",
                        1)
    res = _layout(wide, tmp_path)
    assert res["scroll_w"] > res["view_w"] and res["wide"]
    i = html.index("data:image/png;base64,") + len("data:image/png;base64,")
    res = _layout(html[:i] + "AAAA" + html[i + 40:], tmp_path)
    assert sum(not (x["complete"] and x["w"] > 0) for x in res["imgs"]) == 1


def test_case_study_tables_read_as_text(report):
    """The statements table wraps inside the page; the detail table has human headers and no NaN cells."""
    html = report["report"].read_text(encoding="utf-8")
    assert '<table class="wide">' in html
    detail = html[html.index("X/Y statement in detail"):html.index("<h2>Settings")]
    assert ">NaN<" not in html and "median_X_over_Y" not in detail and "frames_entry" not in detail
    assert "median σ_X / σ_Y, entry lane" in detail
