"""``footprint-uq map``: a per-pixel uncertainty map on disk (:func:`footprint_uq.viz.map_report.write_map_report`)."""

from __future__ import annotations

import click

from ..viz.map_report import write_map_report
from .common import check_confidence, load_camera_and_budget, warn

__all__ = ["map_cmd"]


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
    confidence = check_confidence(confidence)
    camera, budget = load_camera_and_budget(camera_path, budget_spec)
    umap, files = write_map_report(camera, budget, out_dir, step_px=step_px, max_range_m=max_range_m,
                                   confidence=confidence)
    for p in files.values():
        click.echo(f"wrote {p}")
    s = umap.summary(confidence=confidence)
    if s["semi_major_m_median"] is None:
        warn("no pixel of this camera sees the ground")
        return
    lab = "1-sigma" if confidence is None else f"{100 * confidence:g} %"
    click.echo(f"valid pixels {100 * s['fraction_valid']:.1f} %; {lab} semi-major axis: median "
               f"{s['semi_major_m_median']:.3g} m, 95th percentile {s['semi_major_m_p95']:.3g} m, "
               f"max {s['semi_major_m_max']:.3g} m")
