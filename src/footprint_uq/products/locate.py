"""Ground position and covariance of single pixels as plain records (the ``footprint-uq locate`` output).

:func:`locate_records` turns :func:`footprint_uq.propagate` and
:func:`footprint_uq.ellipse_axes` into one JSON-ready dictionary per pixel; :func:`locate_csv`
writes the same records as CSV text.  Invalid pixels keep their row: numbers None (``nan`` in
CSV), ``valid`` False and the reason text of :mod:`footprint_uq.status`.
"""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from .. import status
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.propagation import propagate

__all__ = ["LOCATE_KEYS", "CONFIDENCE_KEYS", "CSV_KEYS", "locate_records", "locate_csv"]

#: keys of every ``locate`` record, in output order
LOCATE_KEYS = ("u_px", "v_px", "x_m", "y_m", "cov_m2", "sigma_major_m", "sigma_minor_m", "orientation_deg",
               "nonlinearity", "linear_ok", "valid", "reason", "budget_missing_terms")
#: extra keys when a confidence level is given
CONFIDENCE_KEYS = ("confidence", "semi_major_m", "semi_minor_m")
#: CSV columns of ``locate`` (covariance flattened)
CSV_KEYS = ("u_px", "v_px", "x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "sigma_major_m", "sigma_minor_m",
            "orientation_deg", "nonlinearity", "linear_ok", "valid", "reason", "budget_missing_terms")


def _num(x):
    """float for JSON: None for NaN/inf."""
    x = float(x)
    return x if math.isfinite(x) else None


def locate_records(camera, budget, uv_px, *, confidence: float | None = None,
                   linear_threshold: float = 0.05) -> list[dict]:
    """Ground position and covariance of pixels, one dictionary per pixel.

    Parameters
    ----------
    camera : Camera
        Any camera model of :mod:`footprint_uq.cameras`.
    budget : ErrorBudget or str
        Error budget, or a preset name / budget file accepted by :func:`footprint_uq.load_budget`.
    uv_px : array_like, shape (N, 2) or (2,)
        Pixels (u right, v down, origin at the centre of the top-left pixel).
    confidence : float, optional
        Also report the semi-axes of the ``confidence`` ellipse (2-D chi-square), keys
        :data:`CONFIDENCE_KEYS`.
    linear_threshold : float
        ``linear_ok`` is ``nonlinearity <= linear_threshold``.

    Returns
    -------
    list of dict
        Keys :data:`LOCATE_KEYS` (plus :data:`CONFIDENCE_KEYS` with ``confidence``), in that
        order.  Numbers are those of :func:`footprint_uq.propagate` and
        :func:`footprint_uq.ellipse_axes` (1 sigma, metres, x east, y north); ``nonlinearity``
        is the predicted relative error of the linear 1-sigma semi-major axis.  An invalid
        point, or a valid one whose outputs are not all finite, has None numbers, ``valid``
        False, ``linear_ok`` False and the reason text of :mod:`footprint_uq.status`.
        ``budget_missing_terms`` lists the error groups the budget has nothing on
        (:meth:`footprint_uq.ErrorBudget.missing_terms`: ``"extrinsic"``, ``"ground"``; the paper's
        presets have no ground terms, the budget of ``calibrate intrinsics`` neither extrinsic ones).
    """
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    budget = load_budget(budget)
    missing = list(budget.missing_terms())
    est = propagate(camera, budget, uv, linear_threshold=linear_threshold)
    a, b, ang = ellipse_axes(est.cov_m2)
    k = chi2_scale(confidence) if confidence is not None else None
    out = []
    for i in range(uv.shape[0]):
        ok = bool(est.valid[i])
        c = est.cov_m2[i]
        why = None if ok else status.REASONS[int(est.reason[i])]
        nums = (est.xy_world_m[i, 0], est.xy_world_m[i, 1], c[0, 0], c[0, 1], c[1, 1], a[i], b[i], ang[i])
        if ok and not np.all(np.isfinite(nums)):  # outputs are checked too: never valid with a missing number
            ok, why = False, "result is not finite (overflow or degenerate geometry)"
        rec = {
            "u_px": float(uv[i, 0]), "v_px": float(uv[i, 1]),
            "x_m": _num(est.xy_world_m[i, 0]), "y_m": _num(est.xy_world_m[i, 1]),
            "cov_m2": [[_num(c[0, 0]), _num(c[0, 1])], [_num(c[1, 0]), _num(c[1, 1])]],
            "sigma_major_m": _num(a[i]), "sigma_minor_m": _num(b[i]), "orientation_deg": _num(ang[i]),
            "nonlinearity": _num(est.nonlinearity[i]), "linear_ok": bool(ok and est.linear_ok[i]),
            "valid": ok, "reason": why, "budget_missing_terms": list(missing),
        }
        if k is not None:
            rec.update({"confidence": confidence, "semi_major_m": _num(k * a[i]), "semi_minor_m": _num(k * b[i])})
        out.append(rec)
    return out


def _cell(v):
    if v is None:
        return "nan"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return v


def locate_csv(records: list[dict], confidence: float | None = None) -> str:
    """The records of :func:`locate_records` as CSV text (header included).

    Parameters
    ----------
    records : list of dict
        Output of :func:`locate_records`.
    confidence : float, optional
        The level the records were computed with: adds the :data:`CONFIDENCE_KEYS` columns.

    Returns
    -------
    str
        Columns :data:`CSV_KEYS` (the covariance flattened to ``cov_xx_m2``, ``cov_xy_m2``,
        ``cov_yy_m2``); missing numbers are ``nan``, booleans ``true``/``false``, floats
        printed in full (``repr``), ``reason`` empty for valid rows, ``budget_missing_terms``
        joined with ``;``.
    """
    cols = list(CSV_KEYS) + (list(CONFIDENCE_KEYS) if confidence is not None else [])
    cols += [k for k in records[0] if k.startswith("gcp_")] if records else []  # products.gcp_support
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in records:
        flat = dict(r)
        cov = flat.pop("cov_m2")
        flat["cov_xx_m2"], flat["cov_xy_m2"], flat["cov_yy_m2"] = cov[0][0], cov[0][1], cov[1][1]
        flat["budget_missing_terms"] = ";".join(flat.get("budget_missing_terms", ()))
        row = [_cell(flat[c]) for c in cols]
        row[cols.index("reason")] = r["reason"] if not r["valid"] else ""
        w.writerow(row)
    return buf.getvalue()
