"""Compiled per-frame steps of the tracker: the filter of :mod:`footprint_uq.tracking.filter` in one pass over the
frame's tracks, and ground points into the image (for ``B`` at predicted positions).

The numpy classes (:class:`~footprint_uq.tracking.filter.SchmidtPredictor`, :class:`~footprint_uq.tracking.filter.
SchmidtUpdater`, :class:`~footprint_uq.tracking.filter.InteractingModels`) are the readable reference;
``tests/test_tracking.py`` holds these kernels to them (1e-9).  A frame of 100 tracks as ~40 small numpy operations
on (100, 4, 4) / (100, 4, r) stacks costs ~400 us of call overhead (several times that for two modes); compiled,
~10-50 us.

:func:`frame_update` is the compiled reference of a frame's update, written as the numpy classes read;
:class:`~footprint_uq.tracking.table.TrackTable` runs :func:`~footprint_uq.tracking.imm_kernels.frame_pass`, the
same filter arranged for speed, held to it in ``tests/test_tracking_fast.py``.  :func:`frame_rows_shared` is
:func:`frame_rows` with ``B`` at the predicted positions formed in the same call (the table's path when its
``shared_at`` is a :class:`~footprint_uq.tracking.table.SharedJacobianAt`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..fast import core
from ..fast.footprint_kernels import KernelCamera, point_jacobian_into
from .kalman_kernels import pick_shared, schmidt_step, start_cov2

__all__ = ["predict_update", "update_slots", "frame_rows", "frame_rows_shared", "frame_update", "initiate_row",
           "project_ground", "motion_fields", "ROW_SKIP", "ROW_UPDATE", "ROW_START", "id_lookup", "id_insert",
           "id_delete", "ID_EMPTY", "claim_rows", "starts_and_outputs"]


@njit(cache=True, nogil=True, error_model="numpy")
def predict_update(x, P, C, dt, q, z, R, B, gate, d2):  # pragma: no cover - compiled
    """Predict n tracks by ``dt (n,)`` (constant velocity, acceleration density ``q``) and update them with ``z (n,
    2)``, ``R (n, 2, 2)``, ``B (n, 2, r)``, in place where the innovation's ``d2 <= gate``; ``d2 (n,)`` receives the
    squared Mahalanobis distances (NaN if not finite).  Rejected tracks are left as they were (not predicted)."""
    r = C.shape[2]
    Pp, Cp, K, cross = np.empty((4, 4)), np.empty((4, r)), np.empty((4, 2)), np.empty((4, 2))
    for i in range(x.shape[0]):
        d2[i] = schmidt_step(x[i], P[i], C[i], dt[i], q, z[i], R[i], B[i], gate, Pp, Cp, K, cross)[0]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _switch_probs(h, rates, pij):  # pragma: no cover - compiled
    """``pij[a, b]`` = P(mode b at the end of a step ``h`` | mode a at its start) of the continuous-time Markov chain
    leaving mode ``a`` at ``rates[a]`` (1/s); one or two modes (closed form of ``expm``)."""
    if rates.shape[0] == 1:
        pij[0, 0] = 1.0
        return
    a, b = rates[0], rates[1]
    tot = a + b
    e = -math.expm1(-tot * h) / tot if tot > 0.0 else 0.0
    pij[0, 1], pij[1, 0] = a * e, b * e
    pij[0, 0], pij[1, 1] = 1.0 - a * e, 1.0 - b * e


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _mix(Xm, Pm, Cm, mu, pij, cbar, xs, Ps, Cs):  # pragma: no cover - compiled
    """IMM mixing of one track's mode-conditioned states ``Xm (M, 4)``, ``Pm (M, 4, 4)``, ``Cm (M, r, 4)`` (the
    table's column-by-column consider columns) with mode probabilities ``mu`` into the start states ``xs``, ``Ps``,
    ``Cs (M, 4, r)`` of each mode's step; ``cbar`` receives the predicted mode probabilities."""
    M, r = Xm.shape[0], Cm.shape[1]
    for j in range(M):
        cb = 0.0
        for i in range(M):
            cb += pij[i, j] * mu[i]
        cbar[j] = cb
        for a in range(4):
            xs[j, a] = 0.0
            for c in range(r):
                Cs[j, a, c] = 0.0
            for b in range(4):
                Ps[j, a, b] = 0.0
        for i in range(M):
            wt = pij[i, j] * mu[i] / cb
            for a in range(4):
                xs[j, a] += wt * Xm[i, a]
                for c in range(r):
                    Cs[j, a, c] += wt * Cm[i, c, a]
        for i in range(M):
            wt = pij[i, j] * mu[i] / cb
            for a in range(4):
                da = Xm[i, a] - xs[j, a]
                for b in range(4):
                    Ps[j, a, b] += wt * (Pm[i, a, b] + da * (Xm[i, b] - xs[j, b]))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _imm_one(s, X, P, Xm, Pm, Cm, mu, t_last, n_upd, t, qs, rates, z, R, B, gate, Pp, Cp, K, cross, xs, Ps, Cs, pij,
             cbar, lik):  # pragma: no cover - compiled
    """One track's IMM Schmidt step (storage row ``s``; measurement ``z (2,)``, ``R (2, 2)``, ``B (2, r)``), in
    place if it passes the gate (see :func:`update_slots`); returns the smallest of the modes' squared Mahalanobis
    distances (NaN if a mode's is not finite).  The rest are scratch."""
    M, r = Xm.shape[1], Cm.shape[2]
    h = t - t_last[s]
    _switch_probs(h, rates, pij)
    _mix(Xm[s], Pm[s], Cm[s], mu[s], pij, cbar, xs, Ps, Cs)
    best, bad = math.inf, False
    for j in range(M):
        mj, det, _, _, _, _, _ = schmidt_step(xs[j], Ps[j], Cs[j], h, qs[j], z, R, B, math.inf, Pp, Cp, K, cross)
        lik[j] = -0.5 * mj - 0.5 * math.log(det) + math.log(cbar[j]) if math.isfinite(mj) else -math.inf
        if not math.isfinite(mj):
            bad = True
        elif mj < best:
            best = mj
    best = math.nan if bad else best  # a singular mode fails the gate
    if not best <= gate:
        return best
    top = lik[0]
    for j in range(1, M):
        top = max(top, lik[j])
    tot = 0.0
    for j in range(M):
        lik[j] = max(math.exp(lik[j] - top), 1e-9)  # a mode never dies out: it must be able to come back
        tot += lik[j]
    for a in range(4):
        X[s, a] = 0.0
        for b in range(4):
            P[s, a, b] = 0.0
    for j in range(M):
        mu[s, j] = lik[j] / tot
        for a in range(4):
            Xm[s, j, a] = xs[j, a]
            X[s, a] += mu[s, j] * xs[j, a]
            for c in range(r):
                Cm[s, j, c, a] = Cs[j, a, c]
            for b in range(4):
                Pm[s, j, a, b] = Ps[j, a, b]
    for j in range(M):
        for a in range(4):
            da = xs[j, a] - X[s, a]
            for b in range(4):
                P[s, a, b] += mu[s, j] * (Ps[j, a, b] + da * (xs[j, b] - X[s, b]))
    t_last[s] = t
    n_upd[s] += 1
    return best


