"""Figures and the self-contained HTML report of the site planner (``footprint-uq plan``).

* :func:`plot_site`: the site to scale (x east, y north, metres, equal aspect): zones, occluders,
  candidate mounts, the chosen cameras with their footprints on the zones and their headings;
* :func:`plot_semi_major`: bird's-eye map of the 95 % semi-major axis over the zones (log colour),
  with each zone's requirement as a contour (the fused map, or the best single camera's);
* :func:`plot_met`: met / unmet / unseen per zone, with the requirement's contour;
* :func:`write_plan_report`: all of it with the layout, the zone table and the sensitivity table.

Figures are :class:`matplotlib.figure.Figure` objects (no pyplot; Agg).
"""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib import colors
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon

from ..planning.coverage import semi_major_from_info
from .report import esc, html_page, html_table, img_tag, lead_block, write_html

__all__ = ["raster", "plot_site", "plot_semi_major", "plot_met", "best_single", "layout_rows", "plan_report_html",
           "write_plan_report", "CAMERA_COLOURS"]

CAMERA_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")
_BAD = "#e6e6e6"


def raster(samples, values, mask=None, fill=np.nan) -> np.ndarray:
    """Values ``(S,)`` of the samples on the site's raster ``(H, W)`` (``fill`` where there is no sample)."""
    out = np.full((samples.grid_y_m.size, samples.grid_x_m.size), fill, dtype=np.float64)
    m = slice(None) if mask is None else mask
    out[samples.cell[m, 0], samples.cell[m, 1]] = np.asarray(values, dtype=np.float64)[m]
    return out


def _extent(samples):
    r = np.sqrt(samples.area_m2) / 2
    return (samples.grid_x_m[0] - r, samples.grid_x_m[-1] + r, samples.grid_y_m[0] - r, samples.grid_y_m[-1] + r)


def _figsize(site, figsize, colorbar: bool = False):
    """``figsize``, or one that follows the site's aspect (width 7.5 in)."""
    if figsize is not None:
        return figsize
    x0, y0, x1, y1 = site.bounds_m(3.0)
    w = 7.5
    return (w, float(np.clip((w - (1.6 if colorbar else 0.0)) * (y1 - y0) / (x1 - x0) + 0.9, 3.0, 8.5)))


def _frame(site, ax, *, zones=True):
    for z in site.zones if zones else ():
        ax.add_patch(Polygon(z.polygon_m, closed=True, fill=False, ec="#555", lw=0.6))
    for o in site.occluders:
        ax.add_patch(Polygon(o.polygon_m, closed=True, fc="#888", ec="#333", hatch="xx", lw=0.8, alpha=0.8))
    x0, y0, x1, y1 = site.bounds_m(3.0)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")


def _draw_cameras(ax, cameras, *, arrow_m=8.0):
    for k, lc in enumerate(cameras):
        c = CAMERA_COLOURS[k % len(CAMERA_COLOURS)]
        x, y = lc.camera.position_world_m[:2]
        pan = np.deg2rad(lc.camera.pan_deg)
        ax.plot([x], [y], marker="o", ms=7, mec="k", mfc=c, zorder=5)
        ax.annotate("", (x + arrow_m * np.sin(pan), y + arrow_m * np.cos(pan)), (x, y),
                    arrowprops={"arrowstyle": "->", "color": c, "lw": 1.6}, zorder=5)
        ax.annotate(lc.name, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7, color=c, zorder=6)


def plot_site(site, samples, cameras, infos, *, title: str = "Site and camera footprints", figsize=None):
    """The site to scale with every chosen camera's footprint (the zone samples it sees, outlined)."""
    fig = Figure(figsize=_figsize(site, figsize), layout="constrained")
    ax = fig.add_subplot()
    for z in site.zones:
        ax.add_patch(Polygon(z.polygon_m, closed=True, fc="#dfe8f3", ec="#555", lw=0.6))
    _frame(site, ax, zones=False)
    X, Y = np.meshgrid(samples.grid_x_m, samples.grid_y_m)
    handles = []
    for k, (lc, (idx, _)) in enumerate(zip(cameras, infos, strict=True)):
        c = CAMERA_COLOURS[k % len(CAMERA_COLOURS)]
        seen = np.zeros(len(samples))
        seen[idx] = 1.0
        R = raster(samples, seen, fill=0.0)
        if R.max() > 0:
            ax.contourf(X, Y, R, levels=[0.5, 1.5], colors=[c], alpha=0.18)
            ax.contour(X, Y, R, levels=[0.5], colors=[c], linewidths=1.0)
        handles.append(Patch(fc=c, alpha=0.5, label=lc.name))
    mounts = np.array([m.position_m for m in site.mounts])
    ax.plot(mounts[:, 0], mounts[:, 1], "^", ms=6, mfc="none", mec="#444", label="candidate mounts")
    handles.append(Line2D([], [], ls="none", marker="^", ms=6, mfc="none", mec="#444", label="candidate mount"))
    handles.append(Line2D([], [], ls="none", marker="o", ms=7, mfc="#bbb", mec="k", label="chosen camera (arrow: pan)"))
    _draw_cameras(ax, cameras)
    if site.occluders:
        handles.append(Patch(fc="#888", hatch="xx", label="occluders"))
    ax.legend(handles=handles, fontsize=7, loc="upper right")
    ax.set_title(title, fontsize=10)
    return fig


