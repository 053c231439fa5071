"""Batch footprints: detections files in, footprint files out (``footprint-uq objects``).

* :func:`process_table` -- one table (a frame, a chunk, a partition) -> footprint table;
* :func:`process_file` -- a CSV / JSON Lines / Parquet file, streamed in chunks, -> CSV /
  JSON Lines / Parquet / GeoJSON, with a :class:`Summary`;
* :mod:`footprint_uq.batch.fleet` -- many cameras, a Parquet dataset, optionally on Dask;
* :func:`read_detections` -- a detector's files (YOLO, YOLOv5 CSV, COCO, MOTChallenge, a ROS 2 bag:
  :mod:`.formats`) as the canonical table; :func:`footprints_from_supervision` / :func:`footprints_from_xyxy` --
  detections in Python (:mod:`.arrays`).

Columns and row accounting: ``docs/batch.md`` and :mod:`footprint_uq.batch.schema`.
"""

from .arrays import footprints_from_supervision, footprints_from_xyxy
from .formats import open_reader, read_detections
from .process import BatchProcessor, Summary, process_file, process_table

__all__ = ["BatchProcessor", "Summary", "process_file", "process_table", "read_detections", "open_reader",
           "footprints_from_supervision", "footprints_from_xyxy"]
