"""Core CLI commands: ``locate``, ``map``, ``presets`` and ``demo``.

Each command is a plain :class:`click.Command` registered in :mod:`footprint_uq.cli.main`.
Bad input raises :class:`~footprint_uq.errors.InputError` / ``ConfigError`` (or a
click usage error); the group prints it as one line and exits with status 2.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from pathlib import Path

import click
import numpy as np

from .. import status
from ..errors import InputError
from ..uncertainty.budget import ErrorBudget, load_budget
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.presets import PRESET_NAMES, display_name

__all__ = ["locate_cmd", "map_cmd", "presets_cmd", "demo_cmd", "locate_records", "LOCATE_KEYS", "CSV_KEYS",
           "run_map", "run_demo", "DEMO_CAMERA", "DEMO_PRESETS", "presets_table"]

#: keys of every ``locate`` record, in output order
LOCATE_KEYS = ("u_px", "v_px", "x_m", "y_m", "cov_m2", "sigma_major_m", "sigma_minor_m", "orientation_deg",
               "nonlinearity", "linear_ok", "valid", "reason")
#: extra keys when ``--confidence`` is given
CONFIDENCE_KEYS = ("confidence", "semi_major_m", "semi_minor_m")
#: CSV columns of ``locate`` (covariance flattened)
CSV_KEYS = ("u_px", "v_px", "x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "sigma_major_m", "sigma_minor_m",
            "orientation_deg", "nonlinearity", "linear_ok", "valid", "reason")

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


# -- shared helpers --------------------------------------------------------------------------
def _load_camera(path):
    from ..io import load_camera

    return load_camera(path)


def _load_budget(spec) -> ErrorBudget:
    return load_budget(spec)


def _check_confidence(confidence):
    if confidence is None:
        return None
    chi2_scale(confidence)  # raises InputError("confidence", ...) outside (0, 1)
    return float(confidence)


def _num(x):
    """float for JSON: None for NaN/inf."""
    x = float(x)
    return x if math.isfinite(x) else None


#: largest pixel coordinate accepted by --pixel (a million image widths away is already no pixel)
MAX_PIXEL_PX = 1e9


def locate_records(camera, budget, uv_px, *, confidence: float | None = None,
                   linear_threshold: float = 0.05) -> list[dict]:
    """The ``locate`` output as a list of dicts (keys :data:`LOCATE_KEYS`, plus
    :data:`CONFIDENCE_KEYS` when ``confidence`` is given).

    Numbers are those of :func:`footprint_uq.propagate` and
    :func:`footprint_uq.ellipse_axes`; invalid points have None numbers, ``valid``
    False and the reason text of :mod:`footprint_uq.status`.  ``nonlinearity`` is the
    predicted relative error of the linear 1-sigma semi-major axis and ``linear_ok``
    is ``nonlinearity <= linear_threshold`` (False for invalid points).
    """
    from ..uncertainty.propagation import propagate

    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    est = propagate(camera, budget, uv, linear_threshold=linear_threshold)
    a, b, ang = ellipse_axes(est.cov_m2)
    k = chi2_scale(confidence) if confidence is not None else None
    out = []
    for i in range(uv.shape[0]):
        ok = bool(est.valid[i])
        c = est.cov_m2[i]
        why = None if ok else status.REASONS[int(est.reason[i])]
        nums = (est.xy_world_m[i, 0], est.xy_world_m[i, 1], c[0, 0], c[0, 1], c[1, 1], a[i], b[i], ang[i])
        if ok and not np.all(np.isfinite(nums)):  # outputs are checked too: never valid with a missing number
            ok, why = False, "result is not finite (overflow or degenerate geometry)"
        rec = {
            "u_px": float(uv[i, 0]), "v_px": float(uv[i, 1]),
            "x_m": _num(est.xy_world_m[i, 0]), "y_m": _num(est.xy_world_m[i, 1]),
            "cov_m2": [[_num(c[0, 0]), _num(c[0, 1])], [_num(c[1, 0]), _num(c[1, 1])]],
            "sigma_major_m": _num(a[i]), "sigma_minor_m": _num(b[i]), "orientation_deg": _num(ang[i]),
            "nonlinearity": _num(est.nonlinearity[i]), "linear_ok": bool(ok and est.linear_ok[i]),
            "valid": ok, "reason": why,
        }
        if k is not None:
            rec.update({"confidence": confidence, "semi_major_m": _num(k * a[i]), "semi_minor_m": _num(k * b[i])})
        out.append(rec)
    return out


def _csv_text(records: list[dict], confidence) -> str:
    cols = list(CSV_KEYS) + (list(CONFIDENCE_KEYS) if confidence is not None else [])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)

    def cell(v):
        if v is None:
            return "nan"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return repr(v)
        return v

    for r in records:
        flat = dict(r)
        cov = flat.pop("cov_m2")
        flat["cov_xx_m2"], flat["cov_xy_m2"], flat["cov_yy_m2"] = cov[0][0], cov[0][1], cov[1][1]
        row = [cell(flat[c]) for c in cols]
        if not r["valid"]:
            row[cols.index("reason")] = r["reason"]
        else:
            row[cols.index("reason")] = ""
        w.writerow(row)
    return buf.getvalue()


# -- locate ---------------------------------------------------------------------------------
@click.command("locate")
@click.option("--camera", "camera_path", required=True, metavar="FILE",
              help="Camera file (YAML/JSON, OpenCV, ROS or TUMTraf; docs/file-formats.md).")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET",
              help=f"Error budget: a preset ({', '.join(PRESET_NAMES)}; append @deg to read Table 3's "
                   "angles as degrees instead of the printed 1e-3 deg) or a YAML/JSON budget file.")
@click.option("--pixel", "pixels", type=(float, float), multiple=True, required=True, metavar="U V",
              help="Pixel (u right, v down, origin at the centre of the top-left pixel); repeat for more.")
@click.option("--format", "fmt", type=click.Choice(["json", "csv"]), default="json", show_default=True)
@click.option("--confidence", type=float, default=None, metavar="P",
              help="Also report the semi-axes of the P-confidence ellipse (2-D chi-square, 0.95 -> 2.4477 sigma).")
@click.option("--linear-threshold", type=float, default=0.05, show_default=True, metavar="E",
              help="linear_ok is true where the predicted relative error of the linear 1-sigma semi-major axis "
                   "(nonlinearity) is at most E.")
def locate_cmd(camera_path, budget_spec, pixels, fmt, confidence, linear_threshold):
    """Ground position (x east, y north, metres) and 2x2 covariance (m^2) of pixels.

    One record per --pixel: u_px, v_px, x_m, y_m, cov_m2, sigma_major_m,
    sigma_minor_m (1 sigma), orientation_deg (major axis, counter-clockwise from
    east), nonlinearity (predicted relative error of the linear sigma_major_m:
    0.05 = 5 %), linear_ok (nonlinearity <= --linear-threshold), valid and reason
    (null when valid).  With --confidence P, also confidence, semi_major_m and
    semi_minor_m of the P ellipse.  A valid pixel that is not linear_ok is also
    reported on stderr: its covariance underestimates the spread (near the
    horizon; docs/uncertainty-model.md, "The linearity flag").
    """
    confidence = _check_confidence(confidence)
    uv = np.array(pixels, dtype=np.float64).reshape(-1, 2)
    bad = ~(np.isfinite(uv) & (np.abs(uv) <= MAX_PIXEL_PX)).all(-1)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"--pixel (#{i + 1})", tuple(pixels[i]),
                         f"finite pixel coordinates U V of magnitude <= {MAX_PIXEL_PX:g}")
    camera = _load_camera(camera_path)
    budget = _load_budget(budget_spec)
    outside = ~camera.in_image(uv)
    for i in np.flatnonzero(outside):
        w, h = camera.image_size_px
        click.echo(f"footprint-uq: warning: --pixel #{i + 1} ({uv[i, 0]:g}, {uv[i, 1]:g}) is outside the "
                   f"{w}x{h} image; computed anyway", err=True)
    records = locate_records(camera, budget, uv, confidence=confidence, linear_threshold=linear_threshold)
    for i, r in enumerate(records):
        if r["valid"] and not r["linear_ok"]:
            nl = r["nonlinearity"]
            click.echo(f"footprint-uq: warning: --pixel #{i + 1} ({uv[i, 0]:g}, {uv[i, 1]:g}): linearisation error "
                       f"predicted {100 * nl:.1f} % of sigma_major_m (> {100 * linear_threshold:g} %): the covariance "
                       "underestimates the spread", err=True)
    if fmt == "json":
        click.echo(json.dumps(records, indent=2, allow_nan=False))
    else:
        click.echo(_csv_text(records, confidence), nl=False)


# -- map ------------------------------------------------------------------------------------
MAP_FILES = {
    "npz": "map.npz",
    "image_png": "uncertainty_image.png",
    "ground_png": "uncertainty_ground.png",
    "gsd_png": "gsd.png",
    "summary_json": "summary.json",
}


def run_map(camera, budget, out_dir, *, step_px: int = 2, max_range_m: float | None = None,
            confidence: float | None = None, vmin_m=None, vmax_m=None, dpi: int = 150, umap=None):
    """Compute an uncertainty map and write its arrays, figures and summary into ``out_dir``.

    ``umap`` may be given (already computed for this camera and budget).
    Returns ``(umap, files)`` with ``files`` the :data:`MAP_FILES` keys mapped to paths.
    """
    from ..products.maps import uncertainty_map
    from ..viz import plot_ground_map, plot_gsd_maps, plot_image_map, save_figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if umap is None:
        umap = uncertainty_map(camera, budget, step_px, max_range_m=max_range_m)
    files = {k: out / v for k, v in MAP_FILES.items()}
    umap.save_npz(files["npz"])
    save_figure(plot_image_map(umap, confidence=confidence, vmin_m=vmin_m, vmax_m=vmax_m), files["image_png"],
                dpi=dpi)
    save_figure(plot_ground_map(umap, confidence=confidence, vmin_m=vmin_m, vmax_m=vmax_m), files["ground_png"],
                dpi=dpi)
    save_figure(plot_gsd_maps(umap), files["gsd_png"], dpi=dpi)
    from ..io import camera_to_dict

    summary = umap.summary(confidence=confidence)
    summary["camera"] = camera_to_dict(camera)
    summary["budget_parameters"] = umap.budget.to_dict()
    summary["files"] = {k: p.name for k, p in files.items()}
    from ..io.atomic import atomic_write_text

    atomic_write_text(files["summary_json"], json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return umap, files


@click.command("map")
@click.option("--camera", "camera_path", required=True, metavar="FILE", help="Camera file.")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET", help="Preset name or budget file.")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--step-px", type=click.IntRange(min=1), default=2, show_default=True,
              help="Grid step in pixels (1 = every pixel).")
@click.option("--max-range-m", type=float, default=None, metavar="M",
              help="Mask ground points farther than M metres from the camera foot point.")
@click.option("--confidence", type=float, default=None, metavar="P",
              help="Draw P-confidence semi-axes instead of 1 sigma (0.95 -> 2.4477 sigma).")
def map_cmd(camera_path, budget_spec, out_dir, step_px, max_range_m, confidence):
    """Per-pixel uncertainty map: PNG heat maps (image and bird's-eye), GSD maps, .npz arrays, summary.json."""
    confidence = _check_confidence(confidence)
    camera = _load_camera(camera_path)
    budget = _load_budget(budget_spec)
    umap, files = run_map(camera, budget, out_dir, step_px=step_px, max_range_m=max_range_m, confidence=confidence)
    s = umap.summary(confidence=confidence)
    for p in files.values():
        click.echo(f"wrote {p}")
    if s["semi_major_m_median"] is not None:
        lab = "1-sigma" if confidence is None else f"{100 * confidence:g} %"
        click.echo(f"valid pixels {100 * s['fraction_valid']:.1f} %; {lab} semi-major axis: median "
                   f"{s['semi_major_m_median']:.3g} m, 95th percentile {s['semi_major_m_p95']:.3g} m, "
                   f"max {s['semi_major_m_max']:.3g} m")
    else:
        click.echo("footprint-uq: warning: no pixel of this camera sees the ground", err=True)


# -- presets --------------------------------------------------------------------------------
_PRESET_ROWS = (
    ("focal_px", "px", "focal length"), ("pp_c_px", "px", "principal point, column"),
    ("pp_r_px", "px", "principal point, row"), ("k1", "-", "radial k1"), ("k2", "-", "radial k2"),
    ("p1", "-", "tangential p1"), ("p2", "-", "tangential p2"), ("k3", "-", "radial k3"),
    ("x_m", "m", "position east (Table 3 sigma Y)"), ("y_m", "m", "position north (Table 3 sigma X)"),
    ("height_m", "m", "height"),
    ("pan_deg", "deg", "pan (alpha)"), ("tilt_deg", "deg", "tilt (theta)"), ("roll_deg", "deg", "roll"),
    ("ground_height_m", "m", "ground height"), ("ground_slope_deg", "deg", "ground slope"),
    ("imaging_px", "px", "imaging noise (per point)"), ("resolution_px", "px", "resolution (per point)"),
)


def presets_table(names=None) -> list[dict]:
    """One row per preset (:meth:`ErrorBudget.table_row`), 1-sigma values, units in the keys.

    ``names``: preset names, each optionally with the ``@deg`` suffix; default the six presets
    with Table 3's angles as printed.
    """
    names = list(names) if names else list(PRESET_NAMES)
    return [ErrorBudget.preset(n).table_row() for n in names]


def _presets_text(rows) -> str:
    names = [display_name(r["name"]) for r in rows]
    header = ["parameter (1 sigma)", "unit"] + names
    body = [[desc, unit] + [f"{r[key]:.4g}" for r in rows] for key, unit, desc in _PRESET_ROWS]
    widths = [max(len(str(x)) for x in col) for col in zip(header, *body, strict=True)]
    lines = ["Error-budget presets: Kusari et al., Tables 2 (intrinsic) and 3 (extrinsic); imaging/resolution "
             "from Sec. III-D.",
             "Table 3's sigma X is north, sigma Y east (the paper's earth frame): world position (east, north) = "
             "(sigma Y, sigma X).",
             "Angles: NAME reads Table 3's sigma alpha/theta as printed, in 1e-3 deg (0.1524 -> 0.0001524 deg); "
             "NAME@deg reads them as degrees.",
             "Roll and ground-plane errors were not measured (0).", ""]
    fmt_row = lambda cells: "  ".join(  # noqa: E731
        (c.ljust(w) if i < 2 else c.rjust(w)) for i, (c, w) in enumerate(zip(cells, widths, strict=True)))
    lines.append(fmt_row(header))
    lines.append("  ".join("-" * w for w in widths))
    lines += [fmt_row(b) for b in body]
    return "\n".join(lines)


@click.command("presets")
@click.argument("names", nargs=-1, metavar="[NAME[@deg]]...")
@click.option("--format", "fmt", type=click.Choice(["text", "json", "csv"]), default="text", show_default=True)
def presets_cmd(names, fmt):
    """The error-budget presets of the paper (Tables 2-3): 1-sigma values of every source.

    Table 3's sigma X is along north and sigma Y along east (the paper's earth frame,
    docs/conventions.md): the world position sigma is (east, north) = (sigma Y, sigma X).
    Table 3 prints sigma alpha and sigma theta in 1e-3 deg. A preset name alone
    (basler1) reads them as printed: the default. NAME@deg (basler1@deg) reads the same
    numbers as degrees; the suffix works wherever a preset is accepted (--budget of
    every command, case-study camera_types, load_budget). Give NAMES to list only
    those, e.g. `footprint-uq presets basler1 basler1@deg`.
    """
    rows = presets_table(names)
    if fmt == "json":
        click.echo(json.dumps(rows, indent=2))
    elif fmt == "csv":
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
        click.echo(buf.getvalue(), nl=False)
    else:
        click.echo(_presets_text(rows))


# -- demo -----------------------------------------------------------------------------------
_DEMO_PIXELS = ((959.5, 1079.0), (959.5, 800.0), (959.5, 539.5), (200.0, 400.0), (1700.0, 300.0), (959.5, 20.0))


def run_demo(out_dir, *, step_px: int = 4, max_range_m: float = 120.0, presets=DEMO_PRESETS, progress=None,
             case_study: bool = True):
    """Build the demonstration: the roadside camera :data:`DEMO_CAMERA` under each budget in ``presets``.

    Writes, in ``out_dir``: ``camera.yaml``, one sub-directory per preset with the
    ``map`` outputs, ``range_profile.png`` and a self-contained ``report.html``;
    with ``case_study``, also the paper's left-turn case study in ``case-study/``
    (:func:`footprint_uq.cli.case_study.run_case_study`), linked from the report.
    Returns the path of the report.
    """
    from ..io import camera_from_dict, camera_to_dict, save_camera
    from ..products.maps import GSD_DEFINITION
    from ..viz import plot_range_profile, save_figure
    from ..viz.report import esc, html_page, html_table, img_tag, write_html

    say = progress or (lambda msg: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    camera = camera_from_dict(dict(DEMO_CAMERA))
    cam_path = save_camera(camera, out / "camera.yaml")
    budgets = [ErrorBudget.preset(p) for p in presets]

    # common colour scale across budgets so that the figures compare directly
    from ..products.maps import uncertainty_map

    maps = []
    for b in budgets:
        say(f"map: {b.name}")
        maps.append(uncertainty_map(camera, b, step_px, max_range_m=max_range_m))
    allv = np.concatenate([m.semi_major_m[m.valid] for m in maps])
    vmin, vmax = float(allv.min()), float(allv.max())
    files = {}
    for b, m in zip(budgets, maps, strict=True):
        say(f"figures: {b.name}")
        _, files[b.name] = run_map(camera, b, out / b.name, step_px=step_px, max_range_m=max_range_m,
                                   vmin_m=vmin, vmax_m=vmax, umap=m)
    prof = save_figure(plot_range_profile(maps, [display_name(b.name) for b in budgets]),
                       out / "range_profile.png")

    # -- report --------------------------------------------------------------------------
    say("report")
    parts = []
    cam_d = camera_to_dict(camera)
    parts.append(
        "<p>Ground-position uncertainty of every pixel of a roadside camera under the error budgets measured in "
        "Kusari et al., <i>Object level footprint uncertainty quantification in infrastructure based sensing</i> "
        "(Tables 2&ndash;3). Each pixel is back-projected onto a flat ground plane and the budget is propagated "
        "to a 2&times;2 covariance of the ground point with closed-form Jacobians (first order). "
        "Numbers are 1&nbsp;&sigma; unless stated; a 95&nbsp;% ellipse is 2.4477&times; larger. "
        f"World frame: x east, y north, metres; pan is a compass heading (see <code>docs/conventions.md</code>). "
        f"Generated by <code>footprint-uq demo</code>; camera file: <code>{esc(cam_path.name)}</code>.</p>")
    if case_study:
        from .case_study import run_case_study

        say("case study")
        try:
            cs = run_case_study(out / "case-study")
        except ModuleNotFoundError as e:  # an optional dependency of the case study is not installed
            cs = None
            msg = f"case study skipped: it needs the Python package '{e.name}' (pip install {e.name})"
            click.echo(f"footprint-uq: warning: {msg}", err=True)
            parts.append("<h2>Case study: left turn seen by two roadside cameras</h2>")
            parts.append(f'<p class="note">{esc(msg)}.</p>')
    if case_study and cs is not None:
        res = cs["result"]
        st = res.statements()
        held = sum(1 for x in st if x["holds"])
        rel = Path(cs["report"]).resolve().relative_to(out.resolve()).as_posix()
        parts.append("<h2>Case study: left turn seen by two roadside cameras</h2>")
        parts.append(f"<p>The paper's case study (Section IV) is reproduced in <a href=\"{esc(rel)}\">"
                     f"{esc(rel)}</a>: {len(res.scene)} frames, {len(res.camera_names)} cameras &times; "
                     f"{len(res.type_names)} camera types; the paper's X/Y statement holds in {held} of {len(st)} "
                     "camera/type/axis cases (details and reasons in that report).</p>")
    parts.append("<h2>Camera</h2>")
    parts.append(html_table([{"key": k, "value": (", ".join(f"{x:g}" for x in v) if isinstance(v, list) else v)}
                             for k, v in cam_d.items()], ["key", "value"], headers={"key": "parameter"}))
    parts.append("<h2>Error budgets (1&nbsp;&sigma;)</h2>")
    trows = [b.table_row() for b in budgets]
    cols = ["name", "focal_px", "pp_c_px", "pp_r_px", "x_m", "y_m", "height_m", "pan_deg", "tilt_deg",
            "imaging_px", "resolution_px"]
    parts.append(html_table(trows, cols))
    parts.append('<p class="note">Angular errors are the paper\'s printed values, which are in 10<sup>-3</sup> '
                 "degrees; they are negligible next to the position and height errors. Roll and ground-plane "
                 "errors were not measured in the paper and are zero here: a real site with uneven ground will be "
                 "worse (add <code>ground_height_m</code> / <code>ground_slope_deg</code> to a budget file).</p>")

    parts.append("<h2>Summary</h2>")
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
        })
    parts.append(html_table(srows, floatfmt=".3g"))
    parts.append(f"<p>Pixels beyond {max_range_m:g} m of ground range are masked; the grid step is {step_px} px. "
                 "Ranges are horizontal distances from the camera foot point.</p>")

    parts.append("<h2>Example pixels (95&nbsp;% ellipse)</h2>")
    prow = []
    for b in budgets:
        for r in locate_records(camera, b, np.array(_DEMO_PIXELS), confidence=0.95):
            prow.append({"budget": display_name(b.name), "u_px": r["u_px"], "v_px": r["v_px"], "x_m": r["x_m"],
                         "y_m": r["y_m"], "semi_major_m (95 %)": r["semi_major_m"],
                         "semi_minor_m (95 %)": r["semi_minor_m"], "orientation_deg": r["orientation_deg"],
                         "status": "ok" if r["valid"] else r["reason"].split(":")[0]})
    parts.append(html_table(prow, floatfmt=".4g"))

    parts.append("<h2>Uncertainty along the image centre column</h2>")
    parts.append(img_tag(prof.read_bytes(), "1-sigma semi-axes against ground range for the three budgets."))
    for b in budgets:
        f = files[b.name]
        parts.append(f"<h2>{esc(display_name(b.name))}</h2>")
        parts.append(img_tag(f["image_png"].read_bytes(), "Semi-major axis per pixel (1 sigma), common colour "
                             "scale across budgets; grey: no ground intersection or beyond the maximum range."))
        parts.append(img_tag(f["ground_png"].read_bytes(), "The same on the ground (bird's-eye view)."))
    parts.append("<h2>Ground sampling distance</h2>")
    parts.append(img_tag(files[budgets[0].name]["gsd_png"].read_bytes(),
                         "Metres of ground per pixel, along and across the line of sight (camera only, no budget)."))
    parts.append(f"<p>Definition: <code>{esc(GSD_DEFINITION)}</code>.</p>")
    parts.append("<h2>Assumptions</h2><ul>"
                 "<li>Flat ground plane; first-order (linear) propagation, accurate well below the horizon and "
                 "under-estimating close to it (see <code>footprint_uq.linearity_ratio</code>).</li>"
                 "<li>Camera-level errors (calibration, pose) are shared by all pixels of an image; the imaging and "
                 "resolution noise is independent per pixel.</li>"
                 "<li>The error sizes are those measured in the paper for its six cameras; use a budget file with "
                 "your own calibration results for a real site.</li></ul>")
    report = write_html(out / "report.html", html_page("footprint-uq demo: roadside camera uncertainty maps", parts))
    return report


@click.command("demo")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--step-px", type=click.IntRange(min=1), default=4, show_default=True, help="Map grid step.")
@click.option("--case-study/--no-case-study", default=True, show_default=True,
              help="Also run the paper's left-turn case study into DIR/case-study.")
def demo_cmd(out_dir, step_px, case_study):
    """Demonstration: a roadside camera (1920x1080, f 1400 px, 8 m high, tilt 20 deg) under three presets.

    Writes maps, figures and a self-contained report.html into DIR (and the
    left-turn case study into DIR/case-study unless --no-case-study).
    """
    report = run_demo(out_dir, step_px=step_px, case_study=case_study,
                      progress=lambda m: click.echo(f"demo: {m}", err=True))
    click.echo(f"report: {report}")
    sys.stdout.flush()
