"""Choosing the layout: a discrete stage over a candidate grid, then a continuous refinement.

Objective: the weighted met area ``f(S) = sum_i w_i a_i [sample i meets its zone's requirement]``
of a set ``S`` of camera configurations (at most one per mount), with the fused covariance of every
camera that sees a sample (or, ``fusion=False``, the best single camera), subject to at most
``max_cameras`` cameras and, optionally, a total cost of at most ``max_cost``.

Discrete stage, over the grid of :func:`candidate_grid` (mount x height x camera type x lens x tilt x pan):

* ``greedy``: add the configuration of largest gain (gain per cost under a cost limit) until the
  count or the money runs out or nothing gains; *lazy* evaluation keeps each configuration's last
  gain as an upper bound and re-evaluates only the top of the queue.  Without fusion the objective
  is a weighted coverage, monotone submodular: greedy is within 1 - 1/e of the optimum and the lazy
  bound is exact.  **With fusion it is not submodular**: two cameras can together meet a sample that
  neither meets alone, so a gain can grow as cameras are added; the lazy bound may then be stale and
  greedy carries no guarantee (``lazy=False`` re-evaluates every candidate in every round).  With
  fusion, greedy scores the progress towards the requirement for every pick but the last
  (:func:`greedy`, ``soft``).
* ``milp``: an integer program (:func:`scipy.optimize.milp`, HiGHS) over the same grid, exact for the
  objective in which a sample counts when one camera or the fused pair of two cameras meets it
  (pair variables ``z_ab <= x_a, x_b`` for every pair that meets some sample neither meets alone).
  Samples met only by three or more fused cameras are not in the program (they are counted when the
  chosen layout is evaluated), so for ``max_cameras <= 2`` it is the exact optimum over the grid.
  Its size grows with the square of the grid: meant for small and medium grids.
* ``both``: run both and keep the better layout (by the full objective).
* ``best`` (the default of :func:`plan` and the command): every start it has -- the integer program where
  the grid allows it (:data:`MILP_MAX_WORK`), greedy by progress and greedy by met area -- each improved by
  a swap search over the grid (:func:`swap_search`: replace one camera by any other candidate while the
  objective grows, which also counts the samples only three or more fused cameras meet), each refined,
  the best kept; all within ``time_limit_s``.  The result states how far from the grid's optimum its
  discrete layout can be (:func:`grid_bound`: the integer program's proven optimum or dual bound where its
  objective is exact, else the LP relaxation of necessary conditions for a sample to be met).

Continuous refinement (:func:`refine`): pattern search over each chosen camera's pan, tilt and height
(within its mount's range), seeded; a move is kept only if it strictly increases the objective, so
the result is never worse than its start.
"""

from __future__ import annotations

import heapq
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import get_context

import numpy as np
from scipy import sparse
from scipy.optimize import Bounds, LinearConstraint, milp
from tqdm.auto import tqdm

from ..errors import InputError
from .coverage import (
    CameraConfig,
    LayoutEvaluation,
    build_camera,
    camera_information,
    evaluate_information,
    information_lambda_min,
    requirement_threshold,
    semi_major_from_info,
)
from .geometry import GroundSamples, ground_samples

__all__ = ["candidate_grid", "Coverage", "precompute", "Objective", "greedy", "milp_select", "refine",
           "PlanResult", "plan", "config_cost", "layout_information", "swap_search", "grid_bound", "METHODS"]

#: the discrete stages; ``best`` is the default
METHODS = ("best", "greedy", "milp", "both")
#: largest number of nonzeros (candidate, sample) the LP relaxation of :func:`grid_bound` is built with
LP_MAX_NNZ = 20_000_000
#: largest (candidates^2 x samples) for which the integer program is built (its pair enumeration)
MILP_MAX_WORK = 1e8


def candidate_grid(site) -> list[CameraConfig]:
    """Every configuration of the site's search grid (mount x height x camera x lens x tilt x pan)."""
    g = site.search
    out = []
    for m in site.mounts:
        for h in g.heights_m(m):
            for ct in site.cameras:
                for lens in ct.lenses:
                    for t in g.tilts_deg:
                        out += [CameraConfig(m.name, ct.name, lens.name, float(h), float(p), float(t))
                                for p in g.pans_deg()]
    return out


def config_cost(site, cfg: CameraConfig) -> float:
    """Mount cost + camera cost of one configuration."""
    return site.mount(cfg.mount).cost + site.camera_type(cfg.camera_type).cost


