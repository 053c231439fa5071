"""Every multi-file output as one set (issue 35, part 3): ``validate``, ``calibrate budget``, ``plan``,
``plan --evaluate``, ``map``, ``calibrate synthetic``, ``calibrate intrinsics`` and ``calibrate motion`` (killed here),
``calibrate extrinsics``, ``demo`` and ``case-study`` (the same helper, not killed here) build their files in a hidden
folder and swap them in together (:func:`footprint_uq.io.atomic.output_set`; ``calibrate gcp`` does the
same with its own code, killed in ``tests/test_calibration_gcp.py``).

The kill test runs each command in forked processes, each SIGKILLed right after its k-th rename (every
rename and atomic exchange the process makes: the per-file commits inside the hidden folder, then the swap),
k = 1, 2, ... until one run passes its last rename; after each, the output folder must hold the previous
set or the new one, byte for byte, never a mix.  The pattern is
``test_calibration_gcp.py::test_kill_after_every_rename_leaves_the_old_set_or_the_new_set``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from footprint_uq.cli.main import main
from footprint_uq.errors import InputError
from footprint_uq.io import save_camera
from footprint_uq.io.atomic import OLD_MARK, TMP_MARK, final_paths, output_set
from footprint_uq.tracking.synthetic import default_camera
from kill_driver import KILL_DRIVER
from test_motion_fit import _write_recording
from test_planning import small_site_dict

DATA = Path(__file__).resolve().parent / "data"
ROPE3D = DATA / "rope3d-demo"
SRC = Path(__file__).resolve().parents[1] / "src"


def _snapshot(folder) -> dict | None:
    """Every file under ``folder`` (relative path -> bytes); None if there is no folder."""
    folder = Path(folder)
    if not folder.is_dir():
        return None
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _timeless(data: bytes):
    """A JSON file's content without its timings (``elapsed_s``, ``seconds_total``, ``seconds``...)."""
    def drop(x):
        if isinstance(x, dict):
            return {k: drop(v) for k, v in x.items() if "elapsed" not in k and "seconds" not in k}
        return [drop(v) for v in x] if isinstance(x, list) else x
    return drop(json.loads(data))


def _same_run(f: str, data: bytes, ref: bytes) -> bool:
    """``data`` is the file ``f`` of the run that wrote ``ref`` (JSON: up to its timings)."""
    return data == ref or (f.endswith(".json") and _timeless(data) == _timeless(ref))


# ------------------------------------------------------------------------------------------------ the helper
def test_output_set_swaps_in_the_whole_set_or_nothing(tmp_path):
    out = tmp_path / "o"
    with output_set(out, ("a.txt", "b.txt", "sub"), "job") as stage:
        (stage / "a.txt").write_text("1")
        (stage / "sub").mkdir()
        (stage / "sub" / "c.txt").write_text("1")
        assert not out.exists() and stage.name.startswith(".o" + TMP_MARK)
    assert _snapshot(out) == {"a.txt": b"1", "sub/c.txt": b"1"}
    # a failing run: the previous set stays, no hidden folder is left
    with pytest.raises(RuntimeError), output_set(out, ("a.txt", "b.txt", "sub"), "job") as stage:
        (stage / "a.txt").write_text("2")
        raise RuntimeError("drawing")
    assert _snapshot(out) == {"a.txt": b"1", "sub/c.txt": b"1"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]
    # a second run replaces the set: a file of the first run that the second does not write is gone
    with output_set(out, ("a.txt", "b.txt", "sub"), "job") as stage:
        (stage / "b.txt").write_text("2")
    assert _snapshot(out) == {"b.txt": b"2"}
    assert final_paths({"x": stage / "b.txt", "y": [stage / "sub" / "c"]}, stage, out) == {
        "x": out / "b.txt", "y": [out / "sub" / "c"]}


def test_output_set_refuses_a_folder_holding_other_files_and_a_file(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / f".x{TMP_MARK}0123abcd.csv").write_text("left by a killed run")  # ignored
    with pytest.raises(InputError, match="holding 'notes.txt'.*previous `job` run") as e:
        with output_set(out, ("a.txt",), "job"):
            raise AssertionError("never reached")
    assert "\n" not in str(e.value)
    assert (out / "notes.txt").read_text() == "mine"
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match="a folder"), output_set(tmp_path / "f", ("a.txt",), "job"):
        pass


