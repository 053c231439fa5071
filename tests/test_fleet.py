"""Fleet batch: registry, in-process vs Dask (equal to 1e-12, error rows included), retried failures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from footprint_uq import PanTiltCamera
from footprint_uq.batch import fleet
from footprint_uq.batch.process import process_table
from footprint_uq.errors import ConfigError, InputError
from footprint_uq.io import save_camera

CAMS = {"cam01": dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0),
        "cam02": dict(focal_px=1200.0, image_size_px=(1920, 1080), height_m=6.5, pan_deg=120.0, tilt_deg=15.0,
                      position_m=(40.0, -5.0)),
        "cam03": dict(focal_px=1800.0, image_size_px=(1280, 720), height_m=10.0, pan_deg=250.0, tilt_deg=25.0,
                      position_m=(-20.0, 30.0))}
BUDGETS = {"cam01": "basler1", "cam02": "bw-bullet1", "cam03": "bw-cube1"}


def _boxes(cam, n, rng):
    d = rng.uniform(15.0, 50.0, n)
    a = np.deg2rad(cam.pan_deg if hasattr(cam, "pan_deg") else 0.0) + np.deg2rad(rng.uniform(-15.0, 15.0, n))
    x0, y0 = cam.params[13], cam.params[14]
    return {"x_m": x0 + d * np.sin(a), "y_m": y0 + d * np.cos(a), "z_m": np.full(n, 0.8),
            "length_m": rng.uniform(3.5, 5.0, n), "width_m": rng.uniform(1.6, 2.0, n), "height_m": np.full(n, 1.5),
            "yaw_deg": rng.uniform(-180.0, 180.0, n)}


@pytest.fixture(scope="module")
def fleet_data(tmp_path_factory):
    """Registry (CSV table) + hive-partitioned dataset (camera_id/date) + one mixed file with bad camera ids."""
    root = tmp_path_factory.mktemp("fleet")
    reg = root / "registry"
    reg.mkdir()
    lines = ["camera_id,camera,budget,heading_offset_deg"]
    cams = {}
    for cid, kw in CAMS.items():
        cam = PanTiltCamera(**kw)
        cams[cid] = cam
        save_camera(cam, reg / f"{cid}.yaml")
        lines.append(f"{cid},{cid}.yaml,{BUDGETS[cid]},{5.0 if cid == 'cam02' else ''}")
    (reg / "cameras.csv").write_text("\n".join(lines) + "\n")
    data = root / "detections"
    rng = np.random.default_rng(11)
    tables = {}
    for cid, cam in cams.items():
        for day in ("2024-05-01", "2024-05-02"):
            n = int(rng.integers(150, 260))
            d = _boxes(cam, n, rng)
            d["frame"] = np.arange(n, dtype=np.int64) // 4
            d["object_id"] = np.arange(n, dtype=np.int64)
            d["length_m"][rng.integers(0, n)] = -1.0
            d["yaw_deg"][rng.integers(0, n)] = np.nan
            p = data / f"camera_id={cid}" / f"date={day}"
            p.mkdir(parents=True)
            t = pa.table(d)
            pq.write_table(t, p / "part-0.parquet", row_group_size=64)
            tables[(cid, day)] = t
    # a flat file holding its own camera_id column, with an unknown and a missing id
    n = 30
    d = _boxes(cams["cam01"], n, rng)
    d["frame"] = np.arange(n, dtype=np.int64)
    d["object_id"] = np.arange(n, dtype=np.int64)
    ids = ["cam01"] * 10 + ["cam03"] * 10 + ["cam99"] * 5 + [None] * 5
    extra = data / "extra"
    extra.mkdir()
    pq.write_table(pa.table({"camera_id": ids, **d}), extra / "mixed.parquet")
    return {"root": root, "registry": reg / "cameras.csv", "data": data, "cams": cams, "tables": tables}


def _read(out: Path) -> pa.Table:
    files = sorted(out.rglob("*.parquet"))
    t = pa.concat_tables([pq.read_table(f, partitioning=None) for f in files], promote_options="default")
    order = np.lexsort((t.column("row").to_numpy(), np.array(t.column("source").to_pylist())))
    return t.take(pa.array(order))


def _assert_equal(a: pa.Table, b: pa.Table):
    assert a.num_rows == b.num_rows
    assert sorted(a.column_names) == sorted(b.column_names)
    for c in a.column_names:
        x, y = a.column(c), b.column(c)
        if pa.types.is_floating(x.type):
            np.testing.assert_allclose(x.to_numpy(), y.to_numpy(), rtol=1e-12, atol=0, equal_nan=True, err_msg=c)
        else:
            assert x.to_pylist() == y.to_pylist(), c


def test_registry_forms(fleet_data, tmp_path):
    reg = fleet.load_registry(fleet_data["registry"])
    assert sorted(reg) == ["cam01", "cam02", "cam03"]
    assert reg["cam02"].heading_offset_deg == 5.0 and reg["cam01"].heading_offset_deg is None
    folder = fleet.load_registry(fleet_data["registry"].parent, budget="basler1")  # folder of camera files
    assert sorted(folder) == ["cam01", "cam02", "cam03"]
    yml = tmp_path / "reg.yaml"
    yml.write_text(f"cameras:\n  - camera_id: a\n    camera: {fleet_data['registry'].parent / 'cam01.yaml'}\n"
                   "    budget: basler1\n    origin_lat_deg: 48.1\n    origin_lon_deg: 11.5\n")
    r = fleet.load_registry(yml)
    assert r["a"].origin_lat_deg == 48.1
    with pytest.raises(ConfigError, match="budget"):
        fleet.load_registry(fleet_data["registry"].parent)
    bad = tmp_path / "bad.csv"
    bad.write_text("camera_id,camera,lens\nx,cam.yaml,1\n")
    with pytest.raises(ConfigError, match="lens"):
        fleet.load_registry(bad)


def test_in_process_accounting_and_numbers(fleet_data, tmp_path):
    out = tmp_path / "out"
    s = fleet.process_fleet(fleet_data["registry"], fleet_data["data"], out, progress=False, chunk_rows=100)
    t = _read(out)
    n_in = sum(t_.num_rows for t_ in fleet_data["tables"].values()) + 30
    assert t.num_rows == n_in == s.rows_in == s.rows_out
    keys = set(zip(t.column("source").to_pylist(), t.column("row").to_pylist(), strict=True))
    assert len(keys) == n_in  # no row lost or duplicated
    js = json.loads((out / "_summary.json").read_text())
    assert js["consistent"] and js["rows_in"] == n_in
    for cid, c in js["cameras"].items():
        assert c["rows_in"] == c["rows_out"] == c["rows_ok"] + c["rows_partial"] + c["rows_error"], cid
    assert js["cameras"]["cam99"]["rows_error"] == 5 and js["cameras"][fleet.UNKNOWN_CAMERA]["rows_error"] == 5
    assert (out / "camera_id=cam02" / "date=2024-05-01" / "part-0.parquet").exists()
    # numbers equal a direct single-camera run (cam02: registry heading offset 5 deg, budget bw-bullet1)
    src = fleet_data["tables"][("cam02", "2024-05-02")]
    ref = process_table(fleet_data["cams"]["cam02"], "bw-bullet1", src, heading_offset_deg=5.0)
    got = pq.read_table(out / "camera_id=cam02" / "date=2024-05-02" / "part-0.parquet")
    for c in ("x_m", "cov_xx_m2", "cov_xy_m2", "largest_sigma_major_m"):
        np.testing.assert_array_equal(got.column(c).to_numpy(), ref.column(c).to_numpy())
    for c in ("status", "reason", "j2735_orientation"):
        assert got.column(c).to_pylist() == ref.column(c).to_pylist()
    assert set(got.column("camera_id").to_pylist()) == {"cam02"}
    mixed = t.filter(pa.compute.equal(t.column("source"), "extra/mixed.parquet"))
    reasons = dict(zip(mixed.column("row").to_pylist(), mixed.column("reason").to_pylist(), strict=True))
    assert reasons[22] == "camera_id not in the registry" and reasons[27] == "missing camera_id"


def test_dask_equals_in_process_with_retried_failure(fleet_data, tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    ref_out = tmp_path / "ref"
    fleet.process_fleet(fleet_data["registry"], fleet_data["data"], ref_out, progress=False, chunk_rows=100)
    ref = _read(ref_out)
    # a worker fails once on one partition (file flag), after writing part of its output
    flag = tmp_path / "fail-once"
    flag.write_text("cam03 2024-05-01")
    real = fleet.process_partition
    log = tmp_path / "calls.log"  # the task function is shipped by value: count calls in a file

    def flaky(task):
        with open(log, "a") as f:
            f.write(task.rel + "\n")
        if "camera_id=cam03/date=2024-05-01" in task.rel and flag.exists():
            flag.unlink()
            real(task)  # the output files are written, then the worker dies: the retry must not duplicate rows
            raise OSError("injected worker failure")
        return real(task)

    monkeypatch.setattr(fleet, "process_partition", flaky)
    with distributed.Client(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as client:
        out = tmp_path / "dask"
        s = fleet.process_fleet(fleet_data["registry"], fleet_data["data"], out, client=client, retries=2,
                                progress=False, chunk_rows=100)
    calls = log.read_text().splitlines()
    assert not flag.exists() and calls.count("camera_id=cam03/date=2024-05-01/part-0.parquet") == 2
    assert len(calls) == 8  # 7 partitions, one retried
    got = _read(out)
    _assert_equal(got, ref)
    assert s.rows_in == s.rows_out == ref.num_rows
    assert not list(out.rglob("*.tmp-*"))  # no partial files left behind
    a = json.loads((ref_out / "_summary.json").read_text())
    b = json.loads((out / "_summary.json").read_text())
    assert a["cameras"] == b["cameras"]


def test_no_retry_fails_loudly(fleet_data, tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")

    def broken(task):
        raise OSError("disk gone")

    monkeypatch.setattr(fleet, "process_partition", broken)
    with distributed.Client(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as client:
        with pytest.raises(OSError, match="disk gone"):
            fleet.process_fleet(fleet_data["registry"], fleet_data["data"], tmp_path / "o", client=client, retries=0,
                                progress=False)


def test_fleet_bad_input(fleet_data, tmp_path):
    with pytest.raises(InputError, match="outside"):
        fleet.process_fleet(fleet_data["registry"], fleet_data["data"], fleet_data["data"] / "out", progress=False)
    with pytest.raises(InputError, match="parquet"):
        fleet.process_fleet(fleet_data["registry"], tmp_path, tmp_path / "o", progress=False)


def test_cli_fleet(fleet_data, tmp_path):
    from click.testing import CliRunner

    distributed = pytest.importorskip("distributed")
    from footprint_uq.cli.main import main
    from footprint_uq.cli.objects import objects_cmd

    if "objects" not in main.commands:
        main.add_command(objects_cmd)
    args = ["objects", "--registry", str(fleet_data["registry"]), "--detections", str(fleet_data["data"]), "--quiet"]
    r = CliRunner().invoke(main, args + ["--out", str(tmp_path / "a")])
    assert r.exit_code == 0, r.output
    assert "over 5 cameras" in r.output
    with distributed.Client(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as client:
        r = CliRunner().invoke(main, args + ["--out", str(tmp_path / "b"), "--scheduler", client.scheduler.address])
    assert r.exit_code == 0, r.output
    _assert_equal(_read(tmp_path / "a"), _read(tmp_path / "b"))
    js = json.loads((tmp_path / "b" / "_summary.json").read_text())
    assert js["mode"] == "dask" and js["consistent"]
    r = CliRunner().invoke(main, args + ["--out", str(tmp_path / "c"), "--camera", "x.yaml"])
    assert r.exit_code == 2 and "--registry" in r.output


def test_local_process_cluster(fleet_data, tmp_path):
    """workers=2: a real local cluster of worker processes (tasks, cameras and budgets pickled)."""
    pytest.importorskip("distributed")
    ref_out = tmp_path / "ref"
    fleet.process_fleet(fleet_data["registry"], fleet_data["data"], ref_out, progress=False, chunk_rows=100)
    out = tmp_path / "procs"
    s = fleet.process_fleet(fleet_data["registry"], fleet_data["data"], out, workers=2, progress=False,
                            chunk_rows=100)
    assert s.consistent and json.loads((out / "_summary.json").read_text())["mode"] == "dask"
    _assert_equal(_read(out), _read(ref_out))


def test_output_paths_never_collide(fleet_data, tmp_path):
    """A flat file with a camera_id column next to camera_id=.../ folders of the same name."""
    import shutil

    data = tmp_path / "d"
    shutil.copytree(fleet_data["data"], data)
    shutil.copy(data / "extra" / "mixed.parquet", data / "camera_id=cam01" / "date=2024-05-01" / "x.parquet")
    (data / "date=2024-05-01").mkdir()
    shutil.copy(data / "extra" / "mixed.parquet", data / "date=2024-05-01" / "x.parquet")
    reg = fleet.load_registry(fleet_data["registry"])
    tasks = fleet.plan(data, tmp_path / "o", reg)
    outs = [t.out_rel for t in tasks]
    assert "date=2024-05-01/part-0.parquet" in outs  # the usual hive layout keeps its names
    assert sum(o.startswith("date=2024-05-01/x.f") for o in outs) == 2
    s = fleet.process_fleet(reg, data, tmp_path / "o", progress=False)
    t = _read(tmp_path / "o")
    assert t.num_rows == s.rows_in == sum(pq.read_metadata(f).num_rows for f in data.rglob("*.parquet"))
