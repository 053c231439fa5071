"""The budget fit's inputs in compact form, and its likelihood evaluated by per-group sums.

:func:`footprint_uq.validation.fit.fit_budget` needs, per object, only the residual (2), the Jacobian
columns of the parameters that carry variance (``k`` of the 22: the free terms' and the base budget's
non-zero ones), the per-object covariance (3 numbers), the ground column ``d(xy)/d(ground_dz)`` (2, only
with ``object_ground_m`` free) and the group index.  :func:`compact_chunks` streams ``(residual_m, dxy_dp,
cov_object_m2, group)`` chunks into these float64 records (``8 (5 + 2k) + 4`` bytes a pair, plus 16 with
the ground term: 92 bytes for pan, tilt and height, against 440 for the full Jacobian and covariance),
checking each chunk with global row numbers.  :class:`CompactModel` evaluates the (restricted)
log-likelihood and its score from the per-group sums of :func:`footprint_uq.fast.fit_kernels.group_sums`:
one pass over the records per evaluation, none at all when no per-object term is free (the sums are then
fixed: sufficient statistics).  It computes exactly what the dense reference
``footprint_uq.validation.fit._Model`` computes (to rounding; tests/test_validation_fit.py).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from .. import params as P
from ..errors import InputError
from ..fast.fit_kernels import group_sums
from .fit_likelihood import GroupLikelihood, GroupTerms

__all__ = ["CompactPairs", "SpilledPairs", "compact_chunks", "check_chunk", "CompactModel", "MEMORY_PAIRS", "PART_ROWS"]


class CompactPairs(NamedTuple):
    """Compact per-object records of the fit (caller's row order)."""

    r: np.ndarray       # (N, 2) residuals, m
    U: np.ndarray       # (N, 2, k) Jacobian columns ``cols``
    R3: np.ndarray      # (N, 3) per-object covariance (R00, R01, R11), m^2
    jg: np.ndarray      # (N, 2) d(xy)/d(ground_dz), or (0, 2) when not needed
    gid: np.ndarray     # (N,) int32 group index into ``labels``
    labels: np.ndarray  # (G,) the caller's group labels
    cols: np.ndarray    # (k,) parameter columns kept

    @property
    def n(self) -> int:
        return int(self.r.shape[0])

    @property
    def has_ground(self) -> bool:
        return self.jg.shape[0] == self.n

    def subset(self, rows) -> CompactPairs:
        """The records ``rows`` (index or mask), same labels and columns."""
        jg = self.jg[rows] if self.jg.shape[0] else self.jg
        return CompactPairs(self.r[rows], self.U[rows], self.R3[rows], jg, self.gid[rows], self.labels, self.cols)

    take = subset

    def parts(self):
        """The records in parts (here: one), for the passes of the fit."""
        yield self

    def groups_present(self) -> int:
        return int(np.unique(self.gid).size)


class SpilledPairs:
    """Compact records written in parts to a temporary folder (deleted with the object): the passes of the
    fit map one part at a time, so the process holds one part (``part_rows`` records), whatever the number
    of pairs; the operating system's page cache keeps the files.  Same interface as :class:`CompactPairs`
    for the fit (``n``, ``labels``, ``cols``, ``has_ground``, ``parts()``, ``take(rows)``)."""

    _FIELDS = ("r", "U", "R3", "jg", "gid")

    def __init__(self, folder: str, sizes: list[int], remap: np.ndarray, labels, cols, has_ground: bool):
        self.folder, self.sizes, self.remap = folder, sizes, remap
        self.labels, self.cols, self.has_ground = labels, cols, has_ground
        self.n = int(sum(sizes))
        self._cleanup = weakref.finalize(self, shutil.rmtree, folder, True)

    def _load(self, i: int) -> CompactPairs:
        a = {f: np.asarray(np.load(os.path.join(self.folder, f"{i}_{f}.npy"), mmap_mode="r"))
             for f in self._FIELDS if f != "jg" or self.has_ground}
        a.setdefault("jg", np.zeros((0, 2)))
        return CompactPairs(a["r"], a["U"], a["R3"], a["jg"], self.remap[a["gid"]], self.labels, self.cols)

    def parts(self):
        for i in range(len(self.sizes)):
            yield self._load(i)

    def take(self, rows) -> CompactPairs:
        """The records ``rows`` (sorted indices) gathered in memory."""
        rows = np.asarray(rows, dtype=np.int64)
        out, start = [], 0
        for i, size in enumerate(self.sizes):
            sel = rows[(rows >= start) & (rows < start + size)] - start
            if sel.size:
                out.append(self._load(i).subset(sel))
            start += size
        jg = np.concatenate([o.jg for o in out]) if self.has_ground else np.zeros((0, 2))
        return CompactPairs(*(np.concatenate([getattr(o, f) for o in out]) for f in ("r", "U", "R3")), jg,
                            np.concatenate([o.gid for o in out]), self.labels, self.cols)

    def groups_present(self) -> int:
        seen = np.zeros(self.labels.size, dtype=bool)
        for p in self.parts():
            seen[p.gid] = True
        return int(seen.sum())

    @staticmethod
    def write_part(folder: str, i: int, part: tuple) -> None:
        for f, a in zip(SpilledPairs._FIELDS, part, strict=True):
            if a.size == 0:
                continue
            np.save(os.path.join(folder, f"{i}_{f}.npy"), a)


def check_chunk(r, J, R, g, offset: int = 0):
    """Checked float64 arrays of one chunk; errors name the global row ``offset + i``."""
    r = np.asarray(r, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 2:
        raise InputError("residual_m", f"shape {r.shape}", "an array (N, 2) with N >= 2 (truth minus prediction, m)")
    n = r.shape[0]
    J = np.asarray(J, dtype=np.float64)
    if J.shape != (n, 2, P.N_PARAMS):
        raise InputError("dxy_dp", f"shape {J.shape}", f"an array ({n}, 2, {P.N_PARAMS}) in PARAM_NAMES order")
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (n, 2, 2):
        raise InputError("cov_object_m2", f"shape {R.shape}", f"an array ({n}, 2, 2) in m^2")
    g = np.asarray(g)
    if g.shape != (n,):
        raise InputError("group", f"shape {g.shape}", f"an array ({n},) of calibration-draw labels")
    for name, a in (("residual_m", r), ("dxy_dp", J), ("cov_object_m2", R)):
        bad = ~np.isfinite(a.reshape(n, int(np.prod(a.shape[1:])))).all(1)  # n = 0: an empty chunk
        if bad.any():
            i = int(np.flatnonzero(bad)[0]) + offset
            raise InputError(f"{name}[{i}]", "non-finite", "finite numbers (drop invalid objects first)")
    det = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
    bad = (R[:, 0, 0] < 0) | (det < -1e-12 * np.maximum(R[:, 0, 0] * R[:, 1, 1], 1e-300)) | \
        (np.abs(R[:, 0, 1] - R[:, 1, 0]) > 1e-9 * np.maximum(np.abs(R[:, 0, 1]), 1e-300))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"cov_object_m2[{i + offset}]", R[i].tolist(),
                         "a symmetric positive semi-definite 2x2 covariance")
    return r, J, R, g


#: records kept in memory; above this many pairs the records are spilled to a temporary folder in parts
MEMORY_PAIRS = 262_144
#: records per part (spilled form)
PART_ROWS = 131_072


def compact_chunks(chunks: Iterable, cols, need_ground: bool, *, memory_pairs: int | None = MEMORY_PAIRS,
                   part_rows: int = PART_ROWS):
    """Stream ``(residual_m (n, 2), dxy_dp (n, 2, 22), cov_object_m2 (n, 2, 2), group (n,))`` chunks into
    compact records (only the Jacobian columns ``cols``; the ground column with ``need_ground``).

    Up to ``memory_pairs`` pairs (``None``: no limit) the records stay in memory (:class:`CompactPairs`);
    beyond, they are written in parts of about ``part_rows`` to a temporary folder (:class:`SpilledPairs`):
    memory is then one part plus one chunk, flat in the number of pairs.  Raises :class:`InputError`
    naming the first bad row (global number) or where there are fewer than 2 rows in all.
    """
    cols = np.asarray(cols, dtype=np.int64)
    pending: list[tuple] = []
    parts: list[tuple] = []
    sizes: list[int] = []
    index: dict = {}
    n, folder = 0, None

    def flush():
        nonlocal folder
        if not pending:
            return
        part = tuple(np.concatenate([p[i] for p in pending]) for i in range(5))
        pending.clear()
        if folder is None and memory_pairs is not None and n > memory_pairs:
            folder = tempfile.mkdtemp(prefix="footprint-uq-fit-")
            for i, old in enumerate(parts):
                SpilledPairs.write_part(folder, i, old)
            parts.clear()
        if folder is not None:
            SpilledPairs.write_part(folder, len(sizes), part)
        else:
            parts.append(part)
        sizes.append(part[0].shape[0])

    try:
        for r, J, R, g in chunks:
            r, J, R, g = check_chunk(r, J, R, g, n)
            if r.shape[0] == 0:
                continue
            lab, inv = np.unique(g, return_inverse=True)
            ids = np.array([index.setdefault(x.item() if isinstance(x, np.generic) else x, len(index)) for x in lab],
                           dtype=np.int32)
            R3 = np.stack([R[:, 0, 0], 0.5 * (R[:, 0, 1] + R[:, 1, 0]), R[:, 1, 1]], 1)
            jg = np.ascontiguousarray(J[:, :, P.GDZ]) if need_ground else np.zeros((0, 2))
            pending.append((r, np.ascontiguousarray(J[:, :, cols]), R3, jg, ids[inv.reshape(-1)]))
            n += r.shape[0]
            if sum(p[0].shape[0] for p in pending) >= part_rows:
                flush()
        flush()
    except BaseException:
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    if n < 2:
        raise InputError("residual_m", f"shape ({n}, 2)", "an array (N, 2) with N >= 2 (truth minus prediction, m)")
    remap, labels = _sorted_labels(index)
    if folder is not None:
        return SpilledPairs(folder, sizes, remap, labels, cols, need_ground)
    cat = [np.concatenate([p[i] for p in parts]) if len(parts) > 1 else parts[0][i] for i in range(5)]
    jg = cat[3] if need_ground else np.zeros((0, 2))
    return CompactPairs(cat[0], cat[1], cat[2], jg, remap[cat[4]], labels, cols)


def _sorted_labels(index: dict):
    """Labels sorted as np.unique sorts them (the dense reference's group order) and the map to them."""
    keys = list(index)
    try:
        order = sorted(range(len(keys)), key=lambda i: keys[i])
    except TypeError:
        order = list(range(len(keys)))
    remap = np.empty(len(keys), dtype=np.int32)
    remap[order] = np.arange(len(keys), dtype=np.int32)
    return remap, np.array([keys[i] for i in order])


class CompactModel(GroupLikelihood):
    """The (restricted) log-likelihood of the variances ``v`` of the free terms and its score, from
    per-group sums (same interface and numbers as the dense ``fit._Model``; the algebra from the sums on is
    :class:`~footprint_uq.validation.fit_likelihood.GroupLikelihood`).

    ``A`` (m_shared, k, k): unit covariances of the free shared terms; ``kinds`` (q,): 0 for
    ``object_m``, 1 for ``object_ground_m``.
    """

    def __init__(self, data: CompactPairs, Sfixed, A, kinds, fit_bias: bool, reml: bool):
        self.d, self.Sf, self.A = data, Sfixed, A
        self.kinds = np.asarray(kinds, dtype=np.int64)
        self.object_free, self.fit_bias, self.reml = self.kinds.size > 0, fit_bias, reml
        self.m = A.shape[0] + self.kinds.size
        self.n = data.n
        self.n_groups = int(data.labels.size)
        self._cache = None
        if not self.object_free:
            self._cache = self._group_sums(np.zeros(0), False)
            if self._cache is None:
                raise InputError("cov_object_m2", "a singular covariance",
                                 "positive-definite per-object covariances (or a free 'object_m' term)")

    def _group_sums(self, vo, with_score):
        """Per-group sums over every part of the records (one pass; None: a singular per-object covariance)."""
        total = None
        for d in self.d.parts():
            s = group_sums(d.r, d.U, d.R3, d.jg, d.gid, self.n_groups, vo, self.kinds, with_score=with_score)
            if s is None:
                return None
            total = s if total is None else {k: total[k] + s[k] for k in total}
        return total

    def _object_score(self, s: dict, t: GroupTerms, Phi_i) -> np.ndarray:
        """Score of the per-object variances: ``-1/2 (tr(C^-1 E) - z^T E z) [+ 1/2 tr(Phi^-1 Z^T E Z)]`` with
        ``z = C^-1 (r - beta)``, ``Z = C^-1 X``, summed per group from the pass's sums."""
        K, KP, beta = t.K, t.KP, t.beta
        c = np.einsum("gkl,gl->gk", K, t.bt)              # z_i = D_i^-1 (r_i - beta) - V_i c_g
        go = np.empty(self.kinds.size)
        for q in range(self.kinds.size):
            W, Y, X = s["W"][:, q], s["Y"][:, q], s["X"][:, q]
            tr = s["T"][:, q].sum() - np.einsum("gkl,glk->", K, W)
            yq = s["y"][:, q] - np.einsum("gka,a->gk", Y, beta)
            aEa = s["s"][:, q].sum() - 2 * s["x"][:, q].sum(0) @ beta + beta @ X.sum(0) @ beta
            zEz = aEa - 2 * np.einsum("gk,gk->", c, yq) + np.einsum("gk,gkl,gl->", c, W, c)
            go[q] = -0.5 * (tr - zEz)
            if Phi_i is not None:
                YtKP = np.swapaxes(Y, 1, 2) @ KP
                ZEZ = (X - YtKP - np.swapaxes(YtKP, 1, 2) + np.swapaxes(KP, 1, 2) @ W @ KP).sum(0)
                go[q] += 0.5 * np.trace(Phi_i @ ZEZ)
        return go
