"""Fault tests (issue 11): killed jobs, full disks, outputs that are inputs, names from data.

The promise tested everywhere: after any failure nothing new stands under a final name, the
previous output (and the summary that describes it) is intact or the summary is gone, never a
summary beside another file than its own; a re-run succeeds.  The kill tests run the CLI in a
subprocess and SIGKILL it once its temporary output exists (i.e. while it writes).
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from footprint_uq import PanTiltCamera, save_camera
from footprint_uq.cli.main import main
from footprint_uq.io.atomic import (
    TMP_MARK,
    atomic_path,
    atomic_write_text,
    clean_temporaries_of,
    path_component,
    recover_folder,
    temp_path,
)

SRC = Path(__file__).resolve().parents[1] / "src"
CAM = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _boxes(n: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    u = rng.uniform(100, 1700, n)
    v = rng.uniform(600, 1000, n)
    return {"frame": np.arange(n, dtype=np.int64), "u_min_px": u, "v_min_px": v - 40.0, "u_max_px": u + 80.0,
            "v_max_px": v}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    d = tmp_path_factory.mktemp("site")
    save_camera(PanTiltCamera(**CAM), d / "cam.yaml")
    pq.write_table(pa.table(_boxes(200)), d / "small.parquet")
    pq.write_table(pa.table(_boxes(400_000, 1)), d / "big.parquet", row_group_size=20_000)
    return d


def _objects(site, det, out, *extra):
    return ["objects", "--camera", str(site / "cam.yaml"), "--budget", "basler1", "--detections", str(det),
            "--out", str(out), "--quiet", *extra]


def _temps(folder: Path) -> list[Path]:
    return [p for p in Path(folder).rglob(f"*{TMP_MARK}*")]


def _rows(path: Path) -> int:
    if path.suffix == ".parquet":
        return pq.ParquetFile(path).metadata.num_rows
    if path.suffix == ".csv":
        import pyarrow.csv as pcsv

        return pcsv.read_csv(path).num_rows
    return sum(1 for _ in path.open())


# -- atomic helper -------------------------------------------------------------------------------
def test_atomic_path_keeps_previous_on_error(tmp_path):
    p = tmp_path / "a.txt"
    atomic_write_text(p, "old")
    with pytest.raises(RuntimeError), atomic_path(p) as tmp:
        tmp.write_text("half")
        raise RuntimeError("killed")
    assert p.read_text() == "old" and _temps(tmp_path) == []
    with atomic_path(p) as tmp:
        assert tmp.name.startswith(".a") and tmp.suffix == ".txt" and tmp.parent == tmp_path
        tmp.write_text("new")
    assert p.read_text() == "new" and _temps(tmp_path) == []


@pytest.mark.parametrize("name", ["a/../../../x", "..", ".", ".hidden", "", "cam 7", "caméra", "a\\b", "x\x00y",
                                  "__unknown__", "%2F"])
def test_path_component_is_one_safe_component(name):
    from urllib.parse import unquote

    c = path_component(name)
    assert "/" not in c and "\\" not in c and "\x00" not in c and c not in (".", "..") and not c.startswith(".")
    assert c and (unquote(c) == name or name == "")


# -- single-file jobs ----------------------------------------------------------------------------
def test_hardlinked_out_is_refused(site, tmp_path):
    det = tmp_path / "d.parquet"
    pq.write_table(pa.table(_boxes(50)), det)
    link = tmp_path / "link.parquet"
    os.link(det, link)
    before = det.read_bytes()
    r = CliRunner().invoke(main, _objects(site, det, link))
    assert r.exit_code == 2 and "same file" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert det.read_bytes() == before


@pytest.mark.parametrize("ext", ["parquet", "csv", "jsonl"])
def test_enospc_keeps_previous_output(site, tmp_path, monkeypatch, ext):
    from footprint_uq.batch import writers

    out = tmp_path / f"fp.{ext}"
    assert CliRunner().invoke(main, _objects(site, site / "small.parquet", out)).exit_code == 0
    old, old_summary = out.read_bytes(), Path(f"{out}.summary.json").read_bytes()
    cls = {"parquet": writers.ParquetOut, "csv": writers.CsvOut, "jsonl": writers.JsonlOut}[ext]
    calls = []

    def full_disk(self, table):
        calls.append(1)
        if len(calls) >= 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(self.tmp))
        return orig(self, table)

    orig = cls._write
    monkeypatch.setattr(cls, "_write", full_disk)
    r = CliRunner().invoke(main, _objects(site, site / "big.parquet", out, "--chunk-rows", "50000"))
    assert r.exit_code == 2 and "No space left" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert out.read_bytes() == old and Path(f"{out}.summary.json").read_bytes() == old_summary
    assert _temps(tmp_path) == []
    monkeypatch.setattr(cls, "_write", orig)
    r = CliRunner().invoke(main, _objects(site, site / "big.parquet", out, "--chunk-rows", "50000"))
    assert r.exit_code == 0 and _rows(out) == 400_000


def _kill_when(proc, seen, timeout_s: float = 120.0) -> bool:
    """SIGKILL ``proc`` as soon as ``seen()`` is true; False if it finished first."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if proc.poll() is not None:
            return False
        if seen():
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            return True
        time.sleep(0.002)
    proc.kill()
    raise AssertionError("job neither wrote nor finished")