@njit(cache=True, nogil=True, error_model="numpy")
def update_slots(X, P, Xm, Pm, Cm, mu, t_last, n_upd, slots, t, qs, rates, z, R, B_pred, B_frame, gate,
                 d2):  # pragma: no cover - compiled
    """One frame's interacting-multiple-model (IMM) Schmidt update of a table's storage, in place.

    Track ``i`` of the frame is row ``slots[i]``: its M constant-velocity modes (acceleration densities ``qs (M,)``,
    leaving rates ``rates (M,)`` in 1/s, M <= 2) are ``Xm (cap, M, 4)``, ``Pm (cap, M, 4, 4)``, ``Cm (cap, M, r,
    4)`` (the consider columns stored column by column) with probabilities ``mu (cap, M)``; ``X (cap, 4)``,
    ``P (cap, 4, 4)`` receive their moment-matched combination.  Each mode is mixed (:func:`_mix`), predicted to
    ``t`` from ``t_last`` and updated with ``z[i]``, ``R[i]`` and ``B_pred[i]`` (``B`` at the predicted position;
    ``(0, 2, 0)``: none) where finite, else ``B_frame[i]``.  ``d2[i]`` receives the smallest of the modes'
    squared Mahalanobis distances; the track is updated only if it is ``<= gate`` (then ``t_last = t`` and one
    more update in ``n_upd``), else left as it was.
    With one mode this is :func:`predict_update`."""
    M, r = Xm.shape[1], Cm.shape[2]
    Pp, Cp, K, cross = np.empty((4, 4)), np.empty((4, r)), np.empty((4, 2)), np.empty((4, 2))
    xs, Ps, Cs = np.empty((M, 4)), np.empty((M, 4, 4)), np.empty((M, 4, r))
    pij, cbar, lik = np.empty((2, 2)), np.empty(M), np.empty(M)
    for i in range(slots.shape[0]):
        d2[i] = _imm_one(slots[i], X, P, Xm, Pm, Cm, mu, t_last, n_upd, t, qs, rates, z[i], R[i],
                         pick_shared(B_pred, i, B_frame, i), gate, Pp, Cp, K, cross, xs, Ps, Cs, pij, cbar, lik)


