"""The lens's valid domain: pinned fold radii, and over random lenses the domain is exactly where
undistortion answers (Hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

from footprint_uq.cameras.distortion import distort, undistort
from footprint_uq.cameras.lens_domain import MARGIN, lens_domain
from footprint_uq.errors import InputError


def test_pinned_fold_k1_only():
    # r_d = r - r^3 / 2: d/dr = 1 - 1.5 r^2 = 0 at r = sqrt(2/3) = 0.81650, r_d = sqrt(2/3) * 2/3 = 0.54433
    dom = lens_domain([-0.5, 0, 0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(dom.r_fold, np.sqrt(2 / 3), rtol=2 * MARGIN)
    np.testing.assert_allclose(dom.r_max_distorted, np.sqrt(2 / 3) * 2 / 3, rtol=3 * MARGIN)
    assert dom.limited and dom.star_shaped


def test_pinned_fold_wide_angle():
    # 1 + 3 k1 r^2 + 5 k2 r^4 = 0 -> r^2 = (-3 k1 - sqrt(9 k1^2 - 20 k2)) / (10 k2)
    k1, k2 = -0.33, 0.045
    r2 = (-3 * k1 - np.sqrt(9 * k1**2 - 20 * k2)) / (10 * k2)
    dom = lens_domain([k1, k2, 0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(dom.r_fold, np.sqrt(r2), rtol=2 * MARGIN)
    np.testing.assert_allclose(dom.r_max_distorted, np.sqrt(r2) * (1 + k1 * r2 + k2 * r2 * r2), rtol=3 * MARGIN)
    # just inside and just outside the largest distorted radius, along several directions
    rd = dom.r_max_distorted[0]
    ang = np.linspace(0, 2 * np.pi, 7)
    unit = np.stack([np.cos(ang), np.sin(ang)], -1)
    assert dom.contains_distorted(unit * rd * (1 - 1e-6)).all()
    assert not dom.contains_distorted(unit * rd * (1 + 1e-6)).any()
    assert undistort(unit * rd * (1 - 1e-6), dom.dist)[1].all()
    assert not undistort(unit * rd * (1 + 1e-6), dom.dist)[1].any()


def test_pincushion_and_no_distortion():
    assert not lens_domain(np.zeros(8)).limited
    assert lens_domain(np.zeros(8)).contains_distorted([[1e6, -1e6]]).all()
    dom = lens_domain([0.1, 0, 0, 0, 0, 0, 0, 0])  # never folds: capped at a distorted radius of tan(87 deg)
    cap = np.tan(np.deg2rad(87.0))
    np.testing.assert_allclose(dom.r_max_distorted, cap, rtol=10 * MARGIN)
    r = dom.r_fold[0]
    np.testing.assert_allclose(r * (1 + 0.1 * r * r), cap, rtol=4 * MARGIN)


def test_bad_coefficients_refused():
    with pytest.raises(InputError, match="dist"):
        lens_domain([np.nan, 0, 0, 0, 0, 0, 0, 0])
    with pytest.raises(InputError, match="dist"):
        lens_domain([0.1, 0.0])


lenses = st.tuples(st.floats(-0.45, 0.3), st.floats(-0.1, 0.1), st.floats(-0.01, 0.01), st.floats(-0.01, 0.01),
                   st.floats(-0.03, 0.03), st.floats(-0.1, 0.1), st.floats(-0.05, 0.05), st.floats(-0.02, 0.02))


@settings(max_examples=80, deadline=None)
@given(k=lenses, seed=st.integers(0, 2**32 - 1))
def test_every_answer_is_a_principal_root(k, seed):
    dom = lens_domain(k)
    rng = np.random.default_rng(seed)
    scale = 1.3 * float(np.max(dom.r_max_distorted)) if dom.limited else 2.0
    xd = rng.uniform(-scale, scale, (400, 2))
    xn, conv = undistort(xd, dom.dist)
    np.testing.assert_array_equal(dom.contains_distorted(xd), conv)
    # an answer re-distorts to the pixel and lies in the principal region; no answer is NaN
    err = np.abs(distort(xn[conv], dom.dist) - xd[conv]).max(-1)
    assert np.all(err <= 1e-13 * np.maximum(1.0, np.abs(xd[conv]).max(-1)))
    assert dom.contains_undistorted(xn[conv]).all()
    assert np.isnan(xn[~conv]).all()
    # beyond the quick filter's radius nothing answers
    far = np.hypot(xd[:, 0], xd[:, 1]) > 1.011 * np.max(dom.r_max_distorted)
    assert not conv[far].any()


@settings(max_examples=80, deadline=None)
@given(k=lenses, seed=st.integers(0, 2**32 - 1))
def test_whole_principal_region_is_answered(k, seed):
    """Every point of U (sampled out to 99.9 % of its boundary in each direction) is found again from its pixel."""
    dom = lens_domain(k)
    rng = np.random.default_rng(seed)
    a = rng.uniform(-np.pi, np.pi, 400)
    bins = np.clip(((a + np.pi) / (2 * np.pi) * (dom.angles_rad.size - 1)).astype(int), 0, dom.angles_rad.size - 2)
    edge = np.minimum(dom.r_fold[bins], dom.r_fold[bins + 1]) if dom.limited else np.full(a.size, 2.0)
    r = np.sqrt(rng.uniform(0, 1, a.size)) * 0.999 * edge
    x = np.stack([r * np.cos(a), r * np.sin(a)], -1)
    assert dom.contains_undistorted(x).all()
    xn, conv = undistort(distort(x, dom.dist), dom.dist)
    assert conv.all()
    np.testing.assert_allclose(xn, x, rtol=0, atol=1e-9 * max(1.0, float(np.max(r))))


@settings(max_examples=60, deadline=None)
@given(k=lenses, seed=st.integers(0, 2**32 - 1))
def test_principal_region_round_trip(k, seed):
    dom = lens_domain(k)
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, 0.999, 300) * np.min(dom.r_fold[np.isfinite(dom.r_fold)], initial=2.0)
    a = rng.uniform(-np.pi, np.pi, 300)
    x = np.stack([r * np.cos(a), r * np.sin(a)], -1)
    assert dom.contains_undistorted(x).all()
    xd = distort(x, dom.dist)
    xn, conv = undistort(xd, dom.dist)
    assert conv.all()
    np.testing.assert_allclose(xn, x, rtol=0, atol=1e-10)


def test_point_near_an_asymmetric_fold_is_answered():
    """Found by test_whole_principal_region_is_answered (Hypothesis): a point at 96 % of the fold radius of a lens
    with a tangential term is in U, but damped Newton stalled against U's boundary where the fold radius jumps
    between two angles (3.63 -> 1.53), so its pixel got no answer."""
    dom = lens_domain(np.array([-0.271484375, 0.03386106185448601, -0.009765625, 0, 0, 0, 0, 0.0]))
    a = 0.20207021
    x = 3.49991515 * np.array([[np.cos(a), np.sin(a)]])
    assert dom.contains_undistorted(x).all()
    xn, conv = undistort(distort(x, dom.dist), dom.dist)
    assert conv.all()
    np.testing.assert_allclose(xn, x, atol=1e-9 * 3.5)


def test_beyond_the_asymmetric_fold_no_point_is_found_again():
    """The same lens past the wall: from 0.225 rad on, every ray crosses the region where the determinant is negative
    (r = 1.53 .. 1.59 at 0.225 rad, 1.43 .. 1.68 at 0.5 rad), so the points beyond it are outside U; their pixels have
    no answer, or one on the near side of the fold (another root, in U)."""
    dom = lens_domain(np.array([-0.271484375, 0.03386106185448601, -0.009765625, 0, 0, 0, 0, 0.0]))
    a, r = np.meshgrid(np.linspace(0.225, 0.5, 12), np.linspace(1.7, 3.6, 12))
    x = np.stack([r * np.cos(a), r * np.sin(a)], -1).reshape(-1, 2)
    assert not dom.contains_undistorted(x).any()
    xn, conv = undistort(distort(x, dom.dist), dom.dist)
    assert dom.contains_undistorted(xn[conv]).all()
    assert np.all(np.abs(xn[conv] - x[conv]).max(-1) > 0.1)
    assert np.isnan(xn[~conv]).all()


def test_point_in_a_corner_of_the_table_is_answered():
    """Just past a step up of the boundary table (its bin reaches 10.385, the one before 10.334): damped Newton came
    from the lower bin and stalled on its arc, where the residual is least along the arc (before 2026-11-27)."""
    dom = lens_domain(np.array([-0.1488, 0.0114, -0.0131, -0.0187, 0.0076, 0.047, -0.0025, 0.0041]))
    a = -0.87129917  # 2e-6 rad past the bin's edge
    x = 10.37904735 * np.array([[np.cos(a), np.sin(a)]])
    assert dom.contains_undistorted(x).all()
    xn, conv = undistort(distort(x, dom.dist), dom.dist)
    assert conv.all()
    np.testing.assert_allclose(xn, x, atol=1e-9 * 10.4)


def _near_fold(k1, u, p1, p2):
    """A barrel lens whose radial part almost folds (k2 near 9 k1^2 / 20: d(r rad)/dr = 1 + 3 k1 r^2 + 5 k2 r^4 nearly
    touches 0); with a tangential term the Jacobian's determinant turns negative there over a range of angles only,
    so the fold radius jumps between two angles."""
    return np.array([k1, 0.45 * k1 * k1 * (1.0 + u), p1, p2, 0, 0, 0, 0.0])


near_fold_lenses = st.builds(_near_fold, st.floats(-0.45, -0.1), st.floats(-0.05, 0.15), st.floats(-0.02, 0.02),
                             st.floats(-0.02, 0.02))
strong_tangential_lenses = st.tuples(st.floats(-0.45, 0.3), st.floats(-0.1, 0.1), st.floats(-0.03, 0.03),
                                     st.floats(-0.03, 0.03), st.floats(-0.03, 0.03), st.floats(-0.1, 0.1),
                                     st.floats(-0.05, 0.05), st.floats(-0.02, 0.02))


def _table_points(dom, rng, n, lo, hi):
    """``n`` points in random directions at ``lo`` .. ``hi`` times U's boundary radius (its table read as the
    core reads it: the smaller of the two entries around the angle)."""
    m = dom.angles_rad.size - 1
    a = rng.uniform(-np.pi, np.pi, n)
    j = np.clip(((a + np.pi) / (2 * np.pi) * m).astype(int), 0, m - 1)
    r = rng.uniform(lo, hi, n) * np.minimum(dom.r_fold[j], dom.r_fold[j + 1])
    return np.stack([r * np.cos(a), r * np.sin(a)], -1)


def _corner_points(dom, rng, n):
    """``n`` points of U in the corners of its boundary table: in the first (last) 15 % of a bin that reaches
    farther than the bin before (after) it, between the two radii."""
    m = dom.angles_rad.size - 1
    rb = np.minimum(dom.r_fold[:-1], dom.r_fold[1:])  # each bin's radius (the bins wrap around at +-pi)
    lower = {1: np.roll(rb, 1), -1: np.roll(rb, -1)}  # the bin before, after
    steps = [(j, side) for side in (1, -1) for j in np.flatnonzero(rb * (1 - 1e-4) > lower[side])]
    if not steps:
        return np.empty((0, 2))
    j, side = np.array(steps).T[:, rng.integers(0, len(steps), n)]
    f = rng.uniform(0.0, 0.15, n)
    a = dom.angles_rad[j] + np.where(side == 1, f, 1.0 - f) * (2 * np.pi / m)
    r = rng.uniform(np.where(side == 1, lower[1][j], lower[-1][j]), rb[j] * (1 - 1e-4))
    return np.stack([r * np.cos(a), r * np.sin(a)], -1)


def _beyond_a_thin_fold(x, k):
    """Whether the Jacobian's determinant is <= 0 somewhere on the segment from the axis to each point (2e5
    samples): a fold thinner than the radial scan of U's table, which the table missed before fold_radius searched
    the scan's dips (test_a_fold_thinner_than_the_scan_is_found)."""
    t = np.linspace(0.0, 1.0, 200_001)[1:, None]
    return np.array([np.any(np.linalg.det(distort(t * p, k, get_gradients=True)[1]) <= 0) for p in x], dtype=bool)


