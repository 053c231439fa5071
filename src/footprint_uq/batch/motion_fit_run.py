"""``calibrate motion``'s job: a recording of detections in, the budget with a fitted ``motion`` section out.

The recording is streamed chunk by chunk through the batch pipeline with tracks
(:class:`~footprint_uq.batch.process.BatchProcessor`, ``tracks=True``: the readers of ``objects``, their row
accounting, the tracker's association by ``object_id``); after each frame's tracking step the frame goes into its
camera's :class:`~footprint_uq.tracking.motion_fit.MotionBank` (the likelihood of every grid model), and at the end
every class is fitted (:func:`~footprint_uq.tracking.motion_fit.fit_classes`).  Memory is the chunk's plus the
live tracks' bank states, not the recording's.  docs/motion-fit.md.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write_text, check_output_folder, final_paths, output_set
from ..io.camera_files import save_budget
from ..tracking.classes import tracker_configs
from ..tracking.imm_fit import IMM_PARAMETERS, ImmGrid, fit_imm_classes
from ..tracking.motion_fit import MotionBank, MotionGrid, fit_classes
from ..tracking.table import SharedJacobianAt, TrackerConfig
from ..uncertainty.budget import ErrorBudget, load_budget
from . import schema as S
from .process import BatchProcessor, Summary, process_chunk
from .readers import open_detections

__all__ = ["run_motion_fit", "MOTION_FIT_FILES", "MODES"]

#: the job's outputs in its folder
MOTION_FIT_FILES = {"budget": "budget.yaml", "summary": "motion_fit.json"}
#: ``--modes``: one mode only; also the prior's IMM (its quiet density on the grid); also the IMM fitted whole
MODES = ("auto", "one", "imm")
#: bad rows listed by number in ``motion_fit.json`` (all of them are counted by reason)
MAX_BAD_ROWS_LISTED = 1000


class _Banks:
    """One bank per camera, fed by the batch processor's ``track_observer``."""

    def __init__(self, grid: MotionGrid, shared_at):
        self.grid, self.shared_at, self.banks = grid, shared_at, {}
        self.frames = 0

    def __call__(self, camera_id, time_s, classes, out, xy_m, cov_frame_m2, shared_m) -> None:
        bank = self.banks.get(camera_id)
        if bank is None:
            bank = self.banks[camera_id] = MotionBank.from_grid(self.grid, rank=self.shared_at.rank,
                                                                shared_at=self.shared_at)
        bank.observe(time_s, out, classes, xy_m, cov_frame_m2, shared_m)
        self.frames += 1


def _grid(prior: TrackerConfig, q_min: float, q_max: float, per_decade: int, modes: str) -> MotionGrid | ImmGrid:
    if not (0 < q_min < q_max) or per_decade < 2:
        raise InputError("q grid", (q_min, q_max, per_decade), "0 < q_min < q_max and at least 2 points per decade")
    n = int(round(np.log10(q_max / q_min) * per_decade)) + 1
    q = np.geomspace(q_min, q_max, max(n, 4))
    if modes == "imm":  # the IMM's parameters fitted too (tracking/imm_fit.py)
        return ImmGrid(q, prior=prior)
    imm = q[::2] if modes == "auto" and prior.manoeuvre_accel_psd_m2ps3 is not None else np.zeros(0)
    return MotionGrid(q, imm if imm.size >= 4 else np.zeros(0), prior)


