"""Figures of an extrinsic calibration against a LiDAR (the paper's figure of checkerboard positions).

:func:`plot_board_poses`: the boards' positions and orientations relative to the
camera (top view and side view in the OpenCV camera frame: x right, y down, z
forward), each board drawn as its outline with its normal.
:func:`plot_pose_spread`: the per-frame poses in the paper's terms (x, y, h, pan,
tilt, roll) around the joint estimate, with the per-frame, bootstrap and Jacobian
standard deviations.

Both return a :class:`matplotlib.figure.Figure` built without pyplot (Agg).
"""

from __future__ import annotations

import cv2
import numpy as np
from matplotlib.figure import Figure

from ..calibration.extrinsics import POSE_NAMES

__all__ = ["plot_board_poses", "plot_pose_spread"]


def _outline_from_corners(X, cols, rows):
    """The inner-corner grid's outline (5, 3) from corners (N, 3) in OpenCV order."""
    g = X.reshape(rows, cols, 3)
    return np.stack([g[0, 0], g[0, -1], g[-1, -1], g[-1, 0], g[0, 0]])


def plot_board_poses(calibration, *, title: str = "Checkerboard positions relative to the camera") -> Figure:
    """Top view (z forward vs x right) and side view (z forward vs height -y) of every used board.

    Parameters
    ----------
    calibration : ExtrinsicCalibration
    """

    cal = calibration
    R = cv2.Rodrigues(cal.rvec)[0]
    t = cal.tvec.ravel()
    fig = Figure(figsize=(11, 4.8))
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    n_used = len(cal.used)
    cmap = __import__("matplotlib").colormaps["viridis"]
    for j, k in enumerate(cal.used):
        fp = cal.frame_poses[k]
        Xc = fp.xyz_m @ R.T + t  # joint pose: LiDAR -> camera
        n = len(Xc)
        f = cal.frames[k]
        cols = rows = None
        for c in range(2, n):
            if n % c == 0 and c >= n // c:
                cols, rows = c, n // c
                break
        col = cmap(j / max(n_used - 1, 1))
        if cols is not None and cols * rows == n:
            o = _outline_from_corners(Xc, cols, rows)
            ax1.plot(o[:, 0], o[:, 2], "-", color=col, lw=1.2)
            ax2.plot(o[:, 2], -o[:, 1], "-", color=col, lw=1.2)
        else:
            ax1.plot(Xc[:, 0], Xc[:, 2], ".", color=col, ms=2)
            ax2.plot(Xc[:, 2], -Xc[:, 1], ".", color=col, ms=2)
        c0 = Xc.mean(axis=0)
        _, _, vt = np.linalg.svd(Xc - c0, full_matrices=False)
        nrm = vt[2] if vt[2] @ c0 < 0 else -vt[2]  # towards the camera
        L = 0.4
        ax1.annotate("", xy=(c0[0] + L * nrm[0], c0[2] + L * nrm[2]), xytext=(c0[0], c0[2]),
                     arrowprops={"arrowstyle": "->", "color": col, "lw": 0.8})
        ax2.annotate("", xy=(c0[2] + L * nrm[2], -c0[1] - L * nrm[1]), xytext=(c0[2], -c0[1]),
                     arrowprops={"arrowstyle": "->", "color": col, "lw": 0.8})
        ax1.text(c0[0], c0[2], f.name, fontsize=6, color=col, ha="center", va="bottom")
    lid = t  # the LiDAR origin in the camera frame
    for ax, (a, b) in ((ax1, (0, 2)), (ax2, (2, 1))):
        sgn = -1 if b == 1 else 1
        ax.plot([0], [0], "k^", ms=9, label="camera")
        ax.plot([lid[a]], [sgn * lid[b]], "rs", ms=6, label="LiDAR")
        ax.grid(True, alpha=0.3)
        ax.set_aspect("equal", adjustable="datalim")
    ax1.set_xlabel("x right (m, camera frame)")
    ax1.set_ylabel("z forward (m)")
    ax1.set_title("top view")
    ax2.set_xlabel("z forward (m, camera frame)")
    ax2.set_ylabel("up = -y (m)")
    ax2.set_title("side view")
    ax1.legend(loc="best", fontsize=8)
    fig.suptitle(f"{title} ({n_used} boards)")
    fig.tight_layout()
    return fig


def plot_pose_spread(calibration, *, truth=None) -> Figure:
    """Per-frame poses minus the joint estimate, one panel per parameter, with +-1 sigma bands
    (per-frame spread, bootstrap, Jacobian); ``truth`` (dict of :data:`POSE_NAMES`) marked if given."""

    cal = calibration
    fig = Figure(figsize=(12, 6))
    d = cal.per_frame - cal.pose
    names = [cal.frames[k].name for k in cal.used]
    srcs = {}
    for s in ("per_frame", "bootstrap", "jacobian"):
        try:
            srcs[s] = cal.sigmas(s)
        except Exception:  # noqa: BLE001 - a missing source (no bootstrap) is simply not drawn
            continue
    colors = {"per_frame": "tab:blue", "bootstrap": "tab:orange", "jacobian": "tab:green"}
    x = np.arange(len(names))
    for i, nm in enumerate(POSE_NAMES):
        ax = fig.add_subplot(2, 3, i + 1)
        ax.plot(x, d[:, i], "ko", ms=4)
        for s, sig in srcs.items():
            ax.axhspan(-sig[i], sig[i], color=colors[s], alpha=0.15, label=f"1 sigma {s}")
        if truth is not None:
            ax.axhline(truth[nm] - cal.pose[i], color="r", ls="--", lw=1, label="truth")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(f"{nm} ({cal.estimator} {cal.pose[i]:.4g})", fontsize=9)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=90, fontsize=6)
        ax.grid(True, alpha=0.3)
        if i == 0:
            ax.legend(fontsize=6, loc="best")
    fig.suptitle(f"Per-frame camera poses relative to the {cal.estimator} estimate (ground frame)")
    fig.tight_layout()
    return fig
