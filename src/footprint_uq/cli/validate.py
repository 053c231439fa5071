"""CLI command ``footprint-uq validate``: labelled detections in, a verdict on the uncertainty out.

Calls :func:`footprint_uq.viz.validation_run.run_validation` (docs/validation.md).  Bad input is one
line on stderr and exit status 2 (the group's policy); bad rows are error rows of ``objects.csv``,
counted in the summary, never a stop.
"""

from __future__ import annotations

import click

from ..batch.formats import INPUT_FORMATS
from ..errors import InputError
from ..io.class_names import UNKNOWN_POLICIES
from ..uncertainty.presets import PRESET_NAMES
from ..validation.coverage import DEFAULT_RANGE_BANDS_M
from ..validation.pairs import CONTACT_MODELS
from ..viz.validation_run import KINDS, run_validation
from .common import FINITE, LATITUDE_DEG, LONGITUDE_DEG, AscendingFloats, FiniteFloatRange, Stages, note

__all__ = ["validate_cmd", "label_source_options", "size_priors_option"]

#: ``--size-priors FILE`` of ``validate`` and ``calibrate budget`` (the footprint-centre contact's class sizes)
size_priors_option = click.option(
    "--size-priors", "size_priors", default=None, metavar="FILE",
    help="Class size priors of --contact footprint-centre: a YAML file in the layout of the shipped "
         "presets/size_priors.yaml, overriding it class by class (docs/validation.md).")


def label_source_options(f):
    """The options that say where labelled data come from and how to read them (``validate``, ``calibrate
    budget``): ``--kind``, ``--camera``, ``--registry``, ``--calibration``, ``--image-size``, ``--origin-lat``,
    ``--origin-lon``, ``--heading-offset-deg``."""
    for opt in reversed(_LABEL_SOURCE_OPTIONS):
        f = opt(f)
    return f


_LABEL_SOURCE_OPTIONS = [
    click.option("--kind", type=click.Choice(KINDS), default=None, help="Input kind (default: from the path)."),
    click.option("--camera", "camera_path", default=None, metavar="FILE",
                 help="Camera file of a one-camera pairs table."),
    click.option("--registry", default=None, metavar="FILE_OR_DIR",
                 help="Camera registry (camera_id -> camera, budget, origin) of a multi-camera pairs table."),
    click.option("--calibration", default=None, metavar="FILE", help="TUMTraf calibration JSON of OpenLABEL labels."),
    click.option("--image-size", nargs=2, type=click.IntRange(min=1), default=None, metavar="W H",
                 help="Image size where the files do not give it (Rope3D: 1920 1080, the default there)."),
    click.option("--origin-lat", type=LATITUDE_DEG, default=None, metavar="LAT",
              help="WGS84 latitude of the world origin."),
    click.option("--origin-lon", type=LONGITUDE_DEG, default=None, metavar="LON",
              help="WGS84 longitude of the world origin."),
    click.option("--heading-offset-deg", type=FINITE, default=0.0, show_default=True, metavar="D",
                 help="Compass bearing of the world +y axis (truth given as lat_deg, lon_deg)."),
]


@click.command("validate")
@click.option("--labels", required=True, metavar="PATH",
              help="Labelled data: a KITTI-layout folder (Rope3D: calib/, denorm/, label_2/), a DAIR-V2X-I folder, "
                   "TUMTraf OpenLABEL .json file(s), or a pairs table (.csv, .jsonl, .parquet).")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output folder (created).")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET",
              help=f"The error budget to validate: a preset ({', '.join(PRESET_NAMES)}, optionally NAME@deg) or a "
                   "budget file (a camera registry's per-camera budgets win).")
@click.option("--contact", type=click.Choice(sorted(CONTACT_MODELS)), default="bottom-centre", show_default=True,
              help="Where a 2-D box touches the ground.")
@size_priors_option
@label_source_options
@click.option("--detections", default=None, metavar="FILE_OR_DIR",
              help="A detector's own files (YOLO labels, YOLOv5 CSV, COCO results, MOTChallenge, a ROS 2 bag's "
                   "Detection2DArray topic (its only one), a canonical table), "
                   "paired with --labels, a truth table of frame, object_id, x_m, y_m (or lat_deg, lon_deg), by "
                   "frame and object_id (docs/integrations.md).")
@click.option("--format", "detections_format", type=click.Choice(["auto", *INPUT_FORMATS]), default="auto",
              show_default=True, help="Format of --detections (auto: from the file).")
@click.option("--class-names", default=None, metavar="coco|coco91|mot|FILE",
              help="Integer class ids of --detections -> names (default: the format's own).")
@click.option("--unknown-class", type=click.Choice(UNKNOWN_POLICIES), default="error", show_default=True,
              help="A class id without a name: that detection's error, or the class 'unknown'.")
@click.option("--range-bands", type=AscendingFloats(0.0), default=",".join(f"{v:g}" for v in DEFAULT_RANGE_BANDS_M),
              show_default=True, metavar="EDGES", help="Range band edges in metres (the last band is open).")
@click.option("--alpha", type=FiniteFloatRange(0.0, 0.5, min_open=True), default=0.05, show_default=True,
              help="Significance of the NEES test (two-sided) and of the bias test.")
