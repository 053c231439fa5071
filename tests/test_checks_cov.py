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
