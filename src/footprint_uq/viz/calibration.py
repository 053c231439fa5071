"""Figures of an intrinsic calibration: the paper's coverage and reprojection-error maps, and more.

Every function returns a :class:`matplotlib.figure.Figure` built without
``pyplot`` (Agg rendering, no global state).  :func:`save_calibration_figures`
writes them all as PNGs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colors
from matplotlib.figure import Figure

from ..io.atomic import atomic_path
from ..params import INTRINSIC_NAMES, PAPER_COLUMNS
from .report import esc, html_page, html_table, img_tag, lead_block, write_html

__all__ = ["plot_coverage", "plot_error_map", "plot_asymmetry", "plot_view_errors", "plot_sigma_comparison",
           "save_calibration_figures"]


def _extent(image_size_px, shape, cell_px):
    ny, nx = shape
    return (-0.5, nx * cell_px - 0.5, ny * cell_px - 0.5, -0.5)


def _frame(ax, image_size_px, pp=None):
    w, h = image_size_px
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_aspect("equal")
    if pp is not None:
        ax.plot([pp[0]], [pp[1]], marker="+", color="k", ms=12, mew=1.5, label="principal point")
        ax.legend(loc="lower right", fontsize=7)


def plot_coverage(coverage, *, principal_point_px=None, title: str | None = None) -> Figure:
    """Boards per grid cell (the paper's checkerboard distribution in image space).

    Parameters
    ----------
    coverage : CoverageMap
    principal_point_px : (float, float), optional
    """
    fig = Figure(figsize=(7.5, 5.2))
    ax = fig.add_subplot()
    c = coverage.count.astype(float)
    im = ax.imshow(np.where(c > 0, c, np.nan), extent=_extent(coverage.image_size_px, c.shape, coverage.cell_px),
                   cmap="viridis", interpolation="nearest", vmin=0.5, vmax=max(1.0, c.max()))
    ax.set_facecolor("0.85")
    fig.colorbar(im, ax=ax, shrink=0.85, label="boards covering the cell")
    _frame(ax, coverage.image_size_px, principal_point_px)
    s = coverage.summary()
    ax.set_title(title or f"Board coverage, {coverage.cell_px:g} px cells: {coverage.n_boards} boards, "
                          f"{100 * s['covered_fraction']:.0f} % of the image (grey: none)", fontsize=9)
    return fig


def plot_error_map(error_map, *, principal_point_px=None, residual_map=None, title: str | None = None) -> Figure:
    """Mean reprojection error per cell; optional arrows of the mean residual per cell of ``residual_map``
    (a coarser map of the same kind, e.g. ``cal.error_map(40.0)``)."""
    fig = Figure(figsize=(7.5, 5.2))
    ax = fig.add_subplot()
    e = error_map.mean_error_px
    vmax = float(np.nanpercentile(e, 99)) if np.isfinite(e).any() else 1.0
    im = ax.imshow(e, extent=_extent(error_map.image_size_px, e.shape, error_map.cell_px), cmap="magma",
                   interpolation="nearest", vmin=0.0, vmax=max(vmax, 1e-6))
    ax.set_facecolor("0.85")
    fig.colorbar(im, ax=ax, shrink=0.85, label="mean reprojection error (px)")
    if residual_map is not None:
        coarse = residual_map
        quiver_cell_px = coarse.cell_px
        ny, nx = coarse.count.shape
        uc = (np.arange(nx) + 0.5) * quiver_cell_px - 0.5
        vc = (np.arange(ny) + 0.5) * quiver_cell_px - 0.5
        U, V = np.meshgrid(uc, vc)
        m = coarse.mean_residual_px
        ok = coarse.count > 0
        if ok.any():
            scale = float(np.nanmax(np.hypot(m[..., 0], m[..., 1])))
            gain = 0.8 * quiver_cell_px / scale if scale > 0 else 1.0
            ax.quiver(U[ok], V[ok], m[..., 0][ok] * gain, m[..., 1][ok] * gain, angles="xy", scale_units="xy",
                      scale=1, color="tab:green", width=0.003)
            ax.text(0.01, 0.01, f"arrows: mean residual per {quiver_cell_px:g} px cell, x{gain:.0f}",
                    transform=ax.transAxes, fontsize=7, color="k", va="bottom")
    _frame(ax, error_map.image_size_px, principal_point_px)
    ax.set_title(title or f"Mean reprojection error per {error_map.cell_px:g} px cell (grey: no corner)", fontsize=9)
    return fig


def plot_asymmetry(asymmetry: dict, image_size_px, *, principal_point_px=None) -> Figure:
    """Cell error minus the error of its point reflection through the principal point."""
    fig = Figure(figsize=(7.5, 5.2))
    ax = fig.add_subplot()
    D = asymmetry["reflection_map_px"]
    lim = float(np.nanmax(np.abs(D))) if np.isfinite(D).any() else 1.0
    im = ax.imshow(D, extent=_extent(image_size_px, D.shape, asymmetry["cell_px"]), cmap="RdBu_r",
                   norm=colors.TwoSlopeNorm(0.0, -max(lim, 1e-9), max(lim, 1e-9)), interpolation="nearest")
    ax.set_facecolor("0.85")
    fig.colorbar(im, ax=ax, shrink=0.85, label="E(p) - E(2c - p) (px)")
    _frame(ax, image_size_px, principal_point_px)
    a = asymmetry
    txt = (f"reflection index {a['reflection_index']:.3f}"
           + (f" (noise p95 {a['reflection_index_null_p95']:.3f})" if "reflection_index_null_p95" in a else "")
           + f", left/right {a['left_right']:+.3f}, top/bottom {a['top_bottom']:+.3f}")
    ax.set_title("Error asymmetry about the principal point\n" + txt, fontsize=9)
    return fig


def plot_view_errors(cal) -> Figure:
    """Mean reprojection error per frame: used frames, frames dropped by the filter (with round), threshold."""
    fig = Figure(figsize=(max(6.0, 0.25 * (len(cal.labels) + len(cal.dropped)) + 2), 3.6))
    ax = fig.add_subplot()
    labels = list(cal.labels) + [d["label"] for d in cal.dropped]
    vals = list(cal.per_view_mean_px) + [d["mean_error_px"] for d in cal.dropped]
    col = ["tab:blue"] * len(cal.labels) + ["tab:red"] * len(cal.dropped)
    x = np.arange(len(labels))
    ax.bar(x, vals, color=col)
    for i, d in enumerate(cal.dropped):
        ax.text(len(cal.labels) + i, d["mean_error_px"], f"r{d['round']}", ha="center", va="bottom", fontsize=7)
    if cal.max_mean_reproj_px is not None:
        ax.axhline(cal.max_mean_reproj_px, color="k", ls="--", lw=1, label=f"threshold {cal.max_mean_reproj_px:g} px")
        ax.legend(fontsize=7)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=90, fontsize=6)
    ax.set_ylabel("mean reprojection error (px)")
    ax.set_title(f"Per-frame error: {len(cal.labels)} used (blue), {len(cal.dropped)} dropped (red, at round r)",
                 fontsize=9)
    fig.tight_layout()
    return fig


def plot_sigma_comparison(cal) -> Figure:
    """Standard deviations per intrinsic from OpenCV, our Jacobian and the bootstrap (log scale)."""
    fig = Figure(figsize=(7.5, 3.8))
    ax = fig.add_subplot()
    x = np.arange(len(INTRINSIC_NAMES))
    series = [("OpenCV", cal.std_opencv), ("Jacobian", cal.std_jacobian)]
    if cal.bootstrap is not None and len(cal.bootstrap.samples) > 1:
        series.append((f"bootstrap ({len(cal.bootstrap.samples)})", cal.bootstrap.std))
    w = 0.8 / len(series)
    for k, (name, s) in enumerate(series):
        ax.bar(x + (k - (len(series) - 1) / 2) * w, s, w, label=name)
    ax.set_yscale("log")
    ax.set_xticks(x)
    ax.set_xticklabels(INTRINSIC_NAMES, fontsize=8)
    ax.set_ylabel("standard deviation (px or unitless)")
    ax.legend(fontsize=7)
    ax.set_title("Variability of the intrinsics by method", fontsize=9)
    fig.tight_layout()
    return fig


def save_calibration_figures(cal, out_dir, *, coverage=None, error_map=None, asymmetry=None, grid_px: float = 5.0,
                             dpi: int = 120) -> dict:
    """Write coverage.png, reprojection_error.png, asymmetry.png, view_errors.png, sigmas.png into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    coverage = coverage if coverage is not None else cal.coverage(grid_px)
    error_map = error_map if error_map is not None else cal.error_map(grid_px)
    asymmetry = asymmetry if asymmetry is not None else cal.asymmetry()
    pp = (cal.K[0, 2], cal.K[1, 2])
    figs = {
        "coverage.png": plot_coverage(coverage, principal_point_px=pp),
        "reprojection_error.png": plot_error_map(error_map, principal_point_px=pp, residual_map=cal.error_map(40.0)),
        "asymmetry.png": plot_asymmetry(asymmetry, cal.image_size_px, principal_point_px=pp),
        "view_errors.png": plot_view_errors(cal),
        "sigmas.png": plot_sigma_comparison(cal),
    }
    files = {}

    for name, fig in figs.items():
        with atomic_path(out / name) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
        files[name] = str(out / name)
    return files


def write_calibration_html(summary: dict, out_dir, *, figures=("coverage.png", "reprojection_error.png",
                                                               "asymmetry.png", "view_errors.png", "sigmas.png")):
    """A self-contained ``report.html`` (figures embedded) from :meth:`IntrinsicCalibration.summary`."""

    out = Path(out_dir)
    s = summary
    fr = s["frames"]
    pt = s["paper_table"].get("opencv") or next(iter(s["paper_table"].values()), {})
    verdict = (f"Calibrated from {fr['used']} of {fr['input']} images with an RMS reprojection error of "
               f"{s['rms_reprojection_error_px']:.3g}&nbsp;px: focal length {s['intrinsics']['fx_px']:.5g}&nbsp;px, "
               f"1-&sigma; {pt.get('sigma_f_px', float('nan')):.2g}&nbsp;px by OpenCV's estimate (the error budget "
               "is in <code>budget.yaml</code>).")
    lead_png = next((out / n for n in figures if (out / n).is_file()), None)
    lead = (lead_block(lead_png.read_bytes(), f"{lead_png.name}: where on the image the board's corners were "
                       "seen, and how well they are fitted.", verdict) if lead_png is not None
            else f'<p class="verdict">{verdict}</p>')
    parts = [lead, f"<p>OpenCV {esc(s['opencv_version'])}; board {s['board']['inner_corners'][0]}x"
             f"{s['board']['inner_corners'][1]} inner corners, square {s['board']['square_m']} m; image "
             f"{s['image_size_px'][0]}x{s['image_size_px'][1]} px. Frames: {fr['input']} input, {fr['board_found']} "
             f"with the board, {fr['used']} used, {fr['dropped_by_filter']} dropped by the filter. RMS reprojection "
             f"error {s['rms_reprojection_error_px']:.4f} px.</p>"]
    rows = [{"parameter": k, "value": s["intrinsics"][k],
             **{src: s["std"][src][k] for src in ("opencv", "jacobian", "bootstrap") if src in s["std"]}}
            for k in INTRINSIC_NAMES]
    parts += ["<h2>Intrinsics and standard deviations</h2>", html_table(rows, floatfmt=".6g")]
    prow = [{"source": src, **row} for src, row in s["paper_table"].items()]
    parts += ["<h2>The paper's Table 2</h2><p>sigma f = RSS(sigma fx, sigma fy); c, r: principal point column, "
              "row.</p>", html_table(prow, ["source", *PAPER_COLUMNS])]
    if "comparison" in s:
        parts.append(f"<h2>OpenCV vs bootstrap</h2><p>Median ratio bootstrap / OpenCV "
                     f"{s['comparison']['median_ratio']:.3g}: {esc(s['comparison']['verdict'])}.</p>")
    f = s["filter"]
    if f["rounds"]:
        parts += ["<h2>Frame filter</h2>",
                  html_table([{**r, "dropped": ", ".join(r["dropped"])} for r in f["rounds"]])]
    bad = fr["not_found"] + [{"label": d["label"], "reason": d["reason"]} for d in f["dropped"]]
    if bad:
        parts += ["<h2>Frames not used</h2>", html_table(bad, ["label", "reason"])]
    parts.append("<h2>Maps</h2>")
    for name in figures:
        p = out / name
        if p.is_file() and p != lead_png:
            parts.append(img_tag(p.read_bytes(), name))
    a = s["maps"]["asymmetry"]
    parts.append("<p>Asymmetry: " + esc(", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                                                  for k, v in a.items())) + "</p>")
    return write_html(out / "report.html", html_page("Intrinsic calibration", parts))
