"""Figure and one-page HTML summary of a ground-control-point solve (``calibrate gcp``).

:func:`plot_gcp`: left, the image (optionally the photo behind) with the clicked points,
their reprojections and the residual arrows (fit and leave-one-out), magnified; right, the
ground (top view, frame W) with the surveyed points, the camera's foot point and view
direction, the 95 % ellipses of the solve's ground uncertainty at each point and the
leave-one-out ground errors.
:func:`gcp_report_html`: the pose with its 1-sigma values, the fit statistics, the figure
and the residual table on one self-contained page.

The figure is built without pyplot (Agg).
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from ..uncertainty.ellipse import ellipse_points
from .report import esc, html_page, html_table, lead_block

__all__ = ["plot_gcp", "gcp_report_html", "MAX_NAMED_POINTS"]

#: above this many points the figure does not write each point's name (10,000 names took ~80 % of a
#: 10,000-point ``calibrate gcp``: matplotlib lays out every text twice); residuals.csv keeps them all
MAX_NAMED_POINTS = 100


def _arrow_scale(lengths, extent) -> float:
    m = np.nanmax(lengths) if np.any(np.isfinite(lengths)) and np.nanmax(lengths) > 0 else 1.0
    raw = 0.06 * extent / m
    return float(10 ** np.floor(np.log10(raw))) if raw > 1 else 1.0


def plot_gcp(solution, *, image=None, confidence: float = 0.95) -> Figure:
    """Points and residual arrows on the image, and the ground view with the solve's ellipses.

    Parameters
    ----------
    solution : footprint_uq.calibration.gcp.GCPSolution
    image : ndarray (H, W, 3) RGB, optional
        The photo, drawn behind the points.
    confidence : float
        Probability of the ground ellipses.
    """
    s = solution
    g = s.gcps
    w, h = s.image_size_px
    fig = Figure(figsize=(13, 5.4))
    ax, axg = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    if image is not None:
        ax.imshow(image, extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    res = s.residual_px
    loo = s.loo_residual_px if s.loo_residual_px is not None else np.full_like(res, np.nan)
    k = _arrow_scale(np.hypot(*np.concatenate([res, loo]).T), max(w, h))
    ax.plot(g.uv_px[:, 0], g.uv_px[:, 1], "o", mfc="none", mec="tab:blue", ms=8, label="clicked pixel")
    ax.plot(s.uv_fit_px[:, 0], s.uv_fit_px[:, 1], "+", color="tab:orange", ms=8, label="reprojected survey point")
    ax.quiver(s.uv_fit_px[:, 0], s.uv_fit_px[:, 1], res[:, 0] * k, res[:, 1] * k, angles="xy", scale_units="xy",
              scale=1, color="tab:red", width=0.004, label=f"residual x{k:g}")
    ok = np.isfinite(loo).all(-1)
    if ok.any():
        base = g.uv_px[ok] - loo[ok]
        ax.quiver(base[:, 0], base[:, 1], loo[ok, 0] * k, loo[ok, 1] * k, angles="xy", scale_units="xy", scale=1,
                  color="tab:purple", width=0.003, alpha=0.7, label=f"leave-one-out residual x{k:g}")
    if len(g.uv_px) <= MAX_NAMED_POINTS:
        for name, (u, v) in zip(g.names, g.uv_px, strict=True):
            ax.annotate(name, (u, v), textcoords="offset points", xytext=(5, 5), fontsize=7, color="tab:blue")
    hull = np.asarray(s.support_data()["hull_uv_px"]) if hasattr(s, "support_data") else np.zeros((0, 2))
    if len(hull) >= 3:  # the control points' support (pixels outside it are extrapolations)
        ring = np.vstack([hull, hull[:1]])
        ax.plot(ring[:, 0], ring[:, 1], "--", color="tab:gray", lw=0.8, label="hull of the points (support)")
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    flag = "" if getattr(s, "usable", True) else "  [NOT USABLE: see the flags]"
    flag += "" if len(g.uv_px) <= MAX_NAMED_POINTS else " (names in residuals.csv)"
    ax.set_title(f"{len(g.uv_px)} GCPs: RMS {s.rms_px:.3g} px, reduced chi-square {s.reduced_chi2:.3g}{flag}",
                 fontsize=10)
    ax.legend(fontsize=7, loc="lower left")
    # ground view
    xy, cov = s.ground_covariance_m2(g.uv_px)
    axg.plot(g.xyz_world_m[:, 0], g.xyz_world_m[:, 1], "o", mfc="none", mec="tab:blue", ms=6, label="survey point")
    good = np.isfinite(cov).all((-1, -2)) & np.isfinite(xy).all(-1)
    if good.any():
        # at the surveyed point: the ellipse of the ground position of its pixel, from the solve alone
        e = ellipse_points(g.xyz_world_m[good, :2], cov[good], confidence=confidence)
        axg.add_collection(LineCollection(list(e), colors="tab:green", linewidths=0.8))  # one artist, any count
        axg.plot([], [], "-", color="tab:green", lw=0.8, label=f"{confidence:.0%} ellipse of the solve")
    if s.loo_ground_error_m is not None:
        le = s.loo_ground_error_m
        okg = np.isfinite(le).all(-1)
        if okg.any():
            axg.quiver(g.xyz_world_m[okg, 0], g.xyz_world_m[okg, 1], le[okg, 0], le[okg, 1], angles="xy",
                       scale_units="xy", scale=1, color="tab:purple", width=0.003,
                       label="leave-one-out ground error (true scale)")
    C = s.camera.position_world_m
    axg.plot(C[0], C[1], "k^", ms=9, label=f"camera foot point (h = {s.camera.height_m:.2f} m)")
    span = np.ptp(g.xyz_world_m[:, :2], axis=0).max() if len(g.uv_px) > 1 else 10.0
    pan = np.deg2rad(s.camera.pan_deg)
    axg.annotate("", xy=(C[0] + 0.2 * span * np.sin(pan), C[1] + 0.2 * span * np.cos(pan)), xytext=(C[0], C[1]),
                 arrowprops={"arrowstyle": "->", "color": "k"})
    axg.set_aspect("equal", adjustable="datalim")
    axg.set_xlabel("x east (m)")
    axg.set_ylabel("y north (m)")
    axg.set_title("ground (world frame W)", fontsize=10)
    axg.grid(alpha=0.3)
    axg.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def gcp_report_html(solution, fig=None, notes=(), *, title: str = "Camera from ground control points") -> str:
    """A self-contained one-page HTML summary of a GCP solve."""
    s = solution
    verdict = (f"Camera solved from {len(s.gcps.uv_px)} ground control points: RMS reprojection "
               f"{s.rms_px:.3g}&nbsp;px, reduced chi-square {s.reduced_chi2:.3g} (about 1 when the stated pixel and "
               "survey sigmas match the residuals; far above 1, the covariance is optimistic).")
    caption = ("Left: clicked pixels, reprojected survey points and residual arrows (magnified). Right: survey points "
               "with the 95 % ellipse of the solve's ground uncertainty and the leave-one-out ground errors.")
    parts = [lead_block(fig, caption, verdict) if fig is not None else f'<p class="verdict">{verdict}</p>']
    stats = [{"points": len(s.gcps.uv_px), "solved": ", ".join(s.estimated), "RMS (px)": s.rms_px,
              "chi-square": s.chi2, "dof": s.dof, "reduced chi-square": s.reduced_chi2,
              "intrinsics covariance": s.intrinsics_cov_given}]
    parts.append("<h2>Fit</h2>" + html_table(stats))
    parts.append("<h2>Pose and 1-sigma</h2>" + html_table(s.pose_table(), floatfmt=".5g"))
    parts.append('<p class="note">1-sigma values from the first-order covariance of the solve: pixel noise and '
                 "survey noise both propagated (effective variance), plus the given intrinsics' covariance. The full "
                 "22 x 22 covariance is in <code>budget.yaml</code>; a reduced chi-square far above 1 means the "
                 "stated sigmas were too small (the covariance is then optimistic).</p>")
    if s.gcps.georef:
        parts.append("<h2>Geodetic origin of W</h2>" + html_table([s.gcps.georef], floatfmt=".9g"))
    if notes:
        parts.append("<h2>Warnings</h2><ul>" + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>")
    cols = ["name", "u_px", "v_px", "x_m", "y_m", "z_m", "du_px", "dv_px", "residual_sigma", "loo_residual_px",
            "loo_ground_error_m", "loo_status"]
    rows = s.residual_rows()
    parts.append("<h2>Residuals</h2>" + html_table(rows, [c for c in cols if c in rows[0]]))
    return html_page(title, parts)
