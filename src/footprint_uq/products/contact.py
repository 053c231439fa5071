"""Where a 2-D box touches the ground: the footprint centre of a detected object, with its covariance.

The bottom edge of the 2-D box of a cuboid standing on the ground is the image of its lowest visible
point -- a ground corner of the footprint, the one nearest the camera -- so the back-projected
bottom-centre pixel lies short of the footprint centre by up to half the footprint's diagonal
(``docs/uncertainty-model.md``, section 3c).  :func:`footprint_centre` models the box: for every node
of a deterministic quadrature over the object's yaw (uniform when unknown, Gauss-Hermite around a
3-D detector's yaw) and size (the unscented points of the class's size prior) it solves, by Newton's
method, for the footprint centre ``c_k`` whose rendered box -- the bounding box of the cuboid's eight
projected corners -- has exactly the detected bottom-centre pixel.  The estimate is the weighted mean
of the ``c_k``; their spread is the contact model's covariance, added to the pixel noise.  The
Jacobians follow from the implicit-function theorem (``dc/dp = -(dF/dc)^-1 dF/dp``), closed form.

``bottom_centre`` keeps the old behaviour (the back-projected bottom-centre pixel) under the same
interface; :data:`CONTACT_MODELS` names both.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from .. import params as P
from .. import status
from .._checks import as_points, check_cov
from .._files import read_input_text
from ..cameras import general
from ..cameras.rotation import R_W_C, dR_W_C
from ..errors import ConfigError, InputError
from ..fast import contact_kernels as ck
from ..uncertainty.budget import load_budget
from .covariance import covariance_points
from .footprints import box2d_contact_points

__all__ = ["ContactResult", "SizePrior", "CONTACT_MODELS", "SIZE_PRIORS_FILE", "load_size_priors",
           "bottom_centre", "bottom_centre_nonlinearity", "footprint_centre", "YAW_NODES_UNKNOWN",
           "DEFAULT_YAW_SIGMA_RAD", "rendered_bottom_centre", "class_size_priors"]

#: the shipped priors (per-class length, width, height: mean and sigma, metres)
SIZE_PRIORS_FILE = Path(__file__).resolve().parents[1] / "presets" / "size_priors.yaml"
#: yaw nodes over [0, pi) when the yaw is unknown (a box is symmetric under a half turn)
YAW_NODES_UNKNOWN = 36
#: default sigma of a 3-D detector's yaw (radians) when ``yaw_rad`` is given without ``yaw_sigma_rad``
DEFAULT_YAW_SIGMA_RAD = float(np.deg2rad(5.0))
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(5)  # probabilists' Gauss-Hermite: nodes for N(0, 1)
_GH_W = _GH_W / _GH_W.sum()
_NEWTON_STEPS = 9
_CHUNK_POINTS = 200_000
_NO_EVIDENCE_PX2 = 1e12  # the width variance of a box cut by the image border (its width says nothing)


class ContactResult(NamedTuple):
    """Ground points of 2-D detections and their covariance.

    Attributes
    ----------
    xy_world_m : (N, 2)          estimated ground point (frame W, metres); NaN where invalid
    cov_m2 : (N, 2, 2)           total covariance = ``dxy_dp @ Sigma_p @ dxy_dp^T + cov_object_m2``
    cov_object_m2 : (N, 2, 2)    per-object part: pixel / detector noise + contact-model spread
    dxy_dp : (N, 2, 22)          Jacobian w.r.t. the camera parameters (``PARAM_NAMES`` order)
    valid : (N,) bool
    status : (N,) int8           :mod:`footprint_uq.status` code
    """

    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    cov_object_m2: np.ndarray
    dxy_dp: np.ndarray
    valid: np.ndarray
    status: np.ndarray


class SizePrior(NamedTuple):
    """``mean_m`` and ``sigma_m`` (3,): length, width, height of a class's 3-D box, metres."""

    mean_m: np.ndarray
    sigma_m: np.ndarray


