"""Large GCP tables (issue 35, part 8b): the PnP starts come from a spread subset of the points
(``START_POINTS``); the solve from those starts is the solve from starts on every point.  (Speed:
``bench/bench_gcp_large.py``, 10,000 points end to end; the table limit ``MAX_POINTS`` is tested in
tests/test_calibration_gcp.py.)"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from footprint_uq.calibration import gcp as G
from gcp_campaigns import campaign


@pytest.mark.parametrize("known", [True, False])
def test_starts_from_a_subset_solve_the_same_camera(known, monkeypatch):
    rng = np.random.default_rng(35)
    cam, g, intr, _ = campaign(rng, known_intrinsics=known)
    size = cam.image_size_px
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        monkeypatch.setattr(G, "START_POINTS", 10**9)  # starts from every point (the behaviour below the limit)
        full = G.solve_gcp(g, size, intrinsics=intr, leave_one_out=False)
        n = len(g.uv_px)
        assert n >= 6
        monkeypatch.setattr(G, "START_POINTS", 5 if known else 6)  # starts from a few of them
        sub_starts = G._initial_params(g.uv_px, g.xyz_world_m, size, None if intr is None else intr.K,
                                       None if intr is None else intr.dist)
        sub = G.solve_gcp(g, size, intrinsics=intr, leave_one_out=False)
    assert len(sub_starts) >= 1
    sigma = full.sigma_params()
    used = sigma > 0
    np.testing.assert_array_less(np.abs(sub.params - full.params)[used] / sigma[used], 1e-3)
    np.testing.assert_allclose(sub.cov_params, full.cov_params, rtol=1e-4, atol=1e-12)
    assert sub.usable == full.usable and sub.chi2 == pytest.approx(full.chi2, rel=1e-9)


def test_the_subset_is_spread_over_the_rows(monkeypatch):
    """The starts see the table's first and last rows (an evenly spread subset, not its head)."""
    seen = {}

    def spy(xyz, uv, K, dist):
        seen["uv"] = uv.copy()
        return []

    monkeypatch.setattr(G, "START_POINTS", 10)
    monkeypatch.setattr(G, "_pnp_candidates", spy)
    uv = np.c_[np.arange(100.0), np.arange(100.0)]
    with pytest.raises(G.InputError):  # no candidate at all: refused (after the subset was taken)
        G._initial_params(uv, np.c_[uv, np.zeros(100)], (1920, 1080), np.eye(3), np.zeros(5))
    assert len(seen["uv"]) == 10 and seen["uv"][0, 0] == 0 and seen["uv"][-1, 0] == 99
