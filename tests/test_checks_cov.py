"""_checks.check_cov: the closed-form 2x2 test (the per-frame path) decides as the eigenvalue test does.

Every detection frame checks its pixel covariances; the 2x2 case skips LAPACK (issue 22's per-frame cost), so it
is held here to the general eigenvalue path over whole domains, edges included.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq._checks import _check_cov_2x2, _check_cov_eig, check_cov
from footprint_uq.errors import InputError

_exp = st.integers(min_value=-150, max_value=150)


def _outcome(fn, c):
    try:
        fn("c", c, 1e-12)
        return "ok"
    except InputError as e:
        return str(e)


@settings(max_examples=400, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), _exp, st.floats(0.0, 1.0))
def test_closed_form_decides_as_the_eigenvalues(v, e, skew):
    a, b, d = abs(v[0]), v[1], abs(v[3])
    c = np.array([[a, b], [b, d]]) * 10.0**e
    c[0, 1] *= 1.0 + 1e-10 * skew  # asymmetry within the accepted 1e-9 of the scale
    w = np.linalg.eigvalsh(c)
    scale = np.abs(c).max()
    if abs(w.min() + 1e-12 * scale) < 1e-14 * max(scale, 1e-300):
        return  # on the tolerance's edge itself: either answer is right
    assert _outcome(_check_cov_2x2, c) == _outcome(_check_cov_eig, c)


def test_batches_psd_singular_negative_and_asymmetric():
    rng = np.random.default_rng(7)
    L = rng.normal(size=(500, 2, 2))
    good = L @ np.swapaxes(L, -1, -2)
    singular = np.array([[4.0, 2.0], [2.0, 1.0]])  # rank 1
    np.testing.assert_array_equal(check_cov("p", good, 2), good)
    check_cov("p", np.stack([singular, np.zeros((2, 2))]), 2)
    bad = good.copy()
    bad[317] = [[1.0, 2.0], [2.0, 1.0]]  # eigenvalues 3 and -1
    with pytest.raises(InputError, match=r"p\[317\]: got 'min eigenvalue -1'"):
        check_cov("p", bad, 2)
    asym = good.copy()
    asym[42, 0, 1] += 1e-3 * np.abs(asym[42]).max()
    with pytest.raises(InputError, match=r"p\[42\].*non-symmetric"):
        check_cov("p", asym, 2)
    with pytest.raises(InputError, match=r"p\[1, 0, 1\]"):
        check_cov("p", np.stack([singular, [[1.0, np.nan], [np.nan, 1.0]]]), 2)
    # a (..., 2, 2) stack of any leading shape, and the general path for n > 2 unchanged
    check_cov("p", good.reshape(5, 100, 2, 2), 2)
    with pytest.raises(InputError, match="min eigenvalue"):
        check_cov("p", np.diag([1.0, -1.0, 1.0]), 3)


def test_extremes_of_the_float_range():
    big = np.array([[1e300, 0.0], [0.0, 1e300]])
    tiny = np.array([[1e-300, 0.0], [0.0, 1e-300]])
    check_cov("p", np.stack([big, tiny]), 2)
    with pytest.raises(InputError, match="min eigenvalue"):
        check_cov("p", np.array([[1e300, 1e300 * 1.5], [1e300 * 1.5, 1e300]]), 2)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), min_size=1, max_size=6), _exp,
       st.sampled_from([None, "nan", "inf", "asym"]), st.integers(0, 5))
def test_compiled_frame_check_finds_what_the_numpy_checks_refuse(mats, e, spoil, at):
    """FrameProcessor's compiled pass (fast.cov_checks) flags a frame exactly when check_cov refuses it."""
    from footprint_uq.fast.cov_checks import first_bad_cov2

    c = np.array([[[abs(v[0]), v[1]], [v[1], abs(v[3])]] for v in mats]) * 10.0**e
    i = at % len(c)
    if spoil == "nan":
        c[i, 1, 1] = np.nan
    elif spoil == "inf":
        c[i, 0, 1] = np.inf
    elif spoil == "asym":
        c[i, 0, 1] += 1e-6 * np.abs(c[i]).max() + 1e-300
    w = np.linalg.eigvalsh(np.where(np.isfinite(c), c, 0.0))[:, 0]
    scale = np.abs(np.where(np.isfinite(c), c, 0.0)).max((1, 2))
    if np.any(np.abs(w + 1e-12 * scale) < 1e-14 * np.maximum(scale, 1e-300)):
        return  # on the tolerance's edge itself
    refused = _outcome(lambda n, x, t: check_cov(n, x, 2, tol=t), c) != "ok"
    k = first_bad_cov2(np.ascontiguousarray(c), 1e-12)
    assert (k >= 0) == refused
    if k >= 0:  # the first matrix that fails on its own
        assert _outcome(_check_cov_2x2, c[k:k + 1]) != "ok" or not np.isfinite(c[k]).all()
        assert all(_outcome(_check_cov_2x2, c[j:j + 1]) == "ok" for j in range(k))


def test_frame_processor_refuses_bad_pixel_covariances_with_the_numpy_message():
    from footprint_uq import PanTiltCamera
    from footprint_uq.products.footprints import FrameProcessor

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=0.0, tilt_deg=20.0)
    fp = FrameProcessor(cam, "basler1")
    boxes = np.array([[0.0, 20.0, 0.8, 4.5, 1.8, 1.5, 0.3]] * 3)
    good = np.broadcast_to(np.eye(2), (3, 2, 2))  # a broadcast view (strides 0), as a detector may pass
    ref = fp.boxes3d(boxes, pixel_cov_px2=good.copy())
    np.testing.assert_allclose(fp.boxes3d(boxes, pixel_cov_px2=good).centre_cov_m2, ref.centre_cov_m2)
    for bad, msg in ((np.array([[1.0, 2.0], [2.0, 1.0]]), r"pixel_cov_px2\[1\]: got 'min eigenvalue -1'"),
                     (np.array([[1.0, 0.5], [0.0, 1.0]]), r"pixel_cov_px2\[1\]: got 'non-symmetric matrix'"),
                     (np.array([[1.0, 0.0], [0.0, np.nan]]), r"pixel_cov_px2\[1, 1, 1\]")):
        c = good.copy()
        c[1] = bad
        with pytest.raises(InputError, match=msg):
            fp.boxes3d(boxes, pixel_cov_px2=c)
        per_corner = np.repeat(c[:, None], 4, 1)  # (N, K, 2, 2)
        with pytest.raises(InputError, match=msg.replace(r"\[1\]", r"\[1, 0\]").replace(r"\[1, 1, 1\]",
                                                                                        r"\[1, 0, 1, 1\]")):
            fp.boxes3d(boxes, pixel_cov_px2=per_corner)
