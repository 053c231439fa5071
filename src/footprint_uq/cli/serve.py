"""CLI command ``footprint-uq serve``: the edge service (docs/service.md).

Only parses the options and calls :func:`footprint_uq.service.runner.run`.
"""

from __future__ import annotations

import sys

import click

from .._checks import as_float
from ..errors import InputError
from ..io.class_names import UNKNOWN_POLICIES, load_class_names
from ..products.footprints import CONTACT_MODES, V2X_POLICIES
from ..service.cp_serve import CpServeOptions
from ..service.messages.asn1_cpm import CDD_RELEASES, DEFAULT_CDD
from ..service.runner import MAX_FRAME_BYTES, QUEUE_DEPTH, run
from ..tracking.consistency import DEFAULT_WINDOW_S
from ..uncertainty.budget import load_budget
from ..uncertainty.presets import PRESET_NAMES
from .common import FINITE, LATITUDE_DEG, LONGITUDE_DEG, FiniteFloatRange, budget_notice, pose_options, warn

__all__ = ["serve_cmd"]


@click.command("serve")
@click.option("--camera", "camera_path", metavar="FILE", help="Camera file (one camera). Not with --registry.")
@click.option("--budget", "budget_spec", metavar="FILE_OR_PRESET",
              help=f"Error budget: a preset ({', '.join(PRESET_NAMES)}) or a budget file; with --registry the "
                   "default for cameras without one.")
@click.option("--registry", default=None, metavar="FILE_OR_DIR",
              help="Many cameras: camera registry as in the batch (docs/batch.md); frames pick theirs by camera_id.")
@click.option("--camera-id", default=None, metavar="ID",
              help="With --camera: the only camera_id accepted (default: any).")
@click.option("--input", "input_", default=None, metavar="-", help="'-': JSON Lines frames on stdin.")
@click.option("--mqtt", default=None, metavar="mqtt://HOST:PORT",
              help="MQTT broker: input from topics detections/<camera_id> (without --input), and/or output.")
@click.option("--output", default="-", show_default=True, metavar="-|mqtt|rosbag:PATH",
              help="'-': JSON Lines on stdout; 'mqtt': topics footprints/<camera_id>, footprints/errors, "
                   "footprints/health; 'rosbag:PATH': the footprints recorded into a ROS 2 bag (PATH.mcap or a "
                   "folder; docs/integrations.md), error and health records on stdout.")
@click.option("--input-prefix", default="detections", show_default=True, help="MQTT input topic prefix.")
@click.option("--output-prefix", default="footprints", show_default=True, help="MQTT output topic prefix.")
@click.option("--overload", "policy", type=click.Choice(["newest", "block"]), default=None,
              help="When input outruns processing: keep the newest frame per camera and count the dropped ones "
                   "(default for MQTT), or block the reader (default for stdin).")
@click.option("--health-interval-s", type=FiniteFloatRange(min=0), default=1.0, show_default=True,
              help="Period of the health/metrics message (0: none).")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes (MQTT input with --registry): the cameras are split over them. Default: "
                   "min(cores - 1, cameras) with MQTT input and a registry (1 on a 2-core machine), else 1.")
@click.option("--client-id", default=None, help="MQTT client id (persistent session; default footprint-uq-serve-PID).")
@click.option("--heading-offset-deg", type=FINITE, default=0.0, show_default=True, metavar="D",
              help="Compass bearing of the world +y axis (V2X fields, message east/north offsets).")
@click.option("--origin-lat", type=LATITUDE_DEG, default=None, metavar="LAT",
              help="WGS84 latitude of the world origin.")
@click.option("--origin-lon", type=LONGITUDE_DEG, default=None, metavar="LON",
              help="WGS84 longitude of the world origin.")
@click.option("--confidence", type=FiniteFloatRange(0, 1, min_open=True, max_open=True), default=0.95,
              show_default=True, help="Probability of the semi_major_m/semi_minor_m ellipse.")
@click.option("--contact", type=click.Choice(list(CONTACT_MODES)), default="bottom-centre", show_default=True,
              help="Ground contact of 2D boxes.")
@click.option("--allow-outside-image", is_flag=True, help="Let corners outside the image enter the centre.")
@click.option("--station-id", type=click.IntRange(0, 4294967295), default=None,
              help="StationId of the messages (one camera; default: CRC-32 of the camera id); with --cp-service the "
                   "unit's CPMs and SDSMs (default: CRC-32 of the sorted camera ids joined by commas).")
