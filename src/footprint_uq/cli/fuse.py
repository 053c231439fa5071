"""CLI command ``footprint-uq fuse``: per-camera footprint files in, fused objects out.

Columns and semantics: docs/uncertainty-model.md, section "Multi-camera fusion".

The work is :func:`footprint_uq.batch.fusion_files.fuse_files`; association is by key only
(default ``frame,object_id``: the ids must be shared across cameras, e.g. from a
tracker).  Bad input (files, columns, options) is one line on stderr and exit
status 2 (the group's policy); bad *rows* never stop the job: they are listed in
the sources table with their row number and reason and counted in the summary.
"""

from __future__ import annotations

import click

from ..batch.fusion_files import CAMERA_ID_FROM, DEFAULT_KEY, fuse_files
from .common import FINITE

__all__ = ["fuse_cmd"]


@click.command("fuse")
@click.argument("inputs", nargs=-1, required=True, metavar="INPUT...")
@click.option("--out", "out", required=True, metavar="FILE",
              help="Fused objects: .parquet, .csv or .jsonl (one row per frame and object).")
@click.option("--sources-out", default=None, metavar="FILE",
              help="Per-input-row table (used, reason, d2, flag); default OUT with .sources before the extension.")
@click.option("--camera-id-from", type=click.Choice(list(CAMERA_ID_FROM)), default=None,
              help="Camera of a row: the input's file name (one file per camera) or its camera_id column "
                   "(default: column if every input has one, else filename).")
@click.option("--key", default=",".join(DEFAULT_KEY), show_default=True, metavar="COL[,COL...]",
              help="Association key: rows with equal values are the same object (ids shared across cameras).")
@click.option("--confidence", type=FINITE, default=0.99, show_default=True, metavar="P",
              help="Level of the chi-square consistency tests (per source d^2 and per object).")
@click.option("--ellipse-confidence", type=FINITE, default=0.95, show_default=True, metavar="P",
              help="Probability of the semi_major_m/semi_minor_m ellipse of the fused centre.")
@click.option("--heading-offset-deg", type=FINITE, default=0.0, show_default=True, metavar="D",
              help="Compass bearing of the world +y axis (V2X fields).")
@click.option("--compression", type=click.Choice(["snappy", "zstd", "lz4", "gzip", "none"]), default="snappy",
              show_default=True, help="Parquet compression.")
def fuse_cmd(inputs, out, sources_out, camera_id_from, key, confidence, ellipse_confidence, heading_offset_deg,
             compression):
    """Fuse the footprint centres of objects seen by several cameras (information form).

    INPUT... are footprint files written by `footprint-uq objects` (.csv, .jsonl,
    .parquet), one per camera or with a camera_id column.  Estimates with the same
    key are fused by covariance weighting; each source gets a Mahalanobis d^2 against
    the fused centre and is flagged above the chi-square quantile at --confidence.
    Every input row is accounted for: a summary goes to stderr and to OUT.summary.json.
    """
    keys = tuple(k.strip() for k in key.split(","))
    s = fuse_files(inputs, out, camera_id_from=camera_id_from, key=keys, confidence=confidence,
                   ellipse_confidence=ellipse_confidence, heading_offset_deg=heading_offset_deg,
                   sources_out=sources_out, compression=None if compression == "none" else compression)
    click.echo(f"footprint-uq fuse: {s.text()}; {s.elapsed_s:.2f} s", err=True)
