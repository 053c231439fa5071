"""Fits that keep their word (issue 35, part 6): a term is "identified" only where its 95 % interval can be
trusted (Satterthwaite's degrees of freedom, the variance inflation by the other terms, the profile likelihood at
the interval's ends, the principal point's confounding with the angles), else "weakly identified"; ``converged``
and the message never contradict, a fit that did not converge says so on stderr; no usable truth is one line and
exit status 2.  The 200-campaign figures: bench/fit_recovery.py (bench/results/fit_recovery.md)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq.cli.main import main
from footprint_uq.validation import fit as F
from footprint_uq.validation.campaigns import synthetic_campaign

ROPE3D = Path(__file__).resolve().parent / "data" / "rope3d-demo"
DEFAULT_TRUTH = {"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2}
DEFAULT_FREE = ["pan_deg", "tilt_deg", "height_m", "object_m"]
ALL_TRUTH = {"focal_px": 20.0, "principal_point_px": [10.0, 10.0], "position_m": [0.3, 0.3], "height_m": 0.2,
             "pan_deg": 0.1, "tilt_deg": 0.05, "roll_deg": 0.05, "ground_height_m": 0.05, "ground_slope_deg": 0.1}
ALL_FREE = [*F.FITTABLE_TERMS, "object_m"]


def _truth(budget: dict) -> dict:
    return {**{k: float(v[0] if isinstance(v, list) else v) for k, v in budget.items()}, "object_m": 0.3}


def test_identified_intervals_hold_the_truth_in_8_camera_campaigns():
    """30 seeded campaigns of 8 cameras x 120 objects, the default terms (200: bench/fit_recovery.py)."""
    truth, hits, called = _truth(DEFAULT_TRUTH), dict.fromkeys(DEFAULT_FREE, 0), dict.fromkeys(DEFAULT_FREE, 0)
    for seed in range(30):
        c = synthetic_campaign(DEFAULT_TRUTH, 8, 120, object_sigma_m=0.3, bias_m=(0.2, -0.1), seed=seed)
        fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=DEFAULT_FREE)
        assert fit.converged == fit.message.startswith("converged")
        for k, t in fit.terms.items():
            assert t.status in ("identified", "weakly identified", "merged")
            assert (t.status == "weakly identified") == ("not to be trusted" in t.note)
            if t.status == "identified":
                called[k] += 1
                hits[k] += t.ci95[0] <= truth[k] <= t.ci95[1]
    assert min(called.values()) >= 20, called
    assert all(hits[k] >= 0.9 * called[k] for k in hits), (hits, called)


@pytest.mark.slow
def test_with_every_term_free_the_angles_confounded_with_the_principal_point_are_never_identified():
    """Every term free (8 cameras x 120 objects): the principal point, pan and tilt cannot be told apart well
    enough for an interval; the terms still called identified hold the truth."""
    truth, hits, called = _truth(ALL_TRUTH), 0, 0
    # seeds 1000, 1008, 1017 and 1054: campaigns where pan or tilt passed every other check with an interval that
    # excluded the truth (found while tuning the checks; without fit.CONFOUNDED this test fails on them)
    for seed in (1, 2, 1000, 1008, 1017, 1054):
        c = synthetic_campaign(ALL_TRUTH, 8, 120, object_sigma_m=0.3, seed=seed)
        fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=ALL_FREE)
        d = fit.to_dict()["terms"]
        for k in ("pan_deg", "tilt_deg", "roll_deg"):
            assert fit.terms[k].status in ("weakly identified", "merged"), (k, fit.terms[k])
            assert d[k]["status"] == fit.terms[k].status
        assert fit.terms["height_m"].status == "merged" or fit.terms["ground_height_m"].status == "merged"
        for k, t in fit.terms.items():
            if t.status == "identified":
                called += 1
                hits += t.ci95[0] <= truth[k] <= t.ci95[1]
                assert t.dof >= F.MIN_DOF and t.vif <= F.MAX_VIF
    assert called >= 8 and hits >= called - 1, (hits, called)


def test_an_exact_merge_leaves_the_other_intervals_alone_an_approximate_one_does_not():
    """Camera height and ground offset have the same effect on flat ground (an exact merge: pan and the per-object
    term stay identified); with every term free, seed 7 merges roll, ground slope, pan and the principal point,
    whose effects differ: the terms left are weakly identified, their intervals conditional on that merge."""
    c = synthetic_campaign({"height_m": 0.3, "pan_deg": 0.1}, 8, 60, object_sigma_m=0.3, seed=3)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group,
                       free=["height_m", "ground_height_m", "pan_deg", "object_m"])
    assert fit.terms["height_m"].status == fit.terms["ground_height_m"].status == "merged"
    assert fit.terms["pan_deg"].status == fit.terms["object_m"].status == "identified", fit.terms
    c = synthetic_campaign(ALL_TRUTH, 8, 120, object_sigma_m=0.3, seed=7)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=ALL_FREE)
    assert fit.terms["roll_deg"].status == "merged" and "ground_slope_deg" in fit.terms["roll_deg"].merged_with
    for k in ("focal_px", "position_m", "object_m"):
        assert fit.terms[k].status == "weakly identified" and "merged terms whose effects differ" in fit.terms[k].note


def test_profile_deviance_is_the_likelihood_drop_with_the_others_refitted():
    c = synthetic_campaign(DEFAULT_TRUTH, 8, 60, object_sigma_m=0.3, seed=4)
    data = F.compact_inputs([(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group)], free=DEFAULT_FREE)
    setup = F._setup(DEFAULT_FREE, None, "reml", 3)
    A = setup.A[:, setup.cols][:, :, setup.cols]
    model = F.CompactModel(data, setup.Sf[np.ix_(setup.cols, setup.cols)], A, np.array([0]), True, True)
    scale = F._scales(data, A, np.array([0]))
    v, ok, _ = F._optimise(model, scale, np.full(4, 0.5))
    ll = model.evaluate(v, grad=False)[0]
    assert ok
    for j in range(4):
        for factor in (0.5, 2.0):
            held = v.copy()
            held[j] *= factor
            fixed = 2 * (ll - model.evaluate(held, grad=False)[0])   # the others held at the estimate
            prof = F._profile_deviance(model, v, scale, j, held[j], ll)
            assert -1e-9 <= prof <= fixed + 1e-9
    assert F._profile_deviance(model, v, scale, 0, v[0], ll) == pytest.approx(0.0, abs=1e-6)


def test_a_flat_profile_makes_a_term_weakly_identified(monkeypatch):
    """The check is live: an interval judged against a deviance it cannot reach is not trusted."""
    c = synthetic_campaign(DEFAULT_TRUTH, 8, 60, object_sigma_m=0.3, seed=2)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=DEFAULT_FREE)
    assert fit.terms["height_m"].status == "identified"
    monkeypatch.setattr(F, "PROFILE_DEVIANCE", 1e6)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=DEFAULT_FREE)
    assert all(t.status == "weakly identified" and "profile likelihood is flat" in t.note
               for t in fit.terms.values()), fit.terms


def test_converged_and_message_never_contradict(monkeypatch):
    c = synthetic_campaign(DEFAULT_TRUTH, 6, 40, object_sigma_m=0.3, seed=1)
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=DEFAULT_FREE)
    assert fit.converged and fit.message.startswith("converged: projected score")
    monkeypatch.setattr(F, "CONVERGED_SCORE", 0.0)  # a score no fit reaches
    fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=DEFAULT_FREE)
    assert not fit.converged and fit.message.startswith("not converged")
    assert "Converged" not in fit.message and fit.to_dict()["converged"] is False
    msg = F._convergence_message(False, 2e-5, "Converged (|f_n-f_(n-1)| ~= 0)")
    assert msg.startswith("not converged") and "Converged" not in msg and "stopped" in msg


def test_a_fit_that_did_not_converge_says_so_on_stderr_and_in_fit_json(tmp_path, monkeypatch):
    monkeypatch.setattr(F, "CONVERGED_SCORE", 0.0)
    r = CliRunner().invoke(main, ["calibrate", "budget", "--labels", str(ROPE3D), "--out", str(tmp_path / "f"),
                                  "--budget", "basler1@deg", "--free", "object_m", "--no-cv"])
    assert r.exit_code == 0, r.output
    assert "warning: the fit did not converge (not converged" in r.stderr and "converged False" in r.stdout
    d = json.loads((tmp_path / "f" / "fit.json").read_text())["fit"]
    assert d["converged"] is False and d["message"].startswith("not converged")


def test_a_fit_with_no_usable_truth_is_one_line_and_exit_2(tmp_path):
    labels = tmp_path / "no-truth"
    shutil.copytree(ROPE3D, labels)
    f = next((labels / "label_2").glob("*.txt"))
    f.write_text("\n".join(" ".join(p[:11] + ["0", "0", "0"] + p[14:]) for p in
                           (ln.split() for ln in f.read_text().splitlines())) + "\n")
    for contact in ("bottom-centre", "footprint-centre"):
        r = CliRunner().invoke(main, ["calibrate", "budget", "--labels", str(labels), "--out", str(tmp_path / "o"),
                                      "--no-cv", "--contact", contact])
        assert r.exit_code == 2, r.output
        assert "at least 2 usable detection/truth pairs (found 0" in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "internal error" not in r.stderr
