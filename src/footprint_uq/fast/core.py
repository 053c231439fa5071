"""The scalar core: per-point lens math written once, inlined into every compiled path.

Every function here works on one point (scalars in, a tuple of scalars out) and is compiled
with ``inline="always"``, so that the kernels that call it in their loops keep vectorising.
The numpy reference (:func:`footprint_uq.cameras.distortion.undistort`,
:mod:`footprint_uq.cameras.lens_domain`) calls the same functions through the small
array wrappers at the end of this module: undistortion and the lens's valid domain exist
once, and every path -- reference, maps, scattered points, per-frame footprints, batch --
gives the same validity and the same numbers.

Distortion coefficients travel as a float64 array ``k`` of 8 in OpenCV order
(k1, k2, p1, p2, k3, k4, k5, k6); normalised coordinates are those of the OpenCV camera
frame (``x = X/Z``, ``y = Y/Z``).  See ``docs/uncertainty-model.md`` ("The lens's valid
domain") for the definitions.

The packed lens domain ``dom`` (built by :func:`footprint_uq.cameras.lens_domain.lens_domain`)
is a float64 vector: ``dom[DOM_M]`` the number M of angular bins, squared inner/outer radii of
the distorted and undistorted boundaries, then the two boundary tables (M + 1 radii each, at
uniform angles from -pi to pi) -- see the ``DOM_*`` offsets.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = [
    "UNDISTORT_TOL", "UNDISTORT_MAX_ITER", "R_CAP", "STRETCH_MAX", "DOM_M", "DOM_RD_IN2", "DOM_RD_OUT2",
    "DOM_RU_IN2", "DOM_RU_OUT2", "DOM_TAB", "distort_point", "distort_jac", "in_domain_distorted",
    "in_domain_undistorted", "undistort_point", "undistort_vec", "undistort_row", "fold_radius", "undistort_many",
    "contains_many", "major_axis", "nonlinearity_forms", "nonlinearity_forms_idn", "nonlinearity_point",
    "nonlinearity_point_idn", "ground_of_ray",
]

_INL = dict(inline="always", cache=True, error_model="numpy", fastmath={"contract"})
_JIT = dict(cache=True, error_model="numpy", fastmath={"contract"})

#: residual tolerance of the undistortion, relative to max(1, |x_d|) in normalised units
#: (about 1e-11 px for a 1000 px focal length)
UNDISTORT_TOL = 1e-14
#: Newton iterations from the start point (each damped by step halving)
UNDISTORT_MAX_ITER = 50
#: continuation steps from the optical axis when Newton from the start point fails
_N_CONTINUATION = 16
_N_HALVINGS = 12
#: a move along the principal region's boundary (:func:`_newton`, a step blocked by it) must lower the squared
#: residual to this fraction: a smaller gain means the iterate rests in a corner, and sliding on spends iterations
_SLIDE_GAIN = 0.99

#: largest normalised radius, undistorted and distorted, of the valid domain (tan 87 deg): beyond it the
#: distortion polynomial is evaluated where no calibration constrains it (and near a rational lens's
#: pole the root cannot be resolved to the tolerance in floating point)
R_CAP = math.tan(math.radians(87.0))

#: largest local stretch of the lens model inside the valid domain (Frobenius norm of d(x_d)/d(x)): near
#: a rational lens's pole the model magnifies without bound, a root can no longer be resolved in double
#: precision, and no calibration constrains the model there
STRETCH_MAX = 20.0

# packed lens domain layout
DOM_M, DOM_RD_IN2, DOM_RD_OUT2, DOM_RU_IN2, DOM_RU_OUT2 = 0, 1, 2, 3, 4  # RD_IN2: kept for layout
DOM_TAB = 5


@nb.njit(**_INL)
def distort_point(x, y, k):
    """Distorted normalised point ``(x_d, y_d)`` of the undistorted ``(x, y)`` (OpenCV's model)."""
    r2 = x * x + y * y
    num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
    den = 1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
    rad = num / den
    xd = x * rad + 2.0 * k[2] * x * y + k[3] * (r2 + 2.0 * x * x)
    yd = y * rad + k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * x * y
    return xd, yd


@nb.njit(**_INL)
def distort_jac(x, y, k):
    """Distorted point and its Jacobian ``d(x_d, y_d)/d(x, y)`` at the undistorted ``(x, y)``.

    Returns ``(xd, yd, j00, j01, j10, j11, rad, den)``; ``rad`` is the radial factor and
    ``den`` its denominator ``1 + k4 r^2 + k5 r^4 + k6 r^6``.
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7]
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    iden = 1.0 / den
    rad = num * iden
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad2 = 2.0 * (dnum - rad * dden) * iden  # 2 d rad / d r2
    j00 = rad + x * x * drad2 + 2.0 * p1 * y + 6.0 * p2 * x
    j01 = x * y * drad2 + 2.0 * p1 * x + 2.0 * p2 * y
    j10 = x * y * drad2 + 2.0 * p1 * x + 2.0 * p2 * y
    j11 = rad + y * y * drad2 + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, j00, j01, j10, j11, rad, den


@nb.njit(**_INL)
def _in_table(dom, off, in2, out2, x, y):
    """``(x, y)`` strictly inside the star-shaped boundary tabulated at ``dom[off:]``."""
    r2 = x * x + y * y
    if r2 < in2:
        return True
    if not r2 < out2:  # also False for NaN
        return False
    m = int(dom[DOM_M])
    t = (math.atan2(y, x) + math.pi) * (m / (2.0 * math.pi))
    j = min(max(int(t), 0), m - 1)
    rb = min(dom[off + j], dom[off + j + 1])
    return r2 < rb * rb


@nb.njit(**_INL)
def in_domain_distorted(dom, xd, yd):
    """Quick filter: False where the distorted point is certainly outside the valid domain.

    Beyond the largest distorted radius of the principal region's boundary (with a 1 %
    margin) no pixel has a ray.  Inside that radius the answer is the solver's: a pixel is
    valid when :func:`undistort_point` finds its root in the principal region.
    """
    return xd * xd + yd * yd < dom[DOM_RD_OUT2]


@nb.njit(**_INL)
def in_domain_undistorted(dom, x, y):
    """True where the undistorted normalised point lies inside the principal region."""
    m = int(dom[DOM_M])
    return _in_table(dom, DOM_TAB + m + 1, dom[DOM_RU_IN2], dom[DOM_RU_OUT2], x, y)


@nb.njit(**_INL)
def _damped_move(dom, xd, yd, k, x, y, dx, dy, rot, r0, gain):
    """Try the move ``(dx, dy)`` from ``(x, y)`` -- with ``rot`` (a literal): the rotation by ``dx`` radians about
    the axis -- halving it (up to 12 times) until it lands in the principal region with a squared residual below
    ``gain * r0``.  Returns ``(moved, x', y')``."""
    lam = 1.0
    for _h in range(_N_HALVINGS):
        if rot:
            ca, sa = math.cos(lam * dx), math.sin(lam * dx)
            xn, yn = ca * x - sa * y, sa * x + ca * y
        else:
            xn, yn = x + lam * dx, y + lam * dy
        gx, gy = distort_point(xn, yn, k)
        if (gx - xd) ** 2 + (gy - yd) ** 2 < gain * r0 and in_domain_undistorted(dom, xn, yn):
            return True, xn, yn
        lam *= 0.5
    return False, x, y


@nb.njit(**_INL)
def _newton(dom, xd, yd, k, x, y, max_iter, tol, slide):
    """Damped Newton for ``distort(x, y) = (xd, yd)`` from ``(x, y)`` in the principal region.

    A step is halved (up to 12 times) until it lowers the residual AND stays in the principal
    region: the iteration never leaves the region where the lens model is one-to-one, so it
    cannot jump over the fold onto another branch.  Returns the last iterate (convergence is
    judged by the caller).

    A step can be blocked by the region's boundary although the root lies inside: the boundary
    table is a staircase -- an arc per angular bin, and a radial wall where the fold radius
    jumps between two bins (a tangential term turns the Jacobian's determinant negative over a
    range of angles only; near such a fold the Jacobian is nearly singular and Newton's steps
    are long and cross the wall).  With ``slide`` (a literal) a blocked iterate moves along the
    boundary instead: by a Gauss-Newton step along its ray (clipped to its bin's radius: along a
    wall), else by a Gauss-Newton rotation about the axis (along an arc), each only if it lowers
    the squared residual by 1 % at least (:data:`_SLIDE_GAIN`); else, in a corner of the
    staircase (the bin the Newton step turns to reaches farther than the iterate's radius), it
    hops across the bin's edge at the same radius, if the residual has dropped since the last
    hop.  Every iterate stays in the principal region.
    """
    r_hop = np.inf
    for _ in range(max_iter):
        fx, fy, j00, j01, j10, j11, _r, _d = distort_jac(x, y, k)
        ex = fx - xd
        ey = fy - yd
        if max(abs(ex), abs(ey)) <= tol or not (math.isfinite(ex) and math.isfinite(ey)):
            break
        idet = 1.0 / (j00 * j11 - j01 * j10)
        sx = (j11 * ex - j01 * ey) * idet
        sy = (j00 * ey - j10 * ex) * idet
        r0 = ex * ex + ey * ey
        moved, x, y = _damped_move(dom, xd, yd, k, x, y, -sx, -sy, False, r0, 1.0)
        if moved:
            continue
        if not slide:
            break
        rr = math.sqrt(x * x + y * y)
        if not rr > 0.0:
            break
        m = int(dom[DOM_M])
        off = DOM_TAB + m + 1
        w = 2.0 * math.pi / m
        j = min(max(int((math.atan2(y, x) + math.pi) / w), 0), m - 1)
        rb = min(dom[off + j], dom[off + j + 1])  # the bin's radius, as in_domain_undistorted reads it
        # along the ray
        ux, uy = x / rr, y / rr
        gx, gy = j00 * ux + j01 * uy, j10 * ux + j11 * uy
        t = min(max(-(gx * ex + gy * ey) / (gx * gx + gy * gy), -rr), rb - rr)
        moved, x, y = _damped_move(dom, xd, yd, k, x, y, t * ux, t * uy, False, r0, _SLIDE_GAIN)
        if moved:
            continue
        # about the axis
        tx, ty = j01 * x - j00 * y, j11 * x - j10 * y
        al = min(max(-(tx * ex + ty * ey) / (tx * tx + ty * ty), -math.pi), math.pi)
        moved, x, y = _damped_move(dom, xd, yd, k, x, y, al, 0.0, True, r0, _SLIDE_GAIN)
        if moved:
            continue
        # across the bin's edge the Newton step turns to
        side = 1 if x * sy - y * sx < 0.0 else -1
        jn = (j + side) % m
        rn = min(dom[off + jn], dom[off + jn + 1])
        if not (r0 < r_hop and rr < rn and rn > rb):
            break
        an = (-math.pi + (j + 1) * w if side > 0 else -math.pi + j * w) + side * 1e-6 * w
        x, y = rr * math.cos(an), rr * math.sin(an)
        r_hop = r0
    return x, y


@nb.njit(**_INL)
def _accept(dom, xd, yd, k, x, y, tol):
    """Converged on the principal branch: residual within ``tol``, det > 0, inside the domain."""
    fx, fy, j00, j01, j10, j11, _r, _d = distort_jac(x, y, k)
    ok = max(abs(fx - xd), abs(fy - yd)) <= tol and j00 * j11 - j01 * j10 > 0.0
    return ok and in_domain_undistorted(dom, x, y)


@nb.njit(**_INL)
def _radial_start(dom, k, xd, yd):
    """Start point on the principal branch from the radial part alone.

    Bisection (60 halvings) of ``r rad(r^2) = |x_d|`` on ``[0, r_fold]`` (the smallest fold
    radius, where the radial map is monotone), along the direction of ``x_d``.  Far from the
    axis (a pincushion lens near its 87 deg cap, a rational lens near its pole) Newton from
    ``x_d`` needs more iterations than it has; from here it needs a few.
    """
    rd = math.sqrt(xd * xd + yd * yd)
    if not rd > 0.0:
        return 0.0, 0.0
    lo, hi = 0.0, min(math.sqrt(dom[DOM_RU_IN2]), 1e3)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        m2 = mid * mid
        g = mid * (1.0 + m2 * (k[0] + m2 * (k[1] + m2 * k[4]))) / (1.0 + m2 * (k[5] + m2 * (k[6] + m2 * k[7])))
        if g < rd:
            lo = mid
        else:
            hi = mid
    return xd * (lo / rd), yd * (lo / rd)


@nb.njit(**_INL)
def undistort_point(dom, k, xd, yd, x0, y0):
    """Undistorted normalised point of ``(xd, yd)``, or ``ok = False``.

    The single definition of undistortion, and of the lens's valid domain in pixels: a pixel
    has an answer when its root lies in the principal region (:func:`in_domain_undistorted`).
    Far pixels are rejected at once (:func:`in_domain_distorted`).  Otherwise damped Newton,
    held inside the principal region (:func:`_newton`), starts from ``(x0, y0)`` (callers pass
    ``(xd, yd)``, or a neighbour's solution continued to first order) if that lies in the
    region, and from the radial part's own inverse (:func:`_radial_start`) if not or if it
    does not converge -- from there sliding along the region's boundary where a step is blocked
    by it (:func:`_newton`); last, by continuation from the optical axis (``distort(x) = t x_d``
    for t = 1/16 .. 1).
    The accepted root is polished by one more Newton step, so that every start gives
    the same answer to rounding.

    Returns ``(ok, x, y, m00, m01, m10, m11)`` with ``m = d(x, y)/d(xd, yd)`` (NaN if not ok).
    """
    nan = np.nan
    if not (math.isfinite(xd) and math.isfinite(yd)) or not in_domain_distorted(dom, xd, yd):
        return False, nan, nan, nan, nan, nan, nan
    tol = UNDISTORT_TOL * max(1.0, max(abs(xd), abs(yd)))
    ok = False
    if in_domain_undistorted(dom, x0, y0):
        x, y = _newton(dom, xd, yd, k, x0, y0, UNDISTORT_MAX_ITER, tol, False)
        ok = _accept(dom, xd, yd, k, x, y, tol)
    if not ok:  # the radial start only when needed: its bisection costs more than the Newton steps
        rx, ry = _radial_start(dom, k, xd, yd)
        x, y = _newton(dom, xd, yd, k, rx, ry, UNDISTORT_MAX_ITER, tol, True)
        ok = _accept(dom, xd, yd, k, x, y, tol)
    if not ok:
        x, y = 0.0, 0.0
        for i in range(1, _N_CONTINUATION + 1):
            t = i / _N_CONTINUATION
            x, y = _newton(dom, t * xd, t * yd, k, x, y, 8, tol, False)
        x, y = _newton(dom, xd, yd, k, x, y, UNDISTORT_MAX_ITER, tol, False)
        if not _accept(dom, xd, yd, k, x, y, tol):
            return False, nan, nan, nan, nan, nan, nan
    fx, fy, j00, j01, j10, j11, _r, _d = distort_jac(x, y, k)
    idet = 1.0 / (j00 * j11 - j01 * j10)
    m00, m01, m10, m11 = j11 * idet, -j01 * idet, -j10 * idet, j00 * idet
    ex, ey = fx - xd, fy - yd
    return True, x - (m00 * ex + m01 * ey), y - (m10 * ex + m11 * ey), m00, m01, m10, m11


@nb.njit(**_INL)
def _regular(x, y, k):
    """The lens model is locally invertible, not folded over, within :data:`R_CAP` and stretching by
    less than :data:`STRETCH_MAX` at ``(x, y)``."""
    return _regularity(x, y, k)[0]


@nb.njit(**_INL)
def _regularity(x, y, k):
    """``(regular, positivity)`` at ``(x, y)``: :func:`_regular`, and the smallest of the quantities it needs
    positive -- the Jacobian determinant, the radial factor and its denominator -- from one evaluation."""
    xd, yd, j00, j01, j10, j11, rad, den = distort_jac(x, y, k)
    det = j00 * j11 - j01 * j10
    ok = ((det > 0.0) and (rad > 0.0) and (den > 0.0) and (xd * xd + yd * yd < R_CAP * R_CAP)
          and (j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11 < STRETCH_MAX * STRETCH_MAX))
    return ok, min(det, min(rad, den))


@nb.njit(**_INL)
def _positivity(r, c, s, k):
    """:func:`_regularity`'s positivity at ``r (c, s)``."""
    return _regularity(r * c, r * s, k)[1]


@nb.njit(**_INL)
def _dip_minimum(k, c, s, lo, hi):
    """The radius in ``[lo, hi]`` where :func:`_positivity` is smallest, by golden-section search (60 steps:
    the bracket shrinks to 1e-12 of its width); the sampled values bracket one dip."""
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    a, b = lo, hi
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = _positivity(x1, c, s, k), _positivity(x2, c, s, k)
    for _ in range(60):
        if f1 <= f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = _positivity(x1, c, s, k)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = _positivity(x2, c, s, k)
    return x1 if f1 <= f2 else x2


@nb.njit(**_JIT)
def fold_radius(k, c, s, r_max, n_grid):
    """Largest ``r <= r_max`` such that the lens is regular on the segment from 0 to ``r (c, s)``.

    Scans ``n_grid`` radii spaced quadratically (dense near the axis) for the first point
    where the Jacobian determinant, the radial factor or its denominator stops being
    positive (or the distorted radius reaches :data:`R_CAP`, or the local stretch
    :data:`STRETCH_MAX`), then bisects to the last regular radius (60 halvings).  A fold
    thinner than the grid (the determinant dipping below 0 between two samples, e.g. where
    ``d(r rad)/dr`` touches 0 and a tangential term pushes it under) is found at every sampled
    local minimum of those three quantities: a golden-section search for the dip's minimum
    (:func:`_dip_minimum`), and, where that is not regular, bisection from the sample before.
    """
    prev2, prev = 0.0, 0.0
    g2, g1 = 1.0, 1.0  # _positivity at prev2, prev (1 on the axis)
    for i in range(1, n_grid + 1):
        r = r_max * (i / n_grid) ** 2
        hi = -1.0
        ok, g0 = _regularity(r * c, r * s, k)
        if not ok:
            lo, hi = prev, r
        else:
            if g1 < g2 and g1 <= g0:  # a sampled local minimum at prev: does the dip cross 0 between samples?
                m = _dip_minimum(k, c, s, prev2, r)
                if not _regular(m * c, m * s, k):
                    lo, hi = prev2, m
            prev2, g2, g1 = prev, g1, g0
        if hi >= 0.0:
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if _regular(mid * c, mid * s, k):
                    lo = mid
                else:
                    hi = mid
            return lo
        prev = r
    return r_max


@nb.njit(**_JIT)
def _undistort_fallback(dom, k, xd, yd, xn, yn, m00, m01, m10, m11, iden, ok):
    """The points :func:`undistort_vec`'s Newton pass left without an accepted root, solved by
    :func:`undistort_point` from ``x_d`` (same answer, or "no answer", as every other path)."""
    for i in range(ok.shape[0]):
        if ok[i] or not in_domain_distorted(dom, xd[i], yd[i]):
            continue
        r = undistort_point(dom, k, xd[i], yd[i], xd[i], yd[i])
        ok[i] = r[0]
        xn[i], yn[i] = r[1], r[2]
        m00[i], m01[i], m10[i], m11[i] = r[3], r[4], r[5], r[6]
        iden[i] = 1.0 / distort_jac(r[1], r[2], k)[7]


@nb.njit(**_INL)
def _newton_vec_point(x, y, xdi, ydi, kt, rd_out2, ru_in2):
    """One undamped Newton step of :func:`undistort_vec` at one point (shared by its two loops).

    Returns ``(x', y', m00, m01, m10, m11, iden, ok, step, near_fold)``: the next iterate (the same
    point where it converged or lies outside the distorted domain), ``m = d(x, y)/d(xd, yd)`` and
    ``1 / den`` at ``(x, y)``, whether ``(x, y)`` is accepted (converged, ``det > 0``, ``x_d`` in the
    domain), whether it stepped, and whether an accepted point lies beyond the domain's inner
    undistorted radius (its principal-region test needs the table: :func:`in_domain_undistorted`).
    """
    fx, fy, j00, j01, j10, j11, _r, den = distort_jac(x, y, kt)
    ex, ey = fx - xdi, fy - ydi
    conv = max(abs(ex), abs(ey)) <= UNDISTORT_TOL * max(1.0, max(abs(xdi), abs(ydi)))
    inside = xdi * xdi + ydi * ydi < rd_out2  # in_domain_distorted; False for NaN
    det = j00 * j11 - j01 * j10
    idet = 1.0 / det
    a, b, c, d = j11 * idet, -j01 * idet, -j10 * idet, j00 * idet
    step = inside & (not conv)  # (bitwise, not short-circuit: the loop stays branch-free and vectorises)
    ok = inside & conv & (det > 0.0)
    near_fold = ok & (not (x * x + y * y < ru_in2))
    xs = x - (a * ex + b * ey) if step else x
    ys = y - (c * ex + d * ey) if step else y
    return xs, ys, a, b, c, d, 1.0 / den, ok, step, near_fold


@nb.njit(**_INL)
def _newton_pass(dom, k, xd, yd_row, yd, xn, yn, m00, m01, m10, m11, iden, ok, one_yd):
    """The Newton pass of :func:`undistort_vec` (``one_yd`` False: ``yd_row[i]``) and :func:`undistort_row`
    (True: the scalar ``yd``); ``one_yd`` is a literal at both call sites, so each compiles a loop of its
    own without the other's load.  Returns the last pass's ``(nfail, nnear)``."""
    n = ok.shape[0]
    kt = (k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7])  # scalars: stores to the rows cannot alias them
    rd_out2, ru_in2 = dom[DOM_RD_OUT2], dom[DOM_RU_IN2]
    nfail = nnear = 0
    for _ in range(UNDISTORT_MAX_ITER):
        nbad = nfail = nnear = 0  # (the counts of the last pass are the final ones)
        for i in range(n):
            ydi = yd if one_yd else yd_row[i]
            xn[i], yn[i], m00[i], m01[i], m10[i], m11[i], iden[i], oki, step, near = _newton_vec_point(
                xn[i], yn[i], xd[i], ydi, kt, rd_out2, ru_in2)
            ok[i] = oki
            nbad += 1 if step else 0
            nfail += 0 if oki else 1
            nnear += 1 if near else 0
        if nbad == 0:
            break
    return nfail, nnear


@nb.njit(**_INL)
def _undistort_accept(dom, k, xd, yd, xn, yn, m00, m01, m10, m11, iden, ok, nfail, nnear):
    """After the Newton pass: accepted points beyond the inner radius (``nnear`` of them) that are past the
    fold are refused, then every refused point goes to :func:`_undistort_fallback` (``yd`` an array)."""
    if nnear:
        nfail = 0
        for i in range(ok.shape[0]):
            if ok[i] and not in_domain_undistorted(dom, xn[i], yn[i]):  # a root, but past the fold
                ok[i] = False
            nfail += 0 if ok[i] else 1
    if nfail:
        _undistort_fallback(dom, k, xd, yd, xn, yn, m00, m01, m10, m11, iden, ok)


@nb.njit(**_JIT)
def undistort_vec(dom, k, xd, yd, xn, yn, m00, m01, m10, m11, iden, ok):
    """:func:`undistort_point` over 1-D arrays, vectorised (the kernels' form).

    On entry ``xn``, ``yn`` hold start points (``xd``, ``yd`` or a neighbour's solution
    continued to first order).  All points take undamped Newton steps together -- a loop
    LLVM vectorises; a converged point is frozen and a point outside the valid domain is not
    iterated.  A point is accepted where it converged with a positive Jacobian determinant in
    the principal region; any other point is solved again by :func:`undistort_point` from
    ``x_d`` (:func:`_undistort_fallback`).  On exit ``ok`` (bool), the solution,
    ``m = d(x, y)/d(xd, yd)`` and ``iden = 1 / den`` at the solution (``den`` as in
    :func:`distort_jac`).  Solutions agree with :func:`undistort_point`'s to the Newton
    tolerance (that one is polished by one more step).  :func:`undistort_row` is the same for
    points that share one ``y_d`` (an image row).
    """
    nfail, nnear = _newton_pass(dom, k, xd, yd, 0.0, xn, yn, m00, m01, m10, m11, iden, ok, False)
    _undistort_accept(dom, k, xd, yd, xn, yn, m00, m01, m10, m11, iden, ok, nfail, nnear)


@nb.njit(**_JIT)
def undistort_row(dom, k, xd, yd, ydb, xn, yn, m00, m01, m10, m11, iden, ok):
    """:func:`undistort_vec` for points that share one distorted ``yd`` (a scalar: an image row of the
    maps; the loop then reads one array less).  ``ydb`` is a scratch row, filled with ``yd`` only when
    some point needs :func:`_undistort_fallback`."""
    nfail, nnear = _newton_pass(dom, k, xd, ydb, yd, xn, yn, m00, m01, m10, m11, iden, ok, True)
    if nfail or nnear:
        ydb[:ok.shape[0]] = yd
    _undistort_accept(dom, k, xd, ydb, xn, yn, m00, m01, m10, m11, iden, ok, nfail, nnear)


# --------------------------------------------------------------------------------------
# ray / ground intersection (docs/uncertainty-model.md, "Back-projection")
# --------------------------------------------------------------------------------------
@nb.njit(**_INL)
def ground_of_ray(h_m, hR00, hR01, hR10, hR11, g0, g1, dxr, dyr, dn):
    """Where the ray of one pixel meets the ground plane, and how that point moves with the ray.

    The ray is ``d = R_world_cam (x, y, 1)`` for undistorted normalised coordinates ``(x, y)``;
    the ground is the plane ``z = s_x x + s_y y + dz`` (normal ``n = (-s_x, -s_y, 1)``).

    Parameters
    ----------
    h_m : float
        Camera height above the ground plane at its foot (m, > 0).
    hR00, hR01, hR10, hR11 : float
        ``h_m`` times ``R_world_cam[0:2, 0:2]`` (m; per camera, precomputed by the callers).
    g0, g1 : float
        ``n . R_world_cam[:, 0]`` and ``n . R_world_cam[:, 1]``: how the ray's normal component
        ``dn`` changes with ``x`` and ``y``.
    dxr, dyr, dn : float
        The ray's world x and y components and its component along ``n`` (< 0 where the ray
        meets the ground in front of the camera; the caller decides validity).

    Returns
    -------
    tuple
        ``(lam, ox, oy, Q00, Q01, Q10, Q11)``: the depth ``lam = h_m / -dn`` along the ray (m),
        the ground point's offset from the camera's foot ``(ox, oy) = lam (dxr, dyr)`` (m) and
        ``Q = d(ox, oy) / d(x, y)`` (m per normalised unit).
    """
    w = -1.0 / dn
    lam = h_m * w
    ox = lam * dxr
    oy = lam * dyr
    return (lam, ox, oy, w * (hR00 + ox * g0), w * (hR01 + ox * g1), w * (hR10 + oy * g0),
            w * (hR11 + oy * g1))


# --------------------------------------------------------------------------------------
# the linearity flag (docs/uncertainty-model.md, "The linearity flag")
# --------------------------------------------------------------------------------------
@nb.njit(**_INL)
def major_axis(c00, c01, c11):
    """Largest eigenvalue and its unit eigenvector of the symmetric 2x2 ``[[c00, c01], [c01, c11]]``.

    Returns ``(lam_max, e0, e1)`` (units of ``c``; ``e`` dimensionless).  The eigenvector is formed
    from the better-conditioned column of ``C - lam_min I`` (no cancellation); a circular ``C``
    gives ``e = (1, 0)``.  NaN in: ``lam_max`` NaN.
    """
    d = 0.5 * (c00 - c11)
    rad = math.sqrt(d * d + c01 * c01)
    lam_max = 0.5 * (c00 + c11) + rad
    pos = d >= 0.0  # selects, no branches: the kernels' pixel loops stay vectorised
    a0 = d + rad if pos else c01
    a1 = c01 if pos else rad - d
    nrm = math.sqrt(a0 * a0 + a1 * a1)
    inv = 1.0 / nrm
    good = nrm > 0.0
    return lam_max, a0 * inv if good else 1.0, a1 * inv if good else 0.0


@nb.njit(**_INL)
def nonlinearity_forms(lam_max_m2, e0, e1, dn, lam_m, dx, dy, mu, gamma, s_num_m2, s_cross_m2, mu_num):
    """Predicted relative error of the linear 1-sigma semi-major axis, one point (scalar port).

    The formula of :func:`footprint_uq.propagation.nonlinearity_from_forms` (same argument
    meanings: ``e = (e0, e1)`` the unit major axis, ``(dx, dy)`` the horizontal part of the world
    ray, ``dn`` the ray denominator ``Dn``, ``lam_m = N / Dn``; ``mu = r^T Sigma g``,
    ``gamma = g^T Sigma g``, ``s_num = r'^T Sigma r'``, ``s_cross = r^T Sigma r'``,
    ``mu_num = r'^T Sigma g``).  Returns a float >= 0; 1.0 where the expansion has broken
    down (``1 + delta / lam_max < 0``), 0 where ``delta`` is 0 (also with ``lam_max`` 0: no uncertainty),
    NaN where an input is not finite.
    """
    return nonlinearity_forms_idn(lam_max_m2, e0, e1, 1.0 / dn, lam_m, dx, dy, mu, gamma, s_num_m2, s_cross_m2,
                                  mu_num)


@nb.njit(**_INL)
def nonlinearity_forms_idn(lam_max_m2, e0, e1, idn, lam_m, dx, dy, mu, gamma, s_num_m2, s_cross_m2, mu_num):
    """:func:`nonlinearity_forms` given ``idn = 1 / Dn`` instead of ``Dn``: a kernel that already holds the
    reciprocal (every ray/ground intersection computes it) saves four divisions per point, which are most of
    the flag's cost in a map's vectorised pixel loop."""
    b = lam_m * (dx * e0 + dy * e1)
    q2 = gamma * (idn * idn)
    w = -b * idn
    c_L = mu * idn
    c_A = (mu_num - w * gamma) * idn
    s_A = s_num_m2 - 2.0 * w * mu_num + w * w * gamma
    s_LA = s_cross_m2 - w * mu
    delta = (2.0 * q2 * q2 * b * b - 4.0 * q2 * b * c_A + q2 * s_A + c_A * c_A - 6.0 * q2 * c_L * b
             + 2.0 * q2 * s_LA + 4.0 * c_L * c_A + (69.0 + 696.0 * q2) * q2 * q2 * q2 * b * b)
    t = 0.0 if delta == 0.0 else delta / lam_max_m2  # no uncertainty at all (a zero budget): exact, 0
    x = 1.0 + t
    nl = abs(t) / (math.sqrt(abs(x)) + 1.0)  # = |sqrt(1 + t) - 1| without cancellation
    nl = nl if x >= 0.0 else 1.0
    return nl if (x - x) == 0.0 else math.nan  # not finite -> NaN (selects: the loops stay vectorised)


@nb.njit(**_INL)
def nonlinearity_point(c00, c01, c11, dn, lam_m, dx, dy, jg0, jg1, gamma, gp0, gp1, x00, x01, x10, x11,
                       sp00, sp01, sp11):
    """The linearity flag of one point from what a kernel has at hand (all sources: parameters and pixel).

    Parameters (``J`` the 2 x n Jacobian of the ground point over every error source, ``g`` the
    gradient of ``Dn`` over the same sources, ``Sigma`` their covariance, ``E`` the selector of
    the camera position x_m, y_m):

    c00, c01, c11 : the linear covariance ``J Sigma J^T``, m^2
    dn, lam_m, dx, dy : ``Dn``, ``lam = N / Dn`` (m) and the ray's horizontal part ``d_xy``
    jg0, jg1 : ``J Sigma g`` (2,), m
    gamma : ``g^T Sigma g``
    gp0, gp1 : ``E^T Sigma g`` (2,), m -- zero when the position is uncorrelated with the rest
    x00, x01, x10, x11 : ``X = J Sigma E`` (2, 2), m^2 -- ``Sigma_pos`` when uncorrelated
    sp00, sp01, sp11 : ``Sigma_pos = E^T Sigma E``, m^2

    With ``e`` the unit major axis (eigenvalue ``lam_max``): ``mu = e . J Sigma g``,
    ``mu_num = mu - e . E^T Sigma g``, ``s_cross = lam_max - e^T X e`` and ``s_num = lam_max -
    2 e^T X e + e^T Sigma_pos e`` (``r' = J'^T e`` with ``J' = J - E^T``); then
    :func:`nonlinearity_forms`.
    """
    return nonlinearity_point_idn(c00, c01, c11, 1.0 / dn, lam_m, dx, dy, jg0, jg1, gamma, gp0, gp1, x00, x01, x10,
                                  x11, sp00, sp01, sp11)


@nb.njit(**_INL)
def nonlinearity_point_idn(c00, c01, c11, idn, lam_m, dx, dy, jg0, jg1, gamma, gp0, gp1, x00, x01, x10, x11,
                           sp00, sp01, sp11):
    """:func:`nonlinearity_point` given ``idn = 1 / Dn`` instead of ``Dn`` (:func:`nonlinearity_forms_idn`)."""
    lam_max, e0, e1 = major_axis(c00, c01, c11)
    mu = e0 * jg0 + e1 * jg1
    mu_num = mu - (e0 * gp0 + e1 * gp1)
    exe = e0 * (x00 * e0 + x01 * e1) + e1 * (x10 * e0 + x11 * e1)
    epe = e0 * (sp00 * e0 + sp01 * e1) + e1 * (sp01 * e0 + sp11 * e1)
    s_crs = lam_max - exe
    s_num = lam_max - 2.0 * exe + epe
    return nonlinearity_forms_idn(lam_max, e0, e1, idn, lam_m, dx, dy, mu, gamma, s_num, s_crs, mu_num)


# --------------------------------------------------------------------------------------
# array wrappers: how the numpy reference calls the core
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT)
def undistort_many(dom, k, xyd, out, ok, minv):
    """Undistort ``xyd`` (n, 2) with coefficients ``k`` (n, 8) (rows may repeat by stride 0).

    Fills ``out`` (n, 2), ``ok`` (n,) and ``minv`` (n, 4): d(undistorted)/d(distorted).
    """
    for i in range(xyd.shape[0]):
        xd, yd = xyd[i, 0], xyd[i, 1]
        r = undistort_point(dom, k[i], xd, yd, xd, yd)
        ok[i] = r[0]
        out[i, 0], out[i, 1] = r[1], r[2]
        minv[i, 0], minv[i, 1], minv[i, 2], minv[i, 3] = r[3], r[4], r[5], r[6]


@nb.njit(**_JIT)
def contains_many(dom, xy, out):
    """Principal-region membership of undistorted normalised points ``xy`` (n, 2)."""
    for i in range(xy.shape[0]):
        out[i] = in_domain_undistorted(dom, xy[i, 0], xy[i, 1])
