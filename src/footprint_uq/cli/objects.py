"""CLI command ``footprint-uq objects``: detections file(s) in, footprints out (docs/batch.md).

Single file: :func:`footprint_uq.batch.process.process_file` (streamed in chunks).
Fleet (a Parquet dataset of many cameras with a camera registry, optionally on a
Dask cluster): :func:`footprint_uq.batch.fleet.process_fleet`.

Bad input (files, columns, options) is one line on stderr and exit status 2 (the
group's policy); bad *rows* never stop the job: they are written with their row
number and reason, and counted in the summary printed at the end.
"""

from __future__ import annotations

import click

from .._notices import set_compile_handler
from ..batch.fleet import process_fleet
from ..batch.process import process_file
from ..batch.schema import DEFAULT_CHUNK_ROWS
from ..errors import InputError
from ..products.footprints import CONTACT_MODES, V2X_POLICIES
from ..products.warmup import compile_handler
from ..uncertainty.presets import PRESET_NAMES
from .common import FINITE, LATITUDE_DEG, LONGITUDE_DEG, load_camera_and_budget, note, pose_options

__all__ = ["objects_cmd"]


@click.command("objects")
@click.option("--camera", "camera_path", metavar="FILE",
              help="Camera file (docs/file-formats.md). Not with --registry.")
@click.option("--budget", "budget_spec", metavar="FILE_OR_PRESET",
              help=f"Error budget: a preset ({', '.join(PRESET_NAMES)}) or a YAML/JSON budget file.")
@click.option("--detections", "detections", required=True, metavar="FILE_OR_DIR",
              help="Detections: .csv, .jsonl/.ndjson or .parquet file; with --registry a Parquet dataset folder.")
@click.option("--out", "out", required=True, metavar="FILE_OR_DIR",
              help="Output: .parquet, .csv, .jsonl or .geojson (needs --origin-lat/--origin-lon); with --registry "
                   "a folder (partitioned Parquet).")
@click.option("--box-type", type=click.Choice(["2d", "3d", "corners"]), default=None,
              help="Box family (default: detected from the columns).")
@click.option("--contact", type=click.Choice(list(CONTACT_MODES)), default="bottom-centre", show_default=True,
              help="Ground contact of 2D boxes: the bottom-edge centre, or its two corners.")
@click.option("--chunk-rows", type=click.IntRange(min=1), default=DEFAULT_CHUNK_ROWS, show_default=True,
              help="Rows per chunk (memory grows with it, not with the file size).")
@click.option("--confidence", type=FINITE, default=None, metavar="P",
              help="Also write semi_major_m/semi_minor_m of the P-confidence ellipse (2-D chi-square).")
@click.option("--heading-offset-deg", type=FINITE, default=0.0, show_default=True, metavar="D",
              help="Compass bearing of the world +y axis (V2X fields, lat/lon).")
@click.option("--origin-lat", type=LATITUDE_DEG, default=None, metavar="LAT",
              help="WGS84 latitude of the world origin.")
@click.option("--origin-lon", type=LONGITUDE_DEG, default=None, metavar="LON",
              help="WGS84 longitude of the world origin.")
@click.option("--corners", is_flag=True, help="Also write every corner's pixel, ground position and covariance.")
@click.option("--allow-outside-image", is_flag=True,
              help="Let corners outside the image enter the centre and the largest point.")
@click.option("--linearity/--no-linearity", default=True, show_default=True,
              help="Compute the centre's linearity flag (columns nonlinearity, linear_ok, c<k>_nonlinearity) and "
                   "apply --v2x-policy to the centres that are not linear_ok; --no-linearity: no flag columns, "
                   "every V2X field from the linear covariance (faster).")
@click.option("--linear-threshold", type=FINITE, default=0.05, show_default=True, metavar="E",
              help="linear_ok is true where the centre's nonlinearity (predicted relative error of the linear "
                   "sigma_major_m) is at most E.")
@click.option("--v2x-policy", type=click.Choice(list(V2X_POLICIES)), default="sampled", show_default=True,
              help="V2X fields of centres that are not linear_ok: the larger of the linear and a seeded Monte-Carlo "
                   "covariance (unavailable beyond nonlinearity 0.5), always unavailable, or the linear one.")