@hypothesis_seed(20261127)
@settings(max_examples=150, deadline=None)
@given(k=st.one_of(near_fold_lenses, strong_tangential_lenses), seed=st.integers(0, 2**32 - 1))
def test_near_a_strongly_asymmetric_fold_all_of_u_is_answered_and_nothing_beyond(k, seed):
    """Lenses whose fold radius varies strongly with the angle (tangential terms): every point of U near its boundary
    -- 90 .. 99.9 % of the table's radius, and the corners of the table -- is found again from its pixel; the
    points just beyond (100.1 .. 102 %) are not: their pixel has no answer, or its answer is another root, in U."""
    dom = lens_domain(k)
    assume(dom.limited)
    rng = np.random.default_rng(seed)
    x = np.concatenate([_table_points(dom, rng, 300, 0.9, 0.999), _corner_points(dom, rng, 200)])
    assert dom.contains_undistorted(x).all()
    xd, J, _ = distort(x, dom.dist, get_gradients=True)
    xn, conv = undistort(xd, dom.dist)
    assert conv.all(), x[~conv]
    assert dom.contains_undistorted(xn).all()
    # x again, to the problem's conditioning (the residual tolerance 1e-14 |x_d| over J's smallest singular value)
    # (before fold_radius found folds thinner than its scan, some x lay beyond one and came back as the root before)
    sigma = np.linalg.svd(J, compute_uv=False)[:, -1]
    atol = 1e-9 * np.maximum(1.0, np.abs(x).max(-1)) + 1e-12 * np.maximum(1.0, np.abs(xd).max(-1)) / sigma
    other = np.abs(xn - x).max(-1) > atol
    assert not other.any(), x[other]
    out = _table_points(dom, rng, 300, 1.001, 1.02)
    assert not dom.contains_undistorted(out).any()
    xo, conv = undistort(distort(out, dom.dist), dom.dist)
    assert dom.contains_undistorted(xo[conv]).all()
    assert np.all(np.abs(xo[conv] - out[conv]).max(-1) > 1e-6 * np.abs(out[conv]).max(-1))