@njit(cache=True, nogil=True, error_model="numpy")
def project_ground(xy, cam, uv):  # pragma: no cover - compiled
    """Pixels ``uv (n, 2)`` of ground points ``xy (n, 2)`` of W (on the nominal ground ``z = ground_z_m``) in the
    camera ``cam`` (:class:`~footprint_uq.fast.footprint_kernels.KernelCamera`): the arithmetic of
    :func:`footprint_uq.cameras.general.project`; NaN behind the camera, for non-finite points and past the lens's
    fold."""
    d = cam.dist
    kt = (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7])
    R = cam.R
    for i in range(xy.shape[0]):
        rx, ry, rz = xy[i, 0] - cam.x0, xy[i, 1] - cam.y0, -cam.h
        pcx = R[0] * rx + R[3] * ry + R[6] * rz
        pcy = R[1] * rx + R[4] * ry + R[7] * rz
        pcz = R[2] * rx + R[5] * ry + R[8] * rz
        x, y = pcx / pcz, pcy / pcz
        ok = math.isfinite(x) & math.isfinite(y) & (pcz > 0.0)
        if ok and cam.has_dist:
            ok = core.in_domain_undistorted(cam.dom, x, y)
        xd, yd = core.distort_point(x, y, kt)
        uv[i, 0] = cam.fx * xd + cam.skew * yd + cam.cx if ok else math.nan
        uv[i, 1] = cam.fy * yd + cam.cy if ok else math.nan


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _norm(x, y):  # pragma: no cover - compiled
    """``hypot(x, y)``: ``sqrt(x^2 + y^2)`` where the squares' sum neither overflows nor loses digits to
    underflow (within an ulp of ``hypot``, ~3 ns less: ~0.6 us of :func:`motion_fields`' ~2.4 per 100 objects),
    else ``hypot`` itself (zero -- the squares of 1e-170 are zero too --, tiny, huge, inf and NaN entries: its
    answers)."""
    s = x * x + y * y
    return math.sqrt(s) if 1e-290 < s < 1e290 else math.hypot(x, y)


