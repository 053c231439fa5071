"""The footprint geometry both paths share: the ground-contact points of image boxes, the bottom corners of 3-D
boxes, the footprint centre and the area centroid, and the detector's pixel covariance laid out per corner.
Public through :mod:`footprint_uq.products.footprints`."""

from __future__ import annotations

import numpy as np

from .._checks import as_points, check_cov
from ..errors import InputError
from .footprint_estimate import BOX3D_COLUMNS, CONTACT_MODES


# -- geometry ------------------------------------------------------------------------------
def box2d_contact_points(boxes_px, contact: str = "bottom-centre"):
    """Ground-contact pixels of axis-aligned boxes and the linear map from the box.

    Parameters
    ----------
    boxes_px : array_like (N, 4)
        ``u_min, v_min, u_max, v_max`` in pixels.
    contact : {"bottom-centre", "bottom-corners"}

    Returns
    -------
    corners_px : (N, K, 2), K = 1 or 2
    A : (2K, 4)
        ``corners.reshape(N, 2K) = boxes @ A.T`` (for mapping box covariances).
    """
    # a float64 array (the service's and the batch's columns) is taken as it is: no call per frame into _checks
    b = boxes_px if type(boxes_px) is np.ndarray and boxes_px.dtype == np.float64 else as_points("boxes_px",
                                                                                                  boxes_px, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError("boxes_px", b.shape, "an array of shape (N, 4): u_min, v_min, u_max, v_max")
    A = _CONTACT_MAPS.get(contact)
    if A is None:
        raise InputError("contact", contact, f"one of {CONTACT_MODES}")
    with np.errstate(invalid="ignore"):
        bad = (b[:, 2] < b[:, 0]) | (b[:, 3] < b[:, 1])
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"boxes_px[{i}]", b[i].tolist(), "u_min <= u_max and v_min <= v_max")
    return (b @ A.T).reshape(-1, A.shape[0] // 2, 2), A.copy()


def box2d_contact_points_checked(boxes_px: np.ndarray, contact: str = "bottom-centre") -> np.ndarray:
    """:func:`box2d_contact_points`' pixels ``(N, K, 2)`` of boxes the caller has checked already: a float64 array
    ``(N, 4)``, finite, ``u_min <= u_max`` and ``v_min <= v_max`` (the service's value checks,
    ``service/detections.py``); the same arithmetic, without the checks (~4 us of a 100-box frame)."""
    A = _CONTACT_MAPS[contact]
    return (boxes_px @ A.T).reshape(-1, A.shape[0] // 2, 2)


#: contact mode -> the linear map ``A (2K, 4)`` from a box to its contact pixels (read-only; callers get copies)
_CONTACT_MAPS = {"bottom-centre": np.array([[0.5, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0]]),
                 "bottom-corners": np.array([[1.0, 0, 0, 0], [0, 0, 0, 1.0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])}
for _A in _CONTACT_MAPS.values():
    _A.flags.writeable = False


def box3d_bottom_corners(boxes_world, *, yaw_unit: str = "rad", bottom_on_ground: bool = True,
                         ground_z_m: float = 0.0) -> np.ndarray:
    """Bottom corners ``(N, 4, 3)`` of 3D boxes ``(N, 7)`` in W (order: see the module doc)."""
    b = as_points("boxes_world", boxes_world, 7)
    if b.ndim != 2:
        raise InputError("boxes_world", b.shape, f"an array of shape (N, 7): {', '.join(BOX3D_COLUMNS)}")
    if yaw_unit not in ("rad", "deg"):
        raise InputError("yaw_unit", yaw_unit, "'rad' (column yaw_rad) or 'deg' (column yaw_deg)")
    with np.errstate(invalid="ignore"):
        bad = (b[:, 3] < 0) | (b[:, 4] < 0) | (b[:, 5] < 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"boxes_world[{i}] (length_m, width_m, height_m)", b[i, 3:6].tolist(), "sizes >= 0")
    yaw = b[:, 6] if yaw_unit == "rad" else np.deg2rad(b[:, 6])
    with np.errstate(invalid="ignore"):  # an infinite yaw gives NaN corners: flagged NOT_FINITE downstream
        c, s = np.cos(yaw), np.sin(yaw)
    hl, hw = 0.5 * b[:, 3], 0.5 * b[:, 4]
    sl = np.array([-1.0, 1.0, 1.0, -1.0])
    sw = np.array([-1.0, -1.0, 1.0, 1.0])
    dl = sl[None, :] * hl[:, None]
    dw = sw[None, :] * hw[:, None]
    x = b[:, 0:1] + c[:, None] * dl - s[:, None] * dw
    y = b[:, 1:2] + s[:, None] * dl + c[:, None] * dw
    z = np.full_like(x, ground_z_m) if bottom_on_ground else np.broadcast_to(
        (b[:, 2] - 0.5 * b[:, 5])[:, None], x.shape)
    return np.stack([x, y, z], -1)


def polygon_centroid(xy_m, *, get_gradients: bool = False):
    """Area centroid of polygons ``(..., K, 2)`` (shoelace), with its Jacobian.

    Not the footprint centre the estimates report (:func:`footprint_centre`, the vertex mean): the
    area centroid divides by the area, so its linear covariance is wrong wherever noise can fold the
    polygon (docs/uncertainty-model.md, "The footprint centre").

    K = 1: the point; K = 2: the midpoint; K >= 3: ``C = sum (p_i + p_{i+1}) c_i / (6 A)``
    with ``c_i = x_i y_{i+1} - x_{i+1} y_i`` and ``A = sum c_i / 2``.  Coordinates are
    shifted to the vertex mean first (the centroid is translation-equivariant and its
    Jacobian translation-invariant), which keeps far-from-origin polygons accurate.

    Returns
    -------
    centroid : (..., 2)        NaN where the area is zero
    area : (...)               signed area (K < 3: 0)
    dC_dxy : (..., 2, 2K)      only with ``get_gradients``; columns x0, y0, x1, y1, ...
    """
    p = as_points("xy_m", xy_m, 2)
    K = p.shape[-2]
    lead = p.shape[:-2]
    if K < 3:
        C = p.mean(-2)
        if not get_gradients:
            return C, np.zeros(lead)
        G = np.zeros(lead + (2, 2 * K))
        G[..., 0, 0::2] = 1.0 / K
        G[..., 1, 1::2] = 1.0 / K
        return C, np.zeros(lead), G
    m = p.mean(-2, keepdims=True)
    q = p - m
    x, y = q[..., 0], q[..., 1]
    xn, yn = np.roll(x, -1, -1), np.roll(y, -1, -1)
    xp, yp = np.roll(x, 1, -1), np.roll(y, 1, -1)
    c = x * yn - xn * y
    A = 0.5 * c.sum(-1)
    Sx = ((x + xn) * c).sum(-1)
    Sy = ((y + yn) * c).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        deg = ~(np.abs(A) > 1e-12 * np.maximum((q * q).sum((-1, -2)), 1e-300))
        inv6A = np.where(deg, np.nan, 1.0 / (6.0 * A))
    C = np.stack([Sx * inv6A, Sy * inv6A], -1) + m[..., 0, :]
    if not get_gradients:
        return C, A
    cp = np.roll(c, 1, -1)
    dA_dx = 0.5 * (yn - yp)
    dA_dy = 0.5 * (xp - xn)
    dSx_dx = c + cp + (x + xn) * yn - (xp + x) * yp
    dSx_dy = -(x + xn) * xn + (xp + x) * xp
    dSy_dx = (y + yn) * yn - (yp + y) * yp
    dSy_dy = c + cp - (y + yn) * xn + (yp + y) * xp
    Cx_l, Cy_l = Sx * inv6A, Sy * inv6A
    G = np.empty(lead + (2, 2 * K))
    G[..., 0, 0::2] = (dSx_dx - 6.0 * Cx_l[..., None] * dA_dx) * inv6A[..., None]
    G[..., 0, 1::2] = (dSx_dy - 6.0 * Cx_l[..., None] * dA_dy) * inv6A[..., None]
    G[..., 1, 0::2] = (dSy_dx - 6.0 * Cy_l[..., None] * dA_dx) * inv6A[..., None]
    G[..., 1, 1::2] = (dSy_dy - 6.0 * Cy_l[..., None] * dA_dy) * inv6A[..., None]
    return C, A, G


def footprint_centre(xy_m, *, get_gradients: bool = False):
    """The footprint centre of polygons ``(..., K, 2)``: the vertex mean, with the polygon's area.

    The centre every path reports (docs/uncertainty-model.md, "The footprint centre"): the mean of the
    K corners, ``C = sum p_k / K`` -- linear in the corners, so it cannot invert whatever the noise does
    to the polygon (the area centroid, :func:`polygon_centroid`, divides by the area and has no finite
    variance once the area's sign can flip).  For the footprint of a box (a parallelogram on the ground)
    the two coincide.

    Returns
    -------
    centre : (..., 2)          NaN where K >= 3 and the polygon has zero area (:data:`DEGENERATE`)
    area : (...)               signed shoelace area, m^2 (K < 3: 0)
    dC_dxy : (..., 2, 2K)      only with ``get_gradients``: the constant ``(1/K) [I I ... I]``
    """
    p = as_points("xy_m", xy_m, 2)
    K = p.shape[-2]
    lead = p.shape[:-2]
    m = p.mean(-2)
    if K < 3:
        area = np.zeros(lead)
        C = m
    else:
        q = p - m[..., None, :]
        x, y = q[..., 0], q[..., 1]
        area = 0.5 * (x * np.roll(y, -1, -1) - np.roll(x, -1, -1) * y).sum(-1)
        with np.errstate(invalid="ignore"):
            deg = ~(np.abs(area) > 1e-12 * np.maximum((q * q).sum((-1, -2)), 1e-300))
        C = np.where(deg[..., None], np.nan, m)
    if not get_gradients:
        return C, area
    G = np.zeros(lead + (2, 2 * K))
    G[..., 0, 0::2] = 1.0 / K
    G[..., 1, 1::2] = 1.0 / K
    return C, area, G


# -- pixel covariances -----------------------------------------------------------------------
def detector_joint_cov(pixel_cov_px2, N: int, K: int) -> np.ndarray | None:
    """Detector covariance as (N, 2K, 2K) (None if not given)."""
    if pixel_cov_px2 is None:
        return None
    c = np.asarray(pixel_cov_px2, dtype=np.float64)
    if c.shape == (N, 2, 2):
        check_cov("pixel_cov_px2", c, 2)
        out = np.zeros((N, 2 * K, 2 * K))
        for k in range(K):
            out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = c
        return out
    if c.shape == (N, K, 2, 2):
        check_cov("pixel_cov_px2", c, 2)
        out = np.zeros((N, 2 * K, 2 * K))
        for k in range(K):
            out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = c[:, k]
        return out
    if c.shape == (N, 2 * K, 2 * K):
        return check_cov("pixel_cov_px2", c, 2 * K)
    raise InputError("pixel_cov_px2", c.shape, f"shape ({N}, 2, 2), ({N}, {K}, 2, 2) or ({N}, {2 * K}, {2 * K})")


def box_cov_to_corners(box_cov_px2, A: np.ndarray, N: int) -> np.ndarray:
    c = np.asarray(box_cov_px2, dtype=np.float64)
    if c.shape == (N, 4):
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise InputError("box_cov_px2", "negative or non-finite sigma", "standard deviations >= 0 (N, 4)")
        c = c[:, :, None] * np.eye(4) * c[:, None, :]
    elif c.shape == (N, 4, 4):
        check_cov("box_cov_px2", c, 4)
    else:
        raise InputError("box_cov_px2", c.shape, f"shape ({N}, 4, 4) (covariance) or ({N}, 4) (sigmas)")
    return A @ c @ A.T
