"""Fleet batch: a Parquet dataset of detections from many cameras, in-process or on Dask.

Input
-----
* a **Parquet dataset**: a folder of ``.parquet`` files, optionally hive-partitioned
  (``camera_id=cam07/date=2024-05-01/part-0.parquet``); the camera of a row is its
  ``camera_id`` column or partition key; other columns as in :mod:`footprint_uq.batch.schema`;
* a **camera registry** (:func:`load_registry`, from :mod:`footprint_uq.io.registry`): camera id ->
  camera, budget and optional heading offset / geodetic origin.

Work
----
One task per input file (:func:`plan`).  :func:`process_partition` -- the one
implementation of the per-partition work, used by both paths -- streams its file in
chunks, groups the rows by camera, runs each camera's :class:`~.process.BatchProcessor`
and writes ``out/camera_id=<id>/<input sub-path>`` (the input's other partition folders
kept), through a temporary name renamed at the end, so a retried task overwrites
rather than duplicates.  It returns a small per-camera summary.  :func:`process_fleet`
runs the tasks in this process (no scheduler) or on Dask (``scheduler=`` an address or
``workers=`` N for a local cluster), with ``retries``.

Row accounting
--------------
Every input row appears once in the output with ``source`` (the input file, relative to
the dataset root) and ``row`` (0-based row in that file): ``(source, row)`` identifies it.
Rows whose ``camera_id`` is missing or not in the registry are error rows (under
``camera_id=__unknown__`` when missing).  The summary (``out/_summary.json``) gives, per
camera and in total, rows in / out / ok / partial / error, with rows_in == rows_out ==
ok + partial + error.
"""

from __future__ import annotations

import json
import os
import sys
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from tqdm import tqdm

from .._files import require_regular
from ..errors import ConfigError, InputError
from ..io.atomic import (
    atomic_write_text,
    clean_temporaries,
    commit,
    discard,
    path_component,
    recover_folder,
    remove_tree,
    swap_in_folder,
    temp_path,
)
from ..io.registry import RegistryEntry, load_registry
from . import schema as S
from .process import BatchProcessor, Summary, prefetch
from .readers import coerce_table, iter_parquet_tables, open_parquet
from .writers import parquet_options

__all__ = ["RegistryEntry", "load_registry", "plan", "Task", "process_partition", "process_fleet", "FleetSummary",
           "UNKNOWN_CAMERA", "require_dask"]

#: output folder name of rows without a camera_id
UNKNOWN_CAMERA = "__unknown__"
#: longest folder name of a camera's partition, bytes (``camera_id=`` + the percent-encoded id; the usual
#: file-system limit is 255): a longer id's rows are error rows in the unknown camera's partition
MAX_PARTITION_NAME_BYTES = 255
#: the lock file beside ``--out`` that keeps a second job off the same output folder
LOCK_SUFFIX = ".lock"
_PROCESSORS: dict = {}  # per-process cache of BatchProcessors (Dask workers keep theirs between tasks)


def require_dask():
    """Import dask.distributed or raise a one-line ConfigError saying how to install it."""
    try:
        import dask  # noqa: F401
        import distributed
    except ImportError:
        raise ConfigError("--scheduler/--workers", "dask not installed",
                          "the optional dependency: pip install 'footprint-uq[dask]' "
                          "(dask[distributed,dataframe])") from None
    return distributed


# -- planning ------------------------------------------------------------------------------------
@dataclass
class Task:
    """One partition: an input file and everything needed to process it (picklable)."""

    index: int
    path: str
    rel: str
    out_dir: str
    cameras: dict
    options: dict
    chunk_rows: int
    compression: str | None
    partition_keys: dict = field(default_factory=dict)
    threads: int | None = 1  # kernel threads per task: 1 on Dask workers, None (up to 2) in-process
    template: RegistryEntry | None = None  # processes the rows of unknown cameras (all error rows)
    out_rel: str = ""  # output path under camera_id=<id>/ (unique among the tasks)
    fsync: bool = True  # durable outputs (io.atomic.commit)


def _hive_keys(rel: str) -> dict:
    keys = {}
    for part in Path(rel).parent.parts:
        if "=" in part:
            k, v = part.split("=", 1)
            keys[k] = v
    return keys


