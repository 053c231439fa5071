"""``footprint-uq calibrate budget``: labelled data -> pairs -> fitted budget.yaml + fit.json (the Rope3D frame
copied into tests/data), and bad input as one line with exit status 2."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from footprint_uq.cli.main import main
from footprint_uq.uncertainty.budget import load_budget

ROPE3D = Path(__file__).resolve().parent / "data" / "rope3d-demo"


def test_rope3d_frame_fits_per_object_terms_and_no_calibration_sigma(tmp_path):
    out = tmp_path / "fit"
    r = CliRunner().invoke(main, ["calibrate", "budget", "--labels", str(ROPE3D), "--out", str(out), "--budget",
                                  "basler1@deg", "--free", "pan_deg,height_m,object_m,object_ground_m",
                                  "--contact", "footprint-centre"])
    assert r.exit_code == 0, r.output
    d = json.loads((out / "fit.json").read_text())
    terms = d["fit"]["terms"]
    assert d["fit"]["n_objects"] == 44 and d["fit"]["n_groups"] == 1 and d["statuses"]["no truth"] == 4
    assert terms["pan_deg"]["status"] == terms["height_m"]["status"] == "unidentifiable"  # one frame, one draw
    for k in ("object_m", "object_ground_m"):
        lo, hi = terms[k]["ci95"]
        assert terms[k]["status"] == "identified" and 0.05 < lo < terms[k]["sigma"] < hi < 1.0
    cv = d["cross_validation"]["object"]
    assert cv["n"] == 44 and cv["levels"] == [0.5, 0.9, 0.95, 0.99] and "group" not in d["cross_validation"]
    b = load_budget(out / "budget.yaml")  # readable by every command: the base budget's calibration terms
    assert b.pan_deg == load_budget("basler1@deg").pan_deg and "object_ground_m" in b.description
    assert "leave-one-object-out coverage (44 pairs)" in r.output and "unidentifiable" in r.output


def test_bad_terms_and_labels_are_one_line_errors(tmp_path):
    for argv, field in ((["--labels", str(ROPE3D), "--free", "imaging_px"], "free"),
                        (["--labels", str(tmp_path / "missing")], "labels")):
        r = CliRunner().invoke(main, ["calibrate", "budget", "--out", str(tmp_path / "o"), "--no-cv", *argv])
        assert r.exit_code == 2 and field in r.output and len(r.output.strip().splitlines()) == 1, r.output
        assert not (tmp_path / "o" / "budget.yaml").exists()
