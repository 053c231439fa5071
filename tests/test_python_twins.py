"""fast.python_twins: the pure-Python twin of the undistortion, which a command line's first run uses for a few
points while the compiled kernel is not cached (group "lens" of products.warmup; issue 24: a first ``locate`` on
a camera with lens distortion took 20 s, 13.5 of them compiling ``core.undistort_many``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from footprint_uq import _notices
from footprint_uq.cameras import distortion
from footprint_uq.cameras.lens_domain import lens_domain
from footprint_uq.fast import core
from footprint_uq.fast.python_twins import python_twin

ROOT = Path(__file__).resolve().parents[1]
CAMERA = ROOT / "tests" / "data" / "cameras" / "opencv.yaml"
LENSES = [np.array([-0.25, 0.05, 0, 0, 0, 0, 0, 0.0]),  # barrel, with a fold inside the sampled square
          np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03, 0, 0, 0.0]),  # the warmup's lens, tangential terms
          np.array([0.3, 0.1, 0, 0, 0.01, 0.2, 0.0, 0.0])]  # pincushion, rational denominator


def _run(fn, k, xy):
    n = xy.shape[0]
    out, ok, minv = np.empty((n, 2)), np.empty(n, bool), np.empty((n, 4))
    fn(lens_domain(k).packed, np.ascontiguousarray(np.broadcast_to(k, (n, 8))), xy, out, ok, minv)
    return out, ok, minv


@pytest.mark.parametrize("lens", range(len(LENSES)))
def test_twin_gives_the_kernels_answer(lens):
    k = LENSES[lens]
    rng = np.random.default_rng(lens)
    xy = np.concatenate([rng.uniform(-1.2, 1.2, (300, 2)), [[0.0, 0.0], [np.nan, 0.1], [5.0, 5.0]]])
    twin = python_twin(core.undistort_many)
    assert twin is not core.undistort_many.py_func and python_twin(core.undistort_many) is twin  # memoised
    got, ref = _run(twin, k, xy), _run(core.undistort_many, k, xy)
    np.testing.assert_array_equal(got[1], ref[1])  # the same points have an answer (domain, fold, retries)
    assert 0 < ref[1].sum() < len(xy)
    np.testing.assert_allclose(got[0][ref[1]], ref[0][ref[1]], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got[2][ref[1]], ref[2][ref[1]], rtol=1e-10, atol=1e-12)


def test_few_points_take_the_twin_only_while_the_gate_says_so(monkeypatch):
    k = LENSES[1]
    xy = np.random.default_rng(9).uniform(-0.5, 0.5, (50, 2))
    ref = _run(core.undistort_many, k, xy)
    calls = []
    monkeypatch.setattr(distortion, "_UNDISTORT_MANY_PY", lambda *a: (calls.append(len(a[2])), core.undistort_many(*a)))
    for gate, n, twin_used in ((None, 50, False), (False, 50, True), (True, 50, False),
                               (False, distortion.PY_MAX_POINTS + 1, False)):
        calls.clear()
        _notices.set_compile_handler(None if gate is None else (lambda g, answer=gate: answer))
        try:
            pts = xy if n == 50 else np.resize(xy, (n, 2))
            got = _run(distortion._undistort_many, k, pts)
        finally:
            _notices.set_compile_handler(None)
        assert bool(calls) == twin_used, (gate, n)
        np.testing.assert_allclose(got[0][:50], ref[0])


def test_a_twin_that_raises_hands_over_to_the_kernel(monkeypatch):
    def raises(*a):
        raise ZeroDivisionError("float division by zero")  # where the compiled code gives inf

    monkeypatch.setattr(distortion, "_UNDISTORT_MANY_PY", raises)
    _notices.set_compile_handler(lambda g: False)
    try:
        k = LENSES[0]
        xy = np.array([[0.1, 0.2], [0.3, -0.1]])
        np.testing.assert_allclose(_run(distortion._undistort_many, k, xy)[0], _run(core.undistort_many, k, xy)[0])
    finally:
        _notices.set_compile_handler(None)


@pytest.mark.slow
def test_locate_on_a_lens_camera_compiles_nothing_and_gives_the_same_records(tmp_path):
    """``locate`` with the kernels left uncompiled (FOOTPRINT_UQ_COMPILE=reference): the undistortion runs as
    Python (no signature compiled or loaded) and the records equal a normal run's."""
    code = ("import json, sys\nfrom click.testing import CliRunner\nfrom footprint_uq.cli.main import main\n"
            "from footprint_uq.fast import core\n"
            "r = CliRunner().invoke(main, sys.argv[1:])\n"
            "print(json.dumps({'out': r.output, 'rc': r.exit_code, 'compiled': "
            "len(core.undistort_many.signatures) + len(core.undistort_point.signatures)}))\n")
    args = ["locate", "--camera", str(CAMERA), "--budget", "basler1", "--pixel", "960", "700", "--pixel", "300", "1000"]
    runs = {}
    for mode in ("reference", "foreground"):
        env = {**os.environ, "FOOTPRINT_UQ_COMPILE": mode, "PYTHONPATH": str(ROOT / "src")}
        p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, timeout=600)
        assert p.returncode == 0, p.stderr[-2000:]
        runs[mode] = json.loads(p.stdout.strip().splitlines()[-1])
    assert runs["reference"]["rc"] == runs["foreground"]["rc"] == 0
    assert runs["reference"]["compiled"] == 0 and runs["foreground"]["compiled"] > 0
    a, b = json.loads(runs["reference"]["out"]), json.loads(runs["foreground"]["out"])
    assert [r["valid"] for r in a] == [r["valid"] for r in b] == [True, True], (a, b)
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_allclose([ra["x_m"], ra["y_m"]], [rb["x_m"], rb["y_m"]], rtol=1e-9)
        np.testing.assert_allclose(ra["cov_m2"], rb["cov_m2"], rtol=1e-9)