@njit(cache=True, nogil=True, error_model="numpy")
def motion_fields(v, cov, ch, sh, ratio, yaw_rad, sigma_yaw_rad, heading_offset_deg, out,
                  cov_out):  # pragma: no cover - compiled
    """:func:`footprint_uq.tracking.motion.object_motion`'s arithmetic in one pass: velocities ``v (n, 2)`` and
    covariances ``cov (n, 2, 2)`` in W, rotated to east / north by ``(ch, sh)`` = cos / sin of the heading offset,
    into ``out (8, n)`` = v_east, v_north, speed, sigma_speed, heading_deg, sigma_heading_deg (NaN below ``ratio``
    velocity sigmas of speed), yaw_deg (compass, :func:`~footprint_uq.tracking.motion.yaw_compass_deg` of
    ``yaw_rad (n,)``), sigma_yaw_deg (of ``sigma_yaw_rad (n,)``) and ``cov_out (n, 2, 2)``; a ``(0,)`` yaw or
    sigma: NaN."""
    nan = math.nan
    has_yaw, has_syaw = yaw_rad.shape[0] > 0, sigma_yaw_rad.shape[0] > 0
    for i in range(v.shape[0]):
        out[6, i] = np.mod(90.0 - np.rad2deg(yaw_rad[i]) + heading_offset_deg, 360.0) if has_yaw else nan
        out[7, i] = np.rad2deg(sigma_yaw_rad[i]) if has_syaw else nan
        ve = ch * v[i, 0] + sh * v[i, 1]
        vn = -sh * v[i, 0] + ch * v[i, 1]
        c00, c01, c11 = cov[i, 0, 0], cov[i, 0, 1], cov[i, 1, 1]
        a = ch * ch * c00 + 2.0 * ch * sh * c01 + sh * sh * c11  # R C R^T, R = [[ch, sh], [-sh, ch]]
        b = -ch * sh * c00 + (ch * ch - sh * sh) * c01 + ch * sh * c11
        d = sh * sh * c00 - 2.0 * ch * sh * c01 + ch * ch * c11
        cov_out[i, 0, 0], cov_out[i, 0, 1], cov_out[i, 1, 0], cov_out[i, 1, 1] = a, b, b, d
        sp = _norm(ve, vn)
        out[0, i], out[1, i], out[2, i] = ve, vn, sp
        if sp > 0.0:
            out[3, i] = math.sqrt(ve * ve * a + 2.0 * ve * vn * b + vn * vn * d) / sp
            hd = math.degrees(math.atan2(ve, vn))
            out[4, i] = hd + 360.0 if hd < 0.0 else hd
            smax = math.sqrt(0.5 * (a + d) + _norm(0.5 * (a - d), b))
            sh_ = math.degrees(math.sqrt(vn * vn * a - 2.0 * ve * vn * b + ve * ve * d) / (sp * sp))
            out[5, i] = sh_ if sp >= ratio * smax else nan
        else:
            out[3, i], out[4, i], out[5, i] = nan, nan, nan


