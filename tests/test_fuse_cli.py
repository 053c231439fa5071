"""Multi-camera fusion through the CLI (``footprint-uq fuse``) and footprint_uq.batch.fusion_files.

The per-camera inputs are made by the real footprint pipeline (``process_file`` on two
PanTiltCameras seeing one shared set of 3D boxes), written as CSV or Parquet.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from footprint_uq import PanTiltCamera
from footprint_uq.batch import process_table
from footprint_uq.batch.fusion_files import fuse_files, fuse_footprints, sources_path, summary_path
from footprint_uq.batch.process import process_file
from footprint_uq.errors import InputError
from footprint_uq.products.footprints import box3d_bottom_corners
from footprint_uq.products.fusion import pairwise_mahalanobis
from footprint_uq.products.v2x import cpm_fields, j2735_fields
from footprint_uq.uncertainty.ellipse import ellipse_axes

BUDGET = "basler1"
# A looks north from the origin; B looks east from 30 m west: the two views cross at right angles
CAM_A = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=0.0, tilt_deg=15.0)
CAM_B = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=10.0, pan_deg=90.0, tilt_deg=15.0,
             position_m=(-30.0, 32.0))
N_OBJ, N_FRAMES = 8, 2
ONLY_A = ("o6", "o7")  # outside B's detections: passed through with n_cameras = 1


def _boxes(seed=0):
    rng = np.random.default_rng(seed)
    n = N_OBJ * N_FRAMES
    return np.stack([rng.uniform(-5, 5, n), rng.uniform(25, 40, n), np.full(n, 0.8), rng.uniform(3.8, 4.8, n),
                     rng.uniform(1.6, 1.9, n), np.full(n, 1.5), rng.uniform(-np.pi, np.pi, n)], 1)


def _detections(boxes, keep=None, seed=None):
    """Detections table; with ``seed`` the box centres get a detector's error (0.1 m, independent per camera)."""
    n = boxes.shape[0]
    if seed is not None:
        boxes = boxes.copy()
        boxes[:, :2] += np.random.default_rng(seed).normal(0.0, 0.1, (n, 2))
    d = {"frame": np.repeat(np.arange(N_FRAMES, dtype=np.int64), N_OBJ),
         "object_id": [f"o{i % N_OBJ}" for i in range(n)], "class": ["car"] * n}
    for j, c in enumerate(("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")):
        d[c] = boxes[:, j]
    t = pa.table(d)
    if keep is not None:
        t = t.filter(pa.array(keep))
    return t


@pytest.fixture(scope="module")
def footprints(tmp_path_factory):
    """Per-camera footprint files (Parquet and CSV) from the real pipeline."""
    tmp = tmp_path_factory.mktemp("fuse")
    boxes = _boxes()
    keep_b = np.array([f"o{i % N_OBJ}" not in ONLY_A for i in range(boxes.shape[0])])
    out = {}
    for name, cam, keep, seed in (("camA", PanTiltCamera(**CAM_A), None, 11),
                                  ("camB", PanTiltCamera(**CAM_B), keep_b, 12)):
        det = tmp / f"det_{name}.parquet"
        pq.write_table(_detections(boxes, keep, seed), det)
        for ext in ("parquet", "csv", "jsonl"):
            f = tmp / ext / f"{name}.{ext}"
            f.parent.mkdir(exist_ok=True)
            s = process_file(cam, BUDGET, det, f, progress=False)
            assert s.rows_error == 0 and s.rows_partial == 0
            out[(name, ext)] = f
    return out


def _cli():
    from footprint_uq.cli.fuse import fuse_cmd
    from footprint_uq.cli.main import FootprintUQGroup

    g = FootprintUQGroup(name="footprint-uq")
    g.add_command(fuse_cmd)
    return g


def _read(path) -> pa.Table:
    if path.suffix == ".jsonl":
        import pyarrow.json as pjson

        return pjson.read_json(path)
    return pq.read_table(path) if path.suffix == ".parquet" else pcsv.read_csv(path)


def _cov(t: pa.Table, i: int) -> np.ndarray:
    r = {c: t.column(c)[i].as_py() for c in ("cov_xx_m2", "cov_xy_m2", "cov_yy_m2")}
    return np.array([[r["cov_xx_m2"], r["cov_xy_m2"]], [r["cov_xy_m2"], r["cov_yy_m2"]]])


def _xy(t: pa.Table, i: int) -> np.ndarray:
    return np.array([t.column("x_m")[i].as_py(), t.column("y_m")[i].as_py()])


