"""Pinhole intrinsics: pixels <-> distorted normalised coordinates, with Jacobians.

``u = fx * x + skew * y + cx``, ``v = fy * y + cy`` (OpenCV's K with an optional skew).
Pixel coordinates: u to the right, v down, origin at the centre of the top-left
pixel (OpenCV's convention).
"""

from __future__ import annotations

import numpy as np

__all__ = ["pixel_to_normalised", "normalised_to_pixel"]


def pixel_to_normalised(uv_px, fx, fy, cx, cy, skew=0.0, *, get_gradients=False):
    """``(..., 2)`` pixels -> ``(..., 2)`` distorted normalised coordinates.

    With ``get_gradients``, also returns ``dxy_duv`` (..., 2, 2) and
    ``dxy_dk`` (..., 2, 5), the latter with respect to (fx, fy, cx, cy, skew).
    """
    uv = np.asarray(uv_px, dtype=np.float64)
    u, v = uv[..., 0], uv[..., 1]
    y = (v - cy) / fy
    x = (u - cx - skew * y) / fx
    out = np.stack([x, y], -1)
    if not get_gradients:
        return out
    z = np.zeros_like(x)
    one_fx, one_fy = 1.0 / fx + z, 1.0 / fy + z
    dx_dv = -skew * one_fy / fx + z
    d_duv = np.stack([np.stack([one_fx, dx_dv], -1), np.stack([z, one_fy], -1)], -2)
    dy_dfy = -y / fy
    dx = [-x / fx, -skew / fx * dy_dfy, -one_fx, skew * one_fy / fx + z, -y / fx]
    dy = [z, dy_dfy, z, -one_fy, z]
    d_dk = np.stack([np.stack(dx, -1), np.stack(dy, -1)], -2)
    return out, d_duv, d_dk


def normalised_to_pixel(xy, fx, fy, cx, cy, skew=0.0, *, get_gradients=False):
    """Inverse of :func:`pixel_to_normalised`.

    With ``get_gradients``, also returns ``duv_dxy`` (..., 2, 2) and
    ``duv_dk`` (..., 2, 5) with respect to (fx, fy, cx, cy, skew).
    """
    xy = np.asarray(xy, dtype=np.float64)
    x, y = xy[..., 0], xy[..., 1]
    u = fx * x + skew * y + cx
    v = fy * y + cy
    out = np.stack([u, v], -1)
    if not get_gradients:
        return out
    z = np.zeros_like(u)
    d_dxy = np.stack([np.stack([fx + z, skew + z], -1), np.stack([z, fy + z], -1)], -2)
    o = np.ones_like(u)
    d_dk = np.stack([np.stack([x, z, o, z, y], -1), np.stack([z, y, z, o, z], -1)], -2)
    return out, d_dxy, d_dk