@dataclass
class Coverage:
    """What every candidate sees: sample indices and information ``(n_c, 3)`` per configuration."""

    configs: list[CameraConfig]
    index: list[np.ndarray]
    info: list[np.ndarray]
    mount: np.ndarray
    cost: np.ndarray


def _infos_of(site, xy_world_m, configs) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for cfg in configs:
        i, inf = camera_information(build_camera(site, cfg), site.camera_type(cfg.camera_type).budget, xy_world_m,
                                    site.occluders)
        out.append((i.astype(np.int64), inf))
    return out


#: candidates per task of the worker processes
CHUNK = 64


def resolve_workers(workers: int | None, n_configs: int) -> int:
    """``workers`` (None: one per CPU, at most 4, and 1 for grids below 500 candidates).

    More than one worker starts processes with ``spawn``: a script that calls the planner with workers
    must keep its top level under ``if __name__ == "__main__":``.
    """
    if workers is None:
        return 1 if n_configs < 500 else max(1, min(os.cpu_count() or 1, 4))
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise InputError("workers", workers, "an integer >= 1 (or None: automatic)")
    return int(workers)


def precompute(site, samples: GroundSamples, configs, *, progress: bool = False, workers: int | None = 1) -> Coverage:
    """:func:`camera_information` of every configuration (with a progress bar).

    ``workers > 1`` spreads the candidates over that many processes (``spawn``: each imports the package
    and loads the compiled kernels from numba's cache, about a second); the result is the same.
    """
    configs = list(configs)
    names = [m.name for m in site.mounts]
    w = resolve_workers(workers, len(configs))
    bar = tqdm(total=len(configs), desc="candidates", unit="cam", disable=not progress, leave=False)
    if w == 1:
        infos = []
        for k in range(0, len(configs), CHUNK):
            infos += _infos_of(site, samples.xy_world_m, configs[k:k + CHUNK])
            bar.update(len(configs[k:k + CHUNK]))
    else:
        with ProcessPoolExecutor(max_workers=w, mp_context=get_context("spawn")) as pool:
            futs = [pool.submit(_infos_of, site, samples.xy_world_m, configs[k:k + CHUNK])
                    for k in range(0, len(configs), CHUNK)]
            infos = []
            for f in futs:
                part = f.result()
                infos += part
                bar.update(len(part))
    bar.close()
    return Coverage(configs, [i for i, _ in infos], [x for _, x in infos],
                    np.array([names.index(c.mount) for c in configs], dtype=np.int64),
                    np.array([config_cost(site, c) for c in configs]))


@dataclass
class Objective:
    """Weights ``w_i a_i`` and requirements of the samples; ``fusion`` and ``confidence`` of the test."""

    weight: np.ndarray
    requirement_m: np.ndarray
    fusion: bool = True
    confidence: float = 0.95

    @classmethod
    def of(cls, site, samples: GroundSamples, *, fusion: bool = True) -> Objective:
        w = np.array([z.weight for z in site.zones])[samples.zone] * samples.area_m2
        req = np.array([z.max_semi_major_m for z in site.zones])[samples.zone]
        return cls(w, req, fusion, site.search.confidence)

    @property
    def threshold(self) -> np.ndarray:
        """``lambda_min(I)`` each sample needs (1/m^2)."""
        return requirement_threshold(self.requirement_m, self.confidence)

    def meets(self, info, idx) -> np.ndarray:
        return semi_major_from_info(info, self.confidence) <= self.requirement_m[idx]

    def value(self, infos) -> float:
        """Objective of a layout given each camera's ``(index, info)``."""
        n = self.weight.shape[0]
        if self.fusion:
            total = np.zeros((n, 3))
            for idx, inf in infos:
                np.add.at(total, idx, inf)
            met = self.meets(total, slice(None))
        else:
            met = np.zeros(n, dtype=bool)
            for idx, inf in infos:
                met[idx] |= self.meets(inf, idx)
        return float(self.weight[met].sum())


def _affordable(cov, used_mounts, spent, max_cost):
    ok = ~np.isin(cov.mount, list(used_mounts))
    if max_cost is not None:
        ok &= cov.cost <= max_cost - spent + 1e-12
    return ok