@click.option("--uper-encoder", type=click.Choice(["fast", "asn1tools"]), default="fast", show_default=True,
              help="CPM UPER writer: the direct writer, or asn1tools (same bytes, ~6 ms per 100 objects).")
@click.option("--linearity/--no-linearity", default=True, show_default=True,
              help="Add per object nonlinearity (predicted relative error of the linear sigma_major_m, worst "
                   "ground-contact point) and linear_ok, as map and objects do; costs ~1.7 ms per 100 points "
                   "(--no-linearity: without).")
@click.option("--linear-threshold", type=FiniteFloatRange(min=0, min_open=True), default=None, metavar="E",
              help="linear_ok is nonlinearity <= E (default 0.05).")
@click.option("--tracks", is_flag=True,
              help="Track each camera's objects by object_id and add their velocity, speed, heading, yaw, their "
                   "sigmas and age (docs/service.md); frames of a camera must come in time order. A budget with a "
                   "motion section (calibrate motion) sets the motion model per class (docs/motion-fit.md).")
@click.option("--motion-window-s", "motion_window_s", type=FiniteFloatRange(min=0), default=DEFAULT_WINDOW_S,
              show_default=True,
              metavar="S", help="With --tracks: window of the on-line check of the motion model per camera and class "
                                "(NIS; health record motion_consistency, docs/motion-fit.md); 0: no check.")
@click.option("--cpm-cdd", type=click.Choice(list(CDD_RELEASES)), default=DEFAULT_CDD, show_default=True,
              help="ETSI-ITS-CDD release of the CPM (2.2.1 also covers 2.4.1); receivers decode only the release "
                   "they compiled (docs/service.md).")
@click.option("--queue-depth", type=click.IntRange(min=1), default=QUEUE_DEPTH, show_default=True, metavar="N",
              help="Frames pending per camera: a burst of up to N frames is processed, not replaced (newest).")
@click.option("--max-frame-bytes", type=click.IntRange(min=1), default=MAX_FRAME_BYTES, show_default=True,
              metavar="B", help="A larger frame (MQTT payload or stdin line) is refused with an error record.")
@click.option("--v2x-policy", type=click.Choice(list(V2X_POLICIES)), default="sampled", show_default=True,
              help="What the V2X fields encode where an object's centre is not linear_ok (far objects): "
                   "docs/uncertainty-model.md; each object's record names it (v2x_source, v2x_cov_m2).")
@click.option("--class-names", "class_names", default=None, metavar="coco|coco91|mot|FILE",
              help="Integer class ids (\"class\": 2) -> names: a built-in map (coco: the 80 COCO names of YOLO / "
                   "ultralytics models by index; coco91: by COCO category id; mot: MOTChallenge), an ultralytics "
                   "data.yaml (names:), a JSON list / mapping / COCO dataset (categories), or a text file of one "
                   "name per line. Without it an integer class is that detection's error entry.")
@click.option("--unknown-class", type=click.Choice(UNKNOWN_POLICIES), default="error", show_default=True,
              help="With --class-names: a class id without a name is that detection's error entry, or the class "
                   "'unknown'.")
@click.option("--record", type=click.Choice(["compact", "full"]), default=None,
              help="Record layout: 'compact' (default with --output mqtt: per object id, class, status, position, "
                   "cov_m2, message id and motion; the CPM as UPER bytes on <prefix>/<camera_id>/cpm) or 'full' "
                   "(default on stdout: every field, the CPM as JSON and UPER hex, the SDSM). docs/service.md.")
@click.option("--cp-service", "cp_service", is_flag=True,
              help="The roadside unit's Collective Perception service: every camera's tracks fused into one object "
                   "list, CPMs by ETSI TS 103 324's generation and inclusion rules (segmented, with Sensor Information "
                   "and perception regions), one SDSM per event; MQTT <prefix>/rsu/cpm, /sdsm, /events, or "
                   "'cp_event' JSON lines on stdout. Needs --tracks; one process (--workers 1). docs/service.md.")
@click.option("--t-gen-cpm-ms", type=click.IntRange(100, 1000), default=None, metavar="MS",
              help="With --cp-service: T_GenCpm, the generation event period (100..1000 ms; default 100).")
