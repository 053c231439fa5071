"""The demonstration report: a roadside camera under three of the paper's budgets (``footprint-uq demo``).

:func:`write_demo` writes, per budget, the map report of :mod:`.map_report` (with a colour scale
common to all budgets), a range profile and one self-contained ``report.html``; optionally the
left-turn case study (:func:`.case_study_run.run_case_study`), linked from the report.  The folder is one
set, built hidden and swapped in together (:func:`footprint_uq.io.atomic.output_set`); it must be new or
hold only a previous demo's files.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ..io import camera_from_dict, camera_to_dict, save_camera
from ..io.atomic import check_output_folder, output_set
from ..products.footprints import FrameProcessor
from ..products.locate import locate_records
from ..products.maps import GSD_DEFINITION, uncertainty_map
from ..uncertainty.budget import ErrorBudget
from ..uncertainty.ellipse import ellipse_axes
from ..uncertainty.presets import display_name
from .camera_view import plot_camera_view
from .case_study_run import run_case_study
from .map_report import write_map_report
from .maps import plot_range_profile, save_figure
from .report import esc, html_page, html_table, img_tag, lead_block, write_html

__all__ = ["DEMO_CAMERA", "DEMO_PRESETS", "DEMO_PIXELS", "DEMO_OBJECTS", "write_demo"]

#: the demonstration camera: a roadside pole, full-HD camera (our pan-tilt camera-file keys)
DEMO_CAMERA = {
    "model": "pan-tilt",
    "image_size_px": [1920, 1080],
    "focal_px": 1400.0,
    "position_m": [0.0, 0.0],
    "height_m": 8.0,
    "pan_deg": 30.0,
    "tilt_deg": 20.0,
    "roll_deg": 0.0,
}
#: budgets compared by the demo (paper Tables 2-3)
DEMO_PRESETS = ("basler1", "bw-bullet1", "bw-cube1")
#: the example pixels of the report's table (image centre column, sides, near the horizon)
DEMO_PIXELS = ((959.5, 1079.0), (959.5, 800.0), (959.5, 539.5), (200.0, 400.0), (1700.0, 300.0), (959.5, 20.0))

_CASE_STUDY_TITLE = "<h2>Case study: left turn seen by two roadside cameras</h2>"


def _car(range_m: float, bearing_deg: float, yaw_deg: float, size_m=(4.6, 1.9, 1.5)) -> list[float]:
    b = np.deg2rad(bearing_deg)
    return [range_m * np.sin(b), range_m * np.cos(b), size_m[2] / 2.0, *size_m, float(np.deg2rad(yaw_deg))]


#: the demo's detected objects (3-D boxes in the world frame: x_m, y_m, z_m, length_m, width_m, height_m,
#: yaw_rad), 13 to 85 m from the pole, drawn with their ellipses in ``camera_view.png``
DEMO_OBJECTS = np.array([_car(13.0, 25.0, 60.0), _car(20.0, 42.0, 60.0), _car(28.0, 18.0, 150.0),
                         _car(42.0, 34.0, 60.0), _car(60.0, 22.0, 150.0), _car(85.0, 38.0, 60.0, (12.0, 2.5, 3.5))])


def _warn(msg: str) -> None:
    warnings.warn(msg, RuntimeWarning, stacklevel=3)


def write_demo(out_dir, *, step_px: int = 4, max_range_m: float = 120.0, presets: Sequence[str] = DEMO_PRESETS,
               progress: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None,
               case_study: bool = True) -> Path:
    """Build the demonstration: the roadside camera :data:`DEMO_CAMERA` under each budget in ``presets``.

    Parameters
    ----------
    out_dir : path
        Output directory (created).
    step_px : int
        Grid step of the maps, pixels.
    max_range_m : float
        Pixels beyond this ground range are masked.
    presets : sequence of str
        Budget presets to compare.
    progress : callable, optional
        Called with a short message at each step.
    warn : callable, optional
        Called with a one-line message when the case study is skipped (default: a
        :class:`RuntimeWarning`).
    case_study : bool
        Also run the paper's left-turn case study into ``out_dir/case-study`` and link it.

    Returns
    -------
    Path
        The report, ``out_dir/report.html``.  Next to it: ``camera.yaml``, ``camera_view.png`` (the camera's
        image with the 95 % ellipses of :data:`DEMO_OBJECTS` under every budget: the report's first figure), one
        sub-directory per preset with the map report (:func:`.map_report.write_map_report`) and
        ``range_profile.png``.
    """
    own = ("camera.yaml", "camera_view.png", "report.html", "range_profile.png", "case-study",
           *(ErrorBudget.preset(p).name for p in presets))
    check_output_folder(out_dir, own, "demo")
    with output_set(out_dir, own, "demo") as stage:
        _write_demo(stage, step_px, max_range_m, presets, progress, warn, case_study)
    return Path(out_dir) / "report.html"


def _write_demo(out: Path, step_px, max_range_m, presets, progress, warn, case_study) -> Path:
    """:func:`write_demo`'s files, into ``out`` (its staging folder)."""
    say = progress or (lambda msg: None)
    camera = camera_from_dict(dict(DEMO_CAMERA))
    cam_path = save_camera(camera, out / "camera.yaml")
    budgets = [ErrorBudget.preset(p) for p in presets]
    maps, files, prof = _maps_and_figures(camera, budgets, out, step_px, max_range_m, say)

    say("camera view")
    view = save_figure(plot_camera_view(camera, budgets, DEMO_OBJECTS, confidence=0.95,
                                        title="What the camera sees: detected cars and the 95 % ellipses of their "
                                              "ground positions"), out / "camera_view.png", dpi=110)
    cs_parts = _case_study_section(out, say, warn or _warn) if case_study else []
    say("report")
    parts = [_lead(camera, budgets, maps, view), _intro(cam_path)]
    parts += _figure_sections(budgets, maps, files, prof)
    parts += _summary_sections(budgets, maps, step_px, max_range_m)
    parts += _example_pixel_section(camera, budgets)
    parts += _camera_and_budget_sections(camera, budgets)
    parts += cs_parts
    parts += _ASSUMPTIONS
    return write_html(out / "report.html", html_page("footprint-uq demo: roadside camera uncertainty maps", parts))


def _maps_and_figures(camera, budgets, out: Path, step_px, max_range_m, say):
    """Maps of every budget on a common colour scale (so that the figures compare directly)."""
    maps = []
    for b in budgets:
        say(f"map: {b.name}")
        maps.append(uncertainty_map(camera, b, step_px, max_range_m=max_range_m))
    allv = np.concatenate([m.semi_major_m[m.valid] for m in maps])
    vmin, vmax = float(allv.min()), float(allv.max())
    files = {}
    for b, m in zip(budgets, maps, strict=True):
        say(f"figures: {b.name}")
        _, files[b.name] = write_map_report(camera, b, out / b.name, step_px=step_px, max_range_m=max_range_m,
                                            vmin_m=vmin, vmax_m=vmax, umap=m)
    prof = save_figure(plot_range_profile(maps, [display_name(b.name) for b in budgets]),
                       out / "range_profile.png")
    return maps, files, prof


def _lead(camera, budgets, maps, view: Path) -> str:
    """The report's opening: the camera view with the ellipses, and one sentence saying what it shows."""
    spans = []
    for b in budgets:
        est = FrameProcessor(camera, b).boxes3d(DEMO_OBJECTS)
        a = ellipse_axes(est.centre_cov_m2, confidence=0.95)[0]
        spans.append(f"{a.min():.2g}&ndash;{a.max():.2g}&nbsp;m with {esc(display_name(b.name))}")
    rng = np.hypot(DEMO_OBJECTS[:, 0], DEMO_OBJECTS[:, 1])
    lin = [m.summary()["fraction_linear_ok"] for m in maps]
    lin_text = (f"the first-order covariances hold for every pixel within {maps[0].max_range_m:g}&nbsp;m (all "
                "<code>linear_ok</code>)"
                if all(f == 1.0 for f in lin if f is not None) else
                "pixels where the first-order covariance is not reliable are hatched in the maps below")
    verdict = (f"For {len(DEMO_OBJECTS)} cars {rng.min():.0f}&ndash;{rng.max():.0f}&nbsp;m from this 8-m pole the "
               f"95&nbsp;% ellipse of each ground position has a semi-major axis of {', '.join(spans)}, growing "
               f"with range; {lin_text}.")
    return lead_block(view.read_bytes(), "The demo camera's image (drawn from its model): each car's 3-D box and the "
                      "95 % ellipse of its footprint centre under the three budgets, labelled with the largest "
                      "budget's semi-major axis; dotted: range rings from the pole's foot.", verdict)


def _intro(cam_path: Path) -> str:
    return (
        "<p>Ground-position uncertainty of every pixel of a roadside camera under the error budgets measured in "
        "Kusari et al., <i>Object level footprint uncertainty quantification in infrastructure based sensing</i> "
        "(Tables 2&ndash;3). Each pixel is back-projected onto a flat ground plane and the budget is propagated "
        "to a 2&times;2 covariance of the ground point with closed-form Jacobians (first order). "
        "Numbers are 1&nbsp;&sigma; unless stated; a 95&nbsp;% ellipse is 2.4477&times; larger. "
        f"World frame: x east, y north, metres; pan is a compass heading (see <code>docs/conventions.md</code>). "
        f"Generated by <code>footprint-uq demo</code>; camera file: <code>{esc(cam_path.name)}</code>.</p>")


def _case_study_section(out: Path, say, warn) -> list[str]:
    say("case study")
    try:
        cs = run_case_study(out / "case-study", progress=lambda msg: say(f"case study: {msg}"))
    except ModuleNotFoundError as e:  # an optional dependency of the case study is not installed
        msg = f"case study skipped: it needs the Python package '{e.name}' (pip install {e.name})"
        warn(msg)
        return [_CASE_STUDY_TITLE, f'<p class="note">{esc(msg)}.</p>']
    res = cs["result"]
    st = res.statements()
    held = sum(1 for x in st if x["holds"])
    rel = Path(cs["report"]).resolve().relative_to(out.resolve()).as_posix()
    return [_CASE_STUDY_TITLE,
            f"<p>The paper's case study (Section IV) is reproduced in <a href=\"{esc(rel)}\">"
            f"{esc(rel)}</a>: {len(res.scene)} frames, {len(res.camera_names)} cameras &times; "
            f"{len(res.type_names)} camera types; the paper's X/Y statement holds in {held} of {len(st)} "
            "camera/type/axis cases (details and reasons in that report).</p>"]


def _camera_and_budget_sections(camera, budgets) -> list[str]:
    cam_d = camera_to_dict(camera)
    cols = ["name", "focal_px", "pp_c_px", "pp_r_px", "x_m", "y_m", "height_m", "pan_deg", "tilt_deg",
            "imaging_px", "resolution_px"]
    return [
        "<h2>Camera</h2>",
        html_table([{"key": k, "value": (", ".join(f"{x:g}" for x in v) if isinstance(v, list) else v)}
                    for k, v in cam_d.items()], ["key", "value"], headers={"key": "parameter"}),
        "<h2>Error budgets (1&nbsp;&sigma;)</h2>",
        html_table([b.table_row() for b in budgets], cols),
        '<p class="note">Angular errors are the paper\'s printed values, which are in 10<sup>-3</sup> '
        "degrees; they are negligible next to the position and height errors. Roll and ground-plane "
        "errors were not measured in the paper and are zero here: a real site with uneven ground will be "
        "worse (add <code>ground_height_m</code> / <code>ground_slope_deg</code> to a budget file).</p>",
    ]


def _summary_sections(budgets, maps, step_px, max_range_m) -> list[str]:
    srows = []
    for b, m in zip(budgets, maps, strict=True):
        s = m.summary()
        thr = {t["semi_major_below_m"]: t for t in s["below_threshold"]}
        srows.append({
            "budget": display_name(b.name),
            "median semi-major [m]": s["semi_major_m_median"],
            "95th pct semi-major [m]": s["semi_major_m_p95"],
            "max range with semi-major < 0.5 m [m]": thr[0.5]["max_range_m"],
            "max range with semi-major < 1 m [m]": thr[1.0]["max_range_m"],
            "ground area with semi-major < 1 m [m²]": thr[1.0]["ground_area_m2"],
            "linear_ok [% of valid px]": (None if s["fraction_linear_ok"] is None
                                          else 100.0 * s["fraction_linear_ok"]),
        })
    return ["<h2>Summary</h2>", html_table(srows, floatfmt=".3g"),
            f"<p>Pixels beyond {max_range_m:g} m of ground range are masked; the grid step is {step_px} px. "
            "Ranges are horizontal distances from the camera foot point.</p>"]


def _example_pixel_section(camera, budgets) -> list[str]:
    prow = []
    for b in budgets:
        for r in locate_records(camera, b, np.array(DEMO_PIXELS), confidence=0.95):
            prow.append({"budget": display_name(b.name), "u_px": r["u_px"], "v_px": r["v_px"], "x_m": r["x_m"],
                         "y_m": r["y_m"], "semi_major_m (95 %)": r["semi_major_m"],
                         "semi_minor_m (95 %)": r["semi_minor_m"], "orientation_deg": r["orientation_deg"],
                         "status": "ok" if r["valid"] else r["reason"].split(":")[0]})
    return ["<h2>Example pixels (95&nbsp;% ellipse)</h2>", html_table(prow, floatfmt=".4g")]


def _linearity_part(m, f) -> str:
    """The linearity map, or one sentence when it has nothing to show (every valid pixel ``linear_ok``)."""
    s = m.summary()
    if s["fraction_linear_ok"] is None:
        return ""
    if s["fraction_linear_ok"] == 1.0:
        worst = np.nanmax(np.where(m.valid, m.nonlinearity, np.nan))
        return (f'<p class="note">Linearity flag: every valid pixel is <code>linear_ok</code> (the largest predicted '
                f"error of the linear 1-&sigma; semi-major axis is {100 * worst:.2g}&nbsp;%, threshold "
                f"{100 * m.linear_threshold:g}&nbsp;%), so there is no map to show.</p>")
    return img_tag(Path(f["nonlinearity_png"]).read_bytes(),
                   "Linearity flag: predicted relative error of the linear 1-sigma semi-major axis per pixel, with the "
                   f"{100 * m.linear_threshold:g} % contour (beyond it the covariance underestimates the spread).")


def _figure_sections(budgets, maps, files, prof: Path) -> list[str]:
    parts = ["<h2>Uncertainty along the image centre column</h2>",
             img_tag(prof.read_bytes(), "1-sigma semi-axes against ground range for the three budgets.")]
    for b in budgets:
        f = files[b.name]
        parts.append(f"<h2>{esc(display_name(b.name))}</h2>")
        parts.append(img_tag(f["image_png"].read_bytes(), "Semi-major axis per pixel (1 sigma), common colour "
                             "scale across budgets; grey: no ground intersection or beyond the maximum range."))
        parts.append(img_tag(f["ground_png"].read_bytes(), "The same on the ground (bird's-eye view)."))
        if f.get("nonlinearity_png") is not None and Path(f["nonlinearity_png"]).exists():
            parts.append(_linearity_part(maps[budgets.index(b)], f))
    parts.append("<h2>Ground sampling distance</h2>")
    parts.append(img_tag(files[budgets[0].name]["gsd_png"].read_bytes(),
                         "Metres of ground per pixel, along and across the line of sight (camera only, no budget)."))
    parts.append(f"<p>Definition: <code>{esc(GSD_DEFINITION)}</code>.</p>")
    return parts


_ASSUMPTIONS = ["<h2>Assumptions</h2><ul>"
                "<li>Flat ground plane; first-order (linear) propagation, accurate well below the horizon and "
                "under-estimating close to it (see <code>footprint_uq.linearity_ratio</code>).</li>"
                "<li>Camera-level errors (calibration, pose) are shared by all pixels of an image; the imaging and "
                "resolution noise is independent per pixel.</li>"
                "<li>The error sizes are those measured in the paper for its six cameras; use a budget file with "
                "your own calibration results for a real site.</li></ul>"]