def greedy(cov: Coverage, obj: Objective, max_cameras: int, max_cost: float | None = None, *,
           lazy: bool = True, soft: bool | None = None) -> list[int]:
    """Greedy selection (see the module docstring); returns indices into ``cov.configs``, in order.

    ``soft`` scores a candidate by the *progress* it brings, ``sum_i w_i (min(1, lambda_min(I_i) / t_i)``
    after - before), ``t_i`` the information the sample's requirement needs: a camera that halves the
    shortfall of samples that only a second camera will bring over the line is credited for it, where
    the met-area gain would be zero.  ``soft=None`` (default): with fusion, the progress for every pick
    but the last (after the last, nothing completes a partial progress), which is chosen by its met-area
    gain; ``soft=False``: the met-area gain throughout (the only score without fusion).
    """
    auto = soft is None
    use_soft = obj.fusion if auto else bool(soft)
    n = obj.weight.shape[0]
    S, score = np.zeros((n, 3)), np.zeros(n)
    chosen, used, spent = [], set(), 0.0
    bound = np.full(len(cov.configs), np.inf)
    tiny = 1e-9 * max(float(cov.cost.max()), 1.0)
    state = {"soft": use_soft}

    def sample_score(info, idx):
        if state["soft"]:
            return np.clip(information_lambda_min(info) / obj.threshold[idx], 0.0, 1.0)
        return obj.meets(info, idx).astype(np.float64)

    def gain(c):
        idx, inf = cov.index[c], cov.info[c]
        new = sample_score(S[idx] + inf, idx) if obj.fusion else np.maximum(score[idx], sample_score(inf, idx))
        return float(obj.weight[idx] @ (new - score[idx]))

    def key(g, c):
        return g if max_cost is None else g / max(cov.cost[c], tiny)

    for step in range(max_cameras):
        if auto and state["soft"] and step == max_cameras - 1:  # the last pick: by met area
            state["soft"] = False
            score = obj.meets(S, slice(None)).astype(np.float64)
            bound[:] = np.inf
        alive = np.flatnonzero(_affordable(cov, used, spent, max_cost))
        if alive.size == 0:
            break
        if lazy:
            c = _lazy_pick(alive, bound, gain, key)
        else:
            for a in alive:
                bound[a] = gain(a)
            c = int(alive[int(np.argmax([key(bound[a], a) for a in alive]))])
        if not bound[c] > 1e-12:
            break
        chosen.append(c)
        used.add(int(cov.mount[c]))
        spent += float(cov.cost[c])
        idx = cov.index[c]
        S[idx] += cov.info[c]
        score[idx] = sample_score(S[idx], idx) if obj.fusion else np.maximum(score[idx], sample_score(cov.info[c], idx))
    return chosen


def _lazy_pick(alive, bound, gain, key) -> int:
    """Pop the best upper bound, re-evaluate it, until the top of the queue is fresh (lazy greedy)."""
    heap = [(-key(bound[c], c), int(c), False) for c in alive]
    heapq.heapify(heap)
    while True:
        _, c, fresh = heapq.heappop(heap)
        if fresh:
            return c
        bound[c] = gain(c)
        heapq.heappush(heap, (-key(bound[c], c), c, True))


def _dense(cov: Coverage, n: int) -> np.ndarray:
    D = np.zeros((len(cov.configs), n, 3))
    for c, (idx, inf) in enumerate(zip(cov.index, cov.info, strict=True)):
        D[c, idx] = inf
    return D


def _pair_cover(cov: Coverage, obj: Objective, single: np.ndarray, D: np.ndarray):
    """Pairs ``(a, b)`` of configurations on different mounts whose fusion meets samples neither meets alone."""
    pairs, rows = [], []
    C = D.shape[0]
    for a in range(C - 1):
        b = np.arange(a + 1, C)
        b = b[cov.mount[b] != cov.mount[a]]
        if b.size == 0:
            continue
        both = obj.meets(D[a][None] + D[b], slice(None)) & ~single[a][None] & ~single[b]
        for j in np.flatnonzero(both.any(1)):
            pairs.append((a, int(b[j])))
            rows.append(np.flatnonzero(both[j]))
    return pairs, rows


def milp_select(cov: Coverage, obj: Objective, max_cameras: int, max_cost: float | None = None, *,
                time_limit_s: float | None = None) -> list[int]:
    """The integer program of the module docstring; returns the chosen indices into ``cov.configs``.

    Stopped at ``time_limit_s`` before proving its optimum, it returns its best layout so far with a
    ``RuntimeWarning`` (that layout can be poor).
    """
    return _milp(cov, obj, max_cameras, max_cost, time_limit_s)[0]