#: near-fold lenses within 0.2 % of the touch (k2 = 9 k1^2 / 20) and tangential terms up to 1e-4: folds of a
#: few thousandths in some directions only, thinner than fold_radius's scan
thin_fold_lenses = st.builds(_near_fold, st.floats(-0.45, -0.1), st.floats(-0.002, 0.002), st.floats(-1e-4, 1e-4),
                             st.floats(-1e-4, 1e-4))


@hypothesis_seed(20261128)
@settings(max_examples=30, deadline=None)
@given(k=st.one_of(thin_fold_lenses, near_fold_lenses, strong_tangential_lenses), offset=st.floats(0.0, 2 * np.pi / 16))
def test_fold_radius_leaves_no_fold_inside_along_its_ray(k, offset):
    """Soundness of the scan against a denser one it did not produce (40,000 radii per direction, 16 directions):
    no point of the segment from the axis to ``fold_radius`` (exclusive; checked up to r = 3, where the near-fold
    lenses fold) is folded (determinant, radial factor or
    its denominator <= 0), and, where the scan stopped before its end, the lens is not regular just beyond (or its
    determinant touches 0 there)."""
    from footprint_uq.fast import core

    for angle in offset + np.arange(16) * (2 * np.pi / 16):
        c, s = float(np.cos(angle)), float(np.sin(angle))
        r_f = core.fold_radius(k, c, s, 19.0, 4096)
        t = np.linspace(0.0, min(r_f, 3.0) * (1.0 - 1e-9), 40_001)[1:]
        J = distort(t[:, None] * np.array([c, s]), k, get_gradients=True)[1]
        r2 = t * t
        num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
        den = 1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
        # (> -1e-12: a lens whose determinant only touches 0, e.g. k2 = 9 k1^2 / 20 exactly, has rounding noise there)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        assert np.all(det > -1e-12) and np.all(num / den > 0.0) and np.all(den > 0.0), (angle, t[det <= -1e-12][:3])
        if r_f < 19.0:  # stopped by something real: not regular, or (a touch) the determinant ~0, just beyond
            beyond = np.linspace(r_f, r_f * (1.0 + 1e-6) + 1e-12, 50)
            assert not all(core._regular(b * c, b * s, k) and core._positivity(b, c, s, k) > 1e-9 for b in beyond)


def test_a_fold_thinner_than_the_scan_is_found():
    """Found by the sweep above (with other seeds): k2 = 9 k1^2 / 20 makes d(r rad)/dr touch 0 at r = 1.217, and a
    tangential term of 1e-5 turns the determinant negative on a sliver 0.0023 wide there (r = 1.2160 .. 1.2183 in
    this direction); U's table missed it in some directions (before fold_radius searched the scan's dips), so a
    point just beyond the sliver counted as in U (its pixel has a second root, 0.0036 nearer the axis, which is the
    one undistortion returns)."""
    k = np.array([-0.45, 0.45 * 0.45**2, 0, 1e-5, 0, 0, 0, 0.0])
    x = np.array([[-0.05955316, -1.2170719]])
    assert _beyond_a_thin_fold(x, k).all()
    assert not lens_domain(k).contains_undistorted(x).any()