def plan(dataset, out_dir, registry: dict, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS,
         compression: str | None = "auto", fsync: bool = True, **options) -> list[Task]:
    """Tasks (one per Parquet file under ``dataset``, sorted by path)."""
    root = Path(dataset)
    if root.is_file():
        files = [root]
        root = root.parent
    elif root.is_dir():
        files = sorted(f for f in root.rglob("*") if not f.is_dir() and f.suffix.lower() in (".parquet", ".pq")
                       and not any(part.startswith((".", "_")) for part in f.relative_to(root).parts))
        for f in files:  # a FIFO / device named .parquet in the dataset: refused by name, never skipped silently
            require_regular(f, f"detections: {f.relative_to(root).as_posix()}", "Parquet needs a seekable file")
    else:
        raise InputError("detections", str(dataset), "a Parquet file or a folder of Parquet files")
    if not files:
        raise InputError("detections", str(dataset), "a folder holding .parquet files")
    out = Path(out_dir)
    if out.resolve() == root.resolve() or root.resolve() in out.resolve().parents:
        raise InputError("out", str(out_dir), "a folder outside the detections dataset")
    template = next(iter(registry.values()))
    tasks, only = [], []
    for i, f in enumerate(files):
        rel = f.relative_to(root).as_posix()
        keys = _hive_keys(rel)
        cid = keys.get("camera_id")
        # a camera_id folder: ship only that camera (a file may still name others in a column: then all)
        cams, one = registry, None
        if cid is not None and not _has_camera_column(f):
            cams, one = ({cid: registry[cid]} if cid in registry else {}), cid
        tasks.append(Task(i, str(f), rel, str(out), cams, dict(options), int(chunk_rows), compression, keys,
                          template=template, fsync=bool(fsync)))
        only.append(one)
    # two inputs that may write the same camera to the same path (they differ only by a camera_id
    # folder, and one holds a camera_id column): number their outputs
    by_path: dict[str, list[int]] = {}
    for t in tasks:
        by_path.setdefault(_strip_camera(t.rel), []).append(t.index)
    for path, idx in by_path.items():
        clash = len(idx) > 1 and (any(only[i] is None for i in idx) or len({only[i] for i in idx}) < len(idx))
        for i in idx:
            tasks[i].out_rel = path[:-len(".parquet")] + f".f{i}.parquet" if clash else path
    return tasks


def _has_camera_column(path) -> bool:

    return "camera_id" in pq.read_schema(path).names


# -- the per-partition work (one implementation for every path) --------------------------------------
def _processor(entry: RegistryEntry, options: dict, names: list, id_fields: list, threads: int | None = 1
               ) -> BatchProcessor:
    """The (cached) processor of one camera for one input layout."""
    opts = dict(options)
    if entry.heading_offset_deg is not None:
        opts["heading_offset_deg"] = entry.heading_offset_deg
    if entry.origin_lat_deg is not None:
        opts["origin_lat_deg"], opts["origin_lon_deg"] = entry.origin_lat_deg, entry.origin_lon_deg
    key = (entry.camera_id, id(entry.camera), id(entry.budget), json.dumps(opts, sort_keys=True, default=str),
           tuple(names), tuple(str(f) for f in id_fields), threads)
    bp = _PROCESSORS.get(key)
    if bp is None:
        bp = BatchProcessor(entry.camera, entry.budget, threads=threads, **opts)
        bp.resolve(names, id_fields)
        if len(_PROCESSORS) > 256:
            _PROCESSORS.clear()
        _PROCESSORS[key] = bp
    return bp


def _strip_camera(rel: str) -> str:
    """``rel`` without its ``camera_id=`` folders, with the ``.parquet`` extension."""
    p = Path(rel)
    parts = [x for x in p.parent.parts if not x.startswith("camera_id=")]
    return Path(*parts, p.stem + ".parquet").as_posix()


def _partition_name(camera_id: str) -> str:
    return f"camera_id={path_component(camera_id)}"


def _too_long(camera_id: str) -> bool:
    """The id's partition folder name would exceed :data:`MAX_PARTITION_NAME_BYTES`."""
    return len(_partition_name(camera_id).encode()) > MAX_PARTITION_NAME_BYTES


def _route_long_ids(cid: pa.Array) -> tuple[pa.Array, pa.Array | None]:
    """``(cid, original)``: ids too long for a folder name replaced by :data:`UNKNOWN_CAMERA` (their rows become
    error rows), and the original ids (None when none was too long)."""
    long_ids = [c for c in pc.unique(cid).to_pylist() if c is not None and _too_long(c)]
    if not long_ids:
        return cid, None
    return pc.if_else(pc.is_in(cid, value_set=pa.array(long_ids, pa.string())), UNKNOWN_CAMERA, cid), cid