def milp_allowed(cov: Coverage, obj: Objective) -> bool:
    """Whether the integer program is built for this grid (candidates^2 x samples <= :data:`MILP_MAX_WORK`)."""
    return float(len(cov.configs)) ** 2 * obj.weight.shape[0] <= MILP_MAX_WORK


def _milp(cov, obj, max_cameras, max_cost, time_limit_s) -> tuple[list[int], bool, float | None]:
    """``(picks, proven optimal, upper bound of the program's objective or None)``."""
    n, C = obj.weight.shape[0], len(cov.configs)
    if not milp_allowed(cov, obj):
        raise InputError("method", "milp", f"a grid with candidates^2 x samples <= {MILP_MAX_WORK:g} (this one: "
                         f"{C}^2 x {n}): use method greedy, a coarser grid or a larger --screen-step")
    D = _dense(cov, n)
    single = np.zeros((C, n), dtype=bool)
    for c in range(C):
        single[c, cov.index[c]] = obj.meets(cov.info[c], cov.index[c])
    pairs, prow = _pair_cover(cov, obj, single, D) if obj.fusion and max_cameras >= 2 else ([], [])
    Pn = len(pairs)
    keep = np.flatnonzero(single.any(0) | np.isin(np.arange(n), np.concatenate(prow) if prow else []))
    m = keep.size
    pos = np.full(n, -1)
    pos[keep] = np.arange(m)
    # cover rows: y_i - sum_c A_ci x_c - sum_p B_pi z_p <= 0
    sc, si = np.nonzero(single[:, keep])
    pr = np.concatenate([pos[r] for r in prow]) if prow else np.zeros(0, dtype=np.int64)
    pc = np.repeat(np.arange(Pn), [r.size for r in prow]) if prow else np.zeros(0, dtype=np.int64)
    cover = sparse.coo_matrix((np.concatenate([-np.ones(si.size), -np.ones(pr.size), np.ones(m)]),
                               (np.concatenate([si, pr, np.arange(m)]),
                                np.concatenate([sc, C + pc, C + Pn + np.arange(m)]))), shape=(m, C + Pn + m))
    link_r = np.repeat(np.arange(2 * Pn), 2)
    link_c = np.array([[C + p, pairs[p][k]] for p in range(Pn) for k in (0, 1)], dtype=np.int64).reshape(-1)
    link = sparse.coo_matrix((np.tile([1.0, -1.0], 2 * Pn), (link_r, link_c)), shape=(2 * Pn, C + Pn + m))
    M = int(cov.mount.max()) + 1
    per_mount = sparse.coo_matrix((np.ones(C), (cov.mount, np.arange(C))), shape=(M, C + Pn + m))
    totals = [np.concatenate([np.ones(C), np.zeros(Pn + m)])]
    ub = [float(max_cameras)]
    if max_cost is not None:
        totals.append(np.concatenate([cov.cost, np.zeros(Pn + m)]))
        ub.append(float(max_cost))
    A = sparse.vstack([cover, link, per_mount, sparse.csr_matrix(np.array(totals))]).tocsr()
    hi = np.concatenate([np.zeros(m + 2 * Pn), np.ones(M), ub])
    c = np.concatenate([np.zeros(C + Pn), -obj.weight[keep]])
    integrality = np.concatenate([np.ones(C), np.zeros(Pn + m)])
    options = {"disp": False} if time_limit_s is None else {"disp": False, "time_limit": float(time_limit_s)}
    res = milp(c, constraints=LinearConstraint(A, -np.inf, hi), integrality=integrality, bounds=Bounds(0, 1),
               options=options)
    if res.x is None and res.status != 1:
        raise InputError("method", "milp", f"a solvable integer program ({res.message})")
    picks = [] if res.x is None else [int(i) for i in np.flatnonzero(res.x[:C] > 0.5)]
    dual = getattr(res, "mip_dual_bound", None)
    bound = None if dual is None or not np.isfinite(dual) else float(-dual)
    if res.status != 0:
        warnings.warn(f"milp stopped before proving its optimum ({res.message}); its best layout so far is kept "
                      "(plan() compares it with greedy's)", RuntimeWarning, stacklevel=2)
        return picks, False, bound
    return picks, True, float(-res.fun) if bound is None else max(bound, float(-res.fun))


