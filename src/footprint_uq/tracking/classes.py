"""The tracker's motion model per object class, from a budget's ``motion`` section (docs/motion-fit.md).

:func:`tracker_configs` turns the section (:mod:`footprint_uq.uncertainty.motion_section`, written by ``calibrate
motion``) into one :class:`~footprint_uq.tracking.table.TrackerConfig` per class and a default;
:class:`ClassTracks` is one camera's tracks under them: one :class:`~footprint_uq.tracking.table.TrackTable` per
distinct motion model, each object routed by its class.  Without a section (or with one model for every class)
it is exactly one ``TrackTable``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from .table import TrackerConfig, TrackOutput, TrackTable

__all__ = ["tracker_configs", "ClassTracks"]

_MODEL_KEYS = ("accel_psd_m2ps3", "manoeuvre_accel_psd_m2ps3", "quiet_sojourn_s", "manoeuvre_sojourn_s")


def _apply(base: TrackerConfig, entry: dict | None) -> TrackerConfig:
    if not entry:
        return base
    return dataclasses.replace(base, **{k: entry[k] for k in _MODEL_KEYS if k in entry})


def tracker_configs(motion: dict | None, base: TrackerConfig | None = None) -> tuple[TrackerConfig, dict]:
    """``(default, {class: config})`` of a budget's motion section over ``base`` (default
    :class:`~footprint_uq.tracking.table.TrackerConfig`): the section's ``default`` entry replaces the base's
    motion keys, each class entry the default's.  ``motion`` None: ``(base, {})``."""
    base = base or TrackerConfig()
    if not motion:
        return base, {}
    default = _apply(base, motion.get("default"))
    return default, {str(c): _apply(default, e) for c, e in (motion.get("classes") or {}).items()}


class ClassTracks:
    """One camera's tracks with a motion model per object class (:func:`tracker_configs`).

    Objects of classes with the same model share one :class:`~footprint_uq.tracking.table.TrackTable` (classes
    without an entry: the default's); an object's class picks its table in every frame (a detector that changes
    an object's class between two models starts a new track in the other table).  With k > 1 tables the reported
    ``track_id`` is ``k * local_id + table`` (unique within the camera); with one table the table's own ids.

    Parameters
    ----------
    default : TrackerConfig
    per_class : dict class -> TrackerConfig
    rank : int, shared_at : callable, optional
        As :class:`~footprint_uq.tracking.table.TrackTable`.
    """

    def __init__(self, default: TrackerConfig, per_class: dict | None = None, *, rank: int, shared_at=None):
        self.default, self.per_class = default, dict(per_class or {})
        configs = [default] + [c for c in self.per_class.values() if c != default]
        self.configs = list(dict.fromkeys(configs))  # distinct, the default first
        self.tables = [TrackTable(c, rank=rank, shared_at=shared_at) for c in self.configs]
        self._table_of = {cls: self.configs.index(c) for cls, c in self.per_class.items()}
        self.rank, self.shared_at = self.tables[0].rank, shared_at
        self._last_parts: list = []  # the last step's (objects, table) per table (several tables only)
        self._last_n = 0

    @property
    def config(self) -> TrackerConfig:
        """The default class's configuration."""
        return self.default

    def fresh(self) -> ClassTracks:
        """An empty copy (same models, no tracks)."""
        return ClassTracks(self.default, self.per_class, rank=self.rank, shared_at=self.shared_at)

    def warm_up(self) -> None:
        """Load the compiled steps of every table (:meth:`~footprint_uq.tracking.table.TrackTable.warm_up`)."""
        for t in self.tables:
            t.warm_up()

    def table_index(self, classes, n: int) -> np.ndarray:
        """The table of each of n objects from their classes (None or unknown: the default's, 0)."""
        if len(self.tables) == 1:
            return np.zeros(n, np.int64)
        if classes is None or len(classes) != n:
            raise InputError("classes", None if classes is None else len(classes), f"{n} class names, one per object")
        get = self._table_of.get
        return np.fromiter((get(str(c), 0) if c is not None else 0 for c in classes), np.int64, n)

    def step(self, time_s: float, object_ids, classes, xy_m, cov_frame_m2=None, shared_m=None, *,
             cov_m2=None) -> TrackOutput:
        """One frame of n objects with their ``classes`` (n names; None: the default model); the other arguments
        and the result as :meth:`~footprint_uq.tracking.table.TrackTable.step`."""
        if len(self.tables) == 1:
            return self.tables[0].step(time_s, object_ids, xy_m, cov_frame_m2, shared_m, cov_m2=cov_m2)
        # (ids as an int64 array stay one: each table's part of it goes to the table's compiled id look-up)
        int64 = type(object_ids) is np.ndarray and object_ids.dtype == np.int64 and object_ids.ndim == 1
        ids = object_ids if int64 else list(object_ids)
        n = len(ids)
        which = self.table_index(classes, n)
        k = len(self.tables)
        out = TrackOutput.untracked(n)
        self._last_parts, self._last_n = [], n
        for j, table in enumerate(self.tables):
            sel = np.flatnonzero(which == j)  # (every table steps, an empty part included: its clock and deleter)
            self._last_parts.append((sel, table))
            part = [None if a is None else np.asarray(a)[sel] for a in (xy_m, cov_frame_m2, shared_m, cov_m2)]
            o = table.step(time_s, ids[sel] if int64 else [ids[i] for i in sel.tolist()], *part[:3], cov_m2=part[3])
            for f, v in zip(out, o, strict=True):
                f[sel] = v
            out.track_id[sel] = np.where(o.track_id >= 0, o.track_id * k + j, -1)
        return out

    def frame_nis(self) -> np.ndarray:
        """The NIS of the last :meth:`step`'s objects, ``(n,)`` in frame order, each from its table
        (:meth:`~footprint_uq.tracking.table.TrackTable.frame_nis`: NaN where the object updated no track)."""
        if len(self.tables) == 1:
            return self.tables[0].frame_nis()
        out = np.full(self._last_n, np.nan)
        for sel, table in self._last_parts:
            if sel.size:
                out[sel] = table.frame_nis()
        return out