def _cli(args) -> list[str]:
    return [sys.executable, "-c", "from footprint_uq.cli.main import main; main()", *[str(a) for a in args]]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.mark.parametrize(("ext", "flags"), [("parquet", ()), ("csv", ()), ("jsonl", ()), ("parquet", ("--no-fsync",))])
def test_sigkill_single_file_job(site, tmp_path, ext, flags):
    """Killed while writing: the previous output and its summary stay, no summary describes another file
    (with ``--no-fsync`` too: only durability across a power loss is given up, not atomicity)."""
    out = tmp_path / f"fp.{ext}"
    assert CliRunner().invoke(main, _objects(site, site / "small.parquet", out)).exit_code == 0
    old = out.read_bytes()
    summ = Path(f"{out}.summary.json")
    killed = 0
    for _attempt in range(3):
        proc = subprocess.Popen(_cli(_objects(site, site / "big.parquet", out, "--chunk-rows", "20000", *flags)),
                                env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if _kill_when(proc, lambda: any(p.name.startswith(".fp") for p in tmp_path.iterdir())):
            killed += 1
            break
    assert killed, "the job always finished before it could be killed"
    # under the final name: the old complete file (or, killed after the rename, the new complete one)
    assert out.read_bytes() == old or _rows(out) == 400_000
    if summ.exists():  # a summary always describes the file beside it
        assert json.loads(summ.read_text())["rows_out"] == _rows(out)
    r = subprocess.run(_cli(_objects(site, site / "big.parquet", out, "--chunk-rows", "20000")), env=_env(),
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert _rows(out) == 400_000 and json.loads(summ.read_text())["consistent"] is True
    assert _temps(tmp_path) == []  # the re-run removed the killed run's temporary file


# -- fleet jobs ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleetrel")
    reg = d / "reg"
    reg.mkdir()
    save_camera(PanTiltCamera(**CAM), reg / "cam1.yaml")
    save_camera(PanTiltCamera(**CAM), reg / "cam2.yaml")
    data = d / "data"
    data.mkdir()
    for i in range(4):
        b = _boxes(60_000, 10 + i)
        ids = np.where(np.arange(60_000) % 2 == 0, "cam1", "cam2").astype(object)
        ids[:3] = "a/../../../x"  # a camera id that would climb out of --out if joined raw
        pq.write_table(pa.table({"camera_id": pa.array(ids.tolist()), **b}), data / f"part-{i}.parquet",
                       row_group_size=10_000)
    return {"reg": reg, "data": data, "root": d}


def _fleet_args(fleet, data, out, *extra):
    return ["objects", "--registry", str(fleet["reg"]), "--budget", "basler1", "--detections", str(data),
            "--out", str(out), "--quiet", *extra]


def test_fleet_names_from_data_overwrite_and_stale_files(fleet, tmp_path):
    import pyarrow.dataset as ds

    out = tmp_path / "out"
    r = CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out))
    assert r.exit_code == 0, r.stderr
    files = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file())
    assert all(f.startswith("out/") for f in files)  # nothing written outside --out
    assert (out / "camera_id=a%2F..%2F..%2F..%2Fx").is_dir()
    t = ds.dataset(out, format="parquet", partitioning="hive").to_table()
    assert t.num_rows == 240_000
    assert set(t.column("camera_id").to_pylist()) == {"cam1", "cam2", "a/../../../x"}
    # a non-empty --out is refused without --overwrite, and left as it was
    before = sorted((p.as_posix(), p.stat().st_size) for p in out.rglob("*"))
    r = CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out))
    assert r.exit_code == 2 and "--overwrite" in r.stderr
    assert sorted((p.as_posix(), p.stat().st_size) for p in out.rglob("*")) == before
    # leftovers of killed runs (a temporary partition, a staging folder) and fewer inputs: --overwrite
    # replaces the whole output, nothing stale remains and the dataset reads
    (out / "camera_id=cam1" / ".part-0.tmp-deadbeef.parquet").write_bytes(b"PAR1 half")
    (out / "camera_id=cam1" / "part-0.parquet.tmp-0123abcd").write_bytes(b"old-style temporary")
    (tmp_path / f".out{TMP_MARK}cafecafe").mkdir()
    fewer = tmp_path / "fewer"
    fewer.mkdir()
    for i in range(2):
        os.link(fleet["data"] / f"part-{i}.parquet", fewer / f"part-{i}.parquet")
    r = CliRunner().invoke(main, _fleet_args(fleet, fewer, out, "--overwrite"))
    assert r.exit_code == 0, r.stderr
    t = ds.dataset(out, format="parquet", partitioning="hive").to_table()
    js = json.loads((out / "_summary.json").read_text())
    assert t.num_rows == js["rows_out"] == 120_000 and js["consistent"] is True
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]
    assert _temps(out) == [] and not list(out.rglob("*.tmp-*"))