#: an empty entry of an id table (:func:`id_lookup`): its value
ID_EMPTY = -1
_ID_MULT = np.uint64(0x9E3779B97F4A7C15)  # (2^64 / golden ratio, odd: Fibonacci hashing)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _id_home(key, shift):  # pragma: no cover - compiled
    """The home entry of the int64 ``key`` in an id table of ``2^(64 - shift)`` entries (its top bits after a
    multiplication by :data:`_ID_MULT`, which spreads consecutive ids over the table)."""
    return np.int64((np.uint64(key) * _ID_MULT) >> np.uint64(shift))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _id_entry(keys, vals, shift, key):  # pragma: no cover - compiled
    """The entry of ``key`` in an id table (:func:`id_lookup`): where it is, or the empty entry that ends its probe
    run (where it would go)."""
    mask = keys.shape[0] - 1
    j = _id_home(key, shift)
    while vals[j] != ID_EMPTY and keys[j] != key:
        j = (j + 1) & mask
    return j


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def id_lookup(keys, vals, shift, ids, slots):  # pragma: no cover - compiled
    """The rows of the int64 ids ``ids (n,)`` in an id table into ``slots (n,)`` (-1 for an id not in it).

    An id table is an open-addressing hash table with linear probing in two arrays of ``2^(64 - shift)`` entries,
    ``keys`` (int64) and ``vals`` (int64, :data:`ID_EMPTY` for an empty entry): the compiled form of
    :class:`~footprint_uq.tracking.table.TrackTable`'s dictionary for frames whose ids are all integers."""
    for i in range(ids.shape[0]):
        j = _id_entry(keys, vals, shift, ids[i])
        slots[i] = -1 if vals[j] == ID_EMPTY else vals[j]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def id_insert(keys, vals, shift, new_keys, new_vals):  # pragma: no cover - compiled
    """Enter ``new_keys (m,)`` with ``new_vals (m,)`` (>= 0) in an id table (:func:`id_lookup`; a key already in it
    gets the new value).  The caller keeps the table at most half full."""
    for i in range(new_keys.shape[0]):
        key = new_keys[i]
        j = _id_entry(keys, vals, shift, key)
        keys[j] = key
        vals[j] = new_vals[i]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def id_delete(keys, vals, shift, old_keys):  # pragma: no cover - compiled
    """Remove ``old_keys (m,)`` from an id table (:func:`id_lookup`; a key not in it is passed over), closing
    each gap by moving later entries of its probe run back (no tombstones: the table never degrades)."""
    mask = keys.shape[0] - 1
    for m in range(old_keys.shape[0]):
        i = _id_entry(keys, vals, shift, old_keys[m])
        if vals[i] == ID_EMPTY:
            continue
        vals[i] = ID_EMPTY
        j = i
        while True:  # entry j moves back to the gap i unless its home lies cyclically in (i, j]
            j = (j + 1) & mask
            if vals[j] == ID_EMPTY:
                break
            h = _id_home(keys[j], shift)
            if (h <= j and (h > i or i > j)) or (h > j and h > i and i > j):
                continue
            keys[i], vals[i] = keys[j], vals[j]
            vals[j] = ID_EMPTY
            i = j


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def claim_rows(ids, old, u, act, slots, free_rows, keys, vals, shift, claimed):  # pragma: no cover - compiled
    """Rows for the unknown int64 ids of a frame of n objects, in place (:meth:`~footprint_uq.tracking.table.
    TrackTable._claim`'s rule, compiled): the u objects listed at the end of ``old`` in reverse frame order (as
    :func:`frame_rows` leaves them) are taken in frame order; the first object of each id among them gets, if
    ``act`` says :data:`ROW_START`, the next row of ``free_rows`` (in its order) in ``slots`` and its id enters
    the id table ``keys, vals, shift`` (:func:`id_lookup`; the caller has made room for u more); a later object of
    an id met before among them gets :data:`ROW_SKIP`.  ``claimed`` receives the objects that got a row, in
    order; returns their count."""
    n = ids.shape[0]
    m = 0
    for q in range(u):
        i = old[n - 1 - q]
        key = ids[i]
        seen = False
        for p in range(q):  # (u is small: the frame's new ids)
            if ids[old[n - 1 - p]] == key:
                seen = True
                break
        if seen:
            act[i] = ROW_SKIP
            continue
        if act[i] == ROW_START:
            s = free_rows[m]
            slots[i] = s
            j = _id_entry(keys, vals, shift, key)
            keys[j] = key
            vals[j] = s
            claimed[m] = i
            m += 1
    return m


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def expire_rows(t, timeout_s, t_last, free, n_free, gone, gone_keys, keys, vals, shift):  # pragma: no cover
    """The deleter's sweep at time ``t`` in one pass (:meth:`~footprint_uq.tracking.table.TrackTable.
    _delete_expired`): the rows whose last update ``t_last`` is more than ``timeout_s`` before ``t`` (a free row's
    NaN never is) listed in ``gone`` in row order, their ids removed from the id table ``keys, vals, shift``
    (:func:`id_lookup`; every entry pointing at one of them, collected in ``gone_keys`` first; a ``(1,)`` table
    of one empty entry: none), ``t_last`` set to NaN and the rows pushed on the free stack ``free[n_free:]`` in
    that order.  ``gone`` and ``gone_keys`` have room for every row.  Returns ``(m, n_free, oldest)``: the rows
    gone, the free stack's new height and the earliest ``t_last`` of the rows left (finite ones; inf if none)."""
    m = 0
    oldest = math.inf
    for s in range(t_last.shape[0]):
        ts = t_last[s]
        if t - ts > timeout_s:
            gone[m] = s
            m += 1
        elif ts < oldest and math.isfinite(ts):
            oldest = ts
    if m:
        k = 0
        for j in range(vals.shape[0]):  # (before t_last changes: the entries of the expired rows)
            s = vals[j]
            if s != ID_EMPTY and t - t_last[s] > timeout_s:
                gone_keys[k] = keys[j]
                k += 1
        id_delete(keys, vals, shift, gone_keys[:k])
        for q in range(m):
            s = gone[q]
            t_last[s] = math.nan
            free[n_free] = s
            n_free += 1
    return m, n_free, oldest


