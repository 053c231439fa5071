"""Detections paired with their truth: the contact function and the pairs builder.

A **contact function** turns 2-D boxes into ground points with their uncertainty::

    contact(camera, budget, boxes_xyxy_px (N, 4), classes (N,), *, yaw_rad=None, cov_uv_px2=None) -> ContactResult

:class:`ContactResult` holds ``xy_world_m`` (N, 2), the total covariance ``cov_m2`` (N, 2, 2), its
per-object part ``cov_object_m2`` (pixel / detector noise and the contact model's own spread; not the
camera calibration), ``dxy_dp`` (N, 2, 22) (columns in :data:`footprint_uq.params.PARAM_NAMES` order) so
that ``cov_m2 = dxy_dp Sigma_params dxy_dp^T + cov_object_m2``, ``valid`` and ``status``
(:mod:`footprint_uq.status`).  :func:`bottom_centre` back-projects the centre of the box's bottom edge
(the behaviour of ``footprint-uq objects --contact bottom-centre``), :func:`footprint_centre
<footprint_uq.products.contact.footprint_centre>` models where the box touches the ground; both live in
:mod:`footprint_uq.products.contact`, whose :data:`CONTACT_MODELS` (re-exported here) names them.

The **pairs builder** (:func:`build_pairs`, :func:`iter_pairs`, :func:`collect_pairs`) runs a contact
function on every :class:`~footprint_uq.validation.readers.LabelChunk` and gives per object the residual
``truth - prediction`` (world frame, metres) with everything the coverage and the budget fit need: the
Jacobian, the per-object covariance and the calibration group (one integer per calibration draw).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, fields

import numpy as np

from .. import params as P
from .. import status
from ..errors import InputError
from ..products.contact import (
    CONTACT_MODELS,
    ContactResult,
    bottom_centre,
    bottom_centre_nonlinearity,
    footprint_centre,
    load_size_priors,
)
from ..uncertainty.budget import load_budget
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD
from .readers import NO_DETECTION, NO_TRUTH, LabelChunk, row_problems

__all__ = ["ContactResult", "bottom_centre", "CONTACT_MODELS", "contact_model", "with_size_priors", "Pairs",
           "GroupIndex",
           "build_pairs", "iter_pairs", "collect_pairs", "STATUS_OK", "STATUS_ERROR", "STATUS_NO_TRUTH",
           "STATUS_NO_DETECTION", "STATUS_NO_GROUND", "refused_reasons", "reason_kind"]

#: per-object status of a pair
STATUS_OK = "ok"                    # residual computed
STATUS_NO_TRUTH = "no truth"        # a detection without truth (unpaired)
STATUS_NO_DETECTION = "no detection"  # a truth without detection (unpaired)
STATUS_NO_GROUND = "no ground point"  # the contact function found no ground point (above the horizon, ...)
STATUS_ERROR = "error"              # a malformed row, unknown camera, missing calibration


def contact_model(name):
    """The contact function registered as ``name`` (a callable is returned unchanged)."""
    if callable(name):
        return name
    if name not in CONTACT_MODELS:
        raise InputError("contact", name, f"one of {sorted(CONTACT_MODELS)}")
    return CONTACT_MODELS[name]


def with_size_priors(contact, size_priors):
    """The contact model ``contact`` with the class size priors of the YAML file ``size_priors`` (``--size-priors
    FILE``: the shipped priors overridden class by class, :func:`footprint_uq.products.contact.load_size_priors`,
    read and checked here, once).  ``None``: ``contact`` unchanged.  Only the footprint-centre contact has size
    priors: with any other, a one-line error (an option that would change nothing is refused, not ignored)."""
    if size_priors is None:
        return contact
    if contact != "footprint-centre":
        raise InputError("--size-priors", str(size_priors), "only with --contact footprint-centre (the "
                         f"{contact if isinstance(contact, str) else 'given'} contact has no size priors)")
    fn = functools.partial(footprint_centre, size_priors=load_size_priors(size_priors))
    fn.__name__ = "footprint-centre"  # the name the summaries report
    return fn


class GroupIndex:
    """Calibration group keys -> consecutive integers (0, 1, ...), kept across chunks and files."""

    def __init__(self):
        self.keys: dict[str, int] = {}

    def __call__(self, key: str) -> int:
        return self.keys.setdefault(key, len(self.keys))

    def names(self) -> list[str]:
        return list(self.keys)


@dataclass
class Pairs:
    """Per object (every row of the input, in order): the pair and its residual.

    Attributes
    ----------
    source : (n,) object; line : (n,) int64     where the row comes from (file, line or row)
    frame, object_id, cls : (n,) object         identifiers
    group : (n,) int64                          calibration group (:class:`GroupIndex`), -1: no camera
    status : (n,) object                        ``ok``, ``no truth``, ``no detection``, ``no ground point``, ``error``
    reason : (n,) object                        why (the error text, or the status code's text)
    box_xyxy_px : (n, 4); truth_xy_world_m, xy_world_m, residual_m : (n, 2)   residual = truth - prediction
    cov_m2, cov_object_m2 : (n, 2, 2)           total and per-object covariance (m^2)
    dxy_dp : (n, 2, 22)                         Jacobian w.r.t. the camera parameters
    range_m : (n,)                              horizontal distance camera foot point -> truth (prediction
                                                where there is no truth)
    truth_z_m : (n,)                            truth height above the camera's ground plane (NaN unknown)
    nonlinearity : (n,); linear_ok : (n,) bool  the bottom-centre point's linearity flag
    """

    source: np.ndarray
    line: np.ndarray
    frame: np.ndarray
    object_id: np.ndarray
    cls: np.ndarray
    group: np.ndarray
    status: np.ndarray
    reason: np.ndarray
    box_xyxy_px: np.ndarray
    truth_xy_world_m: np.ndarray
    xy_world_m: np.ndarray
    residual_m: np.ndarray
    cov_m2: np.ndarray
    cov_object_m2: np.ndarray
    dxy_dp: np.ndarray
    range_m: np.ndarray
    truth_z_m: np.ndarray
    nonlinearity: np.ndarray
    linear_ok: np.ndarray

    def __len__(self) -> int:
        return len(self.line)

    @property
    def usable(self) -> np.ndarray:
        """(n,) bool: rows with a residual (status ``ok``)."""
        return self.status == STATUS_OK

    def subset(self, mask) -> Pairs:
        return Pairs(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})

    @staticmethod
    def concatenate(parts: list[Pairs]) -> Pairs:
        if not parts:
            return _empty_pairs()
        return Pairs(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Pairs)})


def _empty_pairs() -> Pairs:
    z = np.zeros(0)
    o = np.zeros(0, dtype=object)
    return Pairs(o, np.zeros(0, np.int64), o, o, o, np.zeros(0, np.int64), o, o, np.zeros((0, 4)), np.zeros((0, 2)),
                 np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)),
                 np.zeros((0, 2, P.N_PARAMS)), z, z, z, np.zeros(0, dtype=bool))


def _status_of(chunk: LabelChunk) -> tuple[np.ndarray, np.ndarray]:
    n = len(chunk)
    st = np.full(n, STATUS_OK, dtype=object)
    why = np.full(n, "ok", dtype=object)
    numbers = row_problems(chunk)  # a number out of its range: an error row, whatever the reader said
    for i, e in enumerate(chunk.error):
        if numbers[i] is not None and (e is None or e in (NO_TRUTH, NO_DETECTION)):
            e = numbers[i]
        if e is None:
            continue
        st[i] = {NO_TRUTH: STATUS_NO_TRUTH, NO_DETECTION: STATUS_NO_DETECTION}.get(e, STATUS_ERROR)
        why[i] = e
    if chunk.camera is None:
        st[st != STATUS_ERROR] = STATUS_ERROR
    return st, why


def build_pairs(chunk: LabelChunk, budget, *, contact="bottom-centre", groups: GroupIndex | None = None,
                linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> Pairs:
    """The pairs of one chunk: contact function on the detections, residual against the truth.

    Parameters
    ----------
    chunk : LabelChunk
    budget : the error budget (the chunk's own budget, from a camera registry, wins)
    contact : name in :data:`CONTACT_MODELS` or a contact function
    groups : GroupIndex shared by every chunk of a job (calibration group numbers)
    linear_threshold : ``linear_ok = nonlinearity <= linear_threshold`` (of the bottom-centre point)
    """
    fn = contact_model(contact)
    groups = groups if groups is not None else GroupIndex()
    n = len(chunk)
    st, why = _status_of(chunk)
    nan2, nan22 = np.full((n, 2), np.nan), np.full((n, 2, 2), np.nan)
    xy, cov, cov_obj, J = nan2.copy(), nan22.copy(), nan22.copy(), np.full((n, 2, P.N_PARAMS), np.nan)
    nl = np.full(n, np.nan)
    has_det = (st == STATUS_OK) | (st == STATUS_NO_TRUTH)
    idx = np.flatnonzero(has_det)
    if idx.size:
        bud = load_budget(chunk.budget if chunk.budget is not None else budget)
        cuv = None if chunk.cov_uv_px2 is None else chunk.cov_uv_px2[idx]
        boxes = chunk.box_xyxy_px[idx]
        # the labelled yaw (chunk.yaw_world_rad) is truth: never handed to the contact model
        res = fn(chunk.camera, bud, boxes, chunk.cls[idx], yaw_rad=None, cov_uv_px2=cuv)
        # the linearity flag is the bottom-centre point's, whatever the model
        nl_i = bottom_centre_nonlinearity(chunk.camera, bud, boxes, cuv, res.valid if fn is bottom_centre else None)
        xy[idx], cov[idx], cov_obj[idx], J[idx], nl[idx] = res.xy_world_m, res.cov_m2, res.cov_object_m2, \
            res.dxy_dp, nl_i
        bad = idx[~np.asarray(res.valid, dtype=bool)]
        codes = np.asarray(res.status)[~np.asarray(res.valid, dtype=bool)]
        st[bad] = np.where(st[bad] == STATUS_OK, STATUS_NO_GROUND, st[bad])
        why[bad] = [status.REASONS.get(int(c), f"status {int(c)}") for c in codes]
    resid = np.where((st == STATUS_OK)[:, None], chunk.truth_xy_world_m - xy, np.nan)
    _refuse_unusable(st, why, resid, cov)
    g = -1 if chunk.camera is None else groups(chunk.camera_key)
    ref = np.where(np.isfinite(chunk.truth_xy_world_m).all(1)[:, None], chunk.truth_xy_world_m, xy)
    with np.errstate(over="ignore", invalid="ignore"):  # (a truth refused as out of range may overflow here)
        rng = (np.hypot(*(ref - np.asarray(chunk.camera.position_world_m)[:2]).T)
               if chunk.camera is not None else np.full(n, np.nan))
    return Pairs(source=np.full(n, chunk.source, dtype=object), line=np.asarray(chunk.line, dtype=np.int64),
                 frame=chunk.frame, object_id=chunk.object_id, cls=chunk.cls, group=np.full(n, g, dtype=np.int64),
                 status=st, reason=why, box_xyxy_px=chunk.box_xyxy_px, truth_xy_world_m=chunk.truth_xy_world_m,
                 xy_world_m=xy, residual_m=resid, cov_m2=cov, cov_object_m2=cov_obj, dxy_dp=J, range_m=rng,
                 truth_z_m=chunk.truth_z_m, nonlinearity=nl, linear_ok=np.isfinite(nl) & (nl <= linear_threshold))


def _refuse_unusable(st: np.ndarray, why: np.ndarray, resid: np.ndarray, cov: np.ndarray) -> None:
    """Rows ``ok`` whose residual is not finite or whose covariance is not finite and positive definite become
    error rows (in place): no row counts as a pair without a finite NEES."""
    ok = st == STATUS_OK
    a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    with np.errstate(invalid="ignore", over="ignore"):
        pd = np.isfinite(cov).all((1, 2)) & (a > 0) & (a * d - b * b > 0)
    for i in np.flatnonzero(ok & ~np.isfinite(resid).all(1)):
        st[i], why[i] = STATUS_ERROR, "residual not finite (truth or prediction beyond the float range)"
    for i in np.flatnonzero((st == STATUS_OK) & ~pd):
        st[i], why[i] = STATUS_ERROR, "ground covariance not finite and positive definite (no NEES)"


def refused_reasons(status_, reason) -> dict:
    """``{kind: count}`` of the error rows of some pairs, the kinds being their reasons with the values
    (numbers, quoted text, lists) masked as ``#`` (so "box [1.0, 2.0, ...]" rows count as one kind)."""
    out: dict[str, int] = {}
    for r in np.asarray(reason, dtype=object)[np.asarray(status_, dtype=object) == STATUS_ERROR]:
        k = reason_kind(str(r))
        out[k] = out.get(k, 0) + 1
    return out


_VALUE = re.compile(r"\[[^\]]*\]|'[^']*'|\"[^\"]*\"|(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.])")


def reason_kind(reason: str) -> str:
    """A reason with its values masked (``#``): the key of :func:`refused_reasons`."""
    return _VALUE.sub("#", reason)


def iter_pairs(chunks: Iterable[LabelChunk], budget, *, contact="bottom-centre", groups: GroupIndex | None = None,
               linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> Iterator[Pairs]:
    """:func:`build_pairs` over a stream of chunks (memory: one chunk at a time)."""
    groups = groups if groups is not None else GroupIndex()
    for ch in chunks:
        yield build_pairs(ch, budget, contact=contact, groups=groups, linear_threshold=linear_threshold)


def collect_pairs(chunks: Iterable[LabelChunk], budget, *, contact="bottom-centre", groups: GroupIndex | None = None,
                  linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> Pairs:
    """Every pair of a stream in memory: the input of ``footprint_uq.validation.fit.fit_budget``
    (``pairs.subset(pairs.usable)``: ``residual_m``, ``dxy_dp``, ``cov_object_m2``, ``group``)."""
    return Pairs.concatenate(list(iter_pairs(chunks, budget, contact=contact, groups=groups,
                                             linear_threshold=linear_threshold)))
