"""First runs: numba's cache folder (package folder, else the user's cache), the cold-cache notice, `warmup`."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from footprint_uq import InputError, OpenCVCamera, PanTiltCamera, _notices, _numba_cache, save_camera
from footprint_uq.cli.main import main
from footprint_uq.products import warmup as W
from footprint_uq.products.footprints import FrameProcessor


def test_cache_folder_is_the_users_when_the_package_is_read_only(monkeypatch, tmp_path):
    env = {"XDG_CACHE_HOME": str(tmp_path)}
    monkeypatch.setattr(_numba_cache, "_writable", lambda folder: True)
    assert _numba_cache.configure(env) is None and "NUMBA_CACHE_DIR" not in env  # numba's default, beside the code
    monkeypatch.setattr(_numba_cache, "_writable", lambda folder: False)
    assert _numba_cache.configure(env) == tmp_path / "footprint-uq" / "numba"
    assert env["NUMBA_CACHE_DIR"] == str(tmp_path / "footprint-uq" / "numba")
    mine = {"NUMBA_CACHE_DIR": "/somewhere", "XDG_CACHE_HOME": str(tmp_path)}
    assert _numba_cache.configure(mine) is None and mine["NUMBA_CACHE_DIR"] == "/somewhere"  # the user's wins
    assert _numba_cache.user_cache_dir({}) == Path.home() / ".cache" / "footprint-uq" / "numba"


_STALE_SCRIPT = """
import sys
from pathlib import Path
sys.path.insert(0, {root!r})
from footprint_uq import _numba_cache
from footprint_uq.products.warmup import _cached
_numba_cache.install_sources_stamp(Path({root!r}) / "mini")
import mini.b as b
print(_cached(b.g), b.g(1.0))
"""


def test_an_edit_of_a_called_kernel_makes_its_callers_cache_stale(tmp_path):
    """numba keys a cached kernel on its own file only, but compiles the kernels it calls from other files into
    it: without the sources stamp, b.g would load 2 * (1 + 1) from the cache after a.f changed to x + 100 (numba
    0.68 does, checked by hand).  With it, the edit makes b.g's cache stale: `warmup` sees it cold, and it is
    compiled again with the new a.f."""
    pkg = tmp_path / "mini"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from numba import njit\n\n\n@njit(cache=True)\ndef f(x):\n    return x + 1.0\n")
    (pkg / "b.py").write_text("from numba import njit\n\nfrom . import a\n\n\n@njit(cache=True)\ndef g(x):\n"
                              "    return a.f(x) * 2.0\n")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES")}

    def run() -> str:
        out = subprocess.run([sys.executable, "-c", _STALE_SCRIPT.format(root=str(tmp_path))], capture_output=True,
                             text=True, timeout=300, env=env)
        assert out.returncode == 0, out.stderr
        return out.stdout.split()

    assert run() == ["False", "4.0"]  # cold, compiled
    assert run() == ["True", "4.0"]   # loaded from the cache
    (pkg / "a.py").write_text((pkg / "a.py").read_text().replace("x + 1.0", "x + 100.0"))
    assert run() == ["False", "202.0"]  # stale: compiled again with the edited a.f
    assert run() == ["True", "202.0"]
    assert list((pkg / "__pycache__").glob("b.g-*.nbi")), "the cache lives where numba puts it (beside b.py)"


def test_a_numba_without_the_expected_locators_gets_a_warning_not_an_import_error(monkeypatch, tmp_path):
    from numba.core import caching

    for name in ("CacheImpl", "_CacheImpl"):
        monkeypatch.delattr(caching, name, raising=False)
    with pytest.warns(RuntimeWarning, match="cache locators are not where expected"):
        _numba_cache.install_sources_stamp(tmp_path)


def test_an_index_numba_cannot_read_is_cold(tmp_path):
    from footprint_uq.fast import core

    index = tmp_path / "k.nbi"
    index.write_bytes(b"\x80")  # a truncated pickle
    real = core.fold_radius._cache._cache_file
    fake = SimpleNamespace(_index_path=str(index), _load_index=type(real)._load_index.__get__(
        SimpleNamespace(_index_path=str(index), _version=real._version, _source_stamp=real._source_stamp)))
    assert W._cached(SimpleNamespace(_cache=SimpleNamespace(_cache_file=fake))) is False
    core.fold_radius(np.zeros(8), 1.0, 0.0, 1.0, 16)  # compiled (or loaded) and cached
    assert W._cached(core.fold_radius) is True


def test_sources_stamp_follows_the_kernel_files_only(tmp_path):
    (tmp_path / "k.py").write_text("from numba import njit\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "plain.py").write_text("x = 1\n")
    first = _numba_cache.sources_stamp(tmp_path)
    (tmp_path / "sub" / "plain.py").write_text("x = 2\n")
    assert _numba_cache.sources_stamp(tmp_path) == first  # no kernel: not part of the stamp
    (tmp_path / "sub" / "plain.py").write_text("from numba import njit\n")
    second = _numba_cache.sources_stamp(tmp_path)
    assert second != first  # a file that gains a kernel is
    (tmp_path / "k.py").write_text("from numba import njit  # edited\n")
    assert _numba_cache.sources_stamp(tmp_path) not in (first, second)


def test_the_packages_kernels_carry_the_sources_stamp():
    from numba.core import caching

    from footprint_uq.fast import core
    from footprint_uq.tracking import kernels

    root = Path(_numba_cache.__file__).parent
    impls = (getattr(caching, "CacheImpl", None) or caching._CacheImpl)._locator_classes
    n = len(impls)
    _numba_cache.install_sources_stamp(root)  # a second call for the same root does nothing
    assert len(impls) == n
    for kernel in (core.fold_radius, kernels.frame_update):
        locator = kernel._cache._impl._locator
        assert locator.sources_root == os.path.join(str(root), "")
        assert locator.get_source_stamp()[1] == _numba_cache.sources_stamp(root)
        assert type(locator._inner).__module__ == caching.__name__  # numba's locator says where the cache is


def _fake(index: Path):
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(index))))


def test_notice_only_when_a_groups_cache_is_cold(monkeypatch, tmp_path):
    have = tmp_path / "k.nbi"
    have.write_bytes(b"")
    monkeypatch.setitem(W.GROUPS, "objects", (_fake(have),))
    monkeypatch.setitem(W.GROUPS, "map", (_fake(have), _fake(tmp_path / "missing.nbi")))
    assert W.cold_groups(["objects", "map"]) == ["map"]
    assert W.compile_notice(["objects"]) is None
    msg = W.compile_notice(["map", "objects"])
    assert msg.startswith(f"compiling the map kernels once: about {W.ABOUT_S['map']} s") and "warmup" in msg


def test_warmup_fills_the_cache_and_the_command_reports_it():
    W.warmup(["objects"])  # compiled by the suite already, or now
    assert W.cold_groups(["objects"]) == []
    r = CliRunner().invoke(main, ["warmup", "--only", "objects"])
    assert r.exit_code == 0, r.output
    assert "objects:" in r.stdout and "loaded from the cache" in r.stdout and "cache: " in r.stdout


def test_the_notice_never_comes_before_an_input_error(monkeypatch, tmp_path):
    """A cold cache's notice is said right before the kernels run, after every input is checked: a bad option is
    still one line on stderr; a good run says the notice once, before its output."""
    monkeypatch.setattr(W, "cold_groups", lambda groups: list(groups))  # every group "cold"
    cam = tmp_path / "cam.yaml"
    save_camera(PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=0.0, tilt_deg=20.0),
                cam)
    base = ["map", "--camera", str(cam), "--budget", "basler1", "--out", str(tmp_path / "m")]
    r = CliRunner().invoke(main, [*base, "--max-range-m", "-5"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "max_range_m" in r.stderr, r.stderr
    r = CliRunner().invoke(main, [*base, "--step-px", "16"])
    assert r.exit_code == 0, r.output
    assert r.stderr.count("compiling the map kernels once") == 1


class _Job:
    """A stand-in for the detached compile's process."""

    def __init__(self):
        self.returncode = None

    def poll(self):
        return self.returncode