def _state_without(cov, obj, picks, skip) -> tuple[np.ndarray, np.ndarray]:
    """The fused information ``(n, 3)`` (or, without fusion, the count of cameras meeting each sample alone)
    of ``picks`` without position ``skip``, and its met mask."""
    n = obj.weight.shape[0]
    if obj.fusion:
        total = np.zeros((n, 3))
        for j, c in enumerate(picks):
            if j != skip:
                np.add.at(total, cov.index[c], cov.info[c])
        return total, obj.meets(total, slice(None))
    count = np.zeros(n, dtype=np.int64)
    for j, c in enumerate(picks):
        if j != skip:
            count[cov.index[c]] += obj.meets(cov.info[c], cov.index[c])
    return count, count > 0


def _gains(cov, obj, state, met, single) -> np.ndarray:
    """The objective's gain of adding each candidate to the layout of ``state`` / ``met`` (delta on its samples)."""
    out = np.empty(len(cov.configs))
    for c, (idx, inf) in enumerate(zip(cov.index, cov.info, strict=True)):
        new = obj.meets(state[idx] + inf, idx) if obj.fusion else single[c]
        out[c] = float(obj.weight[idx] @ (new & ~met[idx]))
    return out


def swap_search(cov: Coverage, obj: Objective, picks, max_cameras: int, max_cost: float | None = None, *,
                deadline: float | None = None) -> tuple[list[int], float]:
    """Improve a layout over the grid: add a candidate while there is room, or replace one camera by any
    other candidate (one per mount, within the cost), as long as the objective grows; returns ``(picks,
    value)``.  The objective is the full one (fusion of any number of cameras), so the search also finds
    the samples that only three or more cameras meet together.  Stops at ``deadline``
    (``time.perf_counter()``); the result is never worse than ``picks``.
    """
    picks = [int(c) for c in picks]
    single = [obj.meets(inf, idx) for idx, inf in zip(cov.index, cov.info, strict=True)] if not obj.fusion else None
    value = obj.value([(cov.index[c], cov.info[c]) for c in picks])
    improved = True
    while improved and (deadline is None or time.perf_counter() < deadline):
        improved = False
        slots = list(range(len(picks))) + ([len(picks)] if len(picks) < max_cameras else [])
        for j in slots:
            rest = picks[:j] + picks[j + 1:]
            state, met = _state_without(cov, obj, picks, j)
            base = float(obj.weight[met].sum())
            ok = _affordable(cov, {int(cov.mount[c]) for c in rest}, float(cov.cost[rest].sum()), max_cost)
            gains = np.where(ok, _gains(cov, obj, state, met, single), -np.inf)
            c = int(np.argmax(gains))
            if base + gains[c] > value + 1e-9 * max(1.0, value):
                picks = rest[:j] + [c] + rest[j:]
                value = obj.value([(cov.index[q], cov.info[q]) for q in picks])
                improved = True
                break
    return picks, value


#: the directions (deg) of the necessary conditions of :func:`grid_bound` with fusion
BOUND_DIRECTIONS_DEG = (0.0, 45.0, 90.0, 135.0)


def _cover_block(cov: Coverage, obj: Objective, angle_deg: float | None) -> sparse.coo_matrix:
    """Rows ``y_i - sum_c a_ci x_c <= 0`` of :func:`grid_bound`: ``a_ci = min(1, u^T I_ci u / t_i)`` along the
    unit vector at ``angle_deg`` (fusion), or ``[c meets i alone]`` (``angle_deg`` None)."""
    n, C = obj.weight.shape[0], len(cov.configs)
    thr = obj.threshold
    rows, cols, vals = [], [], []
    if angle_deg is not None:
        cu, su = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    for c, (idx, inf) in enumerate(zip(cov.index, cov.info, strict=True)):
        if angle_deg is None:
            a = obj.meets(inf, idx) * 1.0
        else:
            a = np.minimum(1.0, (inf[:, 0] * cu * cu + 2.0 * inf[:, 1] * cu * su + inf[:, 2] * su * su) / thr[idx])
        keep = a > 0
        rows.append(idx[keep])
        cols.append(np.full(int(keep.sum()), c))
        vals.append(-a[keep])
    r, cl, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    return sparse.coo_matrix((np.concatenate([v, np.ones(n)]), (np.concatenate([r, np.arange(n)]),
                                                                 np.concatenate([cl, C + np.arange(n)]))),
                             shape=(n, C + n))