def plot_semi_major(site, samples, semi_major_m, cameras=(), *, title: str, vmin_m=0.05, vmax_m=10.0,
                    figsize=None):
    """Bird's-eye map of a 95 % semi-major axis over the zones, with every zone's requirement contour."""
    fig = Figure(figsize=_figsize(site, figsize, True), layout="constrained")
    ax = fig.add_subplot()
    v = np.where(np.isfinite(semi_major_m), semi_major_m, vmax_m * 10)
    R = raster(samples, v)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad=_BAD, over="#3b0f0f")
    im = ax.imshow(np.ma.masked_invalid(R), origin="lower", extent=_extent(samples), cmap=cmap,
                   norm=colors.LogNorm(vmin_m, vmax_m), interpolation="nearest")
    X, Y = np.meshgrid(samples.grid_x_m, samples.grid_y_m)
    for k, z in enumerate(site.zones):
        Rz = raster(samples, v, mask=samples.zone == k)
        if np.nanmin(Rz) < z.max_semi_major_m < np.nanmax(Rz):
            cs = ax.contour(X, Y, np.ma.masked_invalid(Rz), levels=[z.max_semi_major_m], colors=["#ff2d2d"],
                            linewidths=1.2)
            ax.clabel(cs, fmt=f"{z.name} %g m", fontsize=7)
    _frame(site, ax)
    _draw_cameras(ax, cameras)
    cb = fig.colorbar(im, ax=ax, extend="max", shrink=0.9, aspect=30)
    cb.set_label("95 % semi-major (m); dark red: > scale or unseen", fontsize=8)
    ax.set_title(title, fontsize=10)
    return fig


def plot_met(site, samples, evaluation, zone_index: int, cameras=(), *, figsize=None):
    """Met (green) / unmet (red) / unseen (grey) samples of one zone, with its requirement's contour."""
    z = site.zones[zone_index]
    m = samples.zone == zone_index
    state = np.where(evaluation.met, 2.0, np.where(evaluation.n_seen > 0, 1.0, 0.0))
    fig = Figure(figsize=_figsize(site, figsize), layout="constrained")
    ax = fig.add_subplot()
    cmap = colors.ListedColormap(["#9a9a9a", "#e34a33", "#31a354"]).with_extremes(bad="white")
    ax.imshow(np.ma.masked_invalid(raster(samples, state, mask=m)), origin="lower", extent=_extent(samples),
              cmap=cmap, vmin=-0.5, vmax=2.5, interpolation="nearest")
    X, Y = np.meshgrid(samples.grid_x_m, samples.grid_y_m)
    semi = np.where(np.isfinite(evaluation.semi_major_m), evaluation.semi_major_m, 1e6)
    Rz = raster(samples, semi, mask=m)
    if np.nanmin(Rz) < z.max_semi_major_m < np.nanmax(Rz):
        ax.contour(X, Y, np.ma.masked_invalid(Rz), levels=[z.max_semi_major_m], colors=["k"], linewidths=1.0)
    _frame(site, ax)
    _draw_cameras(ax, cameras)
    frac = float(evaluation.met[m].mean()) if m.any() else 0.0
    ax.legend(handles=[Patch(fc="#31a354", label="met"), Patch(fc="#e34a33", label="seen, not met"),
                       Patch(fc="#9a9a9a", label="not seen")], fontsize=7, loc="upper right")
    ax.set_title(f"{z.name}: 95 % semi-major <= {z.max_semi_major_m:g} m met on {100 * frac:.1f} % of the area",
                 fontsize=10)
    return fig


def best_single(samples, infos, confidence=0.95) -> np.ndarray:
    """Per sample, the smallest 95 % semi-major axis of any single camera (inf where none sees it)."""
    out = np.full(len(samples), np.inf)
    for idx, info in infos:
        out[idx] = np.minimum(out[idx], semi_major_from_info(info, confidence))
    return out


_NOT_MODELLED = ("What the planner does not model: occlusion by traffic (a lorry hides the lane behind it), "
                 "weather and night (the error budget is the daytime, clear-sky one), the detector's own pixel "
                 "error beyond the budget's imaging and resolution noise, and poles swaying in the wind beyond "
                 "the budget's angles. Occluders are prisms on a flat ground.")


