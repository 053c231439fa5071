"""The whole ``footprint-uq validate`` job: labelled data in, report, summary and per-object file out.

:func:`run_validation` picks the reader from the input (:func:`detect_kind`), streams the pairs through
:func:`footprint_uq.validation.job.validate` and writes into one folder, the files as one set (built
in a hidden folder beside it and swapped in together, :func:`footprint_uq.io.atomic.output_set`: a
reader never sees the summary of one run beside the per-object file of another; the folder must be
new or hold only a previous run's files, :data:`VALIDATION_OWN`):

=================  ========================================================================
``summary.json``   coverage, intervals, breakdowns, bias, NEES test and verdict, unpaired counts
``objects.csv``    one row per input object (``--objects-format parquet``: ``objects.parquet``)
``report.html``    self-contained report with the figures
``calibration.png`` the coverage-calibration figure
``motion.csv``     with ``tracks``: per tracked detection, the truth velocity and the velocity / heading scores
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
from ..io.atomic import atomic_write_bytes, atomic_write_text, final_paths, output_set
from ..products.geo import GeoReference
from ..validation import readers as R
from ..validation.coverage import DEFAULT_RANGE_BANDS_M
from ..validation.job import validate
from ..validation.pairs import with_size_priors
from .report import fig_to_png_bytes
from .validation import validation_figures, validation_html

__all__ = ["run_validation", "detect_kind", "label_chunks", "KINDS", "VALIDATION_FILES"]

KINDS = ("kitti", "kitti-cameras", "dair-v2x", "openlabel", "openlabel-sequences", "table")
VALIDATION_FILES = {"summary": "summary.json", "report": "report.html", "calibration_png": "calibration.png"}
#: every name a run writes into its folder (a folder holding anything else is refused, not replaced)
VALIDATION_OWN = ("summary.json", "report.html", "calibration.png", "objects.csv", "objects.parquet", "motion.csv")


def detect_kind(labels) -> str:
    """``kitti`` (a folder with ``label_2/``), ``dair-v2x`` (``label/camera/``), ``openlabel`` (``.json``
    file or a folder of them), ``kitti-cameras`` (a folder of camera folders, each with ``label_2/``),
    ``openlabel-sequences`` (a folder of folders of ``.json`` files) or ``table`` (``.csv``, ``.jsonl``,
    ``.ndjson``, ``.parquet``, ``.pq``)."""
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
        if R.camera_folders(p):
            return "kitti-cameras"
        if R.openlabel_sequences(p):
            return "openlabel-sequences"
        raise InputError("labels", str(labels), "a KITTI-layout folder (label_2/, calib/, denorm/), a folder of "
                         "such camera folders, a DAIR-V2X-I folder (label/camera/, calib/), a folder of OpenLABEL "
                         ".json files or a folder of such sequence folders")
    suffix = p.suffix.lower()
    if suffix == ".json":
        return "openlabel"
    if suffix in (".csv", ".jsonl", ".ndjson", ".parquet", ".pq"):
        return "table"
    raise InputError("labels", str(labels), "a folder, an OpenLABEL .json or a pairs table (.csv, .jsonl, .parquet)")


def label_chunks(labels, kind, report, *, camera, registry, budget, calibration, image_size_px, georef, chunk_rows,
                 detections=None, detections_options=None):
    """The reader of ``labels`` (one of :data:`KINDS`): an iterator of LabelChunk (also for ``calibrate budget``).

    ``detections``: a detector's own files (``detections_options``: ``format``, ``class_names``,
    ``unknown_class``), paired with the truth table ``labels`` by ``(frame, object_id)``
    (:func:`footprint_uq.validation.readers.read_detections_with_truth`)."""
    if detections is not None:
        if kind != "table" or camera is None or registry is not None:
            raise InputError("--detections", str(detections), "a truth table as --labels (.csv, .jsonl, .parquet) "
                             "and one --camera (the detections of one camera)")
        cam = load_camera(camera)
        if image_size_px is not None and tuple(image_size_px) != tuple(cam.image_size_px):
            raise InputError("--image-size", tuple(image_size_px), f"the camera's image size {cam.image_size_px}")
        return R.read_detections_with_truth(detections, labels, cam, georef=georef, chunk_rows=chunk_rows,
                                            **(detections_options or {}))
    if kind == "kitti":
        return R.read_kitti_folder(labels, image_size_px=image_size_px or R.ROPE3D_IMAGE_SIZE_PX, report=report)
    if kind == "kitti-cameras":
        return R.read_camera_folders(labels, image_size_px=image_size_px or R.ROPE3D_IMAGE_SIZE_PX, report=report)
    if kind == "dair-v2x":
        return R.read_dair_v2x_folder(labels, report=report)
    if kind == "openlabel-sequences":
        return R.read_openlabel_sequences(labels, calibration=calibration, image_size_px=image_size_px)
    if kind == "openlabel":
        p = Path(labels)
        own = p / R.SEQUENCE_CALIBRATION if p.is_dir() else None
        calibration = calibration if calibration is not None or own is None or not own.is_file() else own
        if calibration is None:
            raise InputError("--calibration", "missing", "the camera's TUMTraf calibration JSON (OpenLABEL labels)")
        files = sorted(f for f in p.glob("*.json") if f.name != R.SEQUENCE_CALIBRATION) if p.is_dir() else [p]
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


def run_validation(labels, out_dir, budget, *, kind: str | None = None, contact="bottom-centre", size_priors=None,
                   camera=None,
                   registry=None, calibration=None, image_size_px=None, origin_lat_deg=None, origin_lon_deg=None,
                   heading_offset_deg: float = 0.0, range_bands_m=DEFAULT_RANGE_BANDS_M, alpha: float = 0.05,
                   objects_format: str = "csv", chunk_rows: int = 131_072, report: bool = True, dpi: int = 110,
                   fsync: bool = True, progress=None, detections=None, detections_format: str | None = None,
                   class_names=None, unknown_class: str = "error", stage=None, tracks=None,
                   motion_options: dict | None = None) -> tuple[dict, dict]:
    """Validate labelled data and write the outputs into ``out_dir``.

    Parameters
    ----------
    labels : KITTI / DAIR-V2X-I folder, OpenLABEL file or folder, or pairs table
    out_dir : output folder (created)
    budget : preset name, budget file, mapping or ErrorBudget (a registry's per-camera budgets win)
    kind : one of :data:`KINDS`, default from :func:`detect_kind`
    contact : contact model name or function
    size_priors : YAML file of class size priors for ``contact="footprint-centre"`` (``--size-priors``)
    camera : camera file of a pairs table with one camera; registry : camera registry of a multi-camera table
    calibration : TUMTraf calibration JSON of OpenLABEL labels
    image_size_px : (width, height) where the files do not give it (Rope3D default 1920 x 1080)
    origin_lat_deg, origin_lon_deg, heading_offset_deg : the world frame on the map (truth as lat/lon)
    range_bands_m : range band edges; alpha : test significance
    objects_format : ``csv`` or ``parquet`` (the per-object file)
    report : also write ``report.html`` and ``calibration.png``
    detections : a detector's own files (YOLO labels, YOLOv5 CSV, COCO results, MOTChallenge, a canonical table;
        ``detections_format`` / ``class_names`` / ``unknown_class`` as :func:`footprint_uq.batch.formats.open_reader`)
        paired with ``labels``, a truth table of ``frame, object_id`` and the truth point (docs/integrations.md)
    progress : callable(n_pairs) after every chunk; stage : callable(str) as each stage starts
    tracks : None, True or a TrackerConfig: also score velocity and heading where the labels carry a truth
        velocity (:func:`footprint_uq.validation.job.validate`, docs/validation.md "Velocity and heading");
        ``motion_options`` as there

    Returns
    -------
    summary : dict (also in ``summary.json``)
    files : dict name -> Path of the files written
    """
    kind = kind or detect_kind(labels)
    if kind not in KINDS:
        raise InputError("kind", kind, f"one of {KINDS}")
    contact_fn = with_size_priors(contact, size_priors)
    if objects_format not in ("csv", "parquet"):
        raise InputError("objects_format", objects_format, "csv or parquet")
    georef = None
    if origin_lat_deg is not None or origin_lon_deg is not None or heading_offset_deg:
        # (the heading offset alone rotates truth velocities given east / north into W)
        georef = GeoReference(heading_offset_deg, origin_lat_deg, origin_lon_deg)
    folder = R.FolderReport()
    chunks = label_chunks(labels, kind, folder, camera=camera, registry=registry, budget=budget,
                          calibration=calibration, image_size_px=image_size_px, georef=georef, chunk_rows=chunk_rows,
                          detections=detections, detections_options=dict(format=detections_format,
                                                                          class_names=class_names,
                                                                          unknown_class=unknown_class))
    with output_set(out_dir, VALIDATION_OWN, "validate", fsync=fsync) as staging:
        summary, files = _write_validation(staging, labels, kind, folder, chunks, budget, contact_fn, range_bands_m,
                                           alpha, objects_format, report, dpi, fsync, progress, detections,
                                           dict(size_priors=size_priors, stage=stage, tracks=tracks,
                                                motion_options=motion_options))
    return summary, final_paths(files, staging, out_dir)


def _write_validation(out: Path, labels, kind, folder, chunks, budget, contact, range_bands_m, alpha, objects_format,
                      report, dpi, fsync, progress, detections=None, extra: dict | None = None) -> tuple[dict, dict]:
    """The job's files written into ``out`` (the hidden staging folder of :func:`run_validation`); ``extra``:
    ``size_priors``, ``stage`` (the stage lines), ``tracks`` and ``motion_options`` of :func:`run_validation`."""
    extra = extra or {}
    size_priors, tracks, motion_options = extra.get("size_priors"), extra.get("tracks"), extra.get("motion_options")
    files = {"objects": out / f"objects.{objects_format}", "summary": out / VALIDATION_FILES["summary"]}
    if tracks:
        files["motion"] = out / "motion.csv"
    say = extra.get("stage") or (lambda msg: None)
    contact_name = contact if isinstance(contact, str) else getattr(contact, "__name__", "custom")
    say(f"reading the {kind} labels and pairing detections with truth (contact model {contact_name})")
    res = validate(chunks, budget, contact=contact, objects_out=files["objects"], range_bands_m=range_bands_m,
                   alpha=alpha, fsync=fsync, progress=progress, tracks=tracks,
                   motion_options=motion_options, motion_out=files.get("motion"))
    summary = res.summary
    summary.update(labels=str(labels), kind=kind, folder=folder.to_dict(),
                   size_priors=None if size_priors is None else str(size_priors))
    if detections is not None:
        summary["detections"] = str(detections)
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
