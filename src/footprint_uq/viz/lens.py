"""Figure of a lens's valid domain: which pixels have a ray at all (:mod:`footprint_uq.cameras.lens_domain`)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..cameras.distortion import distort
from ..cameras.pinhole import normalised_to_pixel, pixel_to_normalised
from ..status import UNDISTORT_FAILED

__all__ = ["plot_lens_domain"]


def plot_lens_domain(camera, *, margin: float = 0.1, step_px: int = 4, title: str | None = None) -> Figure:
    """Two panels: the image (and ``margin`` beyond it) with the pixels past the lens's fold
    shaded and the domain's boundary drawn; the distorted radius against the undistorted one.

    Parameters
    ----------
    camera : Camera
    margin : float
        Fraction of the image size shown beyond each edge.
    step_px : int
        Sampling step of the shaded mask, pixels.
    """
    dom = camera.lens_domain
    fx, fy, cx, cy, sk = camera.params[:5]
    w, h = camera.image_size_px
    u = np.arange(-margin * w, (1 + margin) * w, step_px)
    v = np.arange(-margin * h, (1 + margin) * h, step_px)
    uv = np.stack(np.meshgrid(u, v), -1)
    inside = dom.contains_distorted(pixel_to_normalised(uv, fx, fy, cx, cy, sk))
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax, ax2 = fig.subplots(1, 2, width_ratios=[1.6, 1])
    ax.imshow(np.where(inside, 1.0, 0.0), extent=(u[0], u[-1], v[-1], v[0]), cmap="RdYlGn", vmin=-0.6, vmax=1.4,
              interpolation="nearest")
    ax.plot([-0.5, w - 0.5, w - 0.5, -0.5, -0.5], [-0.5, -0.5, h - 0.5, h - 0.5, -0.5], "k-", lw=1.5,
            label="image border")
    if dom.limited:
        ang = dom.angles_rad
        edge = distort(np.stack([dom.r_fold * np.cos(ang), dom.r_fold * np.sin(ang)], -1), dom.dist)
        bd = normalised_to_pixel(edge, fx, fy, cx, cy, sk)
        ax.plot(bd[:, 0], bd[:, 1], "r--", lw=1.2, label="lens fold (domain boundary)")
    share = 100.0 * (1.0 - inside[(uv[..., 0] >= 0) & (uv[..., 0] <= w - 1) & (uv[..., 1] >= 0)
                                  & (uv[..., 1] <= h - 1)].mean())
    ax.set_xlim(u[0], u[-1])
    ax.set_ylim(v[-1], v[0])
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title(title or f"valid pixels (green); {share:.1f} % of the image past the fold "
                          f"(status {UNDISTORT_FAILED})", fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    # radial profile along +x
    k = camera.params[5:13]
    r_max = float(dom.r_fold.max()) if dom.limited else 2.0
    r = np.linspace(0.0, min(1.6 * r_max, 5.0), 400)
    r2 = r * r
    rad = (1 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))) / (1 + r2 * (k[5] + r2 * (k[6] + r2 * k[7])))
    ax2.plot(r, r * rad, "k-", label="r_d(r) along +x")
    if dom.limited:
        ax2.axvline(dom.r_fold[dom.r_fold.size // 2], color="r", ls="--", label="fold radius")
        ax2.axhline(dom.r_max_distorted[dom.r_max_distorted.size // 2], color="r", ls=":",
                    label="largest distorted radius")
    ax2.set_xlabel("undistorted radius r (normalised)")
    ax2.set_ylabel("distorted radius r_d (normalised)")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    return fig
