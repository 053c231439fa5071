"""The IMM's own parameters fitted (issue 36, part 1; tracking/imm_fit.py, docs/motion-fit.md section 2): the
profile interval pinned, the fit's decisions on constructed likelihoods, the members, the motion section's new keys,
`calibrate motion --modes imm`, and seeded braking campaigns."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq.errors import ConfigError
from footprint_uq.io import save_camera
from footprint_uq.tracking.imm_fit import ImmGrid, fit_imm_class, profile_interval, run_imm_campaigns
from footprint_uq.tracking.motion_fit import CHI2_95_1DOF, MotionGrid
from footprint_uq.tracking.synthetic import default_camera
from footprint_uq.uncertainty.budget import ErrorBudget, load_budget
from test_motion_fit import _write_recording


def test_profile_interval_pinned_on_a_quadratic():
    """ll = -(ln(x / 2))^2 / (2 * 0.3^2): the maximum at 2, the 95 % interval 2 exp(+-0.3 sqrt(3.84)) =
    [1.1109, 3.6007] (hand-computed); the spline is exact for a quadratic in ln x."""
    x = np.geomspace(0.5, 8.0, 5)
    p = profile_interval(x, -np.log(x / 2.0) ** 2 / (2 * 0.3 ** 2))
    assert p["hat"] == pytest.approx(2.0, rel=2e-3)
    np.testing.assert_allclose(p["ci95"], [1.1109, 3.6007], rtol=3e-3)
    assert np.exp(0.3 * np.sqrt(CHI2_95_1DOF)) == pytest.approx(3.6007 / 2.0, rel=1e-4)
    edge = profile_interval(x, -x)  # best at the first node: not bounded below within the grid
    assert edge["ci95"][0] is None and edge["ci95"][1] is not None


def _bowl(grid: ImmGrid, centre, widths, top: float) -> np.ndarray:
    """A log-likelihood over the product grid: a quadratic bowl in the logs of the parameters."""
    g = np.meshgrid(*(np.log(a) for a in grid.axes), indexing="ij")
    return top - sum((gk - np.log(c)) ** 2 / (2 * w ** 2) for gk, c, w in zip(g, centre, widths, strict=True))


def _sums(grid: ImmGrid, ll4, one_top: float):
    ll1 = one_top - np.log(grid.q_m2ps3 / 1.0) ** 2 / (2 * 0.2 ** 2)  # the one-mode fit: q = 1, well bounded
    LL = np.r_[ll1, ll4.ravel()]
    return LL, np.zeros_like(LL), 20000, 0, 200


def test_fit_keeps_the_imm_where_it_wins_with_its_identified_parameters():
    grid = ImmGrid()
    ll4 = _bowl(grid, (0.3, 10.0, 3.0, 1.0), (0.3, 0.4, 0.3, 0.3), 100.0)
    e = fit_imm_class(grid, _sums(grid, ll4, 80.0))
    assert e["status"] == "identified" and e["log_likelihood_gain"] == pytest.approx(20.0, abs=0.5)
    for k, want in (("accel_psd_m2ps3", 0.3), ("manoeuvre_accel_psd_m2ps3", 10.0), ("quiet_sojourn_s", 3.0),
                    ("manoeuvre_sojourn_s", 1.0)):
        assert e[k] == pytest.approx(want, rel=0.05), k
    lo, hi = e["manoeuvre_accel_psd_ci95_m2ps3"]
    assert lo < 10.0 < hi and e["quiet_sojourn_ci95_s"][0] < 3.0 < e["quiet_sojourn_ci95_s"][1]
    assert "two modes" in e["note"]


def test_fit_holds_an_unidentified_parameter_at_the_prior():
    """The manoeuvre density's likelihood rises to the grid's end: not identified, held at the prior's 30; the
    others are fitted with it there (and the interval of the held one is not written)."""
    grid = ImmGrid()
    g = np.meshgrid(*(np.log(a) for a in grid.axes), indexing="ij")
    ll4 = _bowl(grid, (0.3, 10.0, 3.0, 1.0), (0.3, 1e9, 0.3, 0.3), 100.0) + 2.0 * g[1]
    e = fit_imm_class(grid, _sums(grid, ll4, 80.0))
    assert e["manoeuvre_accel_psd_m2ps3"] == 30.0 and "manoeuvre_accel_psd_ci95_m2ps3" not in e
    assert "manoeuvre_accel_psd_m2ps3 not identified, held at the prior" in e["note"]
    assert e["quiet_sojourn_s"] == pytest.approx(3.0, rel=0.05)


def test_fit_keeps_one_mode_where_the_imm_does_not_win_by_its_margin():
    grid = ImmGrid()
    ll4 = _bowl(grid, (0.3, 10.0, 3.0, 1.0), (0.3, 0.4, 0.3, 0.3), 100.0)
    e = fit_imm_class(grid, _sums(grid, ll4, 98.0))  # gains 2 nats for 3 more parameters (margin 6.6)
    assert e["manoeuvre_accel_psd_m2ps3"] is None and e["accel_psd_m2ps3"] == pytest.approx(1.0, rel=0.02)
    assert "one mode kept" in e["note"]
    few = fit_imm_class(grid, (_sums(grid, ll4, 80.0)[0], np.zeros(1), 100, 0, 3))
    assert few["status"] == "prior" and "too little data" in few["note"]


def test_imm_members_are_the_trackers_models():
    """Every product node is an IMM of the tracker's form: its modes' densities, leaving rates 1 / sojourn and
    the chain's stationary start; the node at the prior's values equals the prior IMM member of the
    one-mode fit's grid (MotionGrid)."""
    grid = ImmGrid()
    qs, nm, mu0, rates = grid.members()
    n1 = grid.n_single
    assert qs.shape == (n1 + int(np.prod(grid.shape)), 2) and (nm[:n1] == 1).all() and (nm[n1:] == 2).all()
    i = n1 + int(np.ravel_multi_index((6, 3, 1, 1), grid.shape))  # q_quiet 0.1, 30, 3 s, 1 s
    mg = MotionGrid(imm_q_m2ps3=grid.q_quiet_m2ps3)
    q2, n2, m2, r2 = mg.members()
    j = mg.n_single + 6
    for a, b in ((qs, q2), (mu0, m2), (rates, r2)):
        np.testing.assert_allclose(a[i], b[j], rtol=1e-12)
    assert grid.prior_index() == (10, 3, 1, 1)  # (1.5 held at the node 2.15: nearer in log than 1.0)


