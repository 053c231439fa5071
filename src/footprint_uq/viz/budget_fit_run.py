"""The job of ``footprint-uq calibrate budget``: labelled data -> pairs -> fitted budget (docs/budget-fit.md).

Readers and pairs are those of ``validate`` (:mod:`footprint_uq.viz.validation_run`,
:mod:`footprint_uq.validation.pairs`); the fit is :func:`footprint_uq.validation.fit.fit_budget`, the
cross-validated coverage :func:`footprint_uq.validation.fit.cross_validate`; the pairs are streamed into
the fit's compact records (:func:`footprint_uq.validation.fit.compact_inputs`), never all held in memory.
Writes the fitted budget (YAML, readable by every command) and a JSON summary as one set (built in a hidden
folder and swapped in together, :func:`footprint_uq.io.atomic.output_set`).
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write_text, check_output_folder, final_paths, output_set
from ..io.camera_files import save_budget
from ..products.geo import GeoReference
from ..uncertainty.budget import ErrorBudget, load_budget
from ..validation import readers as R
from ..validation.fit import compact_inputs, cross_validate_compact, fit_compact
from ..validation.pairs import STATUS_OK, GroupIndex, iter_pairs, refused_reasons, with_size_priors
from .validation_run import KINDS, detect_kind, label_chunks

__all__ = ["run_budget_fit", "DEFAULT_FREE", "BUDGET_FIT_FILES"]

#: the terms fitted by default: the orientation, the height and a per-object sigma
DEFAULT_FREE = ("pan_deg", "tilt_deg", "height_m", "object_m")
BUDGET_FIT_FILES = {"budget": "budget.yaml", "summary": "fit.json"}


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple | np.ndarray):
        return [_jsonable(v) for v in (x.tolist() if isinstance(x, np.ndarray) else x)]
    if isinstance(x, np.generic):
        x = x.item()
    return None if isinstance(x, float) and not np.isfinite(x) else x


def _records(labels, kind, budget, contact, folder, free, **reader):
    """Stream the labelled data chunk by chunk into the fit's compact records (``fit.compact_inputs``):
    memory is the records (about 100 bytes a usable pair) plus one chunk, never every pair's arrays."""
    kind = kind or detect_kind(labels)
    if kind not in KINDS:
        raise InputError("kind", kind, f"one of {KINDS}")
    groups = GroupIndex()
    statuses: Counter = Counter()
    refused: Counter = Counter()  # error rows by kind of reason (the summary's "refused")
    chunks = label_chunks(labels, kind, folder, budget=budget, **reader)

    def usable():
        for p in iter_pairs(chunks, budget, contact=contact, groups=groups):
            statuses.update(p.status.tolist())
            refused.update(refused_reasons(p.status, p.reason))
            ok = p.usable
            yield p.residual_m[ok], p.dxy_dp[ok], p.cov_object_m2[ok], p.group[ok]

    try:
        data = compact_inputs(usable(), free=free, base_budget=budget)
    except InputError as e:
        n_ok = statuses.get(STATUS_OK, 0)
        if n_ok >= 2 or e.field != "residual_m":
            raise
        raise InputError("labels", str(labels), f"at least 2 usable detection/truth pairs (found {n_ok}; "
                         f"statuses {dict(statuses)})") from None
    return kind, data, dict(statuses), groups, {"rows": sum(refused.values()), "by_reason": dict(refused.most_common())}


def run_budget_fit(labels, out_dir, *, base_budget=None, free=DEFAULT_FREE, kind: str | None = None,
                   contact="bottom-centre", size_priors=None, camera=None, registry=None, calibration=None,
                   image_size_px=None,
                   origin_lat_deg=None, origin_lon_deg=None, heading_offset_deg: float = 0.0, method: str = "reml",
                   min_groups: int = 3, cross_validation: bool = True, fsync: bool = True) -> tuple[dict, dict]:
    """Fit the free terms of a budget to labelled data and write ``budget.yaml`` and ``fit.json``.

    Parameters as :func:`footprint_uq.viz.validation_run.run_validation` for the input (``size_priors``: the
    class size priors of the footprint-centre contact, ``--size-priors FILE``); ``base_budget``
    (default: all zero) gives the terms that are not free; ``free``, ``method``, ``min_groups`` as
    :func:`footprint_uq.validation.fit.fit_budget`; ``cross_validation`` adds leave-one-object-out (and,
    with two groups or more, leave-one-group-out) coverage to the summary.

    Returns
    -------
    summary : dict (also in ``fit.json``); files : dict name -> Path
    """
    base = ErrorBudget() if base_budget is None else load_budget(base_budget)
    check_output_folder(out_dir, BUDGET_FIT_FILES.values(), "calibrate budget")  # before the fit, not after
    contact_fn = with_size_priors(contact, size_priors)
    georef = None
    if origin_lat_deg is not None or origin_lon_deg is not None:
        georef = GeoReference(heading_offset_deg, origin_lat_deg, origin_lon_deg)
    folder = R.FolderReport()
    opts = {"free": list(free), "base_budget": base, "method": method, "min_groups": min_groups}
    kind, data, statuses, groups, refused = _records(labels, kind, base, contact_fn, folder, list(free), camera=camera,
                                            registry=registry, calibration=calibration, image_size_px=image_size_px,
                                            georef=georef, chunk_rows=131_072)
    fit = fit_compact(data, **opts)
    summary = {"labels": str(labels), "kind": kind, "contact": contact if isinstance(contact, str) else "custom",
               "size_priors": None if size_priors is None else str(size_priors),
               "statuses": statuses, "refused": refused, "groups": groups.names(), "folder": folder.to_dict(),
               "fit": fit.to_dict(), "cross_validation": {}}
    if cross_validation:  # above fit.CV_MAX_PAIRS pairs: on a seeded subsample, reported in the summary
        summary["cross_validation"]["object"] = cross_validate_compact(data, by="object", **opts).to_dict()
        if data.groups_present() >= 2:
            summary["cross_validation"]["group"] = cross_validate_compact(data, by="group", **opts).to_dict()
    with output_set(out_dir, tuple(BUDGET_FIT_FILES.values()), "calibrate budget", fsync=fsync) as stage:
        files = {k: stage / v for k, v in BUDGET_FIT_FILES.items()}
        save_budget(fit.to_budget(name=f"fitted to {Path(str(labels)).name}"), files["budget"])
        summary["files"] = {k: v.name for k, v in files.items()}
        text = json.dumps(_jsonable(summary), indent=1, allow_nan=False) + "\n"
        atomic_write_text(files["summary"], text, fsync=fsync)
    return summary, final_paths(files, stage, out_dir)