def _table(rows, **kw) -> str:
    """An HTML table that scrolls inside its own box on a narrow screen (the page never overflows)."""
    return f'<div style="overflow-x: auto; max-width: 100%">{html_table(rows, **kw)}</div>'


def layout_rows(cameras) -> list[dict]:
    rows = []
    for lc in cameras:
        c, cfg = lc.camera, lc.config
        rows.append({"camera": lc.name, "mount": cfg.mount if cfg else "-", "type": cfg.camera_type if cfg else "-",
                     "lens": cfg.lens if cfg else "-", "model": c.model, "focal_px": float(c.params[0]),
                     "height_m": c.height_m, "pan_deg": float(np.mod(c.pan_deg, 360.0)), "tilt_deg": c.tilt_deg,
                     "budget": getattr(lc.budget, "name", None) or "custom"})
    return rows


def plan_report_html(site, samples, cameras, evaluation, infos, *, sensitivity_rows=None, plan_info=None,
                     dpi: int = 100) -> str:
    """The report as one self-contained HTML document (figures embedded)."""
    conf = 100 * evaluation.confidence
    how = "fused over every camera that sees it (information form)" if evaluation.fusion else \
        "of the best single camera"
    title = (f"Fused {conf:g} % semi-major axis" if evaluation.fusion
             else f"{conf:g} % semi-major axis (best single camera)")
    zones = "; ".join(f"{esc(z.name)} {100 * z.fraction_met:.0f}&nbsp;%" if np.isfinite(z.fraction_met)
                      else f"{esc(z.name)} unseen" for z in evaluation.zones)
    verdict = (f"This layout of {len(cameras)} camera{'s' if len(cameras) != 1 else ''} meets the accuracy "
               f"requirement on <b>{100 * evaluation.fraction:.1f}&nbsp;%</b> of the weighted zone area ({zones}).")
    parts = [lead_block(plot_semi_major(site, samples, evaluation.semi_major_m, cameras, title=title),
                        "Bird's-eye map of the semi-major axis over the zones; red contours: each zone's requirement; "
                        "circles: the chosen cameras, arrows: their headings.", verdict, dpi=dpi)]
    parts += [f'<p class="note">Site <b>{esc(site.name)}</b>: {len(site.zones)} zones sampled every '
             f"{site.resolution_m:g} m ({len(samples)} samples), {len(site.mounts)} candidate mounts, "
             f"{len(cameras)} cameras. A sample is <i>met</i> when the {conf:g} % semi-major axis of its ground "
             f"position {how} "
             f"is at most its zone's requirement. Weighted met area: <b>{100 * evaluation.fraction:.1f} %</b>.</p>"]
    parts.append(img_tag(plot_site(site, samples, cameras, infos), "The site to scale: zones (light blue), "
                         "occluders (hatched), candidate mounts (open triangles), the chosen cameras (filled circles, "
                         "arrow: heading) and each camera's footprint on the zones (its colour).", dpi=dpi))
    parts += ["<h2>Zones</h2>", _table([z.row() for z in evaluation.zones], floatfmt=".3g")]
    parts += ["<h2>Layout</h2>", _table(layout_rows(cameras), floatfmt=".4g")]
    parts.append("<h2>Maps</h2>")
    if evaluation.fusion and len(cameras) > 1:
        parts.append(img_tag(plot_semi_major(site, samples, best_single(samples, infos, evaluation.confidence),
                                             cameras, title=f"Best single camera, {conf:g} % semi-major axis"),
                             "The same without fusion: where the fused map is better, two cameras overlap.",
                             dpi=dpi))
    for k in range(len(site.zones)):
        parts.append(img_tag(plot_met(site, samples, evaluation, k, cameras),
                             f"Zone {site.zones[k].name}: met / unmet / unseen.", dpi=dpi))
    if sensitivity_rows:
        parts += ["<h2>Sensitivity</h2>", "<p>The weighted met fraction when each camera (and all of them) is "
                  "mounted 1 m higher or lower or tilted 2 deg more or less than planned, and with every sigma of "
                  "the error budgets doubled.</p>", _table(sensitivity_rows, floatfmt=".4g")]
    if plan_info:
        parts += ["<h2>How the plan was found</h2>", _table([{"item": k, "value": v} for k, v in plan_info.items()],
                                                           floatfmt=".4g")]
    parts.append(f'<p class="note">{esc(_NOT_MODELLED)}</p>')
    return html_page(f"Site plan: {site.name}", parts)


def write_plan_report(path, site, samples, cameras, evaluation, infos, **kw):
    """Write :func:`plan_report_html` to ``path`` (atomically); returns the path."""
    return write_html(path, plan_report_html(site, samples, cameras, evaluation, infos, **kw))
