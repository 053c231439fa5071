"""What the camera sees, with the uncertainty drawn in: detected objects in the image and the 95 % ellipse of
each one's footprint centre, projected back into the image (the demo's first figure, ``camera_view.png``).

The scene is drawn from the camera model alone (no photograph): sky above the horizon, the ground plane with a
10-m grid and range rings, each object's 3-D box as a wire frame, and per budget the confidence ellipse of its
footprint centre (:class:`footprint_uq.products.footprints.FrameProcessor`; the ellipse's ground polygon
:func:`footprint_uq.uncertainty.ellipse.ellipse_points` projected with the camera's ``project_ground``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from .._checks import as_points
from ..errors import InputError
from ..products.footprints import FrameProcessor
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import ellipse_axes, ellipse_points
from ..uncertainty.presets import display_name

__all__ = ["plot_camera_view", "box_corners_m"]

_SKY, _GROUND, _GRID = "#dbe9f6", "#c9c9c2", "#f4f4ef"
#: one colour per budget: matplotlib's default cycle, as in the demo's range profile (the same budget, the same colour)
_COLOURS = ("C0", "C1", "C2", "C3")
#: the 12 edges of a box from :func:`box_corners_m` (4 bottom, 4 top, 4 vertical)
_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))


def box_corners_m(boxes3d_world) -> np.ndarray:
    """The 8 corners ``(N, 8, 3)`` (world frame W, metres) of 3-D boxes ``(N, 7)`` = x_m, y_m, z_m (centre),
    length_m, width_m, height_m, yaw_rad (length along yaw, counter-clockwise from east): bottom 4, then top 4."""
    b = np.asarray(boxes3d_world, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 7:
        raise InputError("boxes3d_world", f"shape {b.shape}", "an (N, 7) array")
    sx, sy = np.array([1, 1, -1, -1]) / 2.0, np.array([1, -1, -1, 1]) / 2.0
    c, s = np.cos(b[:, 6])[:, None], np.sin(b[:, 6])[:, None]
    dx, dy = sx * b[:, 3:4], sy * b[:, 4:5]  # (N, 4) in the box frame
    x, y = b[:, 0:1] + c * dx - s * dy, b[:, 1:2] + s * dx + c * dy
    z0, z1 = b[:, 2:3] - b[:, 5:6] / 2.0, b[:, 2:3] + b[:, 5:6] / 2.0
    bottom = np.stack([x, y, np.broadcast_to(z0, x.shape)], -1)
    top = np.stack([x, y, np.broadcast_to(z1, x.shape)], -1)
    return np.concatenate([bottom, top], axis=1)


def _draw_ground(ax, camera, rings_m: Sequence[float]) -> None:
    """Sky and ground split at the horizon, a 10-m grid and labelled range rings around the camera's foot."""
    w, h = camera.image_size_px
    u = np.linspace(-0.5, w - 0.5, 200)
    v = np.clip(np.nan_to_num(camera.horizon_v_px(u), nan=-0.5), -0.5, h - 0.5)
    ax.fill_between(u, -0.5, v, color=_SKY, zorder=0)
    ax.fill_between(u, v, h - 0.5, color=_GROUND, zorder=0)
    foot = camera.position_world_m
    t = np.linspace(-200.0, 200.0, 801)
    for k in np.arange(-200.0, 201.0, 10.0):
        for line in (np.c_[foot[0] + k + 0 * t, foot[1] + t], np.c_[foot[0] + t, foot[1] + k + 0 * t]):
            _plot_ground_line(ax, camera, line, color=_GRID, lw=0.8, zorder=1)
    a = np.linspace(0.0, 2.0 * np.pi, 721)
    for r in rings_m:
        ring = np.c_[foot[0] + r * np.sin(a), foot[1] + r * np.cos(a)]
        uv = _plot_ground_line(ax, camera, ring, color="#8c8c84", lw=0.8, ls=":", zorder=1)
        inside = np.flatnonzero(np.isfinite(uv[:, 0]))
        if inside.size:
            k = inside[np.argmax(uv[inside, 1])]  # the ring's lowest point in the image
            ax.annotate(f"{r:g} m", uv[k], xytext=(3, -3), textcoords="offset points", fontsize=7, color="#5a5a55")


