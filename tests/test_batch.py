"""Batch footprints: row accounting in every format, streaming, summaries, GeoJSON, round trips, CLI."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from footprint_uq import PanTiltCamera
from footprint_uq.batch.process import BatchProcessor, process_file, process_table, summary_path
from footprint_uq.errors import InputError
from footprint_uq.io import save_camera
from footprint_uq.products.footprints import V2X_FIELDS, footprints_from_boxes2d, footprints_from_boxes3d
from footprint_uq.products.v2x import cpm_fields, j2735_fields
from footprint_uq.uncertainty.ellipse import ellipse_axes

CAM = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1"


@pytest.fixture(scope="module")
def cam():
    return PanTiltCamera(**CAM)


def boxes3d(n, seed=0, cam=None):
    rng = np.random.default_rng(seed)
    d = rng.uniform(15.0, 60.0, n)
    a = np.deg2rad(30.0 + rng.uniform(-20.0, 20.0, n))
    return {"frame": np.arange(n, dtype=np.int64) // 3, "object_id": [f"o{i}" for i in range(n)],
            "class": ["car"] * n, "timestamp_s": np.arange(n) * 0.1,
            "x_m": d * np.sin(a), "y_m": d * np.cos(a), "z_m": np.full(n, 0.8),
            "length_m": rng.uniform(3.5, 5.0, n), "width_m": rng.uniform(1.6, 2.0, n),
            "height_m": np.full(n, 1.5), "yaw_rad": rng.uniform(-np.pi, np.pi, n)}


def boxes2d(n, cam, seed=1, cov=False):
    rng = np.random.default_rng(seed)
    d = rng.uniform(15.0, 60.0, n)
    a = np.deg2rad(30.0 + rng.uniform(-20.0, 20.0, n))
    uv = cam.project(np.stack([d * np.sin(a), d * np.cos(a), np.zeros(n)], 1)).uv_px
    w, h = rng.uniform(30, 80, n), rng.uniform(30, 80, n)
    out = {"frame": np.arange(n, dtype=np.int64), "object_id": [str(i) for i in range(n)], "class": ["car"] * n,
           "u_min_px": uv[:, 0] - w / 2, "v_min_px": uv[:, 1] - h, "u_max_px": uv[:, 0] + w / 2,
           "v_max_px": uv[:, 1]}
    if cov:
        s = rng.uniform(0.5, 3.0, (n, 2))
        rho = rng.uniform(-0.8, 0.8, n)
        out.update(cov_uu_px2=s[:, 0] ** 2, cov_uv_px2=rho * s[:, 0] * s[:, 1], cov_vv_px2=s[:, 1] ** 2)
    return out


# bad rows planted in a 2D table: row -> expected reason (substring)
BAD_2D = {
    2: "missing or non-finite field u_min_px",
    5: "inverted box: u_max_px < u_min_px",
    7: "not positive semi-definite",
    11: "no usable corner: all 2 corners: above horizon",
    13: "incomplete pixel covariance",
}


def planted_2d(cam, n=20):
    d = boxes2d(n, cam, cov=True)
    d["u_min_px"][2] = np.nan
    d["u_max_px"][5] = d["u_min_px"][5] - 1.0
    d["cov_uv_px2"][7] = 10.0 * np.sqrt(d["cov_uu_px2"][7] * d["cov_vv_px2"][7])
    d["v_min_px"][11], d["v_max_px"][11] = 10.0, 20.0  # the bottom edge above the horizon (tilt 20, f 1400)
    d["cov_vv_px2"][13] = np.nan
    d["cov_uu_px2"][3] = d["cov_uv_px2"][3] = d["cov_vv_px2"][3] = np.nan  # no detector covariance: budget only
    return d


def write_any(d: dict, path):
    t = pa.table(d)
    if path.suffix == ".parquet":
        pq.write_table(t, path)
    elif path.suffix == ".csv":
        pcsv.write_csv(t, path)
    else:
        with open(path, "w") as f:
            for rec in t.to_pylist():
                f.write(json.dumps({k: (None if isinstance(v, float) and np.isnan(v) else v)
                                    for k, v in rec.items()}) + "\n")


def read_any(path) -> pa.Table:
    if path.suffix == ".parquet":
        return pq.read_table(path)
    if path.suffix == ".csv":
        return pcsv.read_csv(path)
    import pyarrow.json as pjson

    return pjson.read_json(path)


# -- numbers ---------------------------------------------------------------------------------------
BOX3D_RAD = ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")


def near_and_far_boxes3d(n=60):
    """(n, 7) 3D boxes 12-140 m away: with angles read in degrees (``bw-cube1@deg``) the far ones are not
    linear_ok; and the same as table columns."""
    rng = np.random.default_rng(5)
    d = rng.uniform(12.0, 140.0, n)
    a = np.deg2rad(30.0 + rng.uniform(-25.0, 25.0, n))
    B = np.stack([d * np.sin(a), d * np.cos(a), np.full(n, 0.8), np.full(n, 4.5), np.full(n, 1.8),
                  np.full(n, 1.5), rng.uniform(-np.pi, np.pi, n)], 1)
    return B, dict(zip(BOX3D_RAD, B.T.copy(), strict=True))


@pytest.mark.parametrize("corners", [False, True], ids=["lean", "corners"])
def test_flag_columns_match_reference_3d(cam, corners):
    """Columns nonlinearity / linear_ok (and c{k}_nonlinearity) are the reference's centre / corner flags, and
    where a centre is not linear_ok the V2X fields follow the policy as in the reference (lean mode too:
    the flagged rows' pixels are projected again for the sampling)."""
    B, cols = near_and_far_boxes3d()
    n = B.shape[0]
    out = process_table(cam, "bw-cube1@deg", cols, corners=corners)
    ref = footprints_from_boxes3d(cam, "bw-cube1@deg", B)
    nl = out.column("nonlinearity").to_numpy()
    assert np.array_equal(np.isnan(nl), np.isnan(ref.centre_nonlinearity))
    ok = ~np.isnan(nl)
    np.testing.assert_allclose(nl[ok], ref.centre_nonlinearity[ok], rtol=1e-9, atol=1e-12)
    lin = out.column("linear_ok").to_numpy(zero_copy_only=False)
    assert np.array_equal(lin, ref.centre_linear_ok)
    assert 5 <= lin.sum() <= n - 5  # both kinds of rows present
    assert not lin[~ok].any()
    for name in V2X_FIELDS:
        assert np.array_equal(out.column(name).to_numpy(), ref.v2x[name]), name
    assert (ref.v2x_source == 1).any()  # sampled covariances were encoded
    if corners:
        for k in range(4):
            np.testing.assert_allclose(out.column(f"c{k}_nonlinearity").to_numpy(), ref.corners_nonlinearity[:, k],
                                       rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("corners", [False, True], ids=["lean", "corners"])
def test_without_linearity_the_flag_columns_are_absent(cam, corners):
    """linearity=False: no nonlinearity / linear_ok / c{k}_nonlinearity columns (absent, not filled), every
    other column as with the flag, and the V2X fields the linear ones (the reference's policy "linear") --
    including the rows the flag would have sent to the sampled policy; bad rows are still reported."""
    _, cols = near_and_far_boxes3d()
    n = len(cols["x_m"])
    cols["x_m"][3] = np.nan
    on = process_table(cam, "bw-cube1@deg", cols, corners=corners)
    off = process_table(cam, "bw-cube1@deg", cols, corners=corners, linearity=False)
    flag_cols = {"nonlinearity", "linear_ok"} | ({f"c{k}_nonlinearity" for k in range(4)} if corners else set())
    assert flag_cols <= set(on.column_names)
    assert set(off.column_names) == set(on.column_names) - flag_cols
    assert off.num_rows == n and off.column("reason").to_pylist()[3] == "missing or non-finite field x_m"
    B = np.stack([cols[c] for c in BOX3D_RAD], 1)
    ref = footprints_from_boxes3d(cam, "bw-cube1@deg", B, v2x_policy="linear")
    assert (~ref.centre_linear_ok & ref.centre_valid).sum() >= 5  # the flag would have acted on these rows
    for name in off.column_names:
        if name in V2X_FIELDS:
            assert np.array_equal(off.column(name).to_numpy(), ref.v2x[name]), name
        elif name not in ("reason", "status"):
            a_, b_ = off.column(name).to_numpy(zero_copy_only=False), on.column(name).to_numpy(zero_copy_only=False)
            if a_.dtype.kind == "f":
                np.testing.assert_array_equal(a_, b_, err_msg=name)
            else:
                assert np.array_equal(a_, b_), name


def test_process_table_matches_reference_3d(cam):
    d = boxes3d(40)
    out = process_table(cam, BUDGET, d, confidence=0.95, corners=True)
    B = np.stack([d[c] for c in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")], 1)
    ref = footprints_from_boxes3d(cam, BUDGET, B)
    assert out.num_rows == 40
    assert out.column("row").to_pylist() == list(range(40))
    st = np.array(out.column("status").to_pylist())
    assert np.array_equal(st == "ok", ref.centre_valid)
    assert (st == "ok").sum() > 20
    ok = ref.centre_valid
    xy = np.stack([out.column("x_m").to_numpy(), out.column("y_m").to_numpy()], 1)
    np.testing.assert_allclose(xy[ok], ref.centre_xy_world_m[ok], rtol=1e-9, atol=1e-9)
    C = np.stack([out.column(c).to_numpy() for c in ("cov_xx_m2", "cov_xy_m2", "cov_yy_m2")], 1)
    np.testing.assert_allclose(C[ok], ref.centre_cov_m2[ok][:, [0, 0, 1], [0, 1, 1]], rtol=1e-9)
    np.testing.assert_allclose(out.column("largest_sigma_major_m").to_numpy(), ref.largest_semi_major_m, rtol=1e-9)
    assert np.array_equal(out.column("largest_index").to_numpy(), ref.largest_index)
    fields = {**cpm_fields(ref.centre_cov_m2), **j2735_fields(ref.centre_cov_m2)}
    for name in V2X_FIELDS:
        assert np.array_equal(out.column(name).to_numpy(), fields[name]), name
    a = out.column("sigma_major_m").to_numpy()
    ea, eb, eang = ellipse_axes(C[:, [0, 1, 1, 2]].reshape(-1, 2, 2))
    for name, ref_v in (("sigma_major_m", ea), ("sigma_minor_m", eb), ("orientation_deg", eang)):
        np.testing.assert_allclose(out.column(name).to_numpy(), ref_v, rtol=1e-13, atol=1e-15, equal_nan=True)
    assert np.isnan(a[~ok]).all()
    np.testing.assert_allclose(out.column("semi_major_m").to_numpy()[ok], 2.4477468306808166 * a[ok], rtol=1e-12)
    for k in range(4):
        np.testing.assert_allclose(out.column(f"c{k}_x_m").to_numpy()[ok], ref.corners_xy_world_m[ok, k, 0],
                                   rtol=1e-9)
        np.testing.assert_allclose(out.column(f"c{k}_cov_yy_m2").to_numpy()[ok], ref.corners_cov_m2[ok, k, 1, 1],
                                   rtol=1e-9)
    # partial rows (a corner outside the image) keep the largest point and say which corner
    part = np.flatnonzero(st == "partial")
    for i in part:
        assert "no centre: corner" in out.column("reason")[i].as_py()
        assert np.isfinite(out.column("largest_sigma_major_m")[i].as_py())


def test_process_table_2d_detector_covariance_and_bad_rows(cam):
    d = planted_2d(cam)
    out = process_table(cam, BUDGET, d, contact="bottom-corners")
    st = out.column("status").to_pylist()
    reasons = out.column("reason").to_pylist()
    for i, text in BAD_2D.items():
        assert st[i] == "error" and text in reasons[i], (i, reasons[i])
    good = [i for i in range(20) if i not in BAD_2D]
    assert all(st[i] == "ok" for i in good)
    B = np.stack([np.asarray(d[c])[good] for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px")], 1)
    cov = np.stack([d["cov_uu_px2"], d["cov_uv_px2"], d["cov_uv_px2"], d["cov_vv_px2"]], 1)[good].reshape(-1, 2, 2)
    cov = np.nan_to_num(cov, nan=0.0)  # row 3: no detector covariance
    ref = footprints_from_boxes2d(cam, BUDGET, B, contact="bottom-corners", pixel_cov_px2=cov)
    np.testing.assert_allclose(out.column("cov_yy_m2").to_numpy()[good], ref.centre_cov_m2[:, 1, 1], rtol=1e-9)
    np.testing.assert_allclose(out.column("x_m").to_numpy()[good], ref.centre_xy_world_m[:, 0], rtol=1e-9)
    # the detector covariance increases the centre covariance
    plain = process_table(cam, BUDGET, {k: v for k, v in d.items() if not k.startswith("cov_")},
                          contact="bottom-corners")
    with_det = [i for i in good if i != 3]
    assert np.all(out.column("cov_xx_m2").to_numpy()[with_det] > plain.column("cov_xx_m2").to_numpy()[with_det])
    assert out.column("cov_xx_m2")[3].as_py() == plain.column("cov_xx_m2")[3].as_py()  # no covariance: budget only
    # error rows carry the messages' "unavailable" codes
    assert out.column("cpm_x_confidence")[2].as_py() == 4096
    assert out.column("j2735_semi_major")[11].as_py() == 255


def test_layout_errors_raise(cam):
    with pytest.raises(InputError, match="box family"):
        process_table(cam, BUDGET, {"frame": [1], "a": [2.0]})
    with pytest.raises(InputError, match="pixel covariance columns"):
        process_table(cam, BUDGET, {"u_min_px": [1.0], "v_min_px": [1.0], "u_max_px": [2.0], "v_max_px": [2.0],
                                    "cov_uu_px2": [1.0]})
    with pytest.raises(InputError, match="yaw"):
        process_table(cam, BUDGET, {k: [1.0] for k in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m")},
                      box_type="3d")
    with pytest.raises(InputError, match="origin"):
        BatchProcessor(cam, BUDGET, origin_lat_deg=48.0)


# -- files -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", [".csv", ".jsonl", ".parquet"])
def test_bad_rows_in_every_format(cam, tmp_path, ext):
    d = planted_2d(cam)
    src = tmp_path / f"det{ext}"
    write_any(d, src)
    out = tmp_path / "out.parquet"
    s = process_file(cam, BUDGET, src, out, chunk_rows=6, progress=False, contact="bottom-corners")
    t = pq.read_table(out)
    assert t.column("row").to_pylist() == list(range(20))
    st = t.column("status").to_pylist()
    reasons = t.column("reason").to_pylist()
    for i, text in BAD_2D.items():
        assert st[i] == "error" and text in reasons[i], (ext, i, reasons[i])
    assert s.rows_in == s.rows_out == 20 and s.rows_error == len(BAD_2D) and s.rows_ok == 20 - len(BAD_2D)
    ref = process_table(cam, BUDGET, d, contact="bottom-corners")
    for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "largest_sigma_major_m"):
        np.testing.assert_array_equal(t.column(c).to_numpy(), ref.column(c).to_numpy(), err_msg=c)
    assert t.column("object_id").to_pylist() == d["object_id"]
    assert t.column("frame").to_pylist() == d["frame"].tolist()


def test_unparseable_lines_and_values(cam, tmp_path):
    header = "frame,object_id,u_min_px,v_min_px,u_max_px,v_max_px"
    good = "1,a,900,500,980,560"
    csv = tmp_path / "d.csv"
    csv.write_text("\n".join([header, good, "1,b,900,abc,980,560", "2,c,900,500", good, "x,d,900,500,980,560",
                              good, "3,e,1,2,3,4,5,6"]) + "\n")
    s = process_file(cam, BUDGET, csv, tmp_path / "o.csv", chunk_rows=2, progress=False)
    t = pcsv.read_csv(tmp_path / "o.csv")
    assert t.column("row").to_pylist() == list(range(7))
    r = t.column("reason").to_pylist()
    assert t.column("status").to_pylist() == ["ok", "error", "error", "ok", "error", "ok", "error"]
    assert r[1] == "field v_min_px is not a number"
    assert r[2] == "malformed CSV line (4 fields, expected 6)"
    assert r[4] == "field frame is not an integer"
    assert r[6] == "malformed CSV line (8 fields, expected 6)"
    assert s.rows_in == s.rows_out == 7 and s.rows_error == 4
    js = tmp_path / "d.jsonl"
    js.write_text("\n".join(['{"frame": 1, "u_min_px": 900, "v_min_px": 500, "u_max_px": 980, "v_max_px": 560}',
                             "", '{"frame": 1, "u_min_px": "x", "v_min_px": 500, "u_max_px": 980, "v_max_px": 560}',
                             "{not json", "[1, 2]",
                             '{"frame": 2, "u_min_px": 900, "v_min_px": 500, "u_max_px": 980}',
                             '{"frame": 3, "u_min_px": true, "v_min_px": 500, "u_max_px": 980, "v_max_px": 560}'])
                  + "\n")
    s = process_file(cam, BUDGET, js, tmp_path / "o.jsonl", chunk_rows=3, progress=False)
    rows = [json.loads(line) for line in (tmp_path / "o.jsonl").read_text().splitlines()]
    assert [x["row"] for x in rows] == list(range(7))  # JSON Lines rows: physical lines; a blank line is an error
    assert [x["status"] for x in rows] == ["ok", "error", "error", "error", "error", "error", "error"]
    assert rows[1]["reason"] == "empty line"
    rows = rows[1:]
    assert rows[1]["reason"] == "field u_min_px is not a number"
    assert rows[2]["reason"].startswith("invalid JSON line")
    assert rows[3]["reason"] == "JSON line is not an object: list"
    assert rows[4]["reason"] == "missing or non-finite field v_max_px"
    assert rows[5]["reason"] == "field u_min_px is not a number"  # true is not 1.0
    assert rows[1]["x_m"] is None
    assert s.rows_in == s.lines_in == 7 and s.rows_error == 6


def test_streaming_chunks_equal_one_chunk(cam, tmp_path):
    d = boxes3d(203, seed=3)
    d["length_m"][50] = -1.0
    d["yaw_rad"][120] = np.nan
    src = tmp_path / "d.parquet"
    pq.write_table(pa.table(d), src, row_group_size=37)
    one = tmp_path / "one.parquet"
    many = tmp_path / "many.parquet"
    s1 = process_file(cam, BUDGET, src, one, chunk_rows=10_000, progress=False, corners=True)
    s2 = process_file(cam, BUDGET, src, many, chunk_rows=16, progress=False, corners=True)
    a, b = pq.read_table(one), pq.read_table(many)
    assert pq.ParquetFile(many).metadata.num_row_groups > 5
    assert a.column_names == b.column_names
    for c in a.column_names:
        assert a.column(c).to_pylist() == b.column(c).to_pylist() or np.array_equal(
            a.column(c).to_numpy(), b.column(c).to_numpy(), equal_nan=True), c
    assert s1.to_dict()["reasons"] == s2.to_dict()["reasons"]
    assert s2.rows_error == 2 and s2.rows_in == s2.rows_out == 203
    # the same rows through CSV in small chunks
    csv = tmp_path / "d.csv"
    write_any(d, csv)
    s3 = process_file(cam, BUDGET, csv, tmp_path / "c.parquet", chunk_rows=9, progress=False, corners=True)
    c = pq.read_table(tmp_path / "c.parquet")
    for col in ("row", "x_m", "cov_xy_m2", "c2_y_m", "cpm_x_confidence"):
        np.testing.assert_array_equal(c.column(col).to_numpy(), a.column(col).to_numpy())
    assert s3.rows_ok == s1.rows_ok


def test_summary_counts_and_file(cam, tmp_path):
    d = boxes3d(60, seed=5)
    d["width_m"][[3, 4]] = -2.0
    d["x_m"][10] = np.inf
    d["x_m"][20], d["y_m"][20] = -40.0, -40.0  # behind the camera
    src = tmp_path / "d.parquet"
    pq.write_table(pa.table(d), src)
    out = tmp_path / "o.parquet"
    s = process_file(cam, BUDGET, src, out, chunk_rows=25, progress=False)
    t = pq.read_table(out)
    st = np.array(t.column("status").to_pylist())
    assert s.rows_in == s.rows_out == 60 == s.rows_ok + s.rows_partial + s.rows_error
    assert s.rows_ok == (st == "ok").sum() and s.rows_partial == (st == "partial").sum()
    assert s.rows_error == (st == "error").sum() == 4
    assert "behind the camera" in t.column("reason")[20].as_py()
    js = json.loads(summary_path(out).read_text())
    assert js["rows_in"] == 60 and js["rows_out"] == 60 and js["rows_with_errors"] == 4 and js["consistent"]
    assert js["reasons"]["negative size width_m (expected >= 0)"] == 2
    assert sum(js["reasons"].values()) == s.rows_error + s.rows_partial


def test_geojson(cam, tmp_path):
    pytest.importorskip("pyproj")
    from pyproj import Geod

    lat0, lon0, head = 48.15, 11.58, 25.0
    d = boxes3d(30, seed=7)
    d["height_m"][4] = -1.0
    src = tmp_path / "d.parquet"
    pq.write_table(pa.table(d), src)
    out = tmp_path / "o.geojson"
    s = process_file(cam, BUDGET, src, out, chunk_rows=7, progress=False, origin_lat_deg=lat0, origin_lon_deg=lon0,
                     heading_offset_deg=head)
    gj = json.loads(out.read_text())
    feats = [f for f in gj["features"] if f["properties"]["role"] == "footprint"]
    ellipses = [f for f in gj["features"] if f["properties"]["role"] == "ellipse"]
    assert gj["type"] == "FeatureCollection" and len(feats) == 30 == s.rows_out
    assert len(feats) + len(ellipses) == len(gj["features"])
    assert [f["properties"]["row"] for f in ellipses] == [f["properties"]["row"] for f in feats
                                                          if f["properties"]["status"] == "ok"]
    ref = process_table(cam, BUDGET, d, corners=True, heading_offset_deg=head)
    geod = Geod(ellps="WGS84")
    n_poly = 0
    for i, f in enumerate(feats):
        assert f["type"] == "Feature" and f["properties"]["row"] == i
        g = f["geometry"]
        st = f["properties"]["status"]
        if st == "error":
            assert g is None
            continue
        if st == "ok":
            assert g["type"] == "Polygon"
            ring = g["coordinates"][0]
            assert len(ring) == 5 and ring[0] == ring[-1]
            lon, lat = np.array(ring)[:, 0], np.array(ring)[:, 1]
            assert np.all(np.abs(lon - lon0) < 0.01) and np.all(np.abs(lat - lat0) < 0.01)  # lon first, lat second
            # counter-clockwise (RFC 7946 exterior ring), in a local metric frame
            e, nn = (lon - lon0) * np.cos(np.radians(lat0)), lat - lat0
            assert 0.5 * np.sum(e[:-1] * nn[1:] - e[1:] * nn[:-1]) > 0
            n_poly += 1
            # the centre: distance and bearing from the origin as in the world frame rotated by the heading offset
            p = f["properties"]
            az, _, dist = geod.inv(lon0, lat0, p["lon_deg"], p["lat_deg"])
            x, y = ref.column("x_m")[i].as_py(), ref.column("y_m")[i].as_py()
            assert dist == pytest.approx(np.hypot(x, y), abs=1e-6)
            bearing_w = np.degrees(np.arctan2(x, y))  # clockwise from W's +y
            assert (az - bearing_w - head + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-6)
            assert p["cov_xx_m2"] == pytest.approx(ref.column("cov_xx_m2")[i].as_py(), rel=1e-12)
            assert "sigma_major_m" in p and "orientation_deg" in p and "cpm_x_confidence" in p
        else:
            assert g is None or g["type"] == "Point"
    assert n_poly >= 20
    with pytest.raises(InputError, match="GeoJSON"):
        process_file(cam, BUDGET, src, tmp_path / "x.geojson", progress=False)
    # 2D bottom-centre: points
    d2 = boxes2d(5, cam)
    pq.write_table(pa.table(d2), tmp_path / "d2.parquet")
    process_file(cam, BUDGET, tmp_path / "d2.parquet", tmp_path / "o2.geojson", progress=False,
                 origin_lat_deg=lat0, origin_lon_deg=lon0)
    g2 = json.loads((tmp_path / "o2.geojson").read_text())
    assert [f["geometry"]["type"] for f in g2["features"] if f["properties"]["role"] == "footprint"] == ["Point"] * 5


@pytest.mark.parametrize("ext_in", [".csv", ".jsonl", ".parquet"])
def test_round_trip_of_formats(cam, tmp_path, ext_in):
    d = planted_2d(cam, n=20)
    src = tmp_path / f"d{ext_in}"
    write_any(d, src)
    ref = process_table(cam, BUDGET, d, confidence=0.9)
    for ext_out in (".parquet", ".csv", ".jsonl"):
        out = tmp_path / f"o{ext_out}"
        process_file(cam, BUDGET, src, out, chunk_rows=8, progress=False, confidence=0.9)
        t = read_any(out)
        assert t.num_rows == 20
        assert [str(x) for x in t.column("object_id").to_pylist()] == d["object_id"]
        assert [str(x) for x in t.column("status").to_pylist()] == ref.column("status").to_pylist()
        assert [str(x) for x in t.column("reason").to_pylist()] == ref.column("reason").to_pylist()
        for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "semi_major_m", "orientation_deg"):
            got = np.array([np.nan if v is None else v for v in t.column(c).to_pylist()], dtype=float)
            np.testing.assert_allclose(got, ref.column(c).to_numpy(), rtol=1e-14, equal_nan=True,
                                       err_msg=f"{ext_in}->{ext_out} {c}")
        for c in V2X_FIELDS:
            assert t.column(c).to_pylist() == ref.column(c).to_pylist()


# -- CLI -----------------------------------------------------------------------------------------------
def _cli():
    from footprint_uq.cli.main import main
    from footprint_uq.cli.objects import objects_cmd

    if "objects" not in main.commands:
        main.add_command(objects_cmd)
    return main


def test_cli_objects(cam, tmp_path):
    camf = tmp_path / "cam.yaml"
    save_camera(cam, camf)
    d = planted_2d(cam)
    src = tmp_path / "d.csv"
    write_any(d, src)
    out = tmp_path / "o.parquet"
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections", str(src),
                                    "--out", str(out), "--chunk-rows", "4", "--confidence", "0.95", "--quiet"])
    assert r.exit_code == 0, r.output
    assert f"rows in 20, rows out 20 (ok {20 - len(BAD_2D)}, partial 0), rows with errors {len(BAD_2D)}" in r.output
    js = json.loads(summary_path(out).read_text())
    assert js["camera"] == str(camf) and js["budget"] == BUDGET and js["rows_error"] == len(BAD_2D)
    t = pq.read_table(out)
    assert "semi_major_m" in t.column_names and t.num_rows == 20
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections", str(src),
                                    "--out", str(tmp_path / "n.parquet"), "--no-linearity", "--corners", "--quiet"])
    assert r.exit_code == 0, r.output
    t2 = pq.read_table(tmp_path / "n.parquet")
    assert t2.num_rows == 20 and "linear_ok" not in t2.column_names and "c0_nonlinearity" not in t2.column_names
    assert t2.column("x_m").to_pylist() == pytest.approx(t.column("x_m").to_pylist(), nan_ok=True)
    # whole-job bad input: one line, exit status 2
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections", str(src),
                                    "--out", str(tmp_path / "o.txt")])
    assert r.exit_code == 2 and "error: out" in r.output and len(r.output.strip().splitlines()) == 1
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections", str(src),
                                    "--out", str(tmp_path / "o.parquet"), "--box-type", "3d"])
    assert r.exit_code == 2 and "3d box columns" in r.output


