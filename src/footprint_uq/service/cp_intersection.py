"""The CP basic service over the 3-camera intersection: the seeded run behind its proof and its benchmark.

The three cameras, the traffic and the trackers are :mod:`footprint_uq.tracking.rsu_synthetic`'s
(:func:`~footprint_uq.tracking.rsu_synthetic.camera_frames`); here every camera frame goes through
:meth:`CpBasicService.ingest <footprint_uq.service.cp_service.CpBasicService.ingest>` (stamped on the camera's own
clock, Unix s from :data:`T0_UNIX_S`) and after each unit frame the unit's clock (the true time) polls the service.
Every generation event's objects -- predicted to its referenceTime -- are scored against the truth at that time
(:func:`~footprint_uq.tracking.rsu_synthetic.evaluate`: duplicates, vehicles missing, objects holding two vehicles,
the 95 % ellipse's coverage), and the event's CPMs are counted (segments, bytes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..tracking.rsu_fusion import RsuFusionConfig
from ..tracking.rsu_synthetic import RsuSimResult, camera_frames, evaluate, intersection_cameras, score_positions
from .cp_rules import CpRules
from .cp_service import CpBasicService, CpCamera, CpEvent

__all__ = ["T0_UNIX_S", "CpRunResult", "run_intersection"]

#: the runs' time origin (2024-05-01 12:00 UTC): the service's clock is Unix time
T0_UNIX_S = 1714564800.0


@dataclass
class CpRunResult:
    """What a run of the service did.

    fused : RsuSimResult        the events' object lists against the truth (summed over events)
    events : int                generation events (polls that returned an event)
    events_with_cpm : int       events that sent at least one CPM
    segments : list of int      CPM segments per event that sent any
    segment_bytes : list of int the size of every CPM segment (bytes)
    counts : dict               :meth:`CpBasicService.counts` at the end
    kept : list of CpEvent      the events themselves (``keep_events``)
    ghosts : list of int        per event, its objects farther than 3 m from every vehicle (what a receiver
                                sees: :func:`~footprint_uq.tracking.rsu_synthetic.score_positions`)
    duplicates : list of int    per event, vehicles nearest to 2+ of its objects within 3 m (likewise)
    """

    fused: RsuSimResult = field(default_factory=RsuSimResult)
    events: int = 0
    events_with_cpm: int = 0
    segments: list = field(default_factory=list)
    segment_bytes: list = field(default_factory=list)
    counts: dict = field(default_factory=dict)
    kept: list = field(default_factory=list)
    ghosts: list = field(default_factory=list)
    duplicates: list = field(default_factory=list)


def run_intersection(n_frames: int = 300, *, seed: int = 0, rules: CpRules | None = None,
                     fusion: RsuFusionConfig | None = None, cdd: str | None = None, clock_offset_sigma_s: float = 0.005,
                     keep_events: bool = False, **sim) -> CpRunResult:
    """One seeded run of the service over ``n_frames`` unit frames (module doc); ``sim``: the other options of
    :func:`~footprint_uq.tracking.rsu_synthetic.camera_frames`."""
    names = [f"cam{j}" for j in range(len(intersection_cameras()))]
    svc = CpBasicService([CpCamera(n, j + 1, None, clock_offset_sigma_s=clock_offset_sigma_s)
                          for j, n in enumerate(names)], station_id=1000 + seed, rules=rules, fusion=fusion,
                         **({} if cdd is None else {"cdd": cdd}))
    index = {n: j for j, n in enumerate(names)}
    out = CpRunResult()
    for fr in camera_frames(n_frames, seed=seed, clock_offset_sigma_s=clock_offset_sigma_s, **sim):
        seen: set = set()
        for cf in fr.cameras:
            ff = svc.ingest(names[cf.camera], T0_UNIX_S + cf.stamp_s, cf.tracks,
                            class_id=["car"] * cf.truth_index.size, linear_ok=np.ones(cf.truth_index.size, bool))
            seen.update(cf.truth_index[ff.object_id >= 0].tolist())
        ev = svc.poll(T0_UNIX_S + fr.t_s)
        if ev is None:
            continue
        _score(out, svc, ev, fr, seen, index)
        if keep_events:
            out.kept.append(ev)
    out.counts = svc.counts()
    return out


def _score(out: CpRunResult, svc: CpBasicService, ev: CpEvent, fr, seen: set, index: dict) -> None:
    objs = ev.record["objects"]
    m = len(objs)
    oid = np.array([o["objectId"] for o in objs], np.int64)
    xy = np.array([o["xy_m"] for o in objs], np.float64).reshape(m, 2)
    cov = np.array([o["cov_m2"] for o in objs], np.float64).reshape(m, 2, 2)
    v = np.array([[np.nan, np.nan] if o["v_mps"] is None else o["v_mps"] for o in objs], np.float64).reshape(m, 2)
    pairs = {(index[c], tid): o for (c, tid), o in svc.fusion.pairs().items()}
    t_ref = T0_UNIX_S + fr.t_s
    out.fused.add(evaluate(pairs, fr.track_truth, oid, xy, cov, v, fr.truth_xy, seen,
                           lambda o: svc.fusion.contributions(o, t_ref)))
    ghosts, dups = score_positions(xy, fr.truth_xy)
    out.ghosts.append(ghosts)
    out.duplicates.append(dups)
    out.events += 1
    if ev.segments:
        out.events_with_cpm += 1
        out.segments.append(len(ev.segments))
        out.segment_bytes.extend(len(s) for s in ev.segments)