def test_gate_modes(monkeypatch, tmp_path):
    """Cold group: "reference" never compiles and says nothing; "foreground" says the notice and compiles;
    "background" says it starts the compile, takes the reference path until the compile is done, then the
    kernels.  A warm group: the kernels, nothing said."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    cold = {"objects"}
    monkeypatch.setattr(W, "cold_groups", lambda groups: [g for g in groups if g in cold])
    monkeypatch.setattr(W, "_POLL_S", 0.0)
    said = []
    gate = W.KernelGate(said.append, "reference")
    assert [gate("objects"), gate("objects"), gate("map")] == [False, False, False] and said == []
    gate = W.KernelGate(said.append, "foreground")
    assert gate("objects") and gate("map") and len(said) == 1 and "compiling the objects kernels once" in said[0]
    said.clear()
    job = _Job()
    monkeypatch.setattr(W, "start_background", lambda group: job)
    assert W.compile_mode({}) == W.compile_mode({"FOOTPRINT_UQ_COMPILE": ""}) == "background"  # the default
    gate = W.KernelGate(said.append, "background")
    assert not gate("objects") and not gate("objects")
    assert len(said) == 1 and "in the background" in said[0] and "reference path meanwhile" in said[0]
    job.returncode = 0  # the compile ends ...
    assert not gate("objects")  # ... but left the group cold (failed): the reference path for this run
    gate = W.KernelGate(said.append, "background")
    job.returncode = None
    assert not gate("objects")
    job.returncode, cold = 0, set()
    assert gate("objects") and gate("objects") and gate("map") and len(said) == 2


def test_bad_mode_is_one_line(monkeypatch, tmp_path):
    monkeypatch.setenv("FOOTPRINT_UQ_COMPILE", "later")
    cam = tmp_path / "cam.yaml"
    save_camera(PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=0.0, tilt_deg=20.0),
                cam)
    r = CliRunner().invoke(main, ["map", "--camera", str(cam), "--budget", "basler1", "--out", str(tmp_path / "m")])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "FOOTPRINT_UQ_COMPILE" in r.stderr, r.stderr


_HOLD = ("import sys, time\nfrom filelock import FileLock\nlock = FileLock(sys.argv[1], thread_local=False)\n"
         "lock.acquire()\nprint('held', flush=True)\ntime.sleep(120)\n")


def _hold_lock(path: Path) -> subprocess.Popen:
    """A second process that holds the compile lock ``path`` (a compile under way elsewhere) until killed."""
    proc = subprocess.Popen([sys.executable, "-c", _HOLD, str(path)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_group_lock(monkeypatch, tmp_path):
    """One holder at a time, across processes; a holder that dies (killed: no clean-up) holds nothing."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    with W.group_lock("map", wait=False) as held:
        assert held and not W.compiling_elsewhere("map")  # our own compile is not another's
        other = subprocess.run([sys.executable, "-c", "import sys; from footprint_uq.products import warmup as W; "
                                "sys.exit(0 if W.compiling_elsewhere('map') else 1)"], env=dict(os.environ))
        assert other.returncode == 0  # seen from another process: held
    path = W._lock_path("map")
    proc = _hold_lock(path)
    try:
        assert W.compiling_elsewhere("map") and not W.compiling_elsewhere("objects")
        with W.group_lock("map", wait=False) as held:
            assert not held
        assert W.start_background("map") is None  # compiling already: nothing started
        t0 = time.monotonic()
        assert not W.wait_for_compile("map", 0.3) and time.monotonic() - t0 < 2.0
    finally:
        proc.kill()
        proc.wait()
    assert not W.compiling_elsewhere("map")  # SIGKILL: the OS released the lock
    with W.group_lock("map", wait=False) as held:
        assert held


