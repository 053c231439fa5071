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
from ..batch.formats import INPUT_FORMATS, NamedClasses
from ..batch.process import process_file
from ..batch.schema import DEFAULT_CHUNK_ROWS
from ..errors import InputError
from ..integrations.ros2.bag_reader import BagDetectionReader, bag_camera_info, camera_from_bag, is_bag
from ..integrations.ros2.bag_writer import BagOptions, bag_out_kind, bag_writer_factory
from ..integrations.ros2.types import DEFAULT_DISTRO, DISTROS
from ..io.class_names import UNKNOWN_POLICIES, ClassNames
from ..products.footprints import CONTACT_MODES, V2X_POLICIES
from ..products.warmup import compile_handler
from ..uncertainty.budget import load_budget
from ..uncertainty.presets import PRESET_NAMES
from .common import FINITE, LATITUDE_DEG, LONGITUDE_DEG, budget_notice, load_camera_and_budget, note, pose_options, warn

__all__ = ["objects_cmd"]


@click.command("objects")
@click.option("--camera", "camera_path", metavar="FILE",
              help="Camera file (docs/file-formats.md). Not with --registry.")
@click.option("--budget", "budget_spec", metavar="FILE_OR_PRESET",
              help=f"Error budget: a preset ({', '.join(PRESET_NAMES)}) or a YAML/JSON budget file.")
@click.option("--detections", "detections", required=True, metavar="FILE_OR_DIR",
              help="Detections: .csv, .jsonl/.ndjson or .parquet file, a detector's output (--format), or a ROS 2 "
                   "bag (.mcap, .db3 or a bag folder: its vision_msgs/msg/Detection2DArray topic, --topic; "
                   "docs/integrations.md); with --registry a Parquet dataset folder.")
@click.option("--format", "format_in", type=click.Choice(["auto", *INPUT_FORMATS]), default="auto", show_default=True,
              help="Input format: the canonical tables (csv, jsonl, parquet), a folder of YOLO / ultralytics .txt "
                   "labels (yolo), a YOLOv5 pandas CSV (yolov5-csv), COCO results JSON (coco), a MOTChallenge "
                   "det.txt / gt.txt (mot), a ROS 2 bag (ros2-bag); auto: from the file (docs/integrations.md).")
@click.option("--class-names", default=None, metavar="coco|coco91|mot|FILE",
              help="Integer class ids -> names: a built-in map, an ultralytics data.yaml (names:), a JSON list / "
                   "mapping / COCO dataset (categories, images), or a text file of one name per line (default: "
                   "the format's own: COCO for YOLO).")
@click.option("--unknown-class", type=click.Choice(UNKNOWN_POLICIES), default="error", show_default=True,
              help="A class id without a name: that detection's error, or the class 'unknown'.")
@click.option("--image-size", nargs=2, type=click.IntRange(min=1), default=None, metavar="W H",
              help="Size of the images the detections were made on (checked: it must be the camera's).")
@click.option("--out", "out", required=True, metavar="FILE_OR_DIR",
              help="Output: .parquet, .csv, .jsonl or .geojson (needs --origin-lat/--origin-lon), or a ROS 2 bag: "
                   "run.mcap (one MCAP file) or run_bag/ (a bag folder, --bag-storage); with --registry a folder "
                   "(partitioned Parquet).")
@click.option("--topic", default=None, metavar="TOPIC",
              help="ROS 2 bag in: its Detection2DArray topic (default: the bag's only one).")
@click.option("--camera-info-topic", default=None, metavar="TOPIC",
              help="ROS 2 bag in: its sensor_msgs/msg/CameraInfo topic (default: the only one); K, D and the image "
                   "size make the camera when no --camera is given (its pose from the pose options).")
@click.option("--frame-id", default="map", show_default=True, metavar="NAME",
              help="ROS 2 bag out: header.frame_id of the messages (the world frame: x east, y north, z up).")
@click.option("--bag-storage", type=click.Choice(["mcap", "sqlite3"]), default="mcap", show_default=True,
              help="ROS 2 bag folder out: its storage.")
@click.option("--ros-distro", type=click.Choice(list(DISTROS)), default=DEFAULT_DISTRO, show_default=True,
              help="ROS 2 bag out: the distribution whose message definitions the bag records.")
