"""``footprint-uq map``: a per-pixel uncertainty map on disk (:func:`footprint_uq.viz.map_report.write_map_report`)."""

from __future__ import annotations

import click

from .._notices import set_compile_handler
from ..products.gcp_support import load_gcp_support
from ..products.warmup import compile_handler
from ..viz.map_report import write_map_report
from .common import DEFAULT_STEP_PX, FINITE, Stages, check_confidence, load_camera_and_budget, note, pose_options, warn

__all__ = ["map_cmd"]


@click.command("map")
@click.option("--camera", "camera_path", required=True, metavar="FILE",
              help="Camera file (YAML/JSON, OpenCV, ROS or TUMTraf; docs/file-formats.md).")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET", help="Preset name or budget file.")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--step-px", type=click.IntRange(min=1), default=DEFAULT_STEP_PX, show_default=True,
              help="Grid step in pixels (1 = every pixel).")
@click.option("--max-range-m", type=FINITE, default=None, metavar="M",
              help="Mask ground points farther than M metres from the camera foot point.")
@click.option("--confidence", type=FINITE, default=None, metavar="P",
              help="Draw P-confidence semi-axes instead of 1 sigma (0.95 -> 2.4477 sigma).")
@click.option("--linearity/--no-linearity", default=True, show_default=True,
              help="Compute the linearity flag: the nonlinearity layer (map.npz, nonlinearity.png) and, in the "
                   "figures, the pixels that are not linear_ok hatched with the threshold's contour.")
@click.option("--linear-threshold", type=FINITE, default=0.05, show_default=True, metavar="E",
              help="linear_ok where the predicted relative error of the linear 1-sigma semi-major axis is at most E.")
@click.option("--gcp-summary", default=None, metavar="FILE",
              help="summary.json of the `calibrate gcp` run the camera and budget come from: also writes "
                   "gcp_support.npz (inside_hull, leverage_ratio, supported per map pixel).")
@pose_options
def map_cmd(camera_path, budget_spec, out_dir, step_px, max_range_m, confidence, linearity, linear_threshold,
            gcp_summary, pose):
    """Per-pixel uncertainty map: PNG heat maps (image and bird's-eye), GSD maps, the linearity flag, .npz
    arrays, summary.json."""
    confidence = check_confidence(confidence)
    camera, budget = load_camera_and_budget(camera_path, budget_spec, pose)
    support = load_gcp_support(gcp_summary, budget) if gcp_summary is not None else None
    set_compile_handler(compile_handler(note))  # said before the kernels' first compile, after the inputs are checked
    with Stages("map") as say:
        umap, files = write_map_report(camera, budget, out_dir, step_px=step_px, max_range_m=max_range_m,
                                       confidence=confidence, linearity=linearity, linear_threshold=linear_threshold,
                                       gcp_support=support, progress=say)
    for p in files.values():
        click.echo(f"wrote {p}")
    s = umap.summary(confidence=confidence)
    if s["semi_major_m_median"] is None:
        warn("no pixel of this camera sees the ground")
        return
    lab = "1-sigma" if confidence is None else f"{100 * confidence:g} %"
    click.echo(f"valid pixels {100 * s['fraction_valid']:.1f} %; {lab} semi-major axis: median "
               f"{s['semi_major_m_median']:.3g} m, 90th percentile {s['semi_major_m_p90']:.3g} m, "
               f"95th {s['semi_major_m_p95']:.3g} m")
    near = [w for w in s["within_range"] if w["semi_major_m_max"] is not None
            and (max_range_m is None or w["range_m"] < max_range_m)]
    if near:
        click.echo("largest within " + "; ".join(f"{w['range_m']:g} m: {w['semi_major_m_max']:.3g} m" for w in near)
                   + " (range from the camera foot point)")
    if max_range_m is None:
        click.echo(f"max {s['semi_major_m_max']:.3g} m at ranges up to {s['range_m_max']:.3g} m: pixels just below "
                   "the horizon (--max-range-m M masks them)")
    else:
        click.echo(f"max {s['semi_major_m_max']:.3g} m within {max_range_m:g} m")
    if s["fraction_linear_ok"] is not None:
        near = s["range_m_min_not_linear_ok"]
        click.echo(f"linear_ok (nonlinearity <= {s['linear_threshold']:g}) at "
                   f"{100 * s['fraction_linear_ok']:.1f} % of the valid pixels"
                   + (f"; not from {near:.3g} m on" if near is not None else ""))