@click.option("--objects-format", type=click.Choice(["csv", "parquet"]), default="csv", show_default=True,
              help="Format of the per-object file.")
@click.option("--tracks", is_flag=True,
              help="Also track the detections (timestamp_s and object_id; per camera, as objects --tracks, with the "
                   "budget's motion section) and score velocity and heading where the labels carry a truth velocity "
                   "(v_east_mps, v_north_mps; docs/validation.md).")
@click.option("--truth-sigma-m", type=FiniteFloatRange(min=0, min_open=True), default=0.1, show_default=True,
              metavar="M",
              help="With --tracks: position sigma (per axis, m) of the labels, for truth velocities from consecutive "
                   "labelled frames (finite differences; docs/validation.md).")
@click.option("--no-report", is_flag=True, help="No report.html / calibration.png (summary and objects only).")
@click.option("--fsync/--no-fsync", default=True, show_default=True, help="Durable outputs (fsync before rename).")
def validate_cmd(labels, out_dir, budget_spec, contact, size_priors, kind, camera_path, registry, calibration,
                 image_size, origin_lat, origin_lon, heading_offset_deg, detections, detections_format, class_names,
                 unknown_class, range_bands, alpha, objects_format, tracks, truth_sigma_m, no_report, fsync):
    """Do the uncertainty ellipses contain the real errors?  Coverage, bias and a verdict.

    Writes summary.json, objects.csv (one row per input object, with its status) and report.html into
    OUT; prints the verdict.
    """
    if detections is None and (detections_format != "auto" or class_names is not None or unknown_class != "error"):
        raise InputError("--format/--class-names/--unknown-class", (detections_format, class_names, unknown_class),
                         "--detections too (they say how to read a detector's files)")
    with Stages("validate") as say:
        summary, files = run_validation(labels, out_dir, budget_spec, kind=kind, contact=contact,
                                        size_priors=size_priors, camera=camera_path,
                                        registry=registry, calibration=calibration,
                                        image_size_px=tuple(image_size) if image_size else None,
                                        origin_lat_deg=origin_lat, origin_lon_deg=origin_lon,
                                        heading_offset_deg=heading_offset_deg, range_bands_m=range_bands,
                                        alpha=alpha, objects_format=objects_format, report=not no_report, fsync=fsync,
                                        detections=detections,
                                        detections_format=None if detections_format == "auto" else detections_format,
                                        class_names=class_names, unknown_class=unknown_class,
                                        stage=say, progress=lambda n: say(f"{n} pairs so far"),
                                        tracks=True if tracks else None,
                                        motion_options={"truth_sigma_m": truth_sigma_m})
    t = summary["nees_test"]
    c95 = next((c for c in summary["coverage"] if c["nominal"] == 0.95), None)
    un = summary["unpaired"]
    if summary["verdict"] is None:
        msg = "no usable pair (no verdict)"
    else:
        msg = (f"{summary['verdict']}: {summary['n_pairs']} pairs, 95 % ellipse covers {100 * c95['empirical']:.1f} % "
               f"(Wilson {100 * c95['interval'][0]:.1f}-{100 * c95['interval'][1]:.1f} %), mean NEES "
               f"{t['nees_mean']:.3g} (expected 2, n_eff {t['n_eff']:.3g})")
    click.echo(f"footprint-uq validate: {msg}; unpaired: {un['detections_without_truth']} detections without truth, "
               f"{un['truth_without_detection']} truths without detection, {un['error_rows']} error rows, "
               f"{un['no_ground_point']} without ground point; {out_dir}/{files['summary'].name}")
    refused = summary.get("refused", {})
    if refused.get("rows"):  # why rows were refused, the most frequent reasons first (all in summary.json)
        top = list(refused["by_reason"].items())
        why = "; ".join(f"{n} x {k}" for k, n in top[:3]) + ("; ..." if len(top) > 3 else "")
        note(f"{refused['rows']} rows refused ({why}); per row in {files['objects'].name}, by reason in "
             f"{files['summary'].name} ('refused')")
    if tracks:
        click.echo(f"footprint-uq validate --tracks: {_motion_message(summary.get('motion'))}")


def _motion_message(motion) -> str:
    """One line on the velocity and heading scores (``summary["motion"]``)."""
    if motion is None:
        return "no row carries a truth velocity (v_east_mps, v_north_mps): velocity and heading not scored"
    out = []
    for what in ("velocity", "heading"):
        t = motion[what]["test"]
        c95 = next(c for c in motion[what]["coverage"] if c["nominal"] == 0.95)
        out.append(f"{what} {t['verdict'] or 'no verdict'} ({t['n']} scored" + (
            f", 95 % region covers {100 * c95['empirical']:.1f} %, mean NEES {t['nees_mean']:.3g}, n_eff "
            f"{t['n_eff']:.3g})" if t["n"] else ")"))
    c = motion["counts"]
    return "; ".join(out) + (f"; {c.get('detections_without_truth_velocity', 0)} detections without truth velocity, "
                             f"{c.get('first_detection', 0)} first detections (no velocity yet)")