@click.option("--foxglove", is_flag=True,
              help="ROS 2 .mcap out: also the Foxglove scene (ellipses, object ids, the camera) as "
                   "foxglove.SceneUpdate messages on /footprints/scene.")
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
                   "order) and add track_id, velocity, speed, heading, yaw, their sigmas and age (docs/batch.md); "
                   "a budget with a motion section (calibrate motion) sets the motion model per class "
                   "(docs/motion-fit.md). Not in fleet mode.")
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
def objects_cmd(camera_path, budget_spec, detections, format_in, class_names, unknown_class, image_size, out, box_type,
                contact, chunk_rows, confidence,
                heading_offset_deg, origin_lat, origin_lon, corners, allow_outside_image, linearity, linear_threshold,
                v2x_policy, compression, fsync, tracks, quiet, registry, scheduler, workers, retries, overwrite,
                topic, camera_info_topic, frame_id, bag_storage, ros_distro, foxglove, pose):
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
    ros = dict(topic=topic, camera_info_topic=camera_info_topic, frame_id=frame_id, bag_storage=bag_storage,
               ros_distro=ros_distro, foxglove=foxglove)
    reader_opts = dict(format_in=None if format_in == "auto" else format_in, class_names=class_names,
                       unknown_class=unknown_class)
    if registry is None and (is_bag(detections) or bag_out_kind(out) is not None):
        if is_bag(detections) and reader_opts["format_in"] not in (None, "ros2-bag"):
            raise InputError("--format", format_in, "auto or ros2-bag with a ROS 2 bag in")
        ros["names"] = None if class_names is None else ClassNames.load(class_names, unknown=unknown_class)
        summ = _objects_ros(camera_path, budget_spec, detections, out, pose, ros, chunk_rows=chunk_rows,
                            progress=None if not quiet else False, compression=comp, fsync=fsync,
                            **({} if is_bag(detections) else reader_opts), **options)
        click.echo(f"footprint-uq objects: {summ.text()}; {summ.elapsed_s:.2f} s", err=True)
        return
    _no_ros_options(ros)
    if registry is not None:
        if camera_path is not None:
            raise InputError("--camera", camera_path, "no --camera with --registry (the registry names the cameras)")
        if format_in not in ("auto", "parquet") or class_names is not None or image_size is not None:
            raise InputError("--format/--class-names/--image-size", (format_in, class_names, image_size),
                             "none of them with --registry (fleet mode reads a Parquet dataset of canonical columns)")
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
        if image_size is not None and tuple(image_size) != tuple(cam.image_size_px):
            raise InputError("--image-size", f"{image_size[0]} x {image_size[1]}", f"the camera's image size "
                             f"{cam.image_size_px[0]} x {cam.image_size_px[1]} (the detections must be made on the "
                             "camera's images)")
        summ = process_file(cam, bud, detections, out, chunk_rows=chunk_rows, progress=None if not quiet else False,
                            compression=comp, info={"camera": str(camera_path), "budget": str(budget_spec),
                                                      **({} if pose is None else {"pose": pose}),
                                                      "budget_missing_terms": list(bud.missing_terms())},
                            fsync=fsync, **reader_opts, **options)
    click.echo(f"footprint-uq objects: {summ.text()}; {summ.elapsed_s:.2f} s", err=True)


def _no_ros_options(ros: dict) -> None:
    """The ROS 2 options need a bag in or out (InputError naming the first one given)."""
    given = [k for k in ("topic", "camera_info_topic") if ros[k] is not None]
    given += ["foxglove"] if ros["foxglove"] else []
    if given:
        raise InputError(f"--{given[0].replace('_', '-')}", ros[given[0]],
                         "a ROS 2 bag as --detections (.mcap, .db3, a bag folder) or as --out (.mcap, a folder/)")


def _ros_camera(camera_path, budget_spec, detections, pose, ros: dict):
    """The camera and budget of a job with a ROS 2 bag in or out: a --camera file (checked against the bag's
    CameraInfo size when there is one), or the bag's CameraInfo at the pose of the pose options."""
    if budget_spec is None:
        raise InputError("--budget", None, "a preset or budget file")
    if not is_bag(detections):
        if ros["topic"] is not None or ros["camera_info_topic"] is not None:
            raise InputError("--topic" if ros["topic"] is not None else "--camera-info-topic", ros["topic"] or
                             ros["camera_info_topic"], "a ROS 2 bag as --detections")
        if camera_path is None:
            raise InputError("--camera", None, "a camera file")
        return load_camera_and_budget(camera_path, budget_spec, pose)
    if camera_path is None:
        camera = camera_from_bag(detections, pose=pose, topic=ros["camera_info_topic"])
        budget = load_budget(budget_spec)
        if (msg := budget_notice(budget)) is not None:
            warn(msg)
        return camera, budget
    camera, budget = load_camera_and_budget(camera_path, budget_spec, pose)
    info = bag_camera_info(detections, topic=ros["camera_info_topic"])
    if info is not None and info["image_size_px"] is not None and \
            tuple(info["image_size_px"]) != tuple(camera.image_size_px):
        raise InputError("--camera", str(camera_path), f"a camera of the bag's image size "
                         f"{tuple(info['image_size_px'])} (its CameraInfo; the camera file's is "
                         f"{tuple(camera.image_size_px)})")
    return camera, budget


def _objects_ros(camera_path, budget_spec, detections, out, pose, ros: dict, **kw):
    """``objects`` with a ROS 2 bag as input and/or output (docs/integrations.md)."""
    camera, budget = _ros_camera(camera_path, budget_spec, detections, pose, ros)
    reader = BagDetectionReader(detections, topic=ros["topic"], chunk_rows=kw["chunk_rows"]) \
        if is_bag(detections) else None
    if reader is not None and ros["names"] is not None:  # integer class ids of the bag's hypotheses -> names
        reader = NamedClasses(reader, ros["names"])
    if bag_out_kind(out) is not None:
        kw["writer_factory"] = bag_writer_factory(BagOptions(
            frame_id=ros["frame_id"], distro=ros["ros_distro"], storage=ros["bag_storage"], foxglove=ros["foxglove"],
            camera=camera))
    elif ros["foxglove"]:
        raise InputError("--foxglove", True, "a ROS 2 .mcap file as --out")
    info = {"camera": str(camera_path) if camera_path is not None else f"{detections} (CameraInfo)",
            "budget": str(budget_spec), **({} if pose is None else {"pose": pose}),
            "budget_missing_terms": list(budget.missing_terms())}
    return process_file(camera, budget, detections, out, reader=reader, info=info, **kw)