def test_a_library_call_waits_for_another_compile_at_most_the_bound(monkeypatch, tmp_path):
    """A library call (no command's handler) whose kernels another process is compiling warns once, naming the
    wait and `footprint-uq warmup`, waits at most FOOTPRINT_UQ_COMPILE_WAIT_S, then returns the reference path's
    numbers (those of the kernels); once that compile is over, the kernels run."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("FOOTPRINT_UQ_COMPILE_WAIT_S", "1.5")
    monkeypatch.setattr(W, "cold_groups", lambda groups: list(groups))  # every group "cold"
    monkeypatch.setattr(W, "_POLL_S", 0.05)
    _notices.set_compile_handler(None)
    cam = _cams()[0]
    boxes = np.array([[6.0, 11.0, 0.75, 4.8, 1.9, 1.5, 0.3], [-4.0, 30.0, 0.75, 4.5, 1.8, 1.5, 1.0]])
    fast = FrameProcessor(cam, "basler1").boxes3d(boxes)  # the kernels (nobody else compiling)
    monkeypatch.setattr(_notices, "_library_handler", W.LibraryGate())  # a fresh process's gate
    (tmp_path / "cache").mkdir()
    proc = _hold_lock(W._lock_path("objects"))
    try:
        fp = FrameProcessor(cam, "basler1")
        t0 = time.monotonic()
        with pytest.warns(W.CompileWaitWarning) as caught:
            est = fp.boxes3d(boxes)
            est2 = fp.boxes3d(boxes)
        elapsed = time.monotonic() - t0
        assert len(caught) == 1, [str(w.message) for w in caught]
        msg = str(caught[0].message)
        assert "another process is compiling the objects kernels" in msg and "footprint-uq warmup" in msg
        assert "1.5 s" in msg and "reference path" in msg
        assert 1.4 <= elapsed < 10.0  # the bound, not the other compile's length (it never ends by itself)
        assert not fp._kernels and not _close(fast.centre_cov_m2, 2 * fast.centre_cov_m2)
        for e in (est, est2):
            assert _close(e.centre_xy_world_m, fast.centre_xy_world_m)
            assert _close(e.centre_cov_m2, fast.centre_cov_m2)
    finally:
        proc.kill()
        proc.wait()
    time.sleep(0.1)
    fp.boxes3d(boxes)
    assert fp._kernels  # the other compile is over: the kernels, nothing said again


def test_bad_compile_wait_is_named():
    assert W.compile_wait_s({}) == W.WAIT_S and W.compile_wait_s({"FOOTPRINT_UQ_COMPILE_WAIT_S": "0"}) == 0.0
    for bad in ("nan", "-1", "inf", "soon"):
        with pytest.raises(InputError, match="FOOTPRINT_UQ_COMPILE_WAIT_S"):
            W.compile_wait_s({"FOOTPRINT_UQ_COMPILE_WAIT_S": bad})


def _cams():
    pt = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    T = pt.T_cam_world
    cv = OpenCVCamera(pt.K, np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03]), T[:3, :3], T[:3, 3], (1920, 1080))
    return pt, cv


def _close(a, b):
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.allclose(a, b, rtol=1e-9, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("cam", _cams(), ids=["pantilt", "opencv"])
def test_frame_processor_reference_path_gives_the_kernels_numbers(cam):
    """While the kernels compile in the background a command's FrameProcessor runs the numpy reference: the
    same estimate, per-object rows (the batch's columns) and V2X fields as the compiled kernel."""
    rng = np.random.default_rng(3)
    n = 40
    r, a = rng.uniform(8.0, 90.0, n), np.deg2rad(30.0 + rng.uniform(-40.0, 40.0, n))
    boxes = np.c_[r * np.sin(a), r * np.cos(a), np.full(n, 0.75), np.full(n, 4.5), np.full(n, 1.8),
                  np.full(n, 1.5), rng.uniform(0.0, 3.0, n)]
    boxes[0, 0:2] = [0.0, -20.0]  # behind the camera
    boxes2d = np.c_[rng.uniform(0, 1800, n), rng.uniform(300, 900, n)]
    boxes2d = np.c_[boxes2d, boxes2d + rng.uniform(20.0, 120.0, (n, 2))]
    boxes2d[1] = [900.0, 50.0, 950.0, 100.0]  # above the horizon
    P = np.tile(np.diag([4.0, 9.0]), (n, 1, 1))
    for kw in ({}, {"joint_cov": False, "linearity": False}, {"shared_jacobian": True}):
        fast, ref = FrameProcessor(cam, "basler1", **kw), FrameProcessor(cam, "basler1", **kw)
        _notices.set_compile_handler(lambda group: False)
        ests_ref = [ref.boxes3d(boxes), ref.boxes2d(boxes2d, pixel_cov_px2=P), ref.corners(boxes2d.reshape(n, 2, 2))]
        shared_ref = ref.point_shared_jacobian(boxes2d[:, :2])
        _notices.set_compile_handler(None)
        ests_fast = [fast.boxes3d(boxes), fast.boxes2d(boxes2d, pixel_cov_px2=P),
                     fast.corners(boxes2d.reshape(n, 2, 2))]
        assert fast._kernels and not ref._kernels
        assert _close(shared_ref, fast.point_shared_jacobian(boxes2d[:, :2]))
        for e_ref, e_fast in zip(ests_ref, ests_fast, strict=True):
            assert np.array_equal(e_ref.v2x_codes, e_fast.v2x_codes)
            assert np.array_equal(e_ref.v2x_source, e_fast.v2x_source)
            assert np.array_equal(e_ref.centre_reason, e_fast.centre_reason)
            assert np.array_equal(e_ref.corner_reason, e_fast.corner_reason)
            assert np.array_equal(e_ref.largest_index, e_fast.largest_index)
            for name in ("centre_xy_world_m", "centre_cov_m2", "largest_semi_major_m", "largest_xy_world_m",
                         "corners_xy_world_m", "corners_cov_m2", "joint_cov_m2", "centre_nonlinearity",
                         "corners_nonlinearity", "centre_shared_m", "area_m2", "object_rows"):
                assert _close(getattr(e_ref, name), getattr(e_fast, name)), name
            assert np.isfinite(e_ref.object_rows[:2]).any()


def _objects_cmd(d: Path, out: str) -> list[str]:
    return [sys.executable, "-m", "footprint_uq.cli", "objects", "--camera", str(d / "cam.yaml"), "--budget",
            "basler1", "--detections", str(d / "boxes.csv"), "--out", str(d / out), "--quiet"]


def _write_inputs(d: Path, cam) -> None:
    save_camera(cam, d / "cam.yaml")
    rng = np.random.default_rng(0)
    r, a = rng.uniform(10.0, 80.0, 60), np.deg2rad(30.0 + rng.uniform(-30.0, 30.0, 60))
    lines = ["frame,object_id,x_m,y_m,z_m,length_m,width_m,height_m,yaw_rad"]
    lines += [f"{k // 10},{k},{r[k] * np.sin(a[k]):.3f},{r[k] * np.cos(a[k]):.3f},0.75,4.5,1.8,1.5,"
              f"{rng.uniform(0, 3):.3f}" for k in range(60)]
    (d / "boxes.csv").write_text("\n".join(lines) + "\n")


def _same_records(a: Path, b: Path) -> None:
    ta, tb = pq.read_table(a), pq.read_table(b)
    assert ta.column_names == tb.column_names and ta.num_rows == tb.num_rows == 60
    for name in ta.column_names:
        x, y = ta.column(name).to_pylist(), tb.column(name).to_pylist()
        if isinstance(x[0], float):
            assert np.allclose(np.array(x, dtype=float), np.array(y, dtype=float), rtol=1e-9, atol=1e-12,
                               equal_nan=True), name
        else:
            assert x == y, name


def test_objects_on_the_reference_path_writes_the_same_records(tmp_path):
    """`objects` with FOOTPRINT_UQ_COMPILE=reference (the path of a cold cache's first run) and with the
    kernels: the same records."""
    _write_inputs(tmp_path, _cams()[1])
    env = {**os.environ, "FOOTPRINT_UQ_COMPILE": "reference"}
    r = subprocess.run(_objects_cmd(tmp_path, "ref.parquet"), env=env, capture_output=True, text=True)
    assert r.returncode == 0 and "compiling" not in r.stderr, r.stderr
    env["FOOTPRINT_UQ_COMPILE"] = "foreground"
    r = subprocess.run(_objects_cmd(tmp_path, "fast.parquet"), env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    _same_records(tmp_path / "ref.parquet", tmp_path / "fast.parquet")


@pytest.mark.long  # ~100 s of compile on a 2-core VM: FOOTPRINT_UQ_LONG_TESTS=1 make test (bench_first_run does it too)
def test_cold_cache_first_run_compiles_in_the_background(tmp_path):
    """A fresh NUMBA_CACHE_DIR: the first `objects` says it compiles in the background, finishes on the
    reference path, and leaves a detached compile behind (its lock in the cache folder); once it is done the
    group is warm and a second run writes the same records with the kernels (slow: a full compile)."""
    cache = tmp_path / "numba"
    _write_inputs(tmp_path, _cams()[0])
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "FOOTPRINT_UQ_COMPILE": "background"}
    r = subprocess.run(_objects_cmd(tmp_path, "first.parquet"), env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("compiling the objects kernels in the background") == 1, r.stderr
    probe = ("import sys; from footprint_uq.products import warmup as W; "
             "sys.exit(0 if W.compiling_elsewhere('objects') else 1)")
    t0 = time.monotonic()
    while ((subprocess.run([sys.executable, "-c", probe], env=env).returncode == 0
            or not list(cache.rglob("*process_boxes3d*.nbi"))) and time.monotonic() - t0 < 900):
        time.sleep(1.0)
    check = ("from footprint_uq.products.warmup import cold_groups; import sys; "
             "sys.exit(1 if cold_groups(['objects']) else 0)")
    assert subprocess.run([sys.executable, "-c", check], env=env).returncode == 0
    r = subprocess.run(_objects_cmd(tmp_path, "second.parquet"), env=env, capture_output=True, text=True)
    assert r.returncode == 0 and "compiling" not in r.stderr, r.stderr
    _same_records(tmp_path / "first.parquet", tmp_path / "second.parquet")


def test_warmup_compiles_every_signature_the_commands_use(tmp_path):
    """`warmup` (and so the background compile of a first run) leaves nothing for `objects` (2-D and 3-D
    boxes, lean and with corners), the tracker or `serve` to compile: a kernel signature it missed would be a
    second full compile in the foreground (the batch's column-major boxes once were)."""
    from footprint_uq.batch.process import process_file
    from footprint_uq.fast import footprint_kernels as fk
    from footprint_uq.fast import frame_columns as fc
    from footprint_uq.service.core import Service

    W.warmup(["objects"])
    before = {k: set(k.signatures) for k in W.GROUPS["objects"]}
    cam = _cams()[0]
    _write_inputs(tmp_path, cam)
    process_file(cam, "basler1", tmp_path / "boxes.csv", tmp_path / "a.parquet")
    process_file(cam, "basler1", tmp_path / "boxes.csv", tmp_path / "b.parquet", corners=True)
    (tmp_path / "b2d.csv").write_text("frame,object_id,u_min_px,v_min_px,u_max_px,v_max_px,timestamp_s\n"
                                      "0,1,900,600,1000,700,0.0\n1,1,905,602,1005,702,0.1\n")
    process_file(cam, "basler1", tmp_path / "b2d.csv", tmp_path / "c.parquet", tracks=True)
    service = Service(cam, "basler1", camera_id="cam1")
    service.process_frame({"camera_id": "cam1", "frame": 1, "timestamp_s": 1.0, "detections": [
        {"object_id": 7, "class": "car", "u_min_px": 900, "v_min_px": 600, "u_max_px": 1000, "v_max_px": 700}]})
    lean = Service(cam, "basler1", record="compact")  # (serve's default record: the lean frame's one kernel)
    tracked = Service(cam, "basler1", record="compact", tracks=True)  # (the tracked lean frame: the same kernel)
    for svc, cov in itertools.product((lean, tracked), ("", ',"cov_uu_px2":4,"cov_uv_px2":1,"cov_vv_px2":9')):
        out = svc.process_frame_json(b'{"camera_id":"c","frame":1,"timestamp_s":1.7e9,"detections":[{"object_id":7,'
                                      b'"class":"car","u_min_px":900,"v_min_px":600,"u_max_px":1000,"v_max_px":700'
                                      + cov.encode() + b'}]}')
        assert out.type == "footprints"
    assert {k: set(k.signatures) for k in W.GROUPS["objects"]} == before
    assert fk.process_boxes3d in W.GROUPS["objects"] and fc.boxes2d_columns in W.GROUPS["objects"]


def test_a_long_job_switches_to_the_kernels_between_chunks(tmp_path):
    """A batch whose kernels become ready while it runs (the background compile done after the third chunk)
    takes the reference path, then the kernels: the records are those of a run on the kernels alone."""
    from footprint_uq.batch.process import process_file

    cam = _cams()[1]
    _write_inputs(tmp_path, cam)
    asked = []

    def gate(group):
        asked.append(group)
        if group == "lens":  # the reference path's undistortion (an OpenCV camera): its Python twin meanwhile
            return False
        return asked.count("objects") > 3

    _notices.set_compile_handler(gate)
    process_file(cam, "basler1", tmp_path / "boxes.csv", tmp_path / "mixed.parquet", chunk_rows=10, threads=1)
    # asked before every chunk until the kernels ran, then never again
    assert [g for g in asked if g != "lens"] == ["objects"] * 4 and "lens" in asked
    _notices.set_compile_handler(None)
    process_file(cam, "basler1", tmp_path / "boxes.csv", tmp_path / "kernels.parquet", chunk_rows=10, threads=1)
    _same_records(tmp_path / "mixed.parquet", tmp_path / "kernels.parquet")


def test_warmup_says_when_it_waits_for_another_compile(monkeypatch, tmp_path):
    """`footprint-uq warmup` behind another process's compile of a group says so before it waits."""
    import threading

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setitem(W._WARM, "lens", lambda budget: None)
    (tmp_path / "cache").mkdir()
    proc = _hold_lock(W._lock_path("lens"))
    said, out = [], {}
    job = threading.Thread(target=lambda: out.update(W.warmup(["lens"], on_wait=said.append)))
    try:
        job.start()
        job.join(1.0)
        assert job.is_alive() and said == ["lens"]  # waiting, and said so
    finally:
        proc.kill()
        proc.wait()
    job.join(30.0)
    assert not job.is_alive() and set(out) == {"lens"}


def test_a_library_call_that_compiles_in_its_own_process_says_so_once(monkeypatch):
    """The README's first Python call in a cold cache compiles for tens of seconds: never in silence. The gate
    says once per group that it compiles (naming `footprint-uq warmup`), runs the kernels, and is quiet after."""
    import warnings

    monkeypatch.setattr(W, "cold_groups", lambda groups: list(groups))
    monkeypatch.setattr(W, "compiling_elsewhere", lambda group: False)
    gate = W.LibraryGate()
    with pytest.warns(W.CompileNotice) as caught:
        assert gate("objects") is True
    assert len(caught) == 1
    msg = str(caught[0].message)
    assert "compiling the objects kernels once" in msg and "footprint-uq warmup" in msg
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gate("objects") is True  # said once: the group is ready
    monkeypatch.setattr(W, "cold_groups", lambda groups: [])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gate("map") is True  # a cached group: nothing to say


def test_warmup_itself_says_no_compile_notice(monkeypatch):
    """`footprint-uq warmup` (and a command's background compile) compiles on purpose: the library's notice
    would only repeat what its own progress line says."""
    import warnings

    monkeypatch.setattr(W, "cold_groups", lambda groups: list(groups))
    monkeypatch.setattr(W, "compiling_elsewhere", lambda group: False)
    monkeypatch.setattr(_notices, "_library_handler", W.LibraryGate())  # a fresh process's gate, every group cold
    with warnings.catch_warnings():
        warnings.simplefilter("error", W.CompileNotice)
        out = W.warmup(["objects"])
    assert set(out) == {"objects"}