def grid_bound(cov: Coverage, obj: Objective, max_cameras: int, max_cost: float | None = None) -> float | None:
    """An upper bound of the objective over every layout of the grid: the LP relaxation of necessary
    conditions for a sample to be met (None above :data:`LP_MAX_NNZ` nonzeros).

    With fusion, sample ``i`` can be met by a layout ``S`` only if ``sum_{c in S} u^T I_ci u >= t_i`` for
    every unit vector ``u`` (``lambda_min`` of the fused information is at most ``u^T (sum_c I_ci) u``), so
    ``y_i <= sum_c min(1, u^T I_ci u / t_i) x_c`` holds for every integer layout, here for the directions
    :data:`BOUND_DIRECTIONS_DEG`; without fusion ``y_i <= sum_c [c meets i] x_c``.  Maximising
    ``sum_i w_i y_i`` with ``0 <= x, y <= 1``, at most K cameras, one per mount and the cost gives the bound.
    """
    n, C = obj.weight.shape[0], len(cov.configs)
    angles = BOUND_DIRECTIONS_DEG if obj.fusion else (None,)
    if C == 0:
        return 0.0
    if sum(i.size for i in cov.index) * len(angles) > LP_MAX_NNZ:
        return None
    cover = [_cover_block(cov, obj, a) for a in angles]
    M = int(cov.mount.max()) + 1
    per_mount = sparse.coo_matrix((np.ones(C), (cov.mount, np.arange(C))), shape=(M, C + n))
    totals, ub = [np.concatenate([np.ones(C), np.zeros(n)])], [float(max_cameras)]
    if max_cost is not None:
        totals.append(np.concatenate([cov.cost, np.zeros(n)]))
        ub.append(float(max_cost))
    A = sparse.vstack([*cover, per_mount, sparse.csr_matrix(np.array(totals))]).tocsr()
    hi = np.concatenate([np.zeros(n * len(angles)), np.ones(M), ub])
    res = milp(np.concatenate([np.zeros(C), -obj.weight]), constraints=LinearConstraint(A, -np.inf, hi),
               integrality=np.zeros(C + n), bounds=Bounds(0, 1), options={"disp": False})
    return None if res.x is None else float(-res.fun) * (1 + 1e-9) + 1e-9


def layout_information(site, samples: GroundSamples, configs, *, budget_scale: float = 1.0):
    """``(index, info)`` of each configuration of a layout (``budget_scale`` multiplies every sigma)."""
    out = []
    for cfg in configs:
        b = site.camera_type(cfg.camera_type).budget
        out.append(camera_information(build_camera(site, cfg), b if budget_scale == 1.0 else b.scaled(budget_scale),
                                      samples.xy_world_m, site.occluders))
    return out


def _clip(site, cfg: CameraConfig, var: str, value: float) -> float:
    if var == "pan_deg":
        return float(np.mod(value, 360.0))
    if var == "tilt_deg":
        return float(np.clip(value, 0.5, 89.5))
    lo, hi = site.mount(cfg.mount).height_range_m
    return float(np.clip(value, lo, hi))


def _step(site, cfg: CameraConfig, var: str) -> float:
    """First step of the pattern search: half the pan grid, 4 deg of tilt, a quarter of the height range."""
    if var == "pan_deg":
        return site.search.pan_step_deg / 2.0
    if var == "tilt_deg":
        return 4.0
    lo, hi = site.mount(cfg.mount).height_range_m
    return (hi - lo) / 4.0


def refine(site, samples: GroundSamples, configs, obj: Objective, *, seed: int = 0, max_evals: int = 200,
           levels: int = 3, progress: bool = False) -> tuple[list[CameraConfig], float, float, int]:
    """Pattern search over pan, tilt and height of each camera (see the module docstring).

    Returns ``(configs, start_value, value, n_evaluations)``; ``value >= start_value`` always.
    """
    configs = list(configs)
    infos = layout_information(site, samples, configs)
    start = best = obj.value(infos)
    rng = np.random.default_rng(seed)
    evals = 0
    bar = tqdm(total=max_evals, desc="refine", unit="eval", disable=not progress, leave=False)
    for lev in range(levels):
        scale = 2.0 ** -lev
        improved = True
        while improved and evals < max_evals:
            improved = False
            for k in rng.permutation(len(configs)):
                for var in rng.permutation(["pan_deg", "tilt_deg", "height_m"]):
                    s = scale * _step(site, configs[k], var)
                    for sign in (1.0, -1.0):
                        if evals >= max_evals or s <= 0:
                            break
                        trial = configs[k].replace(**{var: _clip(site, configs[k], var,
                                                                 getattr(configs[k], var) + sign * s)})
                        if trial == configs[k]:
                            continue
                        evals += 1
                        bar.update(1)
                        t_info = layout_information(site, samples, [trial])[0]
                        v = obj.value(infos[:k] + [t_info] + infos[k + 1:])
                        if v > best:
                            configs[k], infos[k], best, improved = trial, t_info, v, True
                            break
    bar.close()
    return configs, start, best, evals