# ---------------------------------------------------------------------------------------------
# size priors
# ---------------------------------------------------------------------------------------------
def _read_priors(path) -> dict:
    """The parsed file, cached on its path, modification time and size (read-only: never mutate it)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        st = None
    return _parse_priors(str(p), None if st is None else (st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=32)
def _parse_priors(path: str, stamp) -> dict:
    p = Path(path)
    try:
        d = yaml.safe_load(read_input_text(p, "size priors"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise ConfigError(str(p), type(e).__name__, f"a readable YAML size-prior file ({str(e).splitlines()[0]})") \
            from None
    if not isinstance(d, dict) or not set(d) <= {"classes", "aliases", "fallback"}:
        raise ConfigError(str(p), type(d).__name__, "a mapping with 'classes' (and optional 'aliases', 'fallback')")
    return d


def _prior(where: str, name: str, entry) -> SizePrior:
    keys = ("length_m", "width_m", "height_m")
    if not isinstance(entry, dict) or set(entry) != set(keys):
        raise ConfigError(f"{where}: classes.{name}", entry, f"a mapping with {list(keys)}, each [mean, sigma]")
    try:
        ms = np.array([[float(v) for v in entry[k]] for k in keys])
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: classes.{name}", entry, "[mean, sigma] numbers in metres") from None
    if ms.shape != (3, 2) or not np.all(np.isfinite(ms)) or np.any(ms[:, 0] <= 0) or np.any(ms[:, 1] < 0):
        raise ConfigError(f"{where}: classes.{name}", entry, "[mean > 0, sigma >= 0] in metres for each size")
    return SizePrior(ms[:, 0], ms[:, 1])


def load_size_priors(path=None) -> tuple[dict[str, SizePrior], dict[str, str], str | None]:
    """The shipped priors, overridden class by class by a user YAML file (same layout).

    Returns ``(priors, aliases, fallback class)``; class names are lower case.
    """
    priors, aliases, fallback = {}, {}, None
    for f in (SIZE_PRIORS_FILE, path):
        if f is None:
            continue
        d = _read_priors(f)
        for key in ("classes", "aliases"):
            if not isinstance(d.get(key) or {}, dict):
                raise ConfigError(f"{f}: {key}", d[key], "a mapping" + (" class -> {length_m, width_m, height_m}"
                                                                       if key == "classes" else " alias -> class"))
        for name, entry in (d.get("classes") or {}).items():
            priors[str(name).lower()] = _prior(str(f), str(name), entry)
        aliases.update({str(k).lower(): str(v).lower() for k, v in (d.get("aliases") or {}).items()})
        fallback = str(d["fallback"]).lower() if d.get("fallback") is not None else fallback
    for k, v in aliases.items():
        if v not in priors:
            raise ConfigError("size priors: aliases", f"{k}: {v}", f"an alias of one of {sorted(priors)}")
    if fallback is not None and fallback not in priors:
        raise ConfigError("size priors: fallback", fallback, f"one of {sorted(priors)}")
    return priors, aliases, fallback


def _class_priors(classes, n: int, size_priors, unknown_class: str) -> tuple[np.ndarray, np.ndarray]:
    """Per object: the prior's mean and sigma (N, 3)."""
    if unknown_class not in ("fallback", "error"):
        raise InputError("unknown_class", unknown_class, "'fallback' (the prior 'other') or 'error'")
    priors, aliases, fallback = size_priors if isinstance(size_priors, tuple) else load_size_priors(size_priors)
    names = np.asarray(classes, dtype=object).reshape(-1)
    if names.size != n:
        raise InputError("classes", f"{names.size} names", f"one class name per box ({n})")
    mean, sig = np.empty((n, 3)), np.empty((n, 3))
    for name in set(names.tolist()):
        key = str(name).strip().lower()
        key = aliases.get(key, key)
        if key not in priors:
            if unknown_class == "error" or fallback is None:
                i = int(np.flatnonzero(names == name)[0])
                raise InputError(f"classes[{i}]", name, f"one of {sorted(priors)} (or their aliases "
                                 f"{sorted(aliases)}), or unknown_class='fallback'")
            key = fallback
        rows = names == name
        mean[rows], sig[rows] = priors[key]
    return mean, sig


# ---------------------------------------------------------------------------------------------
# the rendered box and its inverse
# ---------------------------------------------------------------------------------------------
_SL = np.array([-1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, -1.0])   # corner signs along the length
_SW = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0])   # ... along the width
_TOP = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0])       # bottom face, then top face