def _unknown_reasons(original: pa.Array | None, sel: np.ndarray) -> list[str]:
    """Per row of the unknown camera's rows ``sel``: why (no camera_id, or one too long for a folder name)."""
    if original is None:
        return ["missing camera_id"] * sel.size
    out = []
    for c in original.take(pa.array(sel)).to_pylist():
        if c == UNKNOWN_CAMERA:
            out.append("missing camera_id")
        else:
            n = len(_partition_name(c).encode())
            out.append(f"camera_id {c[:24]!r}... ({len(c)} characters) too long for a folder name: {n} bytes "
                       f"percent-encoded, at most {MAX_PARTITION_NAME_BYTES}")
    return out


def _out_path(task: Task, camera_id: str) -> Path:
    """``out/camera_id=<id>/<rel>`` with the id percent-encoded (:func:`~footprint_uq.io.atomic.path_component`).

    The id comes from data: encoded, ``a/../../x`` stays one folder name inside ``out``
    (pyarrow's hive partitioning decodes it back: ``segment_encoding="uri"``).
    """
    return Path(task.out_dir, _partition_name(camera_id), task.out_rel or _strip_camera(task.rel))


class _CameraWriters:
    """One Parquet file per camera of a partition: written under temporary names in a background thread
    (one write in flight, as process_file), renamed into place together by :meth:`commit`."""

    def __init__(self, task: Task):
        self.task = task
        self.writers: dict[str, tuple] = {}  # camera_id -> (ParquetWriter, temporary path, final path)
        self.counts: dict[str, Summary] = {}
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="footprint-uq-writer")
        self.pending = None

    def write(self, cam_id: str, out: pa.Table, n_in: int) -> None:
        """Queue ``out`` (footprints of ``n_in`` input rows of ``cam_id``) for writing; count it."""
        if cam_id not in self.writers:
            path = _out_path(self.task, cam_id)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = temp_path(path)
            opts = parquet_options(out.schema, self.task.compression)
            self.writers[cam_id] = (pq.ParquetWriter(tmp, out.schema, **opts), tmp, path)
            self.counts[cam_id] = Summary()
        if self.pending is not None:
            self.pending.result()
        self.pending = self.pool.submit(self.writers[cam_id][0].write_table, out)
        self.counts[cam_id].add_table(out, n_in)

    def commit(self) -> list[str]:
        """Finish the writes and rename every file into place; returns their paths relative to the output."""
        if self.pending is not None:
            self.pending.result()
        for w, tmp, path in self.writers.values():
            w.close()
            commit(tmp, path, fsync=self.task.fsync)  # a retried task replaces its files, never duplicates them
        self.pool.shutdown()
        return [Path(p).relative_to(self.task.out_dir).as_posix() for _, _, p in self.writers.values()]

    def abort(self) -> None:
        """Wait for the write in flight, then drop every temporary file."""
        self.pool.shutdown(wait=True)
        for w, tmp, _ in self.writers.values():
            try:
                w.close()
            except Exception:  # noqa: BLE001 - the file is dropped: its close error does not matter
                pass
            finally:
                discard(tmp)


def _chunk_camera_ids(t: pa.Table, cam_in_file: bool, part_cam: str | None):
    """A chunk with its ``camera_id`` column set (file column, else the partition's, else unknown).

    Returns ``(table, camera ids, original ids of the ids too long to route (or None))``.
    """
    n = t.num_rows
    if cam_in_file:
        cid = pc.cast(t.column("camera_id"), pa.string()).combine_chunks()
        if part_cam is not None:
            cid = pc.fill_null(cid, part_cam)
        t = t.drop_columns(["camera_id"])
    else:
        cid = pa.nulls(n, pa.string()) if part_cam is None else pc.cast(
            pa.DictionaryArray.from_arrays(pa.array(np.zeros(n, np.int32)), pa.array([part_cam])), pa.string())
    cid, original = _route_long_ids(pc.fill_null(cid, UNKNOWN_CAMERA))
    return t.append_column("camera_id", cid), cid, original