def test_fleet_enospc_keeps_previous_output(fleet, tmp_path, monkeypatch):
    out = tmp_path / "out"
    assert CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out)).exit_code == 0
    before = sorted((p.relative_to(out).as_posix(), p.read_bytes()) for p in out.rglob("*") if p.is_file())
    calls = []
    orig = pq.ParquetWriter.write_table

    def full_disk(self, table, *a, **k):
        calls.append(1)
        if len(calls) >= 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return orig(self, table, *a, **k)

    monkeypatch.setattr(pq.ParquetWriter, "write_table", full_disk)
    r = CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out, "--overwrite"))
    assert r.exit_code == 2 and "No space left" in r.stderr
    after = sorted((p.relative_to(out).as_posix(), p.read_bytes()) for p in out.rglob("*") if p.is_file())
    assert after == before
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no staging folder left
    monkeypatch.setattr(pq.ParquetWriter, "write_table", orig)
    assert CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out, "--overwrite")).exit_code == 0


def test_sigkill_fleet_job(fleet, tmp_path):
    out = tmp_path / "out"
    assert CliRunner().invoke(main, _fleet_args(fleet, fleet["data"], out)).exit_code == 0
    before = sorted((p.relative_to(out).as_posix(), p.read_bytes()) for p in out.rglob("*") if p.is_file())
    proc = subprocess.Popen(_cli(_fleet_args(fleet, fleet["data"], out, "--overwrite", "--chunk-rows", "5000")),
                            env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def writing():
        return any(p.name.startswith(".out") and any(p.rglob("*.parquet")) for p in tmp_path.iterdir())

    killed = _kill_when(proc, writing)
    assert killed, "the fleet job finished before it could be killed"
    after = sorted((p.relative_to(out).as_posix(), p.read_bytes()) for p in out.rglob("*") if p.is_file())
    assert after == before  # the previous output as it was
    r = subprocess.run(_cli(_fleet_args(fleet, fleet["data"], out, "--overwrite")), env=_env(),
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # the killed run's staging folder is gone
    import pyarrow.dataset as ds

    assert ds.dataset(out, format="parquet", partitioning="hive").to_table().num_rows == 240_000


def test_dask_worker_killed_mid_job(fleet, tmp_path):
    """A Dask worker SIGKILLed while it writes: its task is rerun elsewhere, every row is written once."""
    distributed = pytest.importorskip("distributed")
    import threading

    import pyarrow.dataset as ds

    from footprint_uq.batch.fleet import process_fleet

    out = tmp_path / "out"
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    client = distributed.Client(cluster)
    try:
        pids = client.run(os.getpid)
        killed = []

        def killer():
            t0 = time.monotonic()
            while time.monotonic() - t0 < 120 and not killed:
                for p in tmp_path.iterdir():
                    if p.name.startswith(".out") and any(p.rglob(f"*{TMP_MARK}*.parquet")):
                        pid = next(iter(pids.values()))
                        os.kill(pid, signal.SIGKILL)
                        killed.append(pid)
                        return
                time.sleep(0.005)

        th = threading.Thread(target=killer, daemon=True)
        th.start()
        s = process_fleet(fleet["reg"], fleet["data"], out, budget="basler1", client=client, retries=2,
                          chunk_rows=5000, progress=False)
        th.join(5)
    finally:
        client.close()
        cluster.close()
    assert killed, "no worker was killed while writing"
    assert s.consistent and s.rows_in == s.rows_out == 240_000
    t = ds.dataset(out, format="parquet", partitioning="hive").to_table()
    assert t.num_rows == 240_000
    keys = np.array(t.column("source").to_pylist(), dtype=object) + ":" + np.char.mod("%d", t.column("row")
                                                                                      .to_numpy()).astype(object)
    assert len(set(keys.tolist())) == 240_000  # every input row exactly once
    assert _temps(out) == [] and [p.name for p in tmp_path.iterdir()] == ["out"]


def test_batch_never_reports_an_overflowed_row_as_ok():
    """Absurd but finite inputs (a box at 1e300 px, a detector covariance of 1e300 px^2): error rows with a reason."""
    from footprint_uq.batch import process_table
    from footprint_uq.batch.process import OVERFLOW_REASON

    cam = PanTiltCamera(**CAM)
    d = {"u_min_px": np.array([900.0, 1e300, 900.0, 900.0]), "v_min_px": np.array([500.0, 500.0, 1e300, 500.0]),
         "u_max_px": np.array([980.0, 1e301, 980.0, 980.0]), "v_max_px": np.array([560.0, 560.0, 1e301, 560.0]),
         "cov_uu_px2": np.array([np.nan, np.nan, np.nan, 1e300]), "cov_uv_px2": np.array([np.nan, np.nan, np.nan, 0]),
         "cov_vv_px2": np.array([np.nan, np.nan, np.nan, 1e300])}
    with np.errstate(all="ignore"):
        t = process_table(cam, "basler1", d, allow_outside_image=True)
    status, reason = t.column("status").to_pylist(), t.column("reason").to_pylist()
    assert status == ["ok", "error", "error", "error"]
    assert reason[1:3] == [OVERFLOW_REASON] * 2 and reason[3].startswith("pixel covariance out of range")
    for c in ("x_m", "y_m", "cov_xx_m2", "sigma_major_m"):
        v = t.column(c).to_numpy()
        assert np.isfinite(v[0]) and np.isnan(v[1:]).all(), c
    assert t.column("cpm_x_confidence").to_pylist()[1:] == [4096] * 3


def test_fuse_out_hardlinked_to_an_input_is_refused(tmp_path):
    hdr = "frame,object_id,x_m,y_m,cov_xx_m2,cov_xy_m2,cov_yy_m2\n"
    a = tmp_path / "a.csv"
    b = tmp_path / "b.csv"
    a.write_text(hdr + "1,o1,10,5,0.04,0,0.04\n")
    b.write_text(hdr + "1,o1,10.1,5,0.04,0,0.04\n")
    link = tmp_path / "fused.csv"
    os.link(b, link)
    before = b.read_bytes()
    r = CliRunner().invoke(main, ["fuse", str(a), str(b), "--out", str(link)])
    assert r.exit_code == 2 and "same file" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert b.read_bytes() == before and _temps(tmp_path) == []


@pytest.mark.parametrize("name", ["fp", "fp.d", "out.v2.parquet"])
def test_recover_folder_finds_its_own_staging_only(tmp_path, name):
    """A killed job's staging folder (named by temp_path: ``.<stem>.tmp-<hex><suffix>``) is removed on the next
    run for any ``--out`` name, a dotted one included; another folder's staging beside it is left alone."""
    out = tmp_path / name
    mine = temp_path(out)
    mine.mkdir()
    (mine / "part.csv").write_text("x\n")
    other = temp_path(tmp_path / (name + ".d"))  # a different --out whose name starts like ours
    other.mkdir()
    stray_file = temp_path(tmp_path / (name + "x"))
    stray_file.write_text("y")
    recover_folder(out)
    assert not mine.exists()
    assert other.is_dir() and stray_file.is_file()
    assert clean_temporaries_of(tmp_path / (name + "x")) == 1 and not stray_file.exists()