def test_motion_section_reads_the_imm_intervals():
    base = load_budget("basler1@deg").to_dict()
    entry = {"accel_psd_m2ps3": 0.3, "manoeuvre_accel_psd_m2ps3": 9.0, "quiet_sojourn_s": 2.5,
             "manoeuvre_sojourn_s": 1.2, "manoeuvre_accel_psd_ci95_m2ps3": [5.0, None], "quiet_sojourn_ci95_s": None}
    b = ErrorBudget.from_dict({**base, "motion": {"classes": {"car": entry}}})
    assert b.motion["classes"]["car"]["manoeuvre_accel_psd_ci95_m2ps3"] == [5.0, None]
    for bad in ([float("nan"), 2.0], [-1.0, 2.0], [1.0]):
        with pytest.raises(ConfigError, match="manoeuvre_sojourn_ci95_s"):
            ErrorBudget.from_dict({**base, "motion": {"classes": {"car": {**entry, "manoeuvre_sojourn_ci95_s": bad}}}})


def test_calibrate_motion_modes_imm(tmp_path):
    from footprint_uq.cli.main import main

    save_camera(default_camera(), tmp_path / "cam.yaml")
    _write_recording(tmp_path / "d.csv", 0.5)
    args = ["calibrate", "motion", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg",
            "--detections", str(tmp_path / "d.csv"), "--out", str(tmp_path / "fit"), "--modes", "imm",
            "--min-tracks", "5", "--min-updates", "100"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    summary = json.loads((tmp_path / "fit" / "motion_fit.json").read_text())
    assert set(summary["imm_grid"]) == {"accel_psd_m2ps3", "manoeuvre_accel_psd_m2ps3", "quiet_sojourn_s",
                                        "manoeuvre_sojourn_s"}
    n = len(summary["grid_m2ps3"]) + int(np.prod([len(v) for v in summary["imm_grid"].values()]))
    assert len(summary["log_likelihood"]["c1"]["car"]["log_likelihood"]) == n
    b = load_budget(str(tmp_path / "fit" / "budget.yaml"))
    for e in b.motion["classes"].values():  # straight traffic at q = 0.5: one mode
        assert e["status"] == "identified" and e["manoeuvre_accel_psd_m2ps3"] is None and "IMM" in e["note"]
    bad = CliRunner().invoke(main, [*args[:-5], "--modes", "two"])
    assert bad.exit_code == 2 and "--modes" in bad.output and "Traceback" not in bad.output


@pytest.mark.slow
def test_braking_campaigns_fit_the_imm_and_cover():
    """Seeded braking traffic (q = 0.5 + braking to a stop), 2 campaigns of 100 road users x 6 s: the fitted IMM
    is kept in both, its manoeuvre mode denser than its quiet one, and the fitted trackers' 95 % velocity and
    heading regions cover 95 +- 2.5 % (bench/imm_fit_campaigns.py for 20 campaigns)."""
    r = run_imm_campaigns(0.5, scenario="stopping", n_campaigns=2, n_objects=100, duration_s=6.0, seed=0,
                          budget=load_budget("basler1@deg").scaled(0.25))
    for e in r.entries:
        assert e["manoeuvre_accel_psd_m2ps3"] is not None and e["manoeuvre_accel_psd_m2ps3"] > e["accel_psd_m2ps3"]
    assert 0.925 <= r.coverage_velocity <= 0.975 and 0.925 <= r.coverage_heading <= 0.975
    assert r.n_heading > 10000