def _process_camera(task: Task, cam_id: str, sub: pa.Table, rows: np.ndarray, sub_pre, original, sel, template,
                    probe: list, id_fields: list) -> pa.Table:
    """Footprints of one camera's rows of a chunk, with their ``source`` file; unknown cameras give error rows."""
    entry = task.cameras.get(cam_id)
    if entry is None:
        sub_pre = (_unknown_reasons(original, sel) if cam_id == UNKNOWN_CAMERA
                   else ["camera_id not in the registry"] * sel.size)
        bp = template
    else:
        bp = _processor(entry, task.options, probe, id_fields, task.threads)
    if cam_id == UNKNOWN_CAMERA:
        sub = sub.set_column(sub.column_names.index("camera_id"), "camera_id", pa.nulls(sub.num_rows, pa.string()))
    out = bp.process(sub, rows=rows, pre_errors=sub_pre)
    m = out.num_rows
    src = pa.DictionaryArray.from_arrays(pa.array(np.zeros(m, np.int32)), pa.array([task.rel]))
    out = out.append_column(pa.field("source", pa.string()), pc.cast(src, pa.string()))
    return _normalise(out)


def process_partition(task: Task) -> dict:
    """Process one input file: write its footprints per camera, return the per-camera counts.

    Returns
    -------
    dict: ``{"index", "rel", "files": [...], "cameras": {camera_id: Summary.to_dict() counts}, "elapsed_s"}``
    """

    t0 = time.perf_counter()
    pf = open_parquet(task.path, f"detections file {task.rel}")
    names = list(pf.schema_arrow.names)
    cam_in_file = "camera_id" in names
    part_cam = task.partition_keys.get("camera_id")
    probe = list(dict.fromkeys(names + ["camera_id"]))
    id_fields = _id_fields(pf.schema_arrow)
    tmpl_entry = task.template if task.template is not None else next(iter(task.cameras.values()))
    template = _processor(tmpl_entry, task.options, probe, id_fields, task.threads)
    numeric = S.numeric_input_columns(template.box_type, names)
    read_cols = [c for c in dict.fromkeys([c for c in S.ID_COLUMNS if c in names] + list(numeric))]
    start = 0
    # read ahead and write in background threads, as process_file
    tables = prefetch(iter_parquet_tables(pf, read_cols, task.chunk_rows, use_threads=False, where=task.path), 1)
    out = _CameraWriters(task)
    try:
        for t in tables:
            n = t.num_rows
            rows = np.arange(start, start + n, dtype=np.int64)
            start += n
            t, cid, original = _chunk_camera_ids(t, cam_in_file, part_cam)
            t, pre = coerce_table(t, numeric)
            cams = sorted(pc.unique(cid).to_pylist())
            for cam_id in cams:
                if len(cams) == 1:
                    sel, sub = np.arange(n), t
                else:
                    mask = pc.equal(cid, cam_id)
                    sel = np.flatnonzero(mask.to_numpy(zero_copy_only=False))
                    sub = t.filter(mask)
                sub_pre = None if pre is None else [pre[i] for i in sel]
                fp = _process_camera(task, cam_id, sub, rows[sel], sub_pre, original, sel, template, probe, id_fields)
                out.write(cam_id, fp, sel.size)
        files = out.commit()
    except BaseException:
        out.abort()
        raise
    return {"index": task.index, "rel": task.rel, "files": files, "rows_in": start,
            "cameras": {k: _counts(v) for k, v in out.counts.items()}, "elapsed_s": time.perf_counter() - t0}


def _id_fields(schema: pa.Schema) -> list[pa.Field]:
    """Output id fields: camera_id as text, the others with their Parquet types."""
    f = [pa.field("camera_id", pa.string())]
    return f + [schema.field(c) for c in S.ID_COLUMNS if c != "camera_id" and c in schema.names]


def _normalise(t: pa.Table) -> pa.Table:
    """Status/reason as plain strings: every output file of the fleet has the same schema."""
    cols = [pc.cast(c, pa.string()) if pa.types.is_dictionary(c.type) else c for c in t.columns]
    return pa.Table.from_arrays(cols, names=t.column_names)


def _counts(s: Summary) -> dict:
    return {"rows_in": s.rows_in, "rows_out": s.rows_out, "rows_ok": s.rows_ok, "rows_partial": s.rows_partial,
            "rows_error": s.rows_error, "reasons": dict(s.reasons)}