def run_motion_fit(camera, budget, detections, out_dir, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS,
                   format_in: str | None = None, box_type: str | None = None, contact: str = "bottom-centre",
                   modes: str = "auto", q_min_m2ps3: float = 1e-4, q_max_m2ps3: float = 100.0, per_decade: int = 6,
                   min_tracks: int = 10, min_updates: int = 300, fsync: bool = True,
                   info: dict | None = None) -> tuple[dict, dict]:
    """Fit the manoeuvre noise per class to a recording; write ``budget.yaml`` (the budget with its ``motion``
    section replaced) and ``motion_fit.json`` (every class's profile and counts) into ``out_dir``, as one set
    (:func:`~footprint_uq.io.atomic.output_set`: built in a hidden folder and swapped in together; ``out_dir`` must
    be new or hold only a previous run's two files, checked before the recording is read).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
        The camera's budget; its ``motion`` section, if any, is the prior (else the tracker's defaults).
    detections : path
        Any file ``objects`` reads, with ``timestamp_s``, ``object_id`` (and ``class``, ``camera_id``).
    modes : {"auto", "one", "imm"}
        "auto": also try the prior's two-mode IMM (kept where it wins, :func:`~footprint_uq.tracking.motion_fit.
        fit_class`); "one": the one-mode model only (half the work); "imm": also fit the IMM's manoeuvre density
        and sojourns (:mod:`footprint_uq.tracking.imm_fit`: 780 IMM members, ~10 x the work of "auto").
    q_min_m2ps3, q_max_m2ps3, per_decade : the grid of densities (log-spaced).
    min_tracks, min_updates : a class with less keeps the prior (status "prior", with the reason).

    Returns
    -------
    summary : dict (also in ``motion_fit.json``); files : dict name -> Path
    """
    t0 = time.perf_counter()
    if modes not in MODES:
        raise InputError("modes", modes, f"one of {MODES}")
    check_output_folder(out_dir, tuple(MOTION_FIT_FILES.values()), "calibrate motion")  # before the long pass
    bud = load_budget(budget)
    prior_default, prior_classes = tracker_configs(bud.motion)
    grid = _grid(prior_default, q_min_m2ps3, q_max_m2ps3, per_decade, modes)
    reader = open_detections(detections, chunk_rows=chunk_rows, format=format_in)
    bp = BatchProcessor(camera, bud, box_type=box_type, contact=contact, tracks=True, linearity=False,
                        v2x_policy="linear")
    names = reader.columns if bp.box_type is not None else reader.family_columns
    bp.resolve(names, reader.id_fields)
    reader.select(S.numeric_input_columns(bp.box_type, names))
    banks = _Banks(grid, SharedJacobianAt(camera, bud))
    bp.track_observer = banks
    summ, bad = Summary(), []
    try:
        for chunk in reader:
            table = process_chunk(bp, chunk)
            summ.add_table(table, chunk.table.num_rows + len(chunk.malformed))
            _bad_rows(table, bad)
    finally:
        bp.close()
    summ.lines_in = reader.lines
    fit = fit_imm_classes if isinstance(grid, ImmGrid) else fit_classes
    section = fit(grid, banks.banks.values(), min_tracks=min_tracks, min_updates=min_updates)
    section = _keep_priors(section, bud.motion, prior_classes)
    section["source"] = f"fitted to {Path(str(detections)).name} ({len(banks.banks)} camera(s), {banks.frames} frames)"
    fitted = ErrorBudget.from_dict({**bud.to_dict(), "motion": section})
    summary = {"detections": str(detections), "rows": summ.to_dict(), "bad_rows": bad[:MAX_BAD_ROWS_LISTED],
               "grid_m2ps3": grid.q_m2ps3.tolist(),
               **_imm_grid(grid), "motion": section,
               "log_likelihood": _profiles(banks), "elapsed_s": time.perf_counter() - t0, **(info or {})}
    with output_set(out_dir, tuple(MOTION_FIT_FILES.values()), "calibrate motion", fsync=fsync) as stage:
        files = {k: stage / v for k, v in MOTION_FIT_FILES.items()}
        save_budget(fitted, files["budget"])
        atomic_write_text(files["summary"], json.dumps(summary, indent=1, allow_nan=False) + "\n", fsync=fsync)
    return summary, final_paths(files, stage, out_dir)


def _imm_grid(grid) -> dict:
    """The IMM members' grid for ``motion_fit.json``: the quiet densities of the prior's IMM (``auto``), or the
    fitted IMM's four axes (``imm``: the log-likelihoods after the one-mode ones, in C order of these axes)."""
    if isinstance(grid, ImmGrid):
        return {"imm_grid": {k: a.tolist() for k, a in zip(IMM_PARAMETERS, grid.axes, strict=True)}}
    return {"imm_grid_m2ps3": grid.imm_q_m2ps3.tolist()}


def _bad_rows(table, bad: list) -> None:
    """Rows of an output table that give no tracked centre (status error / partial), as ``[row, status, reason]``
    (their 0-based row numbers of the recording; they are counted by reason in the summary's ``rows``)."""
    if len(bad) >= MAX_BAD_ROWS_LISTED:
        return
    status = table.column("status").to_pylist()
    idx = [i for i, s in enumerate(status) if s != "ok"][:MAX_BAD_ROWS_LISTED - len(bad)]
    if idx:
        rows, reasons = table.column("row").to_pylist(), table.column("reason").to_pylist()
        bad += [[rows[i], status[i], reasons[i]] for i in idx]


def _keep_priors(section: dict, prior_motion: dict | None, prior_classes: dict) -> dict:
    """Classes of the prior's section that the recording did not show keep their entries."""
    for c, entry in ((prior_motion or {}).get("classes") or {}).items():
        if c not in section["classes"] and c in prior_classes:
            section["classes"][c] = dict(entry)
    return section


def _profiles(banks: _Banks) -> dict:
    """Per camera and class: the grid's log-likelihoods, mean NIS per update and counts (``motion_fit.json``)."""
    out: dict = {}
    for cam, bank in banks.banks.items():
        for c, (ll, nis, n, bad, tracks) in bank.sums().items():
            out.setdefault(str(cam), {})[c or "(no class)"] = {
                "log_likelihood": ll.tolist(), "mean_nis": (nis / max(n, 1)).tolist(), "n_updates": n,
                "n_bad": bad, "n_tracks": tracks}
    return out