#: row actions of :func:`frame_rows` / :func:`frame_update`: not tracked, update the row's track, start a track
ROW_SKIP, ROW_UPDATE, ROW_START = 0, 1, 2


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (no refcounting: it allocates nothing)
def frame_rows(slots, xy_rows, cov_rows, B, subtract, z, R, t, t_last, seen, stamp, X, act, old,
               pred):  # pragma: no cover - compiled
    """First pass of a frame of n objects over a table's storage: what to do with each object.

    The centres come as rows, ``xy_rows (2, n)`` (x, y) and ``cov_rows (2, 2, n)`` (the layout of an estimate's
    columns: ``FootprintEstimate.centre_xy_world_m.T`` and ``centre_cov_m2.transpose(1, 2, 0)`` are C-contiguous,
    no copy is needed to hand them over), and are written per object into ``z (n, 2)`` and ``R (n, 2, 2)``, what
    the update pass reads.  ``subtract``: ``cov_rows`` holds each centre's whole covariance and ``R`` receives its
    per-frame part ``cov - B B^T`` (symmetrised from its upper entry); else ``cov_rows`` is the per-frame part
    already and ``R`` receives it as given.

    ``slots (n,)`` are the objects' rows in the storage from the id lookup (-1: an unknown id, -2: an id that is
    never tracked).  ``act (n,)`` receives :data:`ROW_UPDATE` for the first object of a known id with a finite
    centre, covariance and ``B (n, 2, r)`` whose track was not updated at ``t`` already; :data:`ROW_START` for an
    unknown id with finite inputs (the caller keeps the first object of each unknown id); :data:`ROW_SKIP`
    otherwise (repeated ids: ``seen (cap,)`` is stamped with ``stamp`` per frame).  The k objects to update are
    listed in ``old[:k]`` in frame order with their tracks' positions predicted to ``t`` in ``pred[:k]`` (for
    ``B`` at the predicted position); returns k and the number u of unknown ids (``slots == -1``), whose objects
    are listed at the end of ``old`` in reverse frame order (``old[n - u:][::-1]``)."""
    k = 0
    n_unknown = 0
    r = B.shape[2]
    for i in range(slots.shape[0]):
        z[i, 0], z[i, 1] = xy_rows[0, i], xy_rows[1, i]
        fin = 0.0
        if subtract:
            a00 = a01 = a11 = 0.0  # (B B^T's three sums, each in the order of c as before: the same bits)
            for c in range(r):
                b0, b1 = B[i, 0, c], B[i, 1, c]
                fin += (b0 - b0) + (b1 - b1)  # (0 if both finite, else NaN: stays 0 only if all are)
                a00 += b0 * b0
                a01 += b0 * b1
                a11 += b1 * b1
            R[i, 0, 0] = cov_rows[0, 0, i] - a00
            R[i, 0, 1] = R[i, 1, 0] = cov_rows[0, 1, i] - a01
            R[i, 1, 1] = cov_rows[1, 1, i] - a11
        else:
            for c in range(r):
                fin += (B[i, 0, c] - B[i, 0, c]) + (B[i, 1, c] - B[i, 1, c])
            R[i, 0, 0], R[i, 0, 1] = cov_rows[0, 0, i], cov_rows[0, 1, i]
            R[i, 1, 0], R[i, 1, 1] = cov_rows[1, 0, i], cov_rows[1, 1, i]
        s = slots[i]
        # (one test of the 26 B entries' sum, not 26 short-circuit tests: ~1 us less per 100-object frame)
        ok = (math.isfinite(z[i, 0]) & math.isfinite(z[i, 1]) & math.isfinite(R[i, 0, 0]) & math.isfinite(R[i, 0, 1])
              & math.isfinite(R[i, 1, 0]) & math.isfinite(R[i, 1, 1]) & (fin == 0.0))
        if s < 0:
            act[i] = ROW_START if (s == -1 and ok) else ROW_SKIP
            if s == -1:
                n_unknown += 1
                old[slots.shape[0] - n_unknown] = i
            continue
        if seen[s] == stamp or not ok or t_last[s] == t:  # a repeated id (in this frame or at this time)
            seen[s] = stamp
            act[i] = ROW_SKIP
            continue
        seen[s] = stamp
        act[i] = ROW_UPDATE
        h = t - t_last[s]
        pred[k, 0] = X[s, 0] + h * X[s, 2]
        pred[k, 1] = X[s, 1] + h * X[s, 3]
        old[k] = i
        k += 1
    return k, n_unknown


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _camera(f, has_dist, dist, R, dom):  # pragma: no cover - compiled
    """The :class:`~footprint_uq.fast.footprint_kernels.KernelCamera` of :func:`~footprint_uq.fast.frame_columns.
    camera_parts`' pieces (the same values, the same numba type; as ``fast/frame_columns.py`` puts it together)."""
    return KernelCamera(f[0], f[1], f[2], f[3], f[4], f[5], f[6], dist, has_dist, f[7], f[8], f[9], f[10], f[11],
                        f[12], R, f[13], f[14], f[15], dom)