# -- driver ---------------------------------------------------------------------------------------
@dataclass
class FleetSummary:
    """Per-camera and total row accounting of a fleet job."""

    cameras: dict = field(default_factory=dict)  # camera_id -> Summary
    files: list = field(default_factory=list)
    elapsed_s: float = 0.0
    info: dict = field(default_factory=dict)

    def add(self, part: dict) -> None:
        for cid, c in part["cameras"].items():
            s = self.cameras.setdefault(cid, Summary())
            s.merge(Summary(c["rows_in"], c["rows_out"], c["rows_ok"], c["rows_partial"], c["rows_error"],
                            dict(c["reasons"])))
        self.files += part["files"]

    @property
    def total(self) -> Summary:
        t = Summary()
        for s in self.cameras.values():
            t.merge(s)
        t.elapsed_s = self.elapsed_s
        return t

    # the single-file Summary interface used by the CLI
    def text(self) -> str:
        return self.total.text() + f" over {len(self.cameras)} cameras"

    @property
    def rows_in(self):
        return self.total.rows_in

    @property
    def rows_out(self):
        return self.total.rows_out

    @property
    def rows_error(self):
        return self.total.rows_error

    @property
    def consistent(self) -> bool:
        return all(s.consistent for s in self.cameras.values())

    def to_dict(self) -> dict:
        tot = self.total.to_dict()
        return {**tot, "consistent": self.consistent,
                "cameras": {k: {**_counts(v), "consistent": v.consistent} for k, v in sorted(self.cameras.items())},
                "files": sorted(self.files), **self.info}


def process_fleet(registry, detections, out_dir, *, budget=None, scheduler=None, workers: int | None = None,
                  retries: int = 2, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, compression: str | None = "auto",
                  progress: bool | None = None, client=None, overwrite: bool = False, fsync: bool = True,
                  **options) -> FleetSummary:
    """Footprints of a multi-camera Parquet dataset, in this process or on a Dask cluster.

    Parameters
    ----------
    registry : path or dict camera_id -> RegistryEntry  (:func:`load_registry`)
    detections : folder (or one file) of Parquet detections
    out_dir : output folder (partitioned Parquet ``camera_id=<id>/...``, plus ``_summary.json``)
    budget : default budget for registry entries without one
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    workers : int, optional
        Start a local Dask cluster of this many worker processes (one thread each).
    retries : int
        Dask retries of a failed partition (its output files are rewritten, never duplicated).
    client : dask.distributed.Client, optional
        Use this client (tests, notebooks) instead of ``scheduler``/``workers``.
    overwrite : bool
        Replace a non-empty ``out_dir`` (refused otherwise).  The job is built in a hidden
        folder next to ``out_dir`` (``.<name>.tmp-<hex>``) and swapped in at the end, summary
        included: a failed or killed job leaves the previous output as it was, a finished one
        leaves only its own files (no stale partitions of an earlier run).  A symbolic link as
        ``out_dir`` is refused (replacing and cleaning it would act on its target), and one job at a
        time writes to a folder: a lock file ``.<name>.lock`` beside it refuses a second one.
    fsync : bool
        Make the outputs durable (default): every file and the folders are fsynced before they are renamed
        into place.  False only renames (never partial for a killed job, not durable across a power loss;
        :func:`footprint_uq.batch.process.process_file`).
    **options
        :class:`~footprint_uq.batch.process.BatchProcessor` options (``box_type``, ``contact``,
        ``confidence``, ``heading_offset_deg``, ``origin_lat_deg``, ``origin_lon_deg``,
        ``corners``, ``allow_outside_image``); the registry's per-camera heading/origin win.

    Returns
    -------
    FleetSummary
    """


    t0 = time.perf_counter()
    reg = registry if isinstance(registry, dict) else load_registry(registry, budget=budget)
    geo = [e.origin_lat_deg is not None or options.get("origin_lat_deg") is not None for e in reg.values()]
    if any(geo) and not all(geo):
        raise ConfigError("registry", "origin given for some cameras only",
                          "an origin for every camera (registry origin_lat_deg/origin_lon_deg, or --origin-lat/lon)")
    options = {k: v for k, v in options.items() if v is not None or k in ("origin_lat_deg", "origin_lon_deg")}
    out = Path(out_dir)
    _check_out(out, detections, overwrite)
    with _OutLock(out):
        return _run_fleet(reg, detections, out, out_dir, t0, chunk_rows=chunk_rows, compression=compression,
                          fsync=fsync, scheduler=scheduler, workers=workers, retries=retries, progress=progress,
                          client=client, options=options)