def _row_of(t: pa.Table, frame: int, oid: str) -> int:
    fr, ob = t.column("frame").to_pylist(), [str(o) for o in t.column("object_id").to_pylist()]
    hits = [i for i in range(t.num_rows) if fr[i] == frame and ob[i] == oid]
    assert len(hits) == 1, (frame, oid, hits)
    return hits[0]


@pytest.mark.parametrize("ext", ["parquet", "csv", "jsonl"])
def test_cli_fuses_two_cameras(footprints, tmp_path, ext):
    a, b = footprints[("camA", ext)], footprints[("camB", ext)]
    out = tmp_path / f"fused.{ext}"
    r = CliRunner().invoke(_cli(), ["fuse", str(a), str(b), "--out", str(out)])
    assert r.exit_code == 0, r.output
    n_a, n_b = N_OBJ * N_FRAMES, (N_OBJ - len(ONLY_A)) * N_FRAMES
    assert (f"rows in {n_a + n_b}, rows used {n_a + n_b}, rows rejected 0; objects out {n_a} "
            f"(fused {n_b}, single camera {n_a - n_b}, unavailable 0), inconsistent objects 0") in r.output
    js = json.loads(summary_path(out).read_text())
    assert js["consistent"] and js["rows_in"] == n_a + n_b and js["camera_id_from"] == "filename"
    assert [i["camera_id"] for i in js["inputs"]] == ["camA", "camB"]
    fused, ta, tb = _read(out), _read(a), _read(b)
    src = _read(sources_path(out))
    assert fused.num_rows == n_a and src.num_rows == n_a + n_b
    assert src.column("used").to_pylist() == [True] * (n_a + n_b)
    assert src.column("source_row").to_pylist() == list(range(n_a)) + list(range(n_b))
    for i in range(fused.num_rows):
        frame, oid = fused.column("frame")[i].as_py(), str(fused.column("object_id")[i].as_py())
        ia = _row_of(ta, frame, oid)
        CA, xa = _cov(ta, ia), _xy(ta, ia)
        P, x = _cov(fused, i), _xy(fused, i)
        if oid in ONLY_A:  # one camera: passed through unchanged
            assert fused.column("n_cameras")[i].as_py() == 1 and fused.column("cameras")[i].as_py() == "camA"
            assert np.array_equal(P, CA) and np.array_equal(x, xa)
            assert fused.column("chi2_dof")[i].as_py() == 0
            continue
        ib = _row_of(tb, frame, oid)
        CB, xb = _cov(tb, ib), _xy(tb, ib)
        assert fused.column("n_cameras")[i].as_py() == 2 and fused.column("cameras")[i].as_py() == "camA,camB"
        assert np.linalg.norm(xa - xb) > 1e-3  # the detectors' errors differ: a non-trivial fusion
        # information form by hand
        P_ref = np.linalg.inv(np.linalg.inv(CA) + np.linalg.inv(CB))
        x_ref = P_ref @ (np.linalg.solve(CA, xa) + np.linalg.solve(CB, xb))
        np.testing.assert_allclose(P, P_ref, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(x, x_ref, rtol=1e-12)
        # smaller than each input: C_i - P positive semi-definite, and strictly smaller ellipses
        for Ci in (CA, CB):
            assert np.linalg.eigvalsh(Ci - P).min() > -1e-12
            assert np.linalg.det(P) < 0.5 * np.linalg.det(Ci)
            assert ellipse_axes(P)[0] < ellipse_axes(Ci)[0]
        # the two views cross at right angles: the fused ellipse is much rounder than either input
        assert fused.column("sigma_major_m")[i].as_py() < 0.5 * min(ellipse_axes(CA)[0], ellipse_axes(CB)[0])
        assert fused.column("consistent")[i].as_py() is True
        d2 = fused.column("max_d2")[i].as_py()
        assert d2 == pytest.approx(pairwise_mahalanobis([xa, xb], [CA, CB])[0, 1], rel=1e-9)
        # V2X fields and ellipse of the fused covariance
        for name, v in {**cpm_fields(P_ref), **j2735_fields(P_ref)}.items():
            assert fused.column(name)[i].as_py() == int(v), name
        a95, b95, _ = ellipse_axes(P_ref, confidence=0.95)
        assert fused.column("semi_major_m")[i].as_py() == pytest.approx(float(a95), rel=1e-9)
        assert fused.column("semi_minor_m")[i].as_py() == pytest.approx(float(b95), rel=1e-9)


def test_one_object_by_hand_through_the_api(footprints):
    """Frame 1, object o3: the fused numbers against numpy's information form, written out."""
    ta, tb = pq.read_table(footprints[("camA", "parquet")]), pq.read_table(footprints[("camB", "parquet")])
    res = fuse_footprints([ta, tb], camera_ids=["A", "B"])
    ia, ib = _row_of(ta, 1, "o3"), _row_of(tb, 1, "o3")
    CA, CB, xa, xb = _cov(ta, ia), _cov(tb, ib), _xy(ta, ia), _xy(tb, ib)
    IA, IB = np.linalg.inv(CA), np.linalg.inv(CB)
    info = IA + IB
    P = np.array([[info[1, 1], -info[0, 1]], [-info[1, 0], info[0, 0]]]) / (info[0, 0] * info[1, 1] - info[0, 1] ** 2)
    x = P @ (IA @ xa + IB @ xb)
    i = _row_of(res.objects, 1, "o3")
    np.testing.assert_allclose(_cov(res.objects, i), P, rtol=1e-10)
    np.testing.assert_allclose(_xy(res.objects, i), x, rtol=1e-12)
    # d_i^2 against the fused mean, (x_i - x)^T (C_i - P)^-1 (x_i - x), equals the pairwise d^2 for two sources
    d2_pair = (xa - xb) @ np.linalg.solve(CA + CB, xa - xb)
    assert 0.01 < d2_pair < 9.21
    src = res.sources
    rows = [j for j in range(src.num_rows) if src.column("frame")[j].as_py() == 1
            and src.column("object_id")[j].as_py() == "o3"]
    assert len(rows) == 2
    for j in rows:
        assert src.column("d2")[j].as_py() == pytest.approx(d2_pair, rel=1e-9)
    # the V2X fields follow the map: W's +y axis 90 deg east of true north swaps east and north
    turned = fuse_footprints([ta, tb], camera_ids=["A", "B"], heading_offset_deg=90.0).objects
    ref = {**cpm_fields(P, 90.0), **j2735_fields(P, 90.0)}
    assert all(turned.column(name)[i].as_py() == int(v) for name, v in ref.items())
    assert turned.column("cpm_x_confidence")[i].as_py() == res.objects.column("cpm_y_confidence")[i].as_py()


def _corner_detections(cam_true, boxes):
    """Footprint corners in pixels as ``cam_true`` sees them (input type 'corners')."""
    c = box3d_bottom_corners(boxes)
    c = c[0] if isinstance(c, tuple) else c
    xyz = c if c.shape[-1] == 3 else np.concatenate([c, np.zeros(c.shape[:-1] + (1,))], -1)
    uv = cam_true.project(xyz).uv_px
    n = boxes.shape[0]
    d = {"frame": np.repeat(np.arange(N_FRAMES, dtype=np.int64), N_OBJ),
         "object_id": [f"o{i % N_OBJ}" for i in range(n)]}
    for k in range(4):
        d[f"u{k}_px"], d[f"v{k}_px"] = uv[:, k, 0], uv[:, k, 1]
    return d


def test_inconsistent_pair_is_flagged(footprints):
    """Camera B knocked 8 degrees in pan but processed with its nominal calibration: every pair flagged."""
    boxes = _boxes()
    cam_b = PanTiltCamera(**CAM_B)
    bumped = PanTiltCamera(**{**CAM_B, "pan_deg": CAM_B["pan_deg"] + 8.0})
    ta = pq.read_table(footprints[("camA", "parquet")])
    good = process_table(cam_b, BUDGET, _corner_detections(cam_b, boxes))
    bad = process_table(cam_b, BUDGET, _corner_detections(bumped, boxes))
    ok = fuse_footprints([ta, good], camera_ids=["A", "B"])
    assert ok.summary.objects_inconsistent == 0 and not any(ok.sources.column("inconsistent").to_pylist())
    res = fuse_footprints([ta, bad], camera_ids=["A", "B"])
    o = res.objects
    two = np.array(o.column("n_cameras").to_pylist()) == 2
    assert two.sum() == N_OBJ * N_FRAMES  # B's corner table has every object
    assert not any(o.column("consistent").to_pylist())
    assert all(s == "A,B" for s in o.column("inconsistent_cameras").to_pylist())
    d2 = np.array(res.sources.column("d2").to_pylist())
    assert np.all(d2 > 9.2103) and res.summary.sources_inconsistent == 2 * N_OBJ * N_FRAMES
    assert np.all(np.array(o.column("chi2").to_pylist()) > np.array(o.column("chi2_threshold").to_pylist()))
    # at a looser level fewer pairs are flagged, never more
    loose = fuse_footprints([ta, bad], camera_ids=["A", "B"], confidence=0.99999)
    assert loose.summary.sources_inconsistent < res.summary.sources_inconsistent


def _bad_rows_csv(src, dst):
    """Plant bad rows in a footprint CSV; returns {row: reason substring}."""
    lines = src.read_text().splitlines()
    header = [h.strip('"') for h in lines[0].split(",")]
    col = {h: j for j, h in enumerate(header)}

    def edit(row, name, value):
        f = lines[row + 1].split(",")
        f[col[name]] = value
        lines[row + 1] = ",".join(f)

    edit(1, "cov_xx_m2", "nan")
    edit(3, "object_id", "")
    edit(4, "cov_xy_m2", "5.0")           # |cov_xy| > sqrt(cov_xx cov_yy): not positive definite
    edit(6, "y_m", "abc")
    lines[5 + 1] = "1,2,3"                 # malformed line (row 5)
    dst.write_text("\n".join(lines) + "\n")
    return {1: "missing or non-finite field cov_xx_m2", 3: "missing key field object_id",
            4: "covariance not positive definite", 5: "malformed CSV line", 6: "field y_m is not a number"}


def _bad_rows_parquet(src, dst):
    t = pq.read_table(src)
    d = t.to_pydict()
    d["cov_yy_m2"][1] = float("nan")
    d["object_id"][3] = None
    d["cov_xx_m2"][4] = -1.0
    d["frame"][6] = None
    d["status"][7] = "partial"
    pq.write_table(pa.table(d), dst)
    return {1: "missing or non-finite field cov_yy_m2", 3: "missing key field object_id",
            4: "covariance not positive definite", 6: "missing key field frame", 7: "input status partial"}


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_bad_rows_reported_with_row_numbers(footprints, tmp_path, ext):
    a = footprints[("camA", ext)]
    b = tmp_path / f"camB.{ext}"
    planted = (_bad_rows_csv if ext == "csv" else _bad_rows_parquet)(footprints[("camB", ext)], b)
    out = tmp_path / "fused.parquet"
    r = CliRunner().invoke(_cli(), ["fuse", str(a), str(b), "--out", str(out), "--sources-out",
                                    str(tmp_path / "src.csv")])
    assert r.exit_code == 0, r.output
    n_a, n_b = N_OBJ * N_FRAMES, (N_OBJ - len(ONLY_A)) * N_FRAMES
    assert f"rows in {n_a + n_b}, rows used {n_a + n_b - len(planted)}, rows rejected {len(planted)}" in r.output
    src = pcsv.read_csv(tmp_path / "src.csv")
    assert src.num_rows == n_a + n_b  # every input row accounted for
    ins, rows = src.column("input").to_pylist(), src.column("source_row").to_pylist()
    used, why = src.column("used").to_pylist(), src.column("reason").to_pylist()
    got = {rows[j]: why[j] for j in range(src.num_rows) if ins[j] == str(b) and not used[j]}
    assert sorted(got) == sorted(planted)
    for row, text in planted.items():
        assert text in got[row], (row, got[row])
    assert all(used[j] for j in range(src.num_rows) if ins[j] == str(a))
    js = json.loads(summary_path(out).read_text())
    assert js["consistent"] and js["rows_rejected"] == len(planted) and sum(js["reasons"].values()) == len(planted)
    # the objects whose B row was rejected are passed through from A alone
    fused = pq.read_table(out)
    assert sum(fused.column("n_cameras").to_pylist()) == n_a + n_b - len(planted)
    assert set(fused.column("status").to_pylist()) == {"ok"}


def test_one_file_with_camera_id_column_and_duplicates(footprints, tmp_path):
    ta, tb = pq.read_table(footprints[("camA", "parquet")]), pq.read_table(footprints[("camB", "parquet")])
    both = pa.concat_tables([ta.append_column("camera_id", pa.array(["A"] * ta.num_rows)),
                             tb.append_column("camera_id", pa.array(["B"] * tb.num_rows))], promote_options="default")
    f = tmp_path / "all.parquet"
    pq.write_table(both, f)
    out = tmp_path / "fused.jsonl"
    r = CliRunner().invoke(_cli(), ["fuse", str(f), "--out", str(out)])
    assert r.exit_code == 0, r.output
    ref = fuse_footprints([ta, tb], camera_ids=["A", "B"]).objects
    got = pa.Table.from_pylist([json.loads(line) for line in out.read_text().splitlines()])
    np.testing.assert_allclose(got.column("cov_xx_m2").to_numpy(), ref.column("cov_xx_m2").to_numpy(), rtol=1e-12)
    assert got.column("cameras").to_pylist() == ref.column("cameras").to_pylist()
    # a camera reporting one object twice in a frame: both rows rejected, the object fused from the other camera
    dup = pa.concat_tables([both, both.slice(0, 1)])
    res = fuse_footprints([dup], key=("frame", "object_id"))
    src = res.sources
    bad = [j for j in range(src.num_rows) if not src.column("used")[j].as_py()]
    assert [src.column("source_row")[j].as_py() for j in bad] == [0, dup.num_rows - 1]
    assert all("duplicate: 2 rows of one camera" in src.column("reason")[j].as_py() for j in bad)
    i = _row_of(res.objects, int(both.column("frame")[0].as_py()), both.column("object_id")[0].as_py())
    assert res.objects.column("cameras")[i].as_py() == "B"


def test_whole_job_errors_are_one_line(footprints, tmp_path):
    a, b = footprints[("camA", "parquet")], footprints[("camB", "parquet")]
    runner = CliRunner()
    cases = [
        (["fuse", str(a), "--out", str(tmp_path / "o.parquet")], "two or more files"),
        (["fuse", str(a), str(tmp_path / "nope.csv"), "--out", str(tmp_path / "o.parquet")], "existing footprint"),
        (["fuse", str(a), str(b), "--out", str(tmp_path / "o.txt")], "error: out"),
        (["fuse", str(a), str(b), "--out", str(tmp_path / "o.csv"), "--key", "frame,track_id"], "missing key"),
        (["fuse", str(a), str(b), "--out", str(tmp_path / "o.csv"), "--camera-id-from", "column"], "camera_id"),
        (["fuse", str(a), str(b), "--out", str(tmp_path / "o.csv"), "--confidence", "1.5"], "confidence"),
    ]
    for args, text in cases:
        r = runner.invoke(_cli(), args)
        assert r.exit_code == 2, (args, r.output)
        assert text in r.output and len(r.output.strip().splitlines()) == 1, r.output
    with pytest.raises(InputError, match="footprint columns"):
        fuse_footprints([{"frame": [0], "object_id": ["a"], "x_m": [0.0]}], camera_ids=["A"])
    with pytest.raises(InputError, match="camera_ids"):
        fuse_footprints([pq.read_table(a)], camera_ids=["A", "B"])
    with pytest.raises(InputError, match="different file"):
        fuse_files([a, b], tmp_path / "x.csv", sources_out=tmp_path / "x.csv")


def test_object_without_usable_estimate_is_listed_with_the_reason():
    nan = float("nan")
    t = {"frame": [0, 0, 1], "object_id": ["a", "b", "a"], "x_m": [1.0, 2.0, 3.0], "y_m": [1.0, 2.0, 3.0],
         "cov_xx_m2": [0.04, nan, 0.04], "cov_xy_m2": [0.0, 0.0, 0.0], "cov_yy_m2": [0.09, 0.09, 0.09],
         "status": ["ok", "ok", "partial"], "reason": ["ok", "ok", "no centre: corner 2 of 4: above horizon"]}
    res = fuse_footprints([t], camera_ids=["A"])
    o = res.objects.to_pylist()
    assert [(r["frame"], r["object_id"], r["status"], r["n_cameras"]) for r in o] == [
        (0, "a", "ok", 1), (0, "b", "error", 0), (1, "a", "error", 0)]
    assert o[1]["reason"] == "no usable estimate: missing or non-finite field cov_xx_m2"
    assert o[2]["reason"] == "no usable estimate: input status partial: no centre: corner 2 of 4: above horizon"
    assert o[1]["consistent"] is None and np.isnan(o[1]["x_m"])
    assert o[1]["cpm_x_confidence"] == 4096 and o[1]["j2735_semi_major"] == 255  # the messages' "unavailable"
    assert o[0]["x_m"] == 1.0 and o[0]["cov_yy_m2"] == 0.09
    s = res.summary
    assert (s.rows_in, s.rows_used, s.rows_rejected, s.objects_unavailable) == (3, 1, 2, 2) and s.consistent