@dataclass
class PlanResult:
    """A plan: the chosen configurations, their evaluation and how they were found.

    ``discrete_value`` is the objective after the discrete stage, ``value`` after the refinement
    (m^2 of weighted met area; ``value >= discrete_value``); ``seconds`` per stage.  ``bound`` (method
    ``best``): how far from the grid's optimum the discrete layout can be, ``{"upper_bound_m2", "value_m2",
    "gap", "kind", "screen_step"}`` on the samples the discrete stage sees (``gap = 1 - value / bound``; 0:
    proven optimal over the grid; the refinement leaves the grid and may exceed the bound); ``starts``: each
    start's discrete and refined value (m^2, every sample).
    """

    configs: list[CameraConfig]
    evaluation: LayoutEvaluation
    discrete_value: float
    value: float
    method: str
    n_candidates: int
    samples: GroundSamples
    seconds: dict = field(default_factory=dict)
    discrete_configs: list[CameraConfig] = field(default_factory=list)
    bound: dict = field(default_factory=dict)
    starts: dict = field(default_factory=dict)


def _discrete(cov, obj, method, k, max_cost, lazy, time_limit_s):
    picks = {}
    if method in ("greedy", "both"):
        picks["greedy"] = greedy(cov, obj, k, max_cost, lazy=lazy)
    if method in ("milp", "both"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            picks["milp"], optimal, _ = _milp(cov, obj, k, max_cost, time_limit_s)
        if not optimal and "greedy" not in picks:  # stopped early: its incumbent against greedy's layout
            picks["greedy"] = greedy(cov, obj, k, max_cost, lazy=lazy)
    vals = {m: obj.value([(cov.index[c], cov.info[c]) for c in p]) for m, p in picks.items()}
    best = max(vals, key=lambda m: (vals[m], m == "milp"))
    return [cov.configs[c] for c in picks[best]], vals[best], best


def _best_starts(cov, obj, k, max_cost, lazy, time_limit_s) -> tuple[dict, dict]:
    """Method ``best``'s discrete stage: every start (milp where allowed, greedy by progress and by met area),
    each through :func:`swap_search`; returns ``(name -> picks, bound dict)``."""
    t0 = time.perf_counter()
    deadline = None if time_limit_s is None else t0 + float(time_limit_s)
    starts, bounds = {"greedy": greedy(cov, obj, k, max_cost, lazy=lazy)}, []
    if obj.fusion:
        starts["greedy-met-area"] = greedy(cov, obj, k, max_cost, lazy=lazy, soft=False)
    if milp_allowed(cov, obj):
        left = None if deadline is None else max(deadline - time.perf_counter(), 1.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            starts["milp"], optimal, mb = _milp(cov, obj, k, max_cost, left)
        if mb is not None and (k <= 2 or not obj.fusion):  # the program's objective is the full one
            bounds.append((mb, "milp (proven optimum)" if optimal else "milp (dual bound, stopped early)"))
    out, seen = {}, set()
    for name, picks in starts.items():
        picks, _ = swap_search(cov, obj, picks, k, max_cost, deadline=deadline)
        if frozenset(picks) not in seen:
            seen.add(frozenset(picks))
            out[name] = picks
    lp = grid_bound(cov, obj, k, max_cost)
    if lp is not None:
        bounds.append((lp, "LP relaxation"))
    best = max(obj.value([(cov.index[c], cov.info[c]) for c in p]) for p in out.values())
    bound = {"value_m2": best, "upper_bound_m2": None, "gap": None, "kind": None}
    if bounds:
        ub, kind = min(bounds)
        ub = max(ub, best)
        bound.update(upper_bound_m2=ub, kind=kind, gap=0.0 if ub <= 0 else max(0.0, 1.0 - best / ub))
    return out, bound


def _refine_starts(site, samples, cov, obj_all, starts, refine_layout, seed, max_refine_evals, progress):
    """Refine every start on all samples; the best final layout: ``(discrete, final, dval, value, name, table)``."""
    table, best = {}, None
    for name, picks in starts.items():
        chosen = [cov.configs[c] for c in picks]
        dval = value = obj_all.value(layout_information(site, samples, chosen))
        final = chosen
        if refine_layout and chosen:
            final, _, value, _ = refine(site, samples, chosen, obj_all, seed=seed, max_evals=max_refine_evals,
                                        progress=progress)
        table[name] = {"discrete_m2": dval, "refined_m2": value}
        if best is None or value > best[3] + 1e-9 * max(1.0, value):
            best = (chosen, final, dval, value, name)
    return (*best, table)


def plan(site, *, method: str = "best", max_cameras: int | None = None, max_cost: float | None = None,
         fusion: bool = True, refine_layout: bool = True, seed: int = 0, lazy: bool = True,
         max_refine_evals: int = 200, time_limit_s: float | None = 300.0, screen_step: int = 1,
         workers: int | None = 1, progress: bool = False) -> PlanResult:
    """Plan a site (see the module docstring): discrete stage, then the continuous refinement.

    Parameters
    ----------
    site : Site
        From :func:`footprint_uq.planning.site.load_site`.
    method : {"best", "greedy", "milp", "both"}
        The discrete stage (``best``, the default: every start, each improved and refined, the best kept,
        with a bound on its distance to the grid's optimum; see the module docstring).
    max_cameras, max_cost : int, float, optional
        K and the cost limit (mounts + cameras); default: the site file's ``search`` section.
    fusion : bool
        A sample is met by the fused covariance of every camera that sees it (else by one camera).
    refine_layout : bool
        Run :func:`refine` after the discrete stage (never worse than its start).
    seed : int
        Seed of the refinement's visiting order: same site, options and seed give the same layout.
    lazy : bool
        Lazy evaluation in :func:`greedy`.
    max_refine_evals : int
        Largest number of layouts the refinement evaluates.
    time_limit_s : float, optional
        Time limit of the integer program (HiGHS keeps its best layout found by then); with ``best``, of
        the whole discrete stage (the program and the swap searches).
    screen_step : int
        ``> 1``: the discrete stage sees every ``screen_step``-th sample in both directions, each standing
        for ``screen_step^2`` cells (about ``screen_step^2`` times faster); the refinement and the
        evaluation always use every sample.
    workers : int or None
        Processes of the candidate screening (:func:`precompute`; None: automatic, see
        :func:`resolve_workers`).
    progress : bool
        tqdm progress bars on stderr.

    Returns
    -------
    PlanResult
    """
    if method not in METHODS:
        raise InputError("method", method, f"one of {list(METHODS)}")
    k = site.search.max_cameras if max_cameras is None else int(max_cameras)
    if k < 1:
        raise InputError("max_cameras", max_cameras, "an integer >= 1")
    cost = site.search.max_cost if max_cost is None else float(max_cost)
    t = {"start": time.perf_counter()}
    if isinstance(screen_step, bool) or not isinstance(screen_step, int | np.integer) or screen_step < 1:
        raise InputError("screen_step", screen_step, "an integer >= 1")
    samples = ground_samples(site)
    obj = Objective.of(site, samples, fusion=fusion)
    screen = samples.thinned(int(screen_step))
    configs = candidate_grid(site)
    cov = precompute(site, screen, configs, progress=progress, workers=workers)
    t["precompute"] = time.perf_counter()
    obj_screen = Objective.of(site, screen, fusion=fusion)
    if method == "best":
        starts, bound = _best_starts(cov, obj_screen, k, cost, lazy, time_limit_s)
        bound["screen_step"] = int(screen_step)
    else:
        chosen, _, used = _discrete(cov, obj_screen, method, k, cost, lazy, time_limit_s)
        starts, bound = {used: [cov.configs.index(c) for c in chosen]}, {}
    t["discrete"] = time.perf_counter()
    chosen, final, dval, value, used, table = _refine_starts(site, samples, cov, obj, starts, refine_layout, seed,
                                                             max_refine_evals, progress)
    t["refine"] = time.perf_counter()
    ev = evaluate_information(site, samples, layout_information(site, samples, final), fusion=fusion)
    t["evaluate"] = time.perf_counter()
    keys = list(t)
    secs = {b: t[b] - t[a] for a, b in zip(keys, keys[1:], strict=False)}
    secs["total"] = t[keys[-1]] - t["start"]
    return PlanResult(final, ev, dval, value, used if method != "best" else f"best ({used})", len(configs), samples,
                      secs, chosen, bound, table)