def _nodes(mean, sig, yaw, yaw_sig):
    """Quadrature nodes of one kind of object (all with, or all without, a yaw).

    Sizes: the 6 unscented points ``mean +- sqrt(3) sigma e_j`` (weight 1/6; exact mean and covariance
    of a Gaussian size, and its fourth moments along each axis).  Yaw: 36 points over [0, pi) when
    unknown, or 5 Gauss-Hermite points around the given yaw.  Returns sizes (n, K, 3), yaw (n, K) with
    K = ny * 6 (yaw-major), the log prior weights of the yaw nodes (ny,) and ny.
    """
    offs = np.sqrt(3.0) * np.vstack([np.eye(3), -np.eye(3)])
    sizes = np.clip(mean[:, None, :] + offs[None] * sig[:, None, :], 0.02, None)   # (n, 6, 3)
    if yaw is None:
        ky = (np.arange(YAW_NODES_UNKNOWN) + 0.5) * np.pi / YAW_NODES_UNKNOWN
        yaws, wy = np.broadcast_to(ky, (mean.shape[0], ky.size)), np.full(ky.size, 1.0 / ky.size)
    else:
        yaws, wy = yaw[:, None] + yaw_sig[:, None] * _GH_X[None], _GH_W
    n, ny = yaws.shape
    S = np.broadcast_to(sizes[:, None], (n, ny, 6, 3)).reshape(n, ny * 6, 3)
    Y = np.broadcast_to(yaws[:, :, None], (n, ny, 6)).reshape(n, ny * 6)
    return S, Y, np.log(wy), ny


def _corners(p, c, sizes, yaw):
    """World corners (..., 8, 3) (z from the nominal ground plane) of boxes centred at ``c`` (..., 2)."""
    cs, sn = np.cos(yaw)[..., None], np.sin(yaw)[..., None]
    dl, dw = 0.5 * sizes[..., 0:1] * _SL, 0.5 * sizes[..., 1:2] * _SW
    x = c[..., 0:1] + cs * dl - sn * dw
    y = c[..., 1:2] + sn * dl + cs * dw
    zg = p[P.GDZ] + p[P.GSX] * (c[..., 0] - p[P.XM]) + p[P.GSY] * (c[..., 1] - p[P.YM])
    z = zg[..., None] + sizes[..., 2:3] * _TOP
    return np.stack([x, y, z], -1)


def _edges(uv, D):
    """The bounding box ``u_min, v_min, u_max, v_max`` (..., 4) of projected corners (..., 8, 2) and the
    same selection of a per-corner derivative D (..., 8, 2, m) -> (..., 4, m)."""
    idx = np.stack([uv[..., 0].argmin(-1), uv[..., 1].argmin(-1), uv[..., 0].argmax(-1), uv[..., 1].argmax(-1)], -1)
    comp = np.array([0, 1, 0, 1])
    E = np.take_along_axis(uv, idx[..., None], -2)[..., np.arange(4), comp]
    dE = np.take_along_axis(D, idx[..., None, None], -3)[..., np.arange(4), comp, :]
    return E, dE


_FB = np.array([[0.5, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0]])   # edges -> bottom-centre pixel
_FW = np.array([-1.0, 0.0, 1.0, 0.0])                           # edges -> box width


def _bottom_uv(camera, c, sizes, yaw):
    """Bottom-centre pixel of the rendered boxes (..., 2) and whether every corner projects."""
    pr = general.project(camera.params, _corners(camera.params, c, sizes, yaw), domain=camera.lens_domain)
    uv = pr.uv_px
    u = 0.5 * (uv[..., 0].min(-1) + uv[..., 0].max(-1))
    return np.stack([u, uv[..., 1].max(-1)], -1), pr.valid.all(-1)


def _render(camera, c, sizes, yaw):
    """Edges of the rendered boxes (..., 4), d(edges)/dc (..., 4, 2), d(edges)/dp (..., 4, 22), valid."""
    p = camera.params
    pr = general.project(p, _corners(p, c, sizes, yaw), get_gradients=True, domain=camera.lens_domain)
    slope = np.array([p[P.GSX], p[P.GSY]])
    duv_dc = pr.duv_dxyz[..., :2] + pr.duv_dxyz[..., 2:3] * slope          # (..., 8, 2, 2)
    dz_dp = np.zeros(c.shape[:-1] + (P.N_PARAMS,))
    dz_dp[..., P.GDZ] = 1.0
    dz_dp[..., P.GSX] = c[..., 0] - p[P.XM]
    dz_dp[..., P.GSY] = c[..., 1] - p[P.YM]
    dz_dp[..., P.XM], dz_dp[..., P.YM] = -p[P.GSX], -p[P.GSY]
    duv_dp = pr.duv_dp + pr.duv_dxyz[..., 2:3] * dz_dp[..., None, None, :]  # (..., 8, 2, 22)
    E, dE = _edges(pr.uv_px, np.concatenate([duv_dc, duv_dp], -1))
    return E, dE[..., :2], dE[..., 2:], pr.valid.all(-1)