@click.option("--cpm-max-bytes", type=click.IntRange(min=64), default=None, metavar="B",
              help="With --cp-service: a CPM larger than B bytes of UPER is split into segments (default 1100).")
@click.option("--region-max-semi-major-m", type=FiniteFloatRange(min=0, min_open=True), default=None, metavar="M",
              help="With --cp-service: each camera's perception region is where its 95 % position ellipse's "
                   "semi-major axis is <= M metres (default 1.0).")
@click.option("--per-camera-output/--no-per-camera-output", default=None,
              help="With --cp-service: write every camera frame's record too (default: yes; a debugging output).")
@pose_options
def serve_cmd(camera_path, budget_spec, registry, camera_id, input_, mqtt, output, input_prefix, output_prefix,
              policy, health_interval_s, workers, client_id, heading_offset_deg, origin_lat, origin_lon, confidence,
              contact, allow_outside_image, station_id, uper_encoder, linearity, linear_threshold, cpm_cdd, v2x_policy,
              queue_depth, max_frame_bytes, tracks, class_names, unknown_class, record, motion_window_s, cp_service,
              t_gen_cpm_ms, cpm_max_bytes, region_max_semi_major_m, per_camera_output, pose):
    """Edge service: detector frames in, positions with uncertainty and V2X messages (CPM, SDSM) out.

    One output record per frame (or an error record), a health record every second;
    SIGTERM drains and exits 0.  See docs/service.md.
    """
    if pose is not None and camera_path is None:
        raise InputError("--pose-file/--height-m", pose, "--camera too (a registry's camera files hold the poses)")
    if class_names is not None:
        load_class_names(class_names)  # a bad names file: one line, exit 2, before the service starts
    elif unknown_class != "error":
        raise InputError("--unknown-class", unknown_class, "--class-names too (the policy of the names map's "
                         "unnamed ids)")
    cp = _cp_options(cp_service, tracks, t_gen_cpm_ms, cpm_max_bytes, region_max_semi_major_m, per_camera_output)
    if budget_spec is not None:
        msg = budget_notice(load_budget(budget_spec))
        if msg is not None:
            warn(msg)
    sys.exit(run(camera=camera_path, pose=pose, budget=budget_spec, registry=registry, camera_id=camera_id,
                 heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat, origin_lon_deg=origin_lon,
                 confidence=confidence, contact=contact, allow_outside_image=allow_outside_image,
                 station_id=station_id, uper_encoder=uper_encoder, linearity=linearity,
                 linear_threshold=linear_threshold, workers=workers, cpm_cdd=cpm_cdd, v2x_policy=v2x_policy,
                 queue_depth=queue_depth, max_frame_bytes=max_frame_bytes, tracks=tracks, class_names=class_names,
                 unknown_class=unknown_class,
                 record=record, consistency_window_s=as_float("--motion-window-s", motion_window_s, nonnegative=True),
                 input=input_ if input_ is not None else (None if mqtt else "-"), mqtt=mqtt, output=output,
                 input_prefix=input_prefix, output_prefix=output_prefix, policy=policy,
                 health_interval_s=health_interval_s, client_id=client_id, cp_service=cp))


def _cp_options(cp_service: bool, tracks: bool, t_gen_cpm_ms, cpm_max_bytes, region_max_semi_major_m,
                per_camera_output) -> CpServeOptions | None:
    """The options of ``--cp-service`` (None without it); an option of it given alone, or ``--cp-service`` without
    ``--tracks``, is one line."""
    given = {"--t-gen-cpm-ms": t_gen_cpm_ms, "--cpm-max-bytes": cpm_max_bytes,
             "--region-max-semi-major-m": region_max_semi_major_m, "--per-camera-output": per_camera_output}
    if not cp_service:
        for name, v in given.items():
            if v is not None:
                raise InputError(name, v, "--cp-service too (an option of the roadside unit's CP service)")
        return None
    if not tracks:
        raise InputError("--cp-service", "without --tracks", "--tracks too (the CP service fuses the cameras' tracks)")
    d = CpServeOptions()
    return CpServeOptions(d.t_gen_cpm_ms if t_gen_cpm_ms is None else t_gen_cpm_ms,
                          d.cpm_max_bytes if cpm_max_bytes is None else cpm_max_bytes,
                          d.region_max_semi_major_m if region_max_semi_major_m is None else region_max_semi_major_m,
                          True if per_camera_output is None else per_camera_output)