@click.option("--compression", type=click.Choice(["auto", "snappy", "zstd", "lz4", "gzip", "none"]), default="auto",
              show_default=True, help="Parquet compression: auto = snappy, small-integer code columns uncompressed; "
                                      "else one codec for every column.")
@click.option("--fsync/--no-fsync", default=True, show_default=True,
              help="Durable outputs: flush to the disk and fsync before the rename into place. --no-fsync only "
                   "renames (never partial for a killed job, but a power loss may leave the output empty or "
                   "missing): for scratch outputs and tmpfs.")
@click.option("--tracks", is_flag=True,
              help="Track objects across frames (needs timestamp_s and object_id; one camera's frames in time "
                   "order) and add track_id, velocity, speed, heading, yaw, their sigmas and age (docs/batch.md). "
                   "Not in fleet mode.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@click.option("--registry", "registry", default=None, metavar="FILE_OR_DIR",
              help="Fleet mode: camera registry (camera_id -> camera file, budget); docs/batch.md.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Fleet mode on an existing Dask cluster (e.g. tcp://10.0.0.5:8786).")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Fleet mode on a local Dask cluster of N workers.")
@click.option("--retries", type=click.IntRange(min=0), default=2, show_default=True,
              help="Fleet mode on Dask: retries of a failed partition.")
@click.option("--overwrite", is_flag=True,
              help="Fleet mode: replace a non-empty --out folder as a whole (refused otherwise).")
@pose_options
def objects_cmd(camera_path, budget_spec, detections, out, box_type, contact, chunk_rows, confidence,
                heading_offset_deg, origin_lat, origin_lon, corners, allow_outside_image, linearity, linear_threshold,
                v2x_policy, compression, fsync, tracks, quiet, registry, scheduler, workers, retries, overwrite,
                pose):
    """Footprints (centre, covariance, largest point, V2X fields) of every detection in a file.

    Every input row gives one output row with its 0-based row number, a status (ok,
    partial, error) and a reason; a summary goes to stderr and to OUT.summary.json.
    """
    options = dict(box_type=box_type, contact=contact, confidence=confidence, heading_offset_deg=heading_offset_deg,
                   origin_lat_deg=origin_lat, origin_lon_deg=origin_lon, corners=corners,
                   allow_outside_image=allow_outside_image, linearity=linearity, linear_threshold=linear_threshold,
                   v2x_policy=v2x_policy)
    if tracks:
        options["tracks"] = True
    comp = None if compression == "none" else compression
    set_compile_handler(compile_handler(note))  # said before the kernels' first compile, after the inputs are checked
    if registry is not None:
        if camera_path is not None:
            raise InputError("--camera", camera_path, "no --camera with --registry (the registry names the cameras)")
        if tracks:
            raise InputError("--tracks", True, "a single detections file (--camera): fleet partitions run in "
                                               "parallel, out of time order")
        if pose is not None:
            raise InputError("--pose-file/--height-m", pose, "no pose options with --registry (its camera files "
                             "hold the poses; `footprint-uq camera compose` writes one)")
        summ = process_fleet(registry, detections, out, budget=budget_spec, scheduler=scheduler, workers=workers,
                             retries=retries, chunk_rows=chunk_rows, progress=None if not quiet else False,
                             compression=comp, overwrite=overwrite, fsync=fsync, **options)
    else:
        if scheduler is not None or workers is not None:
            raise InputError("--scheduler/--workers", scheduler or workers,
                             "--registry too: Dask runs the fleet mode (a dataset of many cameras)")
        if camera_path is None or budget_spec is None:
            raise InputError("--camera/--budget", (camera_path, budget_spec), "both a camera file and a budget")
        cam, bud = load_camera_and_budget(camera_path, budget_spec, pose)
        summ = process_file(cam, bud, detections, out, chunk_rows=chunk_rows, progress=None if not quiet else False,
                            compression=comp, info={"camera": str(camera_path), "budget": str(budget_spec),
                                                      **({} if pose is None else {"pose": pose}),
                                                      "budget_missing_terms": list(bud.missing_terms())},
                            fsync=fsync, **options)
    click.echo(f"footprint-uq objects: {summ.text()}; {summ.elapsed_s:.2f} s", err=True)