def _plot_ground_line(ax, camera, xy_world_m, **style) -> np.ndarray:
    """Project a ground polyline; the parts not in front of the camera or outside the image are left out."""
    pr = camera.project_ground(xy_world_m)
    uv = np.where(pr.valid[:, None] & camera.in_image(pr.uv_px)[:, None], pr.uv_px, np.nan)
    ax.plot(uv[:, 0], uv[:, 1], **style)
    return uv


def plot_camera_view(camera, budgets, boxes3d_world, *, confidence: float = 0.95, title: str | None = None,
                     rings_m: Sequence[float] = (20.0, 40.0, 80.0), figsize=(9.6, 5.9)) -> Figure:
    """The camera's image with each object's box and the ``confidence`` ellipse of its footprint centre.

    Parameters
    ----------
    camera : Camera
        The camera (its image frame is the figure's frame: u right, v down, pixels).
    budgets : budget spec or sequence of them
        Error budgets (preset names, files, ErrorBudget); one ellipse per budget and object, one colour each.
    boxes3d_world : array_like (N, 7)
        x_m, y_m, z_m (box centre), length_m, width_m, height_m, yaw_rad in the world frame W.
    confidence : float
        Probability mass of the ellipses (0.95: 2.4477 sigma).
    title : str, optional
    rings_m : sequence of float
        Range rings drawn on the ground (metres from the camera's foot point).

    Returns
    -------
    matplotlib.figure.Figure
        The figure; each ellipse is labelled (largest budget) with its semi-major axis in metres.
    """
    budgets = [budgets] if isinstance(budgets, str) or not isinstance(budgets, Sequence) else list(budgets)
    boxes = as_points("boxes3d_world", boxes3d_world, 7)
    w, h = camera.image_size_px
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    _draw_ground(ax, camera, rings_m)
    corners = box_corners_m(boxes)
    uv = camera.project(corners.reshape(-1, 3)).uv_px.reshape(corners.shape[0], 8, 2)
    for box_uv in uv:
        for i, j in _EDGES:
            ax.plot(box_uv[[i, j], 0], box_uv[[i, j], 1], color="#303030", lw=1.0, zorder=3)
    for k, spec in enumerate(budgets):
        budget = load_budget(spec)
        est = FrameProcessor(camera, budget).boxes3d(boxes)
        semi_major = ellipse_axes(est.centre_cov_m2, confidence=confidence)[0]
        ring = ellipse_points(est.centre_xy_world_m, est.centre_cov_m2, confidence=confidence, n=96)
        col = _COLOURS[k % len(_COLOURS)]
        for n in range(len(boxes)):
            if not np.isfinite(semi_major[n]):
                continue
            e_uv = camera.project_ground(ring[n]).uv_px
            ax.fill(e_uv[:, 0], e_uv[:, 1], color=col, alpha=0.18, zorder=4)
            ax.plot(e_uv[:, 0], e_uv[:, 1], color=col, lw=1.6, zorder=5,
                    label=f"{display_name(budget.name)}" if n == 0 else None)
            if k == len(budgets) - 1:
                right = e_uv[np.argmax(e_uv[:, 0])]
                ax.annotate(f"{semi_major[n]:.2g} m", right, xytext=(4, 0), textcoords="offset points", va="center",
                            fontsize=7.5, color=col, fontweight="bold", zorder=6,
                            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u [px]")
    ax.set_ylabel("v [px]")
    ax.legend(loc="upper right", fontsize=8, title=f"{100 * confidence:g} % ellipse of the footprint centre",
              title_fontsize=8, framealpha=0.9)
    if title:
        ax.set_title(title, fontsize=10)
    return fig