def _run_fleet(reg, detections, out: Path, out_dir, t0, *, chunk_rows, compression, fsync, scheduler, workers,
               retries, progress, client, options) -> FleetSummary:
    """The body of :func:`process_fleet` once ``out`` is checked and locked."""
    staging = temp_path(out)
    tasks = plan(detections, staging, reg, chunk_rows=chunk_rows, compression=compression, fsync=fsync, **options)
    recover_folder(out)  # a killed job's staging folder (or, killed mid-swap, its previous output back)
    clean_temporaries(out)
    staging.mkdir(parents=True)
    summ = FleetSummary()
    show = sys.stderr.isatty() if progress is None else bool(progress)
    bar = tqdm(total=len(tasks), unit="file", disable=not show, file=sys.stderr, desc="partitions", leave=False)
    fn = process_partition  # module global: one implementation for both paths
    own = None
    done = False
    try:
        if client is None and scheduler is None and workers is None:
            for t in tasks:
                t.threads = None
                summ.add(fn(t))
                bar.update(1)
            mode = "in-process"
        else:
            distributed = require_dask()
            if client is None:
                if scheduler is not None:
                    client = own = distributed.Client(scheduler)
                else:
                    cluster = distributed.LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                                       dashboard_address=":0")
                    client = own = distributed.Client(cluster)
            futs = client.map(fn, tasks, retries=int(retries), pure=False, key=[f"footprints-{uuid.uuid4().hex[:6]}-"
                                                                              f"{t.index}" for t in tasks])
            for fut in distributed.as_completed(futs):
                summ.add(fut.result())
                bar.update(1)
            mode = "dask"
        done = True
    finally:
        if not done:
            remove_tree(staging)
        bar.close()
        if own is not None:
            cluster = getattr(own, "cluster", None)
            own.close()
            if cluster is not None:
                cluster.close()
    summ.elapsed_s = time.perf_counter() - t0
    summ.info = {"detections": str(detections), "out": str(out_dir), "partitions": len(tasks), "mode": mode,
                 "chunk_rows": int(chunk_rows), "options": {k: v for k, v in options.items()}, "fsync": bool(fsync),
                 "elapsed_s": round(summ.elapsed_s, 6)}
    try:
        if not summ.consistent:  # pragma: no cover - a bug, not bad input
            raise RuntimeError(f"row accounting broken: {summ.text()}")
        clean_temporaries(staging)  # files of killed or retried attempts
        atomic_write_text(staging / "_summary.json", json.dumps(summ.to_dict(), indent=2, default=str) + "\n",
                          fsync=fsync)
        swap_in_folder(staging, out, fsync=fsync)
    except BaseException:
        remove_tree(staging)
        raise
    return summ


class _OutLock:
    """An exclusive lock on ``--out`` for one job: the file ``.<name>.lock`` beside it, created with O_EXCL (a
    second job on the same folder is refused, naming the first's pid), removed at the end.  A lock whose
    process is gone (a killed job) is taken over."""

    def __init__(self, out: Path):
        parent = out.parent if str(out.parent) else Path(".")
        self.path = parent / f".{out.name}{LOCK_SUFFIX}"
        self.out = out

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                pid = self._holder()
                if pid is not None and _alive(pid):
                    raise InputError("out", str(self.out), f"a folder no other job writes to (job {pid} holds "
                                     f"{self.path}; delete that file if no such job runs)") from None
                discard(self.path)  # a killed job's lock
                continue
            with os.fdopen(fd, "w") as f:
                f.write(f"{os.getpid()}\n")
            return self
        raise InputError("out", str(self.out), f"a folder no other job writes to ({self.path} keeps reappearing)")

    def _holder(self) -> int | None:
        try:
            return int(self.path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None

    def __exit__(self, *exc):
        if self._holder() == os.getpid():
            discard(self.path)
        return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - another user's live process
        return True
    return True


def _check_out(out: Path, detections, overwrite: bool) -> None:
    """Refuse an output folder that is a file, a symbolic link (``--overwrite`` would replace and clean
    through it), holds the input, or is not empty (without ``overwrite``)."""
    if out.is_symlink():
        raise InputError("out", str(out), f"a real folder, not a symbolic link (to {os.readlink(out)}): pass the "
                         "folder it points to")
    if out.exists() and not out.is_dir():
        raise InputError("out", str(out), "a folder (this is a file)")
    src = Path(detections)
    if src.exists() and out.exists():
        s, o = src.resolve(), out.resolve()
        if s == o or o in s.parents:
            raise InputError("out", str(out), "a folder that does not hold the detections")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InputError("out", str(out), "an empty or new folder (or --overwrite to replace its contents)")
