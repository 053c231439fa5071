"""Every script in examples/ runs (subprocess, Agg backend, temporary output folder) and prints what it should."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from numeric_text import contains_numeric

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

# script -> (substrings its output must contain, files it must write under <out>/<name>/)
EXPECTED = {
    "quickstart.py": (["-> ground x = 6.780 m east, y = 11.743 m north", "95 % ellipse:", "height ",
                       "linear    Monte Carlo   unscented", "valid=False, reason code 1"],
                      ["quickstart/quickstart_ellipse.png"]),
    "footprints_per_frame.py": (["cpm_x", "j_orient", "FrameProcessor.boxes3d", "with a detector covariance",
                                 "no centre (corner"],
                                ["footprints_per_frame/footprints.csv"]),
    "reproduce_paper_partials.py": (["worst relative error: paper vs finite differences",
                                     "paper J Cov(par) J^T", "library propagate"],
                                    ["reproduce_paper_partials/partials.csv"]),
    "linearity_check.py": (["horizon row 29.9 px", "basler1+0.5deg", "bw-cube1@deg", "MC/lin-1", "nonlin",
                            "where linear_ok: largest |MC/lin - 1| = 0.0"], ["linearity_check/linearity.csv"]),
    "cpm_receiver.py": (["perceived objects (", "vruSubClass", "95 % semi-major", "conf x/y"],
                        ["cpm_receiver/cpm_ellipses.png"]),
    "lens_domain.py": (["fold radius (undistorted, normalised): 1.2534", "= 706 px",
                        "status codes equal to the reference:  map True  points True  FrameProcessor True"],
                       ["lens_domain/lens_domain.png"]),
    "architecture_figure.py": (["boxes 19, arrows 20; wrote"], ["architecture_figure/architecture.png"]),
    "contact_figure.py": (["bottom-centre ", "footprint centre (yaw unknown)", "inside the 95 % ellipse",
                           "footprint centre (yaw known)"], ["contact_figure/contact_figure.png"]),
    "rope3d_validation.py": (["|error| median 0.835 m, 95th percentile 3.16 m, max 5.90 m",
                              "basler1@deg   77.3%  84.1%  84.1%  88.6%   2.75   1.10",
                              "0-25 m     n=4   cov95   0.0%"],
                             ["rope3d_validation/validation_rope3d.png", "rope3d_validation/objects_basler1.csv"]),
    "plan_mount.py": (["criterion: 95 % semi-major axis <= 1.75 m", "best reach with basler1: 54.7 m",
                       "linear/Monte-Carlo semi-major there"],
                      ["plan_mount/plan_mount.png", "plan_mount/plan_mount.csv"]),
    "plan_intersection.py": (["1152 candidates, 11256 samples at 0.5 m", "naive layout (one camera per arm, looking "
                              "at the centre): 57.8 % met", "zone lanes (<= 1.75 m): planned"],
                             ["plan_intersection/site.yaml", "plan_intersection/plan/layout.yaml",
                              "plan_intersection/plan/report.html"]),
}


def test_every_example_is_listed():
    scripts = sorted(p.name for p in EXAMPLES.glob("*.py") if not p.name.startswith("_"))
    assert scripts == sorted(EXPECTED)


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_example_runs(script, tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg", "FOOTPRINT_UQ_EXAMPLES_OUT": str(tmp_path / "env-unused")}
    r = subprocess.run([sys.executable, str(EXAMPLES / script), "--out", str(tmp_path)], capture_output=True,
                       text=True, env=env, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    texts, files = EXPECTED[script]
    for t in texts:  # numbers within one unit of their last printed digit (issue 11: any CPU)
        assert contains_numeric(r.stdout, t), (t, r.stdout[-3000:])
    for f in files:
        assert (tmp_path / f).is_file() and (tmp_path / f).stat().st_size > 0, f
    assert not (tmp_path / "env-unused").exists()  # --out wins over the environment variable
    if script == "reproduce_paper_partials.py":
        worst = float(r.stdout.split("paper vs finite differences ")[1].split(",")[0])
        assert worst < 1e-6


DOCS = EXAMPLES.parent / "docs"


def _doc_lines(doc: str, prefixes: tuple[str, ...]) -> list[str]:
    """Output lines quoted in a doc's fenced blocks that start with one of ``prefixes`` (stripped)."""
    text = (DOCS / doc).read_text(encoding="utf-8")
    lines = [ln.strip() for block in text.split("```")[1::2] for ln in block.splitlines()]
    return [ln for ln in lines if ln.startswith(prefixes)]


@pytest.mark.parametrize("script, doc, prefixes", [
    ("plan_mount.py", "planning.md", ("basler1 ", "basler1+", "basler1,", "bw-cube1 ", "best reach", "criterion:")),
    ("linearity_check.py", "uncertainty-model.md", ("basler1 ", "basler1+", "bw-cube1 ", "where linear_ok:",
                                                    "where nonlin")),
    ("rope3d_validation.py", "validation.md", ("basler1 ", "basler1@deg ", "paper-style ", "0-25 m ", "25-50 m ",
                                               "50-75 m ", "75-100 m ")),
    ("quickstart.py", "uncertainty-model.md", ("1-sigma ellipse:", "95 % ellipse:", "height ", "position ",
                                               "principal_point ", "imaging ")),
])
def test_quoted_output_is_current(script, doc, prefixes, tmp_path):
    """The outputs quoted in the docs are what the scripts print today."""
    quoted = _doc_lines(doc, prefixes)
    assert len(quoted) >= 6
    r = subprocess.run([sys.executable, str(EXAMPLES / script), "--out", str(tmp_path)], capture_output=True,
                       text=True, env={**os.environ, "MPLBACKEND": "Agg"}, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    printed = "\n".join(ln.strip() for ln in r.stdout.splitlines())
    stale = [ln for ln in quoted if not contains_numeric(printed, ln, whole_line=True)]
    assert not stale, stale