def test_threaded_parts_equal_one_thread(cam, monkeypatch):
    from footprint_uq.batch import process as P

    d = planted_2d(cam, n=20)
    one = BatchProcessor(cam, BUDGET, threads=1).process(d)
    monkeypatch.setattr(P, "_MIN_ROWS_PER_THREAD", 3)
    bp = BatchProcessor(cam, BUDGET, threads=2)
    if not bp._parallel:
        pytest.skip("the compiled kernel holds the GIL: no threaded path")
    two = bp.process(d)
    bp.close()
    assert two.column("x_m").num_chunks == 2
    for c in one.column_names:
        assert two.column(c).to_pylist() == one.column(c).to_pylist() or np.array_equal(
            two.column(c).to_numpy(), one.column(c).to_numpy(), equal_nan=True), c


def test_parquet_layout_codecs_and_nullability(cam, tmp_path):
    """'auto': code columns bit-packed and uncompressed, the rest snappy; an explicit codec applies to all;
    computed columns are declared non-null (and hold no nulls), id columns stay nullable."""
    src = tmp_path / "d.parquet"
    pq.write_table(pa.table(boxes3d(50)), src)
    ref = process_table(cam, BUDGET, boxes3d(50), corners=True)
    for comp in ("auto", "zstd", None):
        out = tmp_path / f"o_{comp}.parquet"
        process_file(cam, BUDGET, src, out, progress=False, corners=True, compression=comp)
        pf = pq.ParquetFile(out)
        rg = pf.metadata.row_group(0)
        meta = {rg.column(i).path_in_schema: rg.column(i) for i in range(rg.num_columns)}
        for name, col in meta.items():
            code = name in V2X_FIELDS or name == "largest_index" or name.endswith("_reason") and name != "reason"
            if comp == "auto":
                assert col.compression == ("UNCOMPRESSED" if code else "SNAPPY"), name
                assert ("DELTA_BINARY_PACKED" in col.encodings) == code, (name, col.encodings)
            else:
                assert col.compression == ("ZSTD" if comp else "UNCOMPRESSED"), name
        t = pf.read()
        assert t.equals(ref.cast(t.schema))
        for f in t.schema:
            computed = f.name not in ("frame", "object_id", "class", "timestamp_s")
            assert f.nullable == (not computed), f.name
            assert t.column(f.name).null_count == 0 or not computed