class _Nodes(NamedTuple):
    c: np.ndarray        # (n, K, 2)   footprint centres matching the bottom-centre pixel
    dc: np.ndarray       # (n, K, 2, 24) d c / d(params, bottom-centre pixel)
    w: np.ndarray        # (n, K)      rendered box widths (px)
    dw: np.ndarray       # (n, K, 24)
    converged: np.ndarray  # (n,)
    front: np.ndarray      # (n,)


def _writeable(a) -> np.ndarray:
    """``a`` as a writeable C-contiguous float64 array (copied only when it is not one)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def _solve_nodes(camera, b_px, c_start, sizes, yaw) -> _Nodes:
    """:func:`_solve_nodes_reference`, compiled (:func:`footprint_uq.fast.contact_kernels.solve_nodes`:
    every object and node in one call, objects in parallel; the same numbers to rounding)."""
    p = np.array(camera.params, dtype=np.float64, order="C")
    n, K = yaw.shape
    c, dc = np.empty((n, K, 2)), np.empty((n, K, 2, P.N_PARAMS + 2))
    w, dw = np.empty((n, K)), np.empty((n, K, P.N_PARAMS + 2))
    conv, ok = np.empty((n, K), dtype=np.bool_), np.empty((n, K), dtype=np.bool_)
    ang = (p[P.PAN], p[P.TILT], p[P.ROLL])
    # writeable C-contiguous float64 (a read-only array, such as a cached lens domain, is another numba type:
    # a second compilation of the kernel); the small ones copied
    cp, f64 = (lambda a: np.array(a, dtype=np.float64, order="C")), _writeable  # noqa: E731
    with ck.threads_for(n * K):
        ck.solve_nodes(p, cp(R_W_C(*ang)), cp(dR_W_C(*ang)), cp(camera.lens_domain.packed),
                       bool(np.any(p[P.DIST_SLICE])), cp(b_px), f64(c_start), f64(sizes), f64(yaw), _NEWTON_STEPS,
                       c, dc, w, dw, conv, ok)
    return _Nodes(c, dc, w, dw, conv.all(-1), ok.all(-1))


def _solve_nodes_reference(camera, b_px, c_start, sizes, yaw) -> _Nodes:
    """Footprint centres whose rendered boxes have the bottom-centre pixel ``b_px`` (n, 2), one per node.

    Newton's method with the Jacobian refreshed every third step (a chord step in between: the
    projection without gradients costs a fraction), then one exact evaluation for the derivatives
    (implicit-function theorem: dc/dp = -(dF/dc)^-1 dF/dp, dc/db = (dF/dc)^-1).
    """
    c = c_start.copy()
    with np.errstate(all="ignore"):
        for it in range(_NEWTON_STEPS):
            if it % 3 == 0:
                E, dEc, _, ok = _render(camera, c, sizes, yaw)
                Jc = _FB @ dEc
                Jc = np.where(ok[..., None, None] & np.isfinite(Jc).all((-1, -2))[..., None, None], Jc, np.eye(2))
                b = E @ _FB.T
            else:
                b, ok = _bottom_uv(camera, c, sizes, yaw)
            step = np.linalg.solve(Jc, (b - b_px[:, None])[..., None])[..., 0]
            c = c - np.where(ok[..., None] & np.isfinite(step), step, 0.0)
        E, dEc, dEp, ok = _render(camera, c, sizes, yaw)
        Jc = _FB @ dEc
        good = ok & np.isfinite(Jc).all((-1, -2)) & (np.abs(np.linalg.det(np.where(ok[..., None, None], Jc, 1.0))) > 0)
        Jinv = np.linalg.inv(np.where(good[..., None, None], Jc, np.eye(2)))
        conv = good & (np.abs(E @ _FB.T - b_px[:, None]).max(-1) < 1e-4)
        dc = np.concatenate([-Jinv @ (_FB @ dEp), Jinv], -1)                  # (n, K, 2, 24)
        dw = np.einsum("e,nkep->nkp", _FW, np.concatenate([dEp, np.zeros(dEp.shape[:-1] + (2,))], -1)) \
            + np.einsum("e,nkea,nkap->nkp", _FW, dEc, dc)
    return _Nodes(c, dc, E @ _FW, dw, conv.all(-1), ok.all(-1))


def _posterior(nd: _Nodes, ny: int, w_obs, r_w, log_prior):
    """:func:`_posterior_reference`, compiled (:func:`footprint_uq.fast.contact_kernels.posterior`)."""
    n, M = nd.c.shape[0], nd.dw.shape[-1]
    x, dx, cov = np.empty((n, 2)), np.empty((n, 2, M)), np.empty((n, 2, 2))
    f64, cp = _writeable, (lambda a: np.array(a, dtype=np.float64, order="C"))  # noqa: E731
    with ck.threads_for(nd.w.size):
        ck.posterior(f64(nd.c), f64(nd.dc), f64(nd.w), f64(nd.dw), int(ny), cp(w_obs), cp(r_w),
                     cp(np.broadcast_to(log_prior, (ny,))), x, dx, cov)
    return x, dx, cov


def _posterior_reference(nd: _Nodes, ny: int, w_obs, r_w, log_prior):
    """Condition each yaw node's unscented size points on the observed box width (a Kalman update),
    weigh the yaw nodes by the width's marginal likelihood, and mix.  Forward-mode derivatives (24
    columns: the 22 parameters and the bottom-centre pixel) go through every step.

    Returns the centre (n, 2), its derivatives (n, 2, 24) and the contact covariance (n, 2, 2).
    """
    n = nd.c.shape[0]
    c, dc = nd.c.reshape(n, ny, 6, 2), nd.dc.reshape(n, ny, 6, 2, -1)
    z, dz = nd.w.reshape(n, ny, 6), nd.dw.reshape(n, ny, 6, -1)
    cb, dcb, zb, dzb = c.mean(2), dc.mean(2), z.mean(2), dz.mean(2)
    ec, ez, dec, dez = c - cb[:, :, None], z - zb[:, :, None], dc - dcb[:, :, None], dz - dzb[:, :, None]
    Ccz = (ec * ez[..., None]).mean(2)                                              # (n, ny, 2)
    Czz = (ez**2).mean(2) + r_w[:, None]                                            # (n, ny)
    Ccc = np.einsum("njia,njib->njab", ec, ec) / 6
    dCcz = (dec * ez[..., None, None]).mean(2) + (ec[..., None] * dez[..., None, :]).mean(2)
    dCzz = 2 * (ez[..., None] * dez).mean(2)
    G = Ccz / Czz[..., None]
    dG = (dCcz - G[..., None] * dCzz[:, :, None, :]) / Czz[..., None, None]
    innov = w_obs[:, None] - zb
    mu = cb + G * innov[..., None]
    dmu = dcb + dG * innov[..., None, None] - G[..., None] * dzb[:, :, None, :]
    Pj = Ccc - G[..., :, None] * Ccz[..., None, :]
    logL = -0.5 * innov**2 / Czz - 0.5 * np.log(Czz) + log_prior
    dlogL = (innov / Czz)[..., None] * dzb + (0.5 * innov**2 / Czz**2 - 0.5 / Czz)[..., None] * dCzz
    pi = np.exp(logL - logL.max(1, keepdims=True))
    pi /= pi.sum(1, keepdims=True)
    dpi = pi[..., None] * (dlogL - np.einsum("nj,njm->nm", pi, dlogL)[:, None])
    x = np.einsum("nj,nja->na", pi, mu)
    dx = np.einsum("njm,nja->nam", dpi, mu) + np.einsum("nj,njam->nam", pi, dmu)
    d = mu - x[:, None]
    cov = np.einsum("nj,njab->nab", pi, Pj + d[..., :, None] * d[..., None, :])
    return x, dx, cov


# ---------------------------------------------------------------------------------------------
# the two contact models
# ---------------------------------------------------------------------------------------------
def _inputs(budget, boxes_xyxy_px, cov_uv_px2):
    """Boxes (N, 4), bottom-centre pixels (N, 2), per-object pixel covariance (N, 2, 2), parameter covariance
    (22, 22) and the budget."""
    box = as_points("boxes_xyxy_px", boxes_xyxy_px, 4)
    if box.ndim != 2:
        raise InputError("boxes_xyxy_px", box.shape, "an array of shape (N, 4): u_min, v_min, u_max, v_max")
    b = box2d_contact_points(box, "bottom-centre")[0][:, 0, :]
    budget = load_budget(budget)
    n = b.shape[0]
    S_pix = np.broadcast_to(budget.pixel_covariance(), (n, 2, 2))
    if cov_uv_px2 is not None:
        S_pix = S_pix + _detector_cov(cov_uv_px2, n)
    return box, b, S_pix, budget.param_covariance(), budget


def _detector_cov(cov_uv_px2, n: int) -> np.ndarray:
    c = check_cov("cov_uv_px2", cov_uv_px2, 2)
    if c.shape not in ((2, 2), (n, 2, 2)):
        raise InputError("cov_uv_px2", f"shape {c.shape}", f"a covariance (2, 2) or ({n}, 2, 2) in px^2")
    return np.broadcast_to(c, (n, 2, 2))


def _result(camera, b, xy, J, Juv, spread, S_pix, Sp, valid, reason) -> ContactResult:
    """Totals, NaN where invalid; a covariance that overflows is ``OVERFLOW``; a valid point whose
    bottom-centre pixel ``b`` lies outside the image keeps its numbers, flagged ``OUTSIDE_IMAGE``."""
    with np.errstate(invalid="ignore", over="ignore"):
        cov_obj = Juv @ S_pix @ np.swapaxes(Juv, 1, 2) + spread
        cov = J @ Sp @ np.swapaxes(J, 1, 2) + cov_obj
    reason = reason.astype(np.int8)
    ok = valid & np.isfinite(cov).all((-1, -2))
    reason[valid & ~ok] = status.OVERFLOW
    reason[ok & ~camera.in_image(b)] = status.OUTSIDE_IMAGE  # computed, but flagged
    bad = ~ok
    for a in (xy, J, cov_obj, cov):
        a[bad] = np.nan
    return ContactResult(xy, cov, cov_obj, J, ok, reason)


def bottom_centre(camera, budget, boxes_xyxy_px, classes=None, *, yaw_rad=None, cov_uv_px2=None) -> ContactResult:
    """Ground point of the centre of each box's bottom edge, ``((u_min + u_max) / 2, v_max)``: the model
    without a contact offset (``footprint-uq objects --contact bottom-centre``; ``classes`` and ``yaw_rad``
    are accepted for a common interface and unused).

    Parameters and result as :func:`footprint_centre`: ``cov_object_m2 = dxy_duv Sigma_uv dxy_duv^T`` (the
    pixel noise only), ``cov_m2`` adds the calibration part ``dxy_dp Sigma_params dxy_dp^T``.  Invalid points
    are NaN with their status; a valid point whose pixel is outside the image keeps its numbers with status
    ``OUTSIDE_IMAGE``.  The linearity flag of the same pixels: :func:`bottom_centre_nonlinearity`.
    """
    _, b, S_pix, Sp, _ = _inputs(budget, boxes_xyxy_px, cov_uv_px2)
    bp = camera.backproject(b, get_gradients=True)
    return _result(camera, b, bp.xy_world_m.copy(), bp.dxy_dp.copy(), bp.dxy_duv, np.zeros((b.shape[0], 2, 2)),
                   S_pix, Sp, bp.valid.copy(), bp.reason.copy())


def bottom_centre_nonlinearity(camera, budget, boxes_xyxy_px, cov_uv_px2=None, valid=None) -> np.ndarray:
    """The linearity flag's ``nonlinearity`` (N,) of each box's bottom-centre pixel (the compiled kernel's,
    :func:`~footprint_uq.products.covariance.covariance_points`, equal to
    :func:`~footprint_uq.uncertainty.propagation.propagate`'s and ~20x faster than the numpy form); NaN where
    the pixel has none, and where ``valid`` (N,) bool is given and False."""
    box = as_points("boxes_xyxy_px", boxes_xyxy_px, 4)
    uv = box2d_contact_points(box, "bottom-centre")[0][:, 0, :]
    cuv = None if cov_uv_px2 is None else np.ascontiguousarray(_detector_cov(cov_uv_px2, uv.shape[0]))
    nl = covariance_points(camera, budget, uv, cuv, get_nonlinearity=True)[-1]
    return nl if valid is None else np.where(valid, nl, np.nan)


def _yaws(yaw_rad, yaw_sigma_rad, n):
    yaw = np.full(n, np.nan) if yaw_rad is None else np.asarray(yaw_rad, dtype=np.float64).reshape(-1)
    if yaw.shape != (n,) or np.isinf(yaw).any():
        raise InputError("yaw_rad", f"shape {yaw.shape}" if yaw.shape != (n,) else "an infinite yaw",
                         f"({n},) yaws in radians (counter-clockwise from east; NaN = unknown)")
    ys = np.broadcast_to(np.asarray(DEFAULT_YAW_SIGMA_RAD if yaw_sigma_rad is None else yaw_sigma_rad,
                                    dtype=np.float64), (n,))
    if not np.all(np.isfinite(ys) & (ys >= 0)):
        raise InputError("yaw_sigma_rad", yaw_sigma_rad, "finite sigmas >= 0 in radians")
    return yaw, ys


def _start(camera, c0, sizes, yaw):
    """Newton's start per node: the bottom-centre point pushed away from the camera by the box's
    extent along the line of sight (the nearest corner lies that much short of the centre)."""
    d = c0 - camera.params[P.XM:P.YM + 1]
    e = d / np.linalg.norm(d, axis=-1, keepdims=True)
    phi = yaw - np.arctan2(e[:, 1], e[:, 0])[:, None]
    m = 0.5 * sizes[..., 0] * np.abs(np.cos(phi)) + 0.5 * sizes[..., 1] * np.abs(np.sin(phi))
    return c0[:, None, :] + m[..., None] * e[:, None, :]


def footprint_centre(camera, budget, boxes_xyxy_px, classes, *, yaw_rad=None, yaw_sigma_rad=None,
                     cov_uv_px2=None, box_sigma_px: float = 2.0, size_priors=None,
                     unknown_class: str = "fallback") -> ContactResult:
    """The footprint centre of each detected object, with the contact model's covariance.

    Parameters
    ----------
    camera : Camera
    budget : budget spec
        Its camera-level covariance gives ``cov_m2``'s shared part; its imaging and resolution noise
        act on the bottom-centre pixel.
    boxes_xyxy_px : array_like (N, 4)
        ``u_min, v_min, u_max, v_max`` (px) of whole (untruncated) objects.
    classes : sequence of str (N,)
        Class names: car, van, truck, bus, pedestrian, cyclist, motorcyclist (or an alias).
    yaw_rad : array_like (N,), optional
        Heading of each object's length axis (counter-clockwise from east, radians), e.g. from a 3-D
        detector; NaN or None: unknown (uniform).
    yaw_sigma_rad : float or array_like (N,), optional
        Sigma of a given yaw (default :data:`DEFAULT_YAW_SIGMA_RAD`, 5 deg).
    cov_uv_px2 : array_like (2, 2) or (N, 2, 2), optional
        Detector covariance of the bottom-centre pixel, added to the budget's per-point noise.
    box_sigma_px : float
        Sigma of each box edge (px, default 2): the noise of the observed box width on which the yaw and
        size are conditioned (plus the budget's per-point noise along u).  A box touching the left or
        right image border is not conditioned on its width (the border cut it).
    size_priors : path, optional
        A YAML file overriding the shipped priors class by class (:func:`load_size_priors`).
    unknown_class : {"fallback", "error"}
        A class not in the priors: use the broad prior ``other`` (default, documented) or raise InputError.

    Returns
    -------
    ContactResult
        Invalid where the bottom-centre pixel has no ground point (its code), where a rendered corner is
        behind the camera (``BEHIND_CAMERA``) or where the box cannot be matched (``OVERFLOW``).
    """
    box, b, S_pix, Sp, bud = _inputs(budget, boxes_xyxy_px, cov_uv_px2)
    n = b.shape[0]
    mean, sig = _class_priors(classes, n, size_priors, unknown_class)
    yaw, ysig = _yaws(yaw_rad, yaw_sigma_rad, n)
    bs = float(box_sigma_px)
    if not (np.isfinite(bs) and bs > 0):
        raise InputError("box_sigma_px", box_sigma_px, "a finite sigma > 0 (px) of each box edge")
    w_obs = box[:, 2] - box[:, 0]
    r_w = np.full(n, 2 * (bs**2 + bud.pixel_covariance()[0, 0]))
    # a box cut by the left or right image border does not show the object's width: no evidence from it
    r_w[(box[:, 0] <= 0.5) | (box[:, 2] >= camera.image_size_px[0] - 1.5)] = _NO_EVIDENCE_PX2
    bp = camera.backproject(b)
    xy, J = np.full((n, 2), np.nan), np.full((n, 2, P.N_PARAMS + 2), np.nan)
    spread = np.full((n, 2, 2), np.nan)
    valid, reason = bp.valid.copy(), bp.reason.copy()
    for known in (False, True):
        rows = np.flatnonzero(bp.valid & (np.isfinite(yaw) == known))
        step = max(1, _CHUNK_POINTS // (8 * 6 * (5 if known else YAW_NODES_UNKNOWN)))
        for i in range(0, rows.size, step):
            r = rows[i:i + step]
            S, Y, log_prior, ny = _nodes(mean[r], sig[r], yaw[r] if known else None, ysig[r] if known else None)
            nd = _solve_nodes(camera, b[r], _start(camera, bp.xy_world_m[r], S, Y), S, Y)
            xy[r], J[r], spread[r] = _posterior(nd, ny, w_obs[r], r_w[r], log_prior)
            valid[r] = nd.converged
            reason[r[~nd.front]] = status.BEHIND_CAMERA
            reason[r[nd.front & ~nd.converged]] = status.OVERFLOW
    return _result(camera, b, xy, J[..., :P.N_PARAMS].copy(), J[..., P.N_PARAMS:], spread, S_pix, Sp, valid, reason)


#: the contact models by name (``contact=`` of the validation, ``footprint-uq validate / calibrate budget
#: --contact NAME``): the one registry, re-exported by :mod:`footprint_uq.validation.pairs`
CONTACT_MODELS = {"bottom-centre": bottom_centre, "footprint-centre": footprint_centre}


# ---------------------------------------------------------------------------------------------
# the rendered model for other modules (tracking.contact_slide)
# ---------------------------------------------------------------------------------------------
def rendered_bottom_centre(camera, centre_xy_m, sizes_m, yaw_rad, *,
                           gradients: bool = True) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """The bottom-centre pixel of the 2-D box of cuboids standing on the ground, and its derivative.

    Parameters
    ----------
    camera : Camera (a parametric model: ``params``, ``lens_domain``)
    centre_xy_m : (..., 2)   footprint centres, frame W, metres
    sizes_m : (..., 3)       length (along the yaw), width, height, metres
    yaw_rad : (...)          yaw, radians counter-clockwise from W's x axis

    Returns
    -------
    uv_px : (..., 2)           ``((u_min + u_max) / 2, v_max)`` of the box around the 8 projected corners
    duv_dc_px_per_m : (..., 2, 2)   its derivative w.r.t. the centre (the extreme corners held: exact where no two
                               corners tie for an edge); None with ``gradients=False`` (a third of the work)
    valid : (...) bool         every corner projects
    """
    if not gradients:
        uv, valid = _bottom_uv(camera, np.asarray(centre_xy_m, dtype=np.float64), np.asarray(sizes_m, dtype=np.float64),
                               np.asarray(yaw_rad, dtype=np.float64))
        return uv, None, valid
    E, dE_dc, _, valid = _render(camera, np.asarray(centre_xy_m, dtype=np.float64),
                                 np.asarray(sizes_m, dtype=np.float64), np.asarray(yaw_rad, dtype=np.float64))
    return E @ _FB.T, _FB @ dE_dc, valid


def class_size_priors(classes, n: int, size_priors=None, unknown_class: str = "fallback"):
    """Per object, the size prior of its class: ``(mean_m (n, 3), sigma_m (n, 3))`` (length, width, height);
    ``size_priors``: a file, or :func:`load_size_priors`' result; unknown classes: the fallback ('other') or an
    error naming the first (``unknown_class="error"``)."""
    return _class_priors(classes, n, size_priors, unknown_class)
