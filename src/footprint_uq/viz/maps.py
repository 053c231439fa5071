"""Figures of :class:`~footprint_uq.products.maps.UncertaintyMap`: in the image, on the ground, GSD.

* :func:`plot_image_map`: the per-pixel semi-major axis of the ground-position
  ellipse, drawn over the image frame (log colour scale, labelled contours,
  horizon line, region above the horizon greyed out).
* :func:`plot_ground_map`: the same quantity in bird's-eye view on a regular
  ground grid (x east, y north, metres, equal aspect), with the camera position,
  its heading, the ground trace of the image border and range rings.
* :func:`plot_gsd_maps`: ground sampling distance along and across the line of sight.
* :func:`plot_range_profile`: semi-major axis against ground range along the
  image centre column, for several maps (e.g. several budgets).
* :func:`plot_nonlinearity_map`: the linearity flag's layer (predicted relative error of the
  linear 1-sigma semi-major axis) in the image frame, masked where there is no ground point,
  with the contour of the threshold.

Where a map carries the flag, the heat maps hatch the pixels (or ground cells) that are not
``linear_ok`` -- the covariance under-estimates the spread there -- and draw the threshold's
contour (red).

Figures are built with :class:`matplotlib.figure.Figure` (no pyplot; Agg).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib import colors
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from .. import params as P
from .. import status
from ..errors import InputError
from ..io.atomic import atomic_path
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.propagation import propagate

__all__ = ["DEFAULT_LEVELS_M", "GSD_LEVELS_M", "plot_image_map", "plot_ground_map", "plot_gsd_maps",
           "plot_range_profile", "plot_nonlinearity_map", "save_figure", "FLAG_COLOR"]

#: contour levels of the semi-major axis, metres (those inside the colour range are drawn)
DEFAULT_LEVELS_M = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
#: contour levels of the ground sampling distance, metres per pixel
GSD_LEVELS_M = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)

_CMAP = "viridis"
_BAD = "#d9d9d9"
#: the pixels above the horizon (sky: no ground intersection), drawn apart from the masked ground beyond the range
_SKY = "#dbe9f6"
#: colour of the linearity threshold's contour
FLAG_COLOR = "#d62728"
#: hatch of the pixels that are not linear_ok
_FLAG_HATCH = "////"


def _cmap(name=_CMAP):

    return matplotlib.colormaps[name].with_extremes(bad=_BAD)


def _sigma_label(confidence):
    if confidence is None:
        return "1-σ semi-major axis of ground position [m]"
    return f"{100 * confidence:g} % ellipse semi-major axis [m] (= {chi2_scale(confidence):.4g} σ)"


def _lognorm(values, vmin, vmax):
    v = values[np.isfinite(values) & (values > 0)]
    if vmin is None:
        vmin = float(np.min(v)) if v.size else 1e-2
    if vmax is None:
        vmax = float(np.percentile(v, 99.0)) if v.size else 1.0
    vmax = max(vmax, vmin * 1.01)
    return colors.LogNorm(vmin=vmin, vmax=vmax)


def _levels_in(levels, norm):
    return [lv for lv in levels if norm.vmin < lv < norm.vmax * 1.5]


def _camera_caption(camera) -> str:
    w, h = camera.image_size_px
    f = camera.params[P.FX]
    return (f"{w}x{h} px, f = {f:.0f} px, height {camera.height_m:.2f} m, pan {camera.pan_deg:.1f}°, "
            f"tilt {camera.tilt_deg:.1f}°, roll {camera.roll_deg:.1f}°")


def _extent(umap):
    uv = umap.uv_px
    s = umap.step_px
    return (uv[0, 0, 0] - 0.5 * s, uv[0, -1, 0] + 0.5 * s, uv[-1, 0, 1] + 0.5 * s, uv[0, 0, 1] - 0.5 * s)


def _draw_horizon(ax, umap):
    """Horizon line (undistorted cameras) or the boundary of the above-horizon region."""
    cam = umap.camera
    w, h = cam.image_size_px
    if cam is not None and not np.any(cam.params[P.DIST_SLICE]) and abs(cam.params[P.SKEW]) == 0:
        u = np.linspace(-0.5, w - 0.5, 200)
        v = cam.horizon_v_px(u)
        ok = np.isfinite(v) & (v >= -0.5) & (v <= h - 0.5)
        if ok.any():
            ax.plot(u[ok], v[ok], color="white", lw=2.2, zorder=4)
            ax.plot(u[ok], v[ok], color="k", lw=1.0, ls="--", zorder=5, label="horizon")
            return True
        return False
    sky = (umap.reason == status.ABOVE_HORIZON).astype(float)
    if 0 < sky.mean() < 1:
        ax.contour(umap.uv_px[..., 0], umap.uv_px[..., 1], sky, levels=[0.5], colors="k", linestyles="--",
                   linewidths=1.0, zorder=5)
        ax.plot([], [], color="k", ls="--", lw=1.0, label="horizon")
        return True
    return False


def _clabel_inside(ax, cs, fmt, fontsize, xlim, ylim, *, at=(0.3, 0.7), margin=0.08):
    """Contour labels placed well inside the panel (clabel's own choice put them on the right edge, clipped):
    for each level, the point of its line nearest to the fractions ``at`` of the width, at least ``margin`` of
    the panel away from every edge."""
    (x0, x1), (y0, y1) = sorted(xlim), sorted(ylim)
    dx, dy = x1 - x0, y1 - y0
    spots = []
    for segs in cs.allsegs:
        pts = np.concatenate([s for s in segs if len(s)]) if any(len(s) for s in segs) else np.zeros((0, 2))
        inner = pts[(pts[:, 0] > x0 + margin * dx) & (pts[:, 0] < x1 - margin * dx)
                    & (pts[:, 1] > y0 + margin * dy) & (pts[:, 1] < y1 - margin * dy)] if len(pts) else pts
        for f in at[:1] if len(inner) < 2 else at:
            if len(inner):
                spots.append(tuple(inner[np.argmin(np.abs(inner[:, 0] - (x0 + f * dx)))]))
                break
    if spots:
        ax.clabel(cs, fmt=fmt, fontsize=fontsize, inline=True, inline_spacing=3, manual=spots)


def _contours(ax, X, Y, Z, levels, norm, fmt="%g m"):
    lv = _levels_in(levels, norm)
    if not lv or not np.isfinite(Z).any():
        return None
    cs = ax.contour(X, Y, np.ma.masked_invalid(Z), levels=lv, colors="white", linewidths=0.9, zorder=3)
    ax.clabel(cs, fmt=fmt, fontsize=7.5, inline=True, inline_spacing=3)
    return cs


def _colorbar(fig, mappable, ax, label, data=None):
    if data is None:
        data = np.ma.filled(mappable.get_array(), np.nan).astype(float)
    over = bool(np.nanmax(data, initial=-np.inf) > mappable.norm.vmax * (1 + 1e-9))
    under = bool(np.nanmin(data, initial=np.inf) < mappable.norm.vmin * (1 - 1e-9))
    extend = {(True, True): "both", (True, False): "max", (False, True): "min"}.get((over, under), "neither")
    cb = fig.colorbar(mappable, ax=ax, extend=extend, pad=0.02, fraction=0.05)
    cb.set_label(label, fontsize=9)
    cb.ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    cb.ax.yaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    cb.ax.yaxis.set_minor_formatter(NullFormatter())
    cb.ax.tick_params(labelsize=8)
    return cb


def _new_fig(figsize):
    fig = Figure(figsize=figsize, layout="constrained")
    return fig


def _draw_linearity(ax, X, Y, nonlinearity, valid, threshold):
    """Hatch the valid points whose nonlinearity exceeds ``threshold`` and draw its contour.

    Returns the legend handles (none if every point is ``linear_ok`` or there is no layer).
    """

    if nonlinearity is None:
        return []
    with np.errstate(invalid="ignore"):
        bad = valid & ~(nonlinearity <= threshold)
    if not bad.any():
        return []
    ax.contourf(X, Y, bad.astype(float), levels=[0.5, 1.5], colors="none", hatches=[_FLAG_HATCH], zorder=3.5)
    handles = [Patch(facecolor="none", edgecolor="#333", hatch=_FLAG_HATCH,
                     label=f"not linear_ok: linear σ off by > {100 * threshold:g} %")]
    nl = np.ma.masked_invalid(np.where(valid, nonlinearity, np.nan))
    if nl.count() and nl.min() < threshold < nl.max():
        ax.contour(X, Y, nl, levels=[threshold], colors=FLAG_COLOR, linewidths=1.4, zorder=4.5)
        ax.plot([], [], color=FLAG_COLOR, lw=1.4, label=f"nonlinearity = {threshold:g}")
    return handles


def plot_image_map(umap, *, confidence: float | None = None, levels_m=DEFAULT_LEVELS_M, vmin_m=None,
                   vmax_m=None, title: str | None = None, figsize=None, show_linearity: bool = True) -> Figure:
    """Heat map of the ground-position semi-major axis for every pixel, in the image frame.

    Parameters
    ----------
    umap : UncertaintyMap
    confidence : float, optional
        Scale the axes to this probability (2-D chi-square, 0.95 -> 2.4477 sigma); 1 sigma if None.
    levels_m : sequence of float
        Contour levels, metres.
    vmin_m, vmax_m : float, optional
        Colour-scale limits (log scale); default from the data.  Fix them to compare figures.
    title : str, optional
    figsize : (float, float), inches; default from the image aspect ratio
    show_linearity : bool
        Hatch the pixels that are not ``linear_ok`` and draw the threshold's contour (when the map
        carries the flag).

    Returns
    -------
    matplotlib.figure.Figure
    """
    a, _ = umap.semi_axes(confidence)
    a = np.where(umap.valid, a, np.nan)
    norm = _lognorm(a, vmin_m, vmax_m)
    cam = umap.camera
    w, h = cam.image_size_px
    fig = _new_fig(figsize or (8.6, 0.9 + 7.2 * h / w))
    ax = fig.add_subplot()
    im = ax.imshow(np.ma.masked_invalid(a), cmap=_cmap(), norm=norm, extent=_extent(umap), origin="upper",
                   interpolation="nearest", zorder=1)
    _draw_sky(ax, umap)
    _contours(ax, umap.uv_px[..., 0], umap.uv_px[..., 1], a, levels_m, norm)
    flag = _draw_linearity(ax, umap.uv_px[..., 0], umap.uv_px[..., 1], umap.nonlinearity, umap.valid,
                           umap.linear_threshold) if show_linearity else []
    _draw_horizon(ax, umap)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u [px] (column, right)", fontsize=9)
    ax.set_ylabel("v [px] (row, down)", fontsize=9)
    ax.tick_params(labelsize=8)
    handles = ax.get_legend_handles_labels()[0] + flag + _invalid_handles(umap)
    if handles:
        ax.legend(handles=handles, loc="lower right", fontsize=7.5, framealpha=0.85)
    _colorbar(fig, im, ax, _sigma_label(confidence))
    budget = getattr(umap.budget, "name", "")
    fig.suptitle(title or f"Ground-position uncertainty per pixel — budget {budget}", fontsize=11)
    ax.set_title(_camera_caption(cam) + f"; grid step {umap.step_px} px", fontsize=8, color="#444")
    return fig


def _draw_sky(ax, umap) -> None:
    """The pixels above the horizon in their own colour (:data:`_SKY`), over the grey of the masked pixels: the
    band of ground beyond the maximum range (below the horizon) stays grey and is labelled as such."""
    sky = umap.reason == status.ABOVE_HORIZON
    if sky.any():
        ax.imshow(np.ma.masked_where(~sky, np.ones(sky.shape)), cmap=colors.ListedColormap([_SKY]),
                  extent=_extent(umap), origin="upper", interpolation="nearest", zorder=1.05)


def _invalid_handles(umap):
    """Legend patches for the invalid pixels, by reason: sky (above the horizon), ground beyond the range, other."""

    beyond = getattr(status, "BEYOND_RANGE", -1)
    out = []
    if np.any(umap.reason == status.ABOVE_HORIZON):
        out.append(Patch(facecolor=_SKY, edgecolor="#999", label="above the horizon: no ground intersection"))
    if np.any(umap.reason == beyond):
        out.append(Patch(facecolor=_BAD, edgecolor="#999",
                         label=f"ground beyond {umap.max_range_m:g} m (masked; below the horizon)"))
    other = ~umap.valid & (umap.reason != status.ABOVE_HORIZON) & (umap.reason != beyond)
    if np.any(other):
        out.append(Patch(color=_BAD, label="invalid (see reason codes)"))
    return out


def _ground_extent(umap, extent_m):
    cam = umap.camera
    x0, y0 = cam.params[P.XM], cam.params[P.YM]
    if extent_m is not None:
        xmin, xmax, ymin, ymax = (float(e) for e in extent_m)
        return xmin, xmax, ymin, ymax
    xy = umap.xy_world_m[umap.valid]
    if xy.size == 0:
        return x0 - 10, x0 + 10, y0 - 10, y0 + 10
    rng = umap.range_m[umap.valid]
    keep = rng <= (umap.max_range_m if umap.max_range_m is not None else np.percentile(rng, 90))
    xy = xy[keep] if keep.any() else xy
    xmin, ymin = np.minimum(xy.min(0), [x0, y0])
    xmax, ymax = np.maximum(xy.max(0), [x0, y0])
    pad = 0.04 * max(xmax - xmin, ymax - ymin)
    return xmin - pad, xmax + pad, ymin - pad, ymax + pad


def _ground_grid_values(umap, extent, n_cells, confidence):
    """Semi-major axis on a regular ground grid, computed exactly (project, then propagate)."""
    cam = umap.camera
    xmin, xmax, ymin, ymax = extent
    span = max(xmax - xmin, ymax - ymin)
    res = span / n_cells
    xs = np.arange(xmin + 0.5 * res, xmax, res)
    ys = np.arange(ymin + 0.5 * res, ymax, res)
    X, Y = np.meshgrid(xs, ys)
    xy = np.stack([X, Y], -1)
    pr = cam.project_ground(xy)
    inside = pr.valid & cam.in_image(pr.uv_px)
    uv = np.where(inside[..., None], pr.uv_px, np.nan)
    est = propagate(cam, umap.budget, uv)

    a = ellipse_axes(est.cov_m2, confidence=confidence)[0]
    ok = inside & est.valid
    if umap.max_range_m is not None:
        ok &= np.hypot(X - cam.params[P.XM], Y - cam.params[P.YM]) <= umap.max_range_m
    return X, Y, np.where(ok, a, np.nan), res, np.where(ok, est.nonlinearity, np.nan), ok


def _border_trace(cam, n=400):
    """Ground trace of the image border: list of (N, 2) polylines (valid parts only)."""
    w, h = cam.image_size_px
    t = np.linspace(0.0, 1.0, n)
    edges = [np.stack([-0.5 + t * w, np.full(n, -0.5)], -1), np.stack([np.full(n, w - 0.5), -0.5 + t * h], -1),
             np.stack([w - 0.5 - t * w, np.full(n, h - 0.5)], -1), np.stack([np.full(n, -0.5), h - 0.5 - t * h], -1)]
    uv = np.concatenate(edges)
    bp = cam.backproject(uv)
    out, cur = [], []
    for ok, p in zip(bp.valid, bp.xy_world_m, strict=True):
        if ok:
            cur.append(p)
        elif cur:
            out.append(np.array(cur))
            cur = []
    if cur:
        out.append(np.array(cur))
    return out


def plot_ground_map(umap, *, confidence: float | None = None, levels_m=DEFAULT_LEVELS_M, extent_m=None,
                    n_cells: int = 360, vmin_m=None, vmax_m=None, range_rings_m=None, title: str | None = None,
                    figsize=(7.2, 6.4), show_linearity: bool = True) -> Figure:
    """Bird's-eye heat map of the semi-major axis on the ground (x east, y north, metres).

    Each ground cell is projected into the image and propagated exactly
    (:func:`footprint_uq.uncertainty.propagation.propagate`); cells outside the image, above
    the horizon or beyond ``umap.max_range_m`` are left blank.

    Parameters
    ----------
    umap : UncertaintyMap
        Supplies the camera, the budget and (for the default extent) the ground points.
    extent_m : (xmin, xmax, ymin, ymax), optional
        Ground window in W, metres; default: the visible ground up to ``max_range_m``
        (or the 90th percentile of the visible range).
    n_cells : int
        Cells along the longer side of the window.
    range_rings_m : sequence of float, optional
        Dashed circles of constant ground range around the camera foot point.
    show_linearity : bool
        Hatch the cells that are not ``linear_ok`` (threshold ``umap.linear_threshold``) and draw the
        threshold's contour, when the map carries the flag.
    """
    cam = umap.camera
    extent = _ground_extent(umap, extent_m)
    X, Y, a, res, nl, ok = _ground_grid_values(umap, extent, int(n_cells), confidence)
    norm = _lognorm(a, vmin_m, vmax_m)
    fig = _new_fig(figsize)
    ax = fig.add_subplot()
    im = ax.imshow(np.ma.masked_invalid(a), cmap=_cmap(), norm=norm, origin="lower", interpolation="nearest",
                   extent=(X[0, 0] - res / 2, X[0, -1] + res / 2, Y[0, 0] - res / 2, Y[-1, 0] + res / 2), zorder=1)
    _contours(ax, X, Y, a, levels_m, norm)
    flag = (_draw_linearity(ax, X, Y, nl, ok, umap.linear_threshold)
            if show_linearity and umap.nonlinearity is not None else [])
    for k, line in enumerate(_border_trace(cam)):
        ax.plot(line[:, 0], line[:, 1], color="#333", lw=0.8, zorder=4, label="image border on the ground" if k == 0
                else None)
    x0, y0 = cam.params[P.XM], cam.params[P.YM]
    span = max(extent[1] - extent[0], extent[3] - extent[2])
    if range_rings_m is None:
        step = _nice_step(span / 4)
        range_rings_m = np.arange(step, 2 * span, step)
    th = np.linspace(0, 2 * np.pi, 361)
    for r in range_rings_m:
        ax.plot(x0 + r * np.cos(th), y0 + r * np.sin(th), color="#888", lw=0.6, ls=":", zorder=2)
        # label where the ring crosses the heading
        px, py = x0 + r * np.sin(cam.params[P.PAN]), y0 + r * np.cos(cam.params[P.PAN])
        if extent[0] < px < extent[1] and extent[2] < py < extent[3]:
            ax.text(px, py, f"{r:g} m", fontsize=7, color="#444", ha="left", va="bottom", zorder=6)
    ax.plot([x0], [y0], marker="^", ms=9, color="red", mec="k", zorder=7, ls="none",
            label=f"camera (h = {cam.height_m:.1f} m)")
    L = 0.12 * span
    ax.annotate("", xy=(x0 + L * np.sin(cam.params[P.PAN]), y0 + L * np.cos(cam.params[P.PAN])), xytext=(x0, y0),
                arrowprops={"arrowstyle": "-|>", "color": "red", "lw": 1.6}, zorder=7)
    ax.plot([], [], color="red", lw=1.6, label=f"heading {cam.pan_deg % 360:.0f}° (from north)")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x (east) [m]", fontsize=9)
    ax.set_ylabel("y (north) [m]", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(True, color="#ccc", lw=0.4, zorder=0)
    ax.legend(handles=ax.get_legend_handles_labels()[0] + flag, loc="best", fontsize=7.5, framealpha=0.85)
    _colorbar(fig, im, ax, _sigma_label(confidence))
    budget = getattr(umap.budget, "name", "")
    fig.suptitle(title or f"Ground-position uncertainty, bird's-eye view — budget {budget}", fontsize=11)
    ax.set_title(_camera_caption(cam) + f"; ground cell {res:.2g} m", fontsize=8, color="#444")
    return fig


def _nice_step(x):
    if not np.isfinite(x) or x <= 0:
        return 10.0
    e = 10 ** np.floor(np.log10(x))
    for m in (1, 2, 5, 10):
        if m * e >= x:
            return float(m * e)
    return float(10 * e)


def plot_gsd_maps(umap, *, levels_m=GSD_LEVELS_M, vmin_m=None, vmax_m=None, title: str | None = None,
                  figsize=(12.0, 4.2)) -> Figure:
    """Two image-frame panels: ground sampling distance along the line of sight and across it.

    Both panels share one log colour scale, metres per pixel (see
    :mod:`footprint_uq.products.maps` for the definition).
    """
    vals = np.concatenate([umap.gsd_range_m[umap.valid], umap.gsd_cross_m[umap.valid]])
    norm = _lognorm(vals, vmin_m, vmax_m)
    fig = _new_fig(figsize)
    axes = fig.subplots(1, 2, sharey=True)
    cam = umap.camera
    w, h = cam.image_size_px
    im = None
    for ax, arr, name in ((axes[0], umap.gsd_range_m, "along the line of sight (range)"),
                          (axes[1], umap.gsd_cross_m, "across the line of sight")):
        z = np.where(umap.valid, arr, np.nan)
        im = ax.imshow(np.ma.masked_invalid(z), cmap=_cmap("magma"), norm=norm, extent=_extent(umap),
                       origin="upper", interpolation="nearest")
        lv = _levels_in(levels_m, norm)
        if lv and np.isfinite(z).any():
            cs = ax.contour(umap.uv_px[..., 0], umap.uv_px[..., 1], np.ma.masked_invalid(z), levels=lv,
                            colors="white", linewidths=0.8)
            _clabel_inside(ax, cs, "%g m", 7, (-0.5, w - 0.5), (h - 0.5, -0.5))
        _draw_horizon(ax, umap)
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_aspect("equal")
        ax.set_title(f"GSD {name}", fontsize=9.5)
        ax.set_xlabel("u [px]", fontsize=9)
        ax.tick_params(labelsize=8)
    axes[0].set_ylabel("v [px]", fontsize=9)
    cb = _colorbar(fig, im, list(axes), "ground sampling distance [m per pixel]", data=vals)
    cb.ax.tick_params(labelsize=8)
    fig.suptitle(title or "Ground sampling distance: extent of one pixel's ground footprint along and across the "
                 "line of sight", fontsize=10.5)
    return fig


def plot_range_profile(maps, labels=None, *, confidence: float | None = None, column_px: float | None = None,
                       title: str | None = None, figsize=(7.0, 4.2)) -> Figure:
    """Semi-major axis against ground range along one image column (default: the centre column).

    Parameters
    ----------
    maps : sequence of UncertaintyMap
        Typically the same camera under several budgets.
    labels : sequence of str, optional
        Legend entries (default: budget names).
    column_px : float, optional
        Image column to follow; the grid column nearest to it is used.
    """
    maps = list(maps)
    labels = labels or [getattr(m.budget, "name", f"map {i}") for i, m in enumerate(maps)]
    fig = _new_fig(figsize)
    ax = fig.add_subplot()
    for m, lab in zip(maps, labels, strict=True):
        cam = m.camera
        col = (cam.image_size_px[0] - 1) / 2 if column_px is None else column_px
        j = int(np.argmin(np.abs(m.uv_px[0, :, 0] - col)))
        a, b = m.semi_axes(confidence)
        ok = m.valid[:, j]
        r = m.range_m[ok, j]
        order = np.argsort(r)
        ax.plot(r[order], a[ok, j][order], lw=1.6, label=f"{lab}: semi-major")
        ax.plot(r[order], b[ok, j][order], lw=1.0, ls="--", color=ax.lines[-1].get_color(),
                label=f"{lab}: semi-minor")
    ax.set_yscale("log")
    ax.set_xlabel("ground range from the camera foot point [m]", fontsize=9)
    ax.set_ylabel(_sigma_label(confidence).replace(" semi-major axis", " semi-axes"), fontsize=9)
    ax.grid(True, which="both", color="#ddd", lw=0.5)
    ax.tick_params(labelsize=8)
    # below the axes: inside them it covered the curves (the semi-major axis rises to its top-left corner)
    ax.legend(fontsize=7.5, ncol=min(3, len(maps)), loc="upper center", bbox_to_anchor=(0.5, -0.16),
              frameon=False)
    ax.set_title(title or "Uncertainty along the image centre column", fontsize=10.5)
    return fig


def plot_nonlinearity_map(umap, *, vmin=1e-4, vmax=1.0, title: str | None = None, figsize=None) -> Figure:
    """The linearity flag's layer in the image frame: ``nonlinearity`` per pixel (log colour scale),
    masked (grey) where there is no ground point, with the contour of ``umap.linear_threshold``.

    Parameters
    ----------
    umap : UncertaintyMap
        With the ``nonlinearity`` layer (:func:`footprint_uq.maps.uncertainty_map`, ``linearity=True``).
    vmin, vmax : float
        Colour-scale limits (dimensionless; values beyond are clipped and the colour bar extended).
    """

    if umap.nonlinearity is None:
        raise InputError("umap.nonlinearity", None, "a map computed with linearity=True")
    z = np.where(umap.valid, umap.nonlinearity, np.nan)
    norm = colors.LogNorm(vmin=vmin, vmax=vmax)
    cam = umap.camera
    w, h = cam.image_size_px
    fig = _new_fig(figsize or (8.6, 0.9 + 7.2 * h / w))
    ax = fig.add_subplot()
    im = ax.imshow(np.ma.masked_invalid(np.clip(z, vmin * 0.999, None)), cmap=_cmap("plasma"), norm=norm,
                   extent=_extent(umap), origin="upper", interpolation="nearest", zorder=1)
    thr = umap.linear_threshold
    zm = np.ma.masked_invalid(z)
    if zm.count() and zm.min() < thr < zm.max():
        ax.contour(umap.uv_px[..., 0], umap.uv_px[..., 1], zm, levels=[thr], colors=FLAG_COLOR, linewidths=1.6,
                   zorder=4)
        ax.plot([], [], color=FLAG_COLOR, lw=1.6, label=f"threshold {thr:g}: linear_ok below (nearer)")
    _draw_sky(ax, umap)
    _draw_horizon(ax, umap)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u [px] (column, right)", fontsize=9)
    ax.set_ylabel("v [px] (row, down)", fontsize=9)
    ax.tick_params(labelsize=8)
    handles = ax.get_legend_handles_labels()[0] + _invalid_handles(umap)
    if handles:
        ax.legend(handles=handles, loc="lower right", fontsize=7.5, framealpha=0.85)
    _colorbar(fig, im, ax, "nonlinearity: predicted relative error of the linear 1-σ semi-major axis", data=z)
    ok = umap.linear_ok[umap.valid]
    share = f"; linear_ok at {100 * ok.mean():.1f} % of the valid pixels" if ok.size else ""
    budget = getattr(umap.budget, "name", "")
    fig.suptitle(title or f"Linearity flag per pixel — budget {budget}", fontsize=11)
    ax.set_title(_camera_caption(cam) + f"; grid step {umap.step_px} px{share}", fontsize=8, color="#444")
    return fig


def save_figure(fig: Figure, path, *, dpi: int = 150) -> Path:
    """Save ``fig`` (PNG/PDF/SVG by extension), creating parent directories."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)

    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    return p