# (numba's reference counting set, not inherited: point_jacobian_into allocates, and a caller without it --
# imm_kernels.frame_step -- would otherwise compile it without)
@njit(cache=True, nogil=True, error_model="numpy", _nrt=True)
def frame_rows_shared(slots, xy_rows, cov_rows, B, subtract, z, R, t, t_last, seen, stamp, X, act, old, pred,
                      cam_f, has_dist, dist, cam_R, dom, dR, Lr, Lc, Lv, uv, B_pred, S):  # pragma: no cover - compiled
    """:func:`frame_rows` and then ``B`` at the k predicted positions in one call: ``pred[:k]`` into the image
    (:func:`project_ground`, pixels into ``uv[:k]``) and through :func:`~footprint_uq.fast.footprint_kernels.
    point_jacobian_into` into ``B_pred[:k] (k, 2, r)`` -- the same ``B`` to the bit as
    :class:`~footprint_uq.tracking.table.SharedJacobianAt` at ``pred[:k]``.  ``cam_f, has_dist, dist, cam_R,
    dom``: the camera's :class:`~footprint_uq.fast.footprint_kernels.KernelCamera` as :func:`~footprint_uq.fast.
    frame_columns.camera_parts` gives it (four arrays and a flag: unboxed in a fraction of the 20-field
    structure's ~1 us per call; put together inside); ``dR, Lr, Lc, Lv``: the rest of the point kernel's inputs
    (:meth:`~footprint_uq.products.frame_processor.FrameProcessor.point_jacobian_kernel`); ``uv (n, 2)``,
    ``B_pred (n, 2, r)`` and ``S`` (``footprint_kernels.SCRATCH_SHAPE``) are the caller's.  Returns what
    :func:`frame_rows` returns."""
    k, n_unknown = frame_rows(slots, xy_rows, cov_rows, B, subtract, z, R, t, t_last, seen, stamp, X, act, old,
                              pred)
    if k:
        cam = _camera(cam_f, has_dist, dist, cam_R, dom)
        project_ground(pred[:k], cam, uv[:k])
        point_jacobian_into(uv[:k], cam, dR, Lr, Lc, Lv, B_pred[:k], S)
    return k, n_unknown


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def initiate_row(s, X, P, Xm, Pm, Cm, mu, mu0, var_v0, z, R, B):  # pragma: no cover - compiled
    """A new track in storage row ``s`` from one measurement (:class:`~footprint_uq.tracking.filter.Initiator`:
    the position is the measurement, its calibration share ``C = -B``; the velocity zero with variance
    ``var_v0``), the same in every mode, mode probabilities ``mu0``."""
    for a in range(4):
        for b in range(4):
            P[s, a, b] = 0.0
    X[s, 0], X[s, 1], X[s, 2], X[s, 3] = z[0], z[1], 0.0, 0.0
    p00, p01, p11 = start_cov2(R, B)
    P[s, 0, 0], P[s, 1, 1] = p00, p11
    P[s, 0, 1] = P[s, 1, 0] = p01
    P[s, 2, 2] = P[s, 3, 3] = var_v0
    for j in range(Xm.shape[1]):
        mu[s, j] = mu0[j]
        for a in range(4):
            Xm[s, j, a] = X[s, a]
            for b in range(4):
                Pm[s, j, a, b] = P[s, a, b]
            for c in range(Cm.shape[2]):
                Cm[s, j, c, a] = -B[a, c] if a < 2 else 0.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def starts_and_outputs(act, slots, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, mu0, var_v0, z, R,
                       B_frame, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v, o_cv):  # pragma: no cover - compiled
    """The end of a frame's update pass (:func:`frame_update`, :func:`~footprint_uq.tracking.imm_kernels.frame_pass`),
    in frame order: the starts (:func:`initiate_row`, track ids ``next_id, next_id + 1, ...``) and every object's
    outputs (:class:`~footprint_uq.tracking.table.TrackOutput`: -1 / False / 0 / NaN for :data:`ROW_SKIP`; the
    velocity from the second update on).  Returns the next free track id."""
    nan = math.nan
    for i in range(act.shape[0]):
        s = slots[i]
        if act[i] == ROW_SKIP:
            o_tid[i], o_new[i], o_n[i], o_age[i] = -1, False, 0, nan
            o_xy[i, 0] = o_xy[i, 1] = o_v[i, 0] = o_v[i, 1] = nan
            for a in range(2):
                for b in range(2):
                    o_cxy[i, a, b] = o_cv[i, a, b] = nan
            continue
        started = act[i] == ROW_START
        if started:
            initiate_row(s, X, P, Xm, Pm, Cm, mu, mu0, var_v0, z[i], R[i], B_frame[i])
            t_last[s] = t_first[s] = t
            n_upd[s] = 1
            tid[s] = next_id
            next_id += 1
        o_tid[i], o_new[i], o_n[i], o_age[i] = tid[s], started, n_upd[s], t - t_first[s]
        o_xy[i, 0], o_xy[i, 1] = X[s, 0], X[s, 1]
        o_cxy[i, 0, 0], o_cxy[i, 0, 1], o_cxy[i, 1, 0], o_cxy[i, 1, 1] = P[s, 0, 0], P[s, 0, 1], P[s, 1, 0], P[s, 1, 1]
        velocity = n_upd[s] >= 2
        o_v[i, 0], o_v[i, 1] = (X[s, 2], X[s, 3]) if velocity else (nan, nan)
        o_cv[i, 0, 0], o_cv[i, 0, 1] = (P[s, 2, 2], P[s, 2, 3]) if velocity else (nan, nan)
        o_cv[i, 1, 0], o_cv[i, 1, 1] = (P[s, 3, 2], P[s, 3, 3]) if velocity else (nan, nan)
    return next_id