def test_output_set_refuses_the_current_folder_and_its_parents(tmp_path, monkeypatch):
    work = tmp_path / "w"
    work.mkdir()
    monkeypatch.chdir(work)
    for out in (".", "..", str(work), "/", "sub/.."):
        with pytest.raises(InputError, match="a folder of its own"), output_set(out, ("a.txt",), "job"):
            raise AssertionError("never reached")
    with output_set("sub/../o", ("a.txt",), "job") as stage:  # a named folder, however it is spelt
        (stage / "a.txt").write_text("1")
    assert _snapshot(work / "o") == {"a.txt": b"1"} and sorted(p.name for p in work.iterdir()) == ["o"]


def test_output_set_puts_right_what_a_killed_swap_left(tmp_path):
    out = tmp_path / "o"
    old = tmp_path / f".o{OLD_MARK}0123abcd"  # killed between the two renames of the fallback swap
    old.mkdir()
    (old / "a.txt").write_text("old")
    staging = tmp_path / f".o{TMP_MARK}89abcdef"
    staging.mkdir()
    with output_set(out, ("a.txt",), "job") as stage:
        assert _snapshot(out) == {"a.txt": b"old"} and not staging.exists()
        (stage / "a.txt").write_text("new")
    assert _snapshot(out) == {"a.txt": b"new"} and sorted(p.name for p in tmp_path.iterdir()) == ["o"]


@pytest.mark.parametrize("argv", [
    ["validate", "--labels", str(ROPE3D), "--budget", "basler1@deg", "--no-report"],
    ["calibrate", "budget", "--labels", str(ROPE3D), "--no-cv", "--free", "object_m"],
])
def test_commands_refuse_a_folder_with_the_users_files_in_one_line(tmp_path, argv):
    out = tmp_path / "o"
    out.mkdir()
    (out / "my-notes.txt").write_text("mine")
    r = CliRunner().invoke(main, [*argv, "--out", str(out)])
    assert r.exit_code == 2 and "my-notes.txt" in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert _snapshot(out) == {"my-notes.txt": b"mine"}


# ------------------------------------------------------------------------------------------------ killed runs


def _site_files(tmp_path):
    site = tmp_path / "site.yaml"
    site.write_text(yaml.safe_dump(small_site_dict()))
    return site


def _plan_args(site, extra):
    return ["plan", "--site", str(site), "--no-progress", "--no-sensitivity", "--max-refine-evals", "4", "--method",
            "greedy", *extra]


def _case(tmp_path, name):
    """(args of run A, args of run B, files whose bytes vary between identical runs) of the command ``name``."""
    site = _site_files(tmp_path)
    if name == "validate":
        val = ["validate", "--labels", str(ROPE3D)]
        return val + ["--budget", "basler1@deg"], val + ["--budget", "basler2@deg"], set()
    if name == "calibrate budget":
        fit = ["calibrate", "budget", "--labels", str(ROPE3D), "--no-cv", "--contact", "footprint-centre"]
        return fit + ["--free", "object_m"], fit + ["--free", "object_m,object_ground_m"], set()
    if name == "plan":  # report.html shows seconds_total
        return _plan_args(site, ["--cameras", "1"]), _plan_args(site, ["--cameras", "2"]), {"report.html"}
    if name == "plan --evaluate":
        la, lb = tmp_path / "layout_a", tmp_path / "layout_b"
        for lay, k in ((la, "1"), (lb, "2")):
            r = CliRunner().invoke(main, _plan_args(site, ["--cameras", k, "--no-refine"]) + ["--out", str(lay)])
            assert r.exit_code == 0, r.output
        evl = ["plan", "--site", str(site), "--no-sensitivity", "--evaluate"]
        return evl + [str(la / "layout.yaml")], evl + [str(lb / "layout.yaml")], set()
    if name == "calibrate intrinsics":
        imgs = sorted((DATA / "opencv-chessboard-right").glob("*.jpg"))
        (tmp_path / "some").mkdir()
        for p in imgs[:9]:
            shutil.copy(p, tmp_path / "some" / p.name)
        cal = ["calibrate", "intrinsics", "--board", "9x6", "--square-m", "0.025", "--quiet", "--workers", "1"]
        return ([*cal[:2], str(DATA / "opencv-chessboard-right"), *cal[2:]],
                [*cal[:2], str(tmp_path / "some"), *cal[2:]], {"*"})  # a time stamp, last digits of the solve
    if name == "calibrate synthetic":
        syn = ["calibrate", "synthetic", "--views", "3", "--scale", "0.2"]
        return syn + ["--seed", "1"], syn + ["--seed", "2"], set()
    if name == "calibrate motion":  # run A keeps the prior (too few tracks), run B fits
        save_camera(default_camera(), tmp_path / "cam.yaml")
        _write_recording(tmp_path / "d.csv", 0.5, n_objects=6, duration_s=2.0)
        mot = ["calibrate", "motion", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg",
               "--detections", str(tmp_path / "d.csv"), "--modes", "one", "--min-updates", "50"]
        return mot + ["--min-tracks", "100"], mot + ["--min-tracks", "2"], set()
    mp = ["map", "--camera", str(DATA / "cameras" / "pantilt.yaml")]
    return mp + ["--budget", "basler1", "--step-px", "96"], mp + ["--budget", "basler2", "--step-px", "80"], set()


