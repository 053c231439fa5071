"""The budget fit (footprint_uq.validation.fit): likelihood and score against a dense reference,
recovery of a known budget from synthetic campaigns (the calibration error drawn once per camera),
identifiability (one camera; collinear terms), cross-validated coverage, files and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq.errors import InputError
from footprint_uq.uncertainty.budget import ErrorBudget, load_budget
from footprint_uq.validation import fit as F
from footprint_uq.validation.campaigns import synthetic_campaign, synthetic_campaign_chunks

TRUTH = {"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2}
FREE = ["pan_deg", "tilt_deg", "height_m", "object_m"]


def _small_case(seed=1, n=12):
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(n, 2))
    J = rng.normal(size=(n, 2, 22))
    L = rng.normal(size=(n, 2, 2)) * 0.3
    R = L @ np.swapaxes(L, 1, 2) + 0.05 * np.eye(2)
    g = rng.integers(0, 3, n)
    return r, J, R, g


def _dense_loglik(r, J, R, g, S, s2, reml, fit_bias=True, gz2=0.0):
    """The textbook Gaussian (restricted) log-likelihood with the full (2N, 2N) covariance."""
    n = r.shape[0]
    C = np.zeros((2 * n, 2 * n))
    for i in range(n):
        for j in range(n):
            if g[i] == g[j]:
                C[2 * i:2 * i + 2, 2 * j:2 * j + 2] = J[i] @ S @ J[j].T
        jg = J[i][:, 19]
        C[2 * i:2 * i + 2, 2 * i:2 * i + 2] += R[i] + s2 * np.eye(2) + gz2 * np.outer(jg, jg)
    X, y = np.tile(np.eye(2), (n, 1)), r.ravel()
    Ci = np.linalg.inv(C)
    Phi = X.T @ Ci @ X
    beta = np.linalg.solve(Phi, X.T @ Ci @ y) if fit_bias else np.zeros(2)
    e = y - X @ beta
    ll = -0.5 * (np.linalg.slogdet(C)[1] + e @ Ci @ e + 2 * n * np.log(2 * np.pi))
    return ll - (0.5 * np.linalg.slogdet(Phi)[1] if reml and fit_bias else 0.0), beta


@pytest.mark.parametrize("reml", [False, True])
@pytest.mark.parametrize("fit_bias", [False, True])
def test_woodbury_likelihood_and_score_match_the_dense_reference(reml, fit_bias):
    r, J, R, g = _small_case()
    terms = ("pan_deg", "height_m", "position_m")
    A = np.stack([F._unit_covariance(t) for t in terms])
    Sf = np.zeros((22, 22))
    Sf[0, 0] = Sf[1, 1] = Sf[0, 1] = Sf[1, 0] = 0.3
    data = F._prepare(r, J, R, g, np.arange(22))
    E = F._object_shapes(J[data.order], list(F.OBJECT_TERMS))
    model = F._Model(data, Sf, A, E, fit_bias, reml)
    v = np.array([0.2, 0.5, 0.1, 0.3, 0.15])
    ll, score, beta, _ = model.evaluate(v)

    def dense(x):
        return _dense_loglik(r, J, R, g, Sf + np.tensordot(x[:3], A, 1), x[3], reml, fit_bias, gz2=x[4])

    ll_d, beta_d = dense(v)
    assert ll == pytest.approx(ll_d, rel=1e-10, abs=1e-10)
    np.testing.assert_allclose(beta, beta_d, rtol=1e-9, atol=1e-12)
    h = 1e-6
    num = np.array([(dense(v + h * e)[0] - dense(v - h * e)[0]) / (2 * h) for e in np.eye(5)])
    np.testing.assert_allclose(score, num, rtol=1e-6, atol=1e-7)


def test_public_log_likelihood_is_the_dense_one_of_a_budget():
    r, J, R, g = _small_case(seed=4)
    b = ErrorBudget(pan_deg=2.0, height_m=0.5, focal_px=3.0)
    ll = F.log_likelihood(r, J, R, g, b, object_sigma_m=0.2)
    assert ll == pytest.approx(_dense_loglik(r, J, R, g, b.param_covariance(), 0.04, True)[0], rel=1e-10)


def test_fit_recovers_each_sigma_inside_its_interval_in_90_percent_of_campaigns():
    """40 seeded campaigns of 10 cameras x 40 objects (200 campaigns: bench/fit_recovery.py)."""
    truth = {**TRUTH, "object_m": 0.3}
    hits, called = dict.fromkeys(FREE, 0), dict.fromkeys(FREE, 0)
    n = 40
    for seed in range(n):
        c = synthetic_campaign(TRUTH, 10, 40, object_sigma_m=0.3, bias_m=(0.2, -0.1), seed=seed)
        fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=FREE)
        assert all(t.status in ("identified", "weakly identified") for t in fit.terms.values())
        for k in FREE:  # an interval is a promise only where the term is called identified (test_fit_identification)
            lo, hi = fit.terms[k].ci95
            called[k] += fit.terms[k].status == "identified"
            hits[k] += fit.terms[k].status == "identified" and lo <= truth[k] <= hi
    assert min(called.values()) >= 0.75 * n, called
    assert all(hits[k] >= 0.9 * called[k] for k in FREE), (hits, called)


def test_bias_and_object_sigma_recovered_on_a_large_campaign():
    c = synthetic_campaign(TRUTH, 12, 80, object_sigma_m=0.3, bias_m=(0.3, -0.2), seed=11)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=FREE)
    sd = np.sqrt(np.diag(fit.bias_cov_m2))
    assert np.all(np.abs(fit.bias_m - [0.3, -0.2]) < 3 * sd)
    assert abs(fit.object_sigma_m - 0.3) < 3 * fit.terms["object_m"].se
    assert fit.converged and np.isfinite(fit.log_likelihood)


def test_one_camera_cannot_give_a_calibration_sigma():
    c = synthetic_campaign(TRUTH, 1, 200, object_sigma_m=0.3, seed=2)
    base = ErrorBudget(pan_deg=0.07)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=FREE, base_budget=base)
    for k in ("pan_deg", "tilt_deg", "height_m"):
        assert fit.terms[k].status == "unidentifiable" and "1 calibration group" in fit.terms[k].note
    assert fit.terms["object_m"].status == "identified"
    b = fit.to_budget()
    assert b.pan_deg == 0.07 and b.height_m == 0.0  # the base budget's values, not an estimate


def test_terms_the_data_cannot_tell_apart_are_merged_not_split():
    """Camera height and ground offset move every point identically (on flat ground): one direction."""
    c = synthetic_campaign({"height_m": 0.3}, 8, 40, seed=3)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=["height_m", "ground_height_m"])
    st = {k: t.status for k, t in fit.terms.items()}
    assert st == {"height_m": "merged", "ground_height_m": "merged"}
    keep = next(k for k, t in fit.terms.items() if t.sigma > 0)
    other = next(k for k in fit.terms if k != keep)
    assert fit.terms[other].sigma == 0.0 and fit.terms[other].merged_with == (keep,)
    lo, hi = fit.terms[keep].ci95
    assert lo <= 0.3 <= hi
    assert "merged" in fit.to_budget().description


def test_cross_validated_coverage_is_near_nominal_for_a_correct_model():
    c = synthetic_campaign(TRUTH, 6, 30, object_sigma_m=0.3, seed=5)
    for by in ("group", "object"):
        cv = F.cross_validate(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=FREE, by=by,
                              n_folds=6 if by == "object" else None, min_groups=2)
        assert cv.n_folds == 6 and np.isfinite(cv.nees).all()
        se = np.sqrt(cv.levels * (1 - cv.levels) / cv.nees.size)
        # held-out groups share their calibration draw: the group fold's spread is larger than binomial
        np.testing.assert_array_less(np.abs(cv.coverage - cv.levels), 4 * se + 0.02)


def test_a_fit_without_the_object_term_under_covers_when_it_is_needed():
    c = synthetic_campaign(TRUTH, 6, 30, object_sigma_m=0.5, seed=6)
    cv = F.cross_validate(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=FREE[:3], by="object",
                          n_folds=5)
    assert cv.coverage[2] < 0.85


def test_budget_file_and_summary_round_trip(tmp_path):
    c = synthetic_campaign(TRUTH, 6, 30, object_sigma_m=0.3, seed=7)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=["pan_deg", "position_m", "object_m"],
                       base_budget="basler1")
    paths = fit.write(tmp_path / "budget.yaml", tmp_path / "fit.json")
    b = load_budget(paths[0])
    assert b == fit.to_budget(name="fitted")
    assert b.position_m[0] == b.position_m[1] == pytest.approx(fit.terms["position_m"].sigma)
    assert b.focal_px == ErrorBudget.preset("basler1").focal_px  # fixed terms come from the base budget
    import json

    d = json.loads((tmp_path / "fit.json").read_text())
    assert set(d["terms"]) == {"pan_deg", "position_m", "object_m"} and d["n_groups"] == 6


def test_ground_slope_is_fitted_in_degrees():
    c = synthetic_campaign({"ground_slope_deg": 0.5, "pan_deg": 0.05}, 12, 40, seed=8)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=["ground_slope_deg", "pan_deg"])
    t = fit.terms["ground_slope_deg"]
    assert t.ci95[0] <= 0.5 <= t.ci95[1] and 0.2 < t.sigma < 1.0


@pytest.mark.parametrize("kw, field", [
    ({"free": ["imaging_px"]}, "free"), ({"free": ["nonsense"]}, "free"), ({"free": []}, "free"),
    ({"free": ["pan_deg"], "method": "bayes"}, "method"), ({"free": ["pan_deg"], "min_groups": 0}, "min_groups"),
])
def test_bad_options_are_one_line_errors(kw, field):
    c = synthetic_campaign(TRUTH, 3, 10, seed=0)
    with pytest.raises(InputError) as e:
        F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, **kw)
    assert e.value.field == field and "\n" not in str(e.value)


def test_bad_arrays_name_the_field_and_row():
    c = synthetic_campaign(TRUTH, 3, 10, seed=0)
    r = c.residual_m.copy()
    r[4, 1] = np.nan
    with pytest.raises(InputError, match=r"residual_m\[4\]"):
        F.fit_budget(r, c.dxy_dp, c.cov_object_m2, c.group, free=["pan_deg"])
    with pytest.raises(InputError, match="dxy_dp"):
        F.fit_budget(c.residual_m, c.dxy_dp[:, :, :20], c.cov_object_m2, c.group, free=["pan_deg"])
    R = c.cov_object_m2.copy()
    R[2] = [[1.0, 0.0], [0.0, -1.0]]
    with pytest.raises(InputError, match=r"cov_object_m2\[2\]"):
        F.fit_budget(c.residual_m, c.dxy_dp, R, c.group, free=["pan_deg"])
    with pytest.raises(InputError, match="by"):
        F.cross_validate(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=["pan_deg"], by="camera")


# ---------------------------------------------------------------------------------------------
# the compact / streamed path (fit_compact: per-group sums, records spilled in parts) = the dense reference
# ---------------------------------------------------------------------------------------------
def _dense_model(data, Sf, A, kinds, fit_bias, reml):
    """The dense reference model (every per-object array, rows sorted by group) on compact records."""
    R = np.stack([data.R3[:, [0, 1]], data.R3[:, [1, 2]]], 1)
    order = np.argsort(data.gid, kind="stable")
    gid = data.gid[order]
    starts = np.flatnonzero(np.r_[True, gid[1:] != gid[:-1]])
    d = F._Data(data.r[order], data.U[order], R[order], starts, gid, order, data.labels, data.cols)
    E = np.stack([np.broadcast_to(np.eye(2), (data.n, 2, 2)) if k == 0 else
                  data.jg[:, :, None] * data.jg[:, None, :] for k in kinds])[:, order] \
        if len(kinds) else np.zeros((0, data.n, 2, 2))
    return F._Model(d, Sf, A, E, fit_bias, reml)


@pytest.mark.parametrize("reml", [False, True])
def test_compact_likelihood_and_score_equal_the_dense_ones(reml):
    c = synthetic_campaign(TRUTH, 5, 30, object_sigma_m=0.3, seed=21)
    free = ["pan_deg", "height_m", "object_m", "object_ground_m"]
    setup = F._setup(free, "basler1", "reml", 3)
    data = F.compact_inputs([(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group)], free=free, base_budget="basler1")
    A, Sf = setup.A[:, data.cols][:, :, data.cols], setup.Sf[np.ix_(data.cols, data.cols)]
    v = np.array([3e-6, 0.04, 0.09, 0.01])
    a = F.CompactModel(data, Sf, A, [0, 1], True, reml).evaluate(v)
    b = _dense_model(data, Sf, A, [0, 1], True, reml).evaluate(v)
    assert a[0] == pytest.approx(b[0], rel=1e-12)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-9, atol=1e-9 * np.abs(b[1]).max())
    np.testing.assert_allclose(a[2], b[2], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("free, method", [(FREE, "reml"), (["pan_deg", "object_m", "object_ground_m"], "ml")])
def test_compact_fit_equals_the_dense_reference_fit(monkeypatch, free, method):
    """The whole fit (optimiser, information, intervals, identifiability) with the compact model and with the
    dense reference model in its place: the same estimates to 1e-8 relative."""
    c = synthetic_campaign(TRUTH, 8, 40, object_sigma_m=0.3, bias_m=(0.1, 0.0), seed=22)
    args = (c.residual_m, c.dxy_dp, c.cov_object_m2, c.group)
    fast = F.fit_budget(*args, free=free, method=method)
    monkeypatch.setattr(F, "CompactModel", _dense_model)
    ref = F.fit_budget(*args, free=free, method=method)
    assert fast.log_likelihood == pytest.approx(ref.log_likelihood, rel=1e-12)
    np.testing.assert_allclose(fast.bias_m, ref.bias_m, rtol=1e-8, atol=1e-12)
    for k, t in ref.terms.items():
        u = fast.terms[k]
        assert (u.status, u.merged_with) == (t.status, t.merged_with)
        np.testing.assert_allclose([u.sigma, u.se, *u.ci95], [t.sigma, t.se, *t.ci95], rtol=1e-8, atol=1e-12)


def test_records_spilled_in_parts_give_the_same_fit_and_cross_validation(tmp_path):
    free = ["pan_deg", "tilt_deg", "object_m", "object_ground_m"]
    chunks = [x[:4] for x in synthetic_campaign_chunks(TRUTH, 6, 50, object_sigma_m=0.3, seed=3, batch=20)]
    mem = F.compact_inputs(chunks, free=free, memory_pairs=None)
    spilled = F.compact_inputs(chunks, free=free, memory_pairs=70)
    assert isinstance(mem, F.CompactPairs) and not isinstance(spilled, F.CompactPairs) and spilled.n == mem.n == 300
    a, b = F.fit_compact(mem, free=free), F.fit_compact(spilled, free=free)
    for k in a.terms:
        np.testing.assert_allclose([b.terms[k].sigma, *b.terms[k].ci95], [a.terms[k].sigma, *a.terms[k].ci95],
                                   rtol=1e-10)
    cv_a = F.cross_validate_compact(mem, free=free, max_pairs=120, seed=4)
    cv_b = F.cross_validate_compact(spilled, free=free, max_pairs=120, seed=4)
    np.testing.assert_allclose(cv_b.nees, cv_a.nees, rtol=1e-10)  # NaN where the same rows are left out
    d = cv_a.to_dict()
    assert d["subsampled"] and d["n_sampled"] == d["n"] == 120 and d["n_pairs"] == 300
    folder = spilled.folder
    del spilled
    import gc

    gc.collect()
    assert not __import__("os").path.exists(folder)  # the temporary parts go with the records


def test_a_bad_row_in_a_later_chunk_is_named_by_its_global_number():
    c = synthetic_campaign(TRUTH, 3, 10, seed=0)
    R = c.cov_object_m2.copy()
    R[17] = [[1.0, 0.0], [0.0, -1.0]]
    chunks = [(c.residual_m[s], c.dxy_dp[s], R[s], c.group[s]) for s in (slice(0, 12), slice(12, None))]
    with pytest.raises(InputError, match=r"cov_object_m2\[17\]"):
        F.compact_inputs(chunks, free=["pan_deg"])
