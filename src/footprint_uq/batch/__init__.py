"""Batch footprints: detections files in, footprint files out (``footprint-uq objects``).

* :func:`process_table` -- one table (a frame, a chunk, a partition) -> footprint table;
* :func:`process_file` -- a CSV / JSON Lines / Parquet file, streamed in chunks, -> CSV /
  JSON Lines / Parquet / GeoJSON, with a :class:`Summary`;
* :mod:`footprint_uq.batch.fleet` -- many cameras, a Parquet dataset, optionally on Dask.

Columns and row accounting: ``docs/batch.md`` and :mod:`footprint_uq.batch.schema`.
"""

from .process import BatchProcessor, Summary, process_file, process_table

__all__ = ["BatchProcessor", "Summary", "process_file", "process_table"]
