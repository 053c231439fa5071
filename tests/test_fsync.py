"""Durable outputs and ``fsync=False`` / ``--no-fsync``: what is synced, and that nothing else changes.

By default every batch output is flushed to the disk and fsynced (file and folder) before it is renamed
into place; ``fsync=False`` skips exactly those calls and keeps the write-then-rename (a killed job never
leaves a partial output: tests/test_reliability.py kills one run with ``--no-fsync``).  The calls are
counted by wrapping ``os.fsync`` / ``os.fdatasync``, so these tests fail if either path stops syncing or
starts syncing.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from footprint_uq import PanTiltCamera, save_camera
from footprint_uq.batch.fleet import process_fleet
from footprint_uq.batch.process import process_file
from footprint_uq.cli.main import main
from footprint_uq.io.atomic import TMP_MARK, atomic_write_text, commit, temp_path

CAM = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


@pytest.fixture
def syncs(monkeypatch):
    """Counts of os.fsync / os.fdatasync calls (the real calls still run)."""
    n = {"fsync": 0, "fdatasync": 0}
    for name in n:
        real = getattr(os, name)

        def counted(fd, _real=real, _name=name):
            n[_name] += 1
            return _real(fd)

        monkeypatch.setattr(os, name, counted)
    return n


def _boxes(n: int, seed: int = 0, cameras=None) -> pa.Table:
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(100, 1700, n), rng.uniform(600, 1000, n)
    cols = {"frame": np.arange(n, dtype=np.int64), "u_min_px": u, "v_min_px": v - 40.0, "u_max_px": u + 80.0,
            "v_max_px": v}
    if cameras:
        cols = {"camera_id": pa.array([cameras[i % len(cameras)] for i in range(n)]), **cols}
    return pa.table(cols)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    d = tmp_path_factory.mktemp("fsync")
    save_camera(PanTiltCamera(**CAM), d / "cam.yaml")
    pq.write_table(_boxes(5_000), d / "det.parquet")
    reg = d / "reg"
    reg.mkdir()
    for c in ("cam1", "cam2"):
        save_camera(PanTiltCamera(**CAM), reg / f"{c}.yaml")
    data = d / "data"
    data.mkdir()
    for i in range(2):
        pq.write_table(_boxes(3_000, i, ["cam1", "cam2"]), data / f"part-{i}.parquet")
    return d


def test_commit_without_fsync_only_renames(tmp_path, syncs):
    final = tmp_path / "a.txt"
    final.write_text("old")
    tmp = temp_path(final)
    tmp.write_text("new")
    commit(tmp, final, fsync=False)
    assert final.read_text() == "new" and not tmp.exists()
    assert syncs == {"fsync": 0, "fdatasync": 0}
    atomic_write_text(final, "newer")  # the default: the file and its folder
    assert final.read_text() == "newer" and syncs["fsync"] == 2


@pytest.mark.parametrize("ext", ["parquet", "csv", "jsonl"])
def test_process_file_with_and_without_fsync(site, tmp_path, syncs, ext):
    cam = PanTiltCamera(**CAM)
    a, b = tmp_path / f"a.{ext}", tmp_path / f"b.{ext}"
    s_a = process_file(cam, "basler1", site / "det.parquet", a, chunk_rows=1_000, progress=False)
    synced = dict(syncs)
    assert synced["fdatasync"] >= 5 and synced["fsync"] >= 4  # a chunk each; output, summary and their folder
    s_b = process_file(cam, "basler1", site / "det.parquet", b, chunk_rows=1_000, progress=False, fsync=False)
    assert syncs == synced  # not one call more
    assert a.read_bytes() == b.read_bytes()
    assert s_a.rows_out == s_b.rows_out == 5_000
    assert json.loads(Path(f"{a}.summary.json").read_text())["fsync"] is True
    assert json.loads(Path(f"{b}.summary.json").read_text())["fsync"] is False
    assert not [p for p in tmp_path.iterdir() if TMP_MARK in p.name]


def test_fleet_with_and_without_fsync(site, tmp_path, syncs):
    a = process_fleet(site / "reg", site / "data", tmp_path / "a", budget="basler1", progress=False)
    synced = dict(syncs)
    assert synced["fsync"] >= 4  # each camera's file, the summary, the folders
    b = process_fleet(site / "reg", site / "data", tmp_path / "b", budget="basler1", progress=False, fsync=False)
    assert syncs == synced
    assert a.rows_out == b.rows_out == 6_000
    ta = ds.dataset(tmp_path / "a", format="parquet", partitioning="hive").to_table().sort_by("row")
    tb = ds.dataset(tmp_path / "b", format="parquet", partitioning="hive").to_table().sort_by("row")
    assert ta.num_rows == 6_000 and ta.drop_columns(["source"]).equals(tb.drop_columns(["source"]))
    assert json.loads((tmp_path / "b" / "_summary.json").read_text())["fsync"] is False


def test_cli_no_fsync(site, tmp_path, syncs):
    out = tmp_path / "fp.parquet"
    r = CliRunner().invoke(main, ["objects", "--camera", str(site / "cam.yaml"), "--budget", "basler1",
                                  "--detections", str(site / "det.parquet"), "--out", str(out), "--quiet",
                                  "--no-fsync"])
    assert r.exit_code == 0, r.output
    assert syncs == {"fsync": 0, "fdatasync": 0}
    assert pq.ParquetFile(out).metadata.num_rows == 5_000
    r = CliRunner().invoke(main, ["objects", "--camera", str(site / "cam.yaml"), "--budget", "basler1",
                                  "--detections", str(site / "det.parquet"), "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert syncs["fsync"] >= 4 and syncs["fdatasync"] >= 1