@pytest.mark.parametrize("name", ["validate", "calibrate budget", "plan", "plan --evaluate", "map",
                                  "calibrate synthetic", "calibrate intrinsics", "calibrate motion"])
def test_kill_after_every_rename_leaves_the_old_set_or_the_new_set(tmp_path, name):
    args_a, args_b, volatile = _case(tmp_path, name)
    for tag, args in (("A", args_a), ("B", args_b)):
        r = CliRunner().invoke(main, args + ["--out", str(tmp_path / tag)])
        assert r.exit_code == 0, r.output
    old, new = _snapshot(tmp_path / "A"), _snapshot(tmp_path / "B")
    assert len(new) >= 2 and all(not _same_run(k, new[k], old.get(k, b"-")) for k in new), sorted(new)  # every file
    # tells its run
    outs = []
    for k in range(1, 41):
        outs.append(tmp_path / f"out{k}")
        shutil.copytree(tmp_path / "A", outs[-1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SRC), str(Path(__file__).parent),
                                                       os.environ.get("PYTHONPATH", "")]))
    p = subprocess.run([sys.executable, "-c", KILL_DRIVER, ",".join(map(str, outs)), *args_b], env=env,
                       capture_output=True, text=True, timeout=900)
    status = [line.split()[1:] for line in p.stdout.splitlines() if line.startswith("STATUS ")]
    assert status and status[-1][1] == "0" and all(s[1] == "9" for s in status[:-1]), (status, p.stderr[-800:])
    assert len(status) >= 3, status  # at least one file commit and the swap were killed
    seen = []
    for (k, _), out in zip(status, outs, strict=False):
        got = _snapshot(out)
        if got == old:
            seen.append("old")
            continue
        assert got is not None and got.keys() == new.keys(), (name, k, sorted(got or ()))
        for f, data in got.items():  # every file of the new run, none of the old one
            if f in volatile or "*" in volatile:  # not byte-stable: at least not the old run's
                assert data and data != old.get(f), (name, k, f)
            else:
                assert _same_run(f, data, new[f]) and not _same_run(f, data, old.get(f, b"-")), (name, k, f)
        seen.append("new")
    assert seen[0] == "old" and seen[-1] == "new" and seen == sorted(seen, key=("old", "new").index), seen
    # the next run cleans what a killed one left (hidden folders) and writes its set
    r = CliRunner().invoke(main, args_b + ["--out", str(outs[0])])
    assert r.exit_code == 0, r.output
    assert _snapshot(outs[0]).keys() == new.keys()
    assert not [q.name for q in tmp_path.iterdir() if q.name.startswith((".out1" + TMP_MARK, ".out1" + OLD_MARK))]


def test_plan_evaluate_into_the_plan_folder_is_refused_not_emptied(tmp_path):
    site = _site_files(tmp_path)
    out = tmp_path / "p"
    r = CliRunner().invoke(main, _plan_args(site, ["--cameras", "1", "--no-refine"]) + ["--out", str(out)])
    assert r.exit_code == 0, r.output
    before = _snapshot(out)
    r = CliRunner().invoke(main, ["plan", "--site", str(site), "--evaluate", str(out / "layout.yaml"),
                                  "--out", str(out)])
    assert r.exit_code == 2 and "holding 'cameras'" in r.output and "plan --evaluate" in r.output, r.output
    assert _snapshot(out) == before
    assert json.loads((out / "plan.json").read_text())["candidates"] > 0
