"""The whole ``footprint-uq validate`` job: labelled data in, report, summary and per-object file out.

:func:`run_validation` picks the reader from the input (:func:`detect_kind`), streams the pairs through
:func:`footprint_uq.validation.job.validate` and writes into one folder, each file atomically:

=================  ========================================================================
``summary.json``   coverage, intervals, breakdowns, bias, NEES test and verdict, unpaired counts
``objects.csv``    one row per input object (``--objects-format parquet``: ``objects.parquet``)
``report.html``    self-contained report with the figures
``calibration.png`` the coverage-calibration figure
=================  ========================================================================
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..batch.fleet import load_registry
from ..errors import InputError
from ..io import load_camera
from ..io.atomic import atomic_write_bytes, atomic_write_text
from ..products.geo import GeoReference
from ..validation import readers as R
from ..validation.coverage import DEFAULT_RANGE_BANDS_M
from ..validation.job import validate
from .report import fig_to_png_bytes
from .validation import validation_figures, validation_html

__all__ = ["run_validation", "detect_kind", "label_chunks", "KINDS", "VALIDATION_FILES"]

KINDS = ("kitti", "dair-v2x", "openlabel", "table")
VALIDATION_FILES = {"summary": "summary.json", "report": "report.html", "calibration_png": "calibration.png"}


def detect_kind(labels) -> str:
    """``kitti`` (a folder with ``label_2/``), ``dair-v2x`` (``label/camera/``), ``openlabel`` (``.json``
    file or a folder of them) or ``table`` (``.csv``, ``.jsonl``, ``.ndjson``, ``.parquet``, ``.pq``)."""
    p = Path(labels)
    if not p.exists():
        raise InputError("labels", str(labels), "an existing folder or file")
    if p.is_dir():
        if (p / "label_2").is_dir():
            return "kitti"
        if (p / "label" / "camera").is_dir():
            return "dair-v2x"
        if any(p.glob("*.json")):
            return "openlabel"
        raise InputError("labels", str(labels), "a KITTI-layout folder (label_2/, calib/, denorm/), a DAIR-V2X-I "
                         "folder (label/camera/, calib/) or a folder of OpenLABEL .json files")
    suffix = p.suffix.lower()
    if suffix == ".json":
        return "openlabel"
    if suffix in (".csv", ".jsonl", ".ndjson", ".parquet", ".pq"):
        return "table"
    raise InputError("labels", str(labels), "a folder, an OpenLABEL .json or a pairs table (.csv, .jsonl, .parquet)")


def label_chunks(labels, kind, report, *, camera, registry, budget, calibration, image_size_px, georef, chunk_rows):
    """The reader of ``labels`` (one of :data:`KINDS`): an iterator of LabelChunk (also for ``calibrate budget``)."""
    if kind == "kitti":
        return R.read_kitti_folder(labels, image_size_px=image_size_px or R.ROPE3D_IMAGE_SIZE_PX, report=report)
    if kind == "dair-v2x":
        return R.read_dair_v2x_folder(labels, report=report)
    if kind == "openlabel":
        if calibration is None:
            raise InputError("--calibration", "missing", "the camera's TUMTraf calibration JSON (OpenLABEL labels)")
        p = Path(labels)
        files = sorted(p.glob("*.json")) if p.is_dir() else [p]
        return R.read_openlabel(files, calibration=calibration, image_size_px=image_size_px)
    if (camera is None) == (registry is None):
        raise InputError("--camera/--registry", (camera, registry), "exactly one of them for a pairs table")
    cams = load_camera(camera) if camera is not None else load_registry(registry, budget=budget)
    return R.read_pairs_table(labels, cams, georef=georef, chunk_rows=chunk_rows)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def run_validation(labels, out_dir, budget, *, kind: str | None = None, contact="bottom-centre", camera=None,
                   registry=None, calibration=None, image_size_px=None, origin_lat_deg=None, origin_lon_deg=None,
                   heading_offset_deg: float = 0.0, range_bands_m=DEFAULT_RANGE_BANDS_M, alpha: float = 0.05,
                   objects_format: str = "csv", chunk_rows: int = 131_072, report: bool = True, dpi: int = 110,
                   fsync: bool = True, progress=None, stage=None) -> tuple[dict, dict]:
    """Validate labelled data and write the outputs into ``out_dir``.

    Parameters
    ----------
    labels : KITTI / DAIR-V2X-I folder, OpenLABEL file or folder, or pairs table
    out_dir : output folder (created)
    budget : preset name, budget file, mapping or ErrorBudget (a registry's per-camera budgets win)
    kind : one of :data:`KINDS`, default from :func:`detect_kind`
    contact : contact model name or function
    camera : camera file of a pairs table with one camera; registry : camera registry of a multi-camera table
    calibration : TUMTraf calibration JSON of OpenLABEL labels
    image_size_px : (width, height) where the files do not give it (Rope3D default 1920 x 1080)
    origin_lat_deg, origin_lon_deg, heading_offset_deg : the world frame on the map (truth as lat/lon)
    range_bands_m : range band edges; alpha : test significance
    objects_format : ``csv`` or ``parquet`` (the per-object file)
    report : also write ``report.html`` and ``calibration.png``
    progress : callable(n_pairs) after every chunk; stage : callable(str) as each stage starts

    Returns
    -------
    summary : dict (also in ``summary.json``)
    files : dict name -> Path of the files written
    """
    kind = kind or detect_kind(labels)
    if kind not in KINDS:
        raise InputError("kind", kind, f"one of {KINDS}")
    if objects_format not in ("csv", "parquet"):
        raise InputError("objects_format", objects_format, "csv or parquet")
    georef = None
    if origin_lat_deg is not None or origin_lon_deg is not None:
        georef = GeoReference(heading_offset_deg, origin_lat_deg, origin_lon_deg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folder = R.FolderReport()
    chunks = label_chunks(labels, kind, folder, camera=camera, registry=registry, budget=budget,
                          calibration=calibration, image_size_px=image_size_px, georef=georef, chunk_rows=chunk_rows)
    files = {"objects": out / f"objects.{objects_format}", "summary": out / VALIDATION_FILES["summary"]}
    say = stage or (lambda msg: None)
    say(f"reading the {kind} labels and pairing detections with truth (contact model {contact})")
    res = validate(chunks, budget, contact=contact, objects_out=files["objects"], range_bands_m=range_bands_m,
                   alpha=alpha, fsync=fsync, progress=progress)
    summary = res.summary
    summary.update(labels=str(labels), kind=kind, folder=folder.to_dict())
    summary["files"] = {k: v.name for k, v in files.items()}
    say(f"{summary.get('n_pairs', 0)} pairs; coverage and verdict done")
    if report:
        say("report and figures")
        figs = validation_figures(summary, res.accumulator.sample)
        files["report"] = out / VALIDATION_FILES["report"]
        files["calibration_png"] = out / VALIDATION_FILES["calibration_png"]
        summary["files"].update(report=files["report"].name, calibration_png=files["calibration_png"].name)
        atomic_write_bytes(files["calibration_png"], fig_to_png_bytes(figs["calibration"], dpi=dpi), fsync=fsync)
        title = f"Validation of the uncertainty: {Path(str(labels)).name}"
        atomic_write_text(files["report"], validation_html(summary, figs, title=title, dpi=dpi), fsync=fsync)
    atomic_write_text(files["summary"], json.dumps(_jsonable(summary), indent=1), fsync=fsync)
    return summary, files
