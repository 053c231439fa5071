"""The ``motion`` section of a budget file: the tracker's manoeuvre noise per object class (docs/motion-fit.md).

Written by ``footprint-uq calibrate motion`` (:mod:`footprint_uq.tracking.motion_fit`), read by ``objects
--tracks`` and ``serve --tracks`` (:func:`footprint_uq.tracking.classes.tracker_configs`)::

    motion:
      source: "fitted to site.parquet (3 cameras, 1812 tracks)"
      default:                          # every class without its own entry (optional: the tracker's defaults)
        accel_psd_m2ps3: 1.5
        manoeuvre_accel_psd_m2ps3: 30.0 # null: one mode (a plain constant-velocity filter)
      classes:
        car:
          accel_psd_m2ps3: 0.52
          manoeuvre_accel_psd_m2ps3: null
          accel_psd_ci95_m2ps3: [0.41, 0.66]
          status: identified            # or "prior" (the data could not tell; the prior kept) -- with a note
          n_tracks: 240
          n_updates: 61000

Entry keys (units in the names): ``accel_psd_m2ps3`` (> 0, required), ``manoeuvre_accel_psd_m2ps3`` (> 0 or
null), ``quiet_sojourn_s`` and ``manoeuvre_sojourn_s`` (> 0), and the fit's record: ``accel_psd_ci95_m2ps3``
(``[lo, hi]``, ``hi`` null when unbounded), ``status``, ``note``, ``n_tracks``, ``n_updates``,
``log_likelihood_gain`` (informational, never used by the tracker); with a fitted IMM (``calibrate motion --modes
imm``, :mod:`footprint_uq.tracking.imm_fit`) also ``manoeuvre_accel_psd_ci95_m2ps3``, ``quiet_sojourn_ci95_s``,
``manoeuvre_sojourn_ci95_s`` (``[lo, hi]``, either null where not bounded within the grid; informational).
"""

from __future__ import annotations

import math

from .._checks import as_float
from ..errors import ConfigError, InputError

__all__ = ["parse_motion_section", "MOTION_ENTRY_KEYS", "MOTION_STATUSES"]

#: keys the tracker uses
_MODEL_KEYS = ("accel_psd_m2ps3", "manoeuvre_accel_psd_m2ps3", "quiet_sojourn_s", "manoeuvre_sojourn_s")
#: keys that record the fit
_RECORD_KEYS = ("accel_psd_ci95_m2ps3", "status", "note", "n_tracks", "n_updates", "log_likelihood_gain")
#: the fitted IMM's intervals of its other parameters (``calibrate motion --modes imm``; ``[lo, hi]``, either null
#: where not bounded within the grid; informational)
_IMM_CI_KEYS = ("manoeuvre_accel_psd_ci95_m2ps3", "quiet_sojourn_ci95_s", "manoeuvre_sojourn_ci95_s")
MOTION_ENTRY_KEYS = _MODEL_KEYS + _RECORD_KEYS + _IMM_CI_KEYS
MOTION_STATUSES = ("identified", "prior")


def _positive(where: str, key: str, value) -> float:
    try:
        return as_float(key, value, positive=True)
    except InputError:
        raise ConfigError(f"{where}.{key}", value, "a finite number > 0 (m^2/s^3 or s, as the key names)") from None


def _bounds(where: str, key: str, ci) -> list:
    """An interval ``[lo, hi]`` of numbers > 0, either null (not bounded within the fit's grid)."""
    ok = isinstance(ci, list | tuple) and len(ci) == 2 and all(
        v is None or (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0)
        for v in ci)
    if not ok:
        raise ConfigError(f"{where}.{key}", ci, "[lo, hi]: numbers > 0 or null (not bounded within the grid)")
    return [None if v is None else float(v) for v in ci]


def _entry(e, where: str) -> dict:
    if not isinstance(e, dict):
        raise ConfigError(where, type(e).__name__, "a mapping of motion keys")
    unknown = sorted(set(e) - set(MOTION_ENTRY_KEYS))
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}", e[unknown[0]], f"one of {list(MOTION_ENTRY_KEYS)}")
    if "accel_psd_m2ps3" not in e:
        raise ConfigError(f"{where}.accel_psd_m2ps3", "missing", "the quiet mode's acceleration density, m^2/s^3")
    out: dict = {"accel_psd_m2ps3": _positive(where, "accel_psd_m2ps3", e["accel_psd_m2ps3"])}
    if "manoeuvre_accel_psd_m2ps3" in e:
        m = e["manoeuvre_accel_psd_m2ps3"]
        out["manoeuvre_accel_psd_m2ps3"] = None if m is None else _positive(where, "manoeuvre_accel_psd_m2ps3", m)
    for k in ("quiet_sojourn_s", "manoeuvre_sojourn_s"):
        if e.get(k) is not None:
            out[k] = _positive(where, k, e[k])
    ci = e.get("accel_psd_ci95_m2ps3")
    if ci is not None:
        ok = isinstance(ci, list | tuple) and len(ci) == 2 and all(
            v is None or (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v >= 0)
            for v in ci) and ci[0] is not None
        if not ok:
            raise ConfigError(f"{where}.accel_psd_ci95_m2ps3", ci, "[lo, hi] with 0 <= lo and hi a number or null")
        out["accel_psd_ci95_m2ps3"] = [float(ci[0]), None if ci[1] is None else float(ci[1])]
    for k in _IMM_CI_KEYS:
        if e.get(k) is not None:
            out[k] = _bounds(where, k, e[k])
    if "status" in e:
        if e["status"] not in MOTION_STATUSES:
            raise ConfigError(f"{where}.status", e["status"], f"one of {list(MOTION_STATUSES)}")
        out["status"] = e["status"]
    for k in ("n_tracks", "n_updates"):
        if k in e:
            v = e[k]
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ConfigError(f"{where}.{k}", v, "an integer >= 0")
            out[k] = v
    if e.get("log_likelihood_gain") is not None:
        try:
            out["log_likelihood_gain"] = as_float("log_likelihood_gain", e["log_likelihood_gain"])
        except InputError:
            raise ConfigError(f"{where}.log_likelihood_gain", e["log_likelihood_gain"], "a finite number") from None
    if "note" in e:
        out["note"] = str(e["note"])
    return out


def parse_motion_section(d, where: str = "motion") -> dict:
    """Validate a budget file's ``motion`` mapping (module doc); returns it with checked values.

    Raises :class:`~footprint_uq.errors.ConfigError` naming the key, the value and what was expected.
    """
    if not isinstance(d, dict):
        raise ConfigError(where, type(d).__name__, "a mapping with 'classes' and/or 'default'")
    unknown = sorted(set(d) - {"classes", "default", "source"})
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}", d[unknown[0]], "one of ['classes', 'default', 'source']")
    out: dict = {}
    if d.get("source") is not None:
        out["source"] = str(d["source"])
    if d.get("default") is not None:
        out["default"] = _entry(d["default"], f"{where}.default")
    classes = d.get("classes") or {}
    if not isinstance(classes, dict):
        raise ConfigError(f"{where}.classes", type(classes).__name__, "a mapping class name -> motion entry")
    out["classes"] = {str(k): _entry(v, f"{where}.classes.{k}") for k, v in classes.items()}
    return out