@njit(cache=True, nogil=True, error_model="numpy")
def frame_update(act, slots, old, n_old, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, qs, rates,
                 mu0, var_v0, z, R, B_pred, B_frame, gate, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v,
                 o_cv):  # pragma: no cover - compiled
    """Second pass of a frame (after :func:`frame_rows` and the slots of new ids): every update, start and output.

    The objects ``old[:n_old]`` get the IMM Schmidt step of :func:`update_slots` (``B_pred[k]`` is ``B`` at the
    k-th one's predicted position; ``(0, 2, 0)``: none, use ``B_frame``); one beyond the ``gate`` becomes a start
    (its id was reused: a new track in the same row).  Then in frame order the starts (:func:`initiate_row`, track
    ids ``next_id, next_id + 1, ...``) and the outputs of every object (:class:`~footprint_uq.tracking.table.
    TrackOutput`: -1 / False / 0 / NaN for :data:`ROW_SKIP`; the velocity from the second update on).  Returns the
    next free track id."""
    M, r = Xm.shape[1], Cm.shape[2]
    Pp, Cp, K, cross = np.empty((4, 4)), np.empty((4, r)), np.empty((4, 2)), np.empty((4, 2))
    xs, Ps, Cs = np.empty((M, 4)), np.empty((M, 4, 4)), np.empty((M, 4, r))
    pij, cbar, lik = np.empty((2, 2)), np.empty(M), np.empty(M)
    for k in range(n_old):
        i = old[k]
        d2 = _imm_one(slots[i], X, P, Xm, Pm, Cm, mu, t_last, n_upd, t, qs, rates, z[i], R[i],
                      pick_shared(B_pred, k, B_frame, i), gate, Pp, Cp, K, cross, xs, Ps, Cs, pij, cbar, lik)
        if not d2 <= gate:  # NaN (a singular S) fails the gate too
            act[i] = ROW_START
    return starts_and_outputs(act, slots, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, mu0,
                              var_v0, z, R, B_frame, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v, o_cv)
