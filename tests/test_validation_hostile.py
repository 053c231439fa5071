"""Numbers in, numbers checked (issue 35, part 1): every numeric field of every reader of ``validate`` /
``calibrate budget`` is finite and in its range, or the row is an error row with its line and reason.

Hostile values (inf, 1e308, 1e400, -0, nan, huge and negative variances, non-PSD covariances) in a pairs table
(CSV, JSON Lines, Parquet), a KITTI/Rope3D folder and OpenLABEL; ``n_pairs``, the rows' statuses, the
per-object file and the verdict always agree, and the summary counts the refused rows by reason.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from footprint_uq.cameras.pantilt import PanTiltCamera
from footprint_uq.io import save_camera
from footprint_uq.io.dataset_files import camera_from_rope3d
from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.validation.coverage import CoverageAccumulator
from footprint_uq.validation.pairs import STATUS_ERROR, build_pairs, collect_pairs, reason_kind
from footprint_uq.validation.readers import (
    LabelChunk,
    read_kitti_folder,
    read_openlabel,
    read_pairs_table,
    row_problems,
)
from footprint_uq.viz.validation_run import run_validation

CAM = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=18.0,
                    position_m=(5.0, -3.0))
BUDGET = ErrorBudget(pan_deg=0.1, tilt_deg=0.1, roll_deg=0.1, height_m=0.05, imaging_px=(1.0, 1.0))
N_GOOD = 40
HEADER = ["object_id", "u_min_px", "v_min_px", "u_max_px", "v_max_px", "cov_uu_px2", "cov_uv_px2", "cov_vv_px2",
          "x_m", "y_m"]


def _good_rows(n=N_GOOD, seed=3):
    """Rows of objects on the ground (exact boxes; truth shifted by a draw of the pixel noise)."""
    rng = np.random.default_rng(seed)
    W, H = CAM.image_size_px
    uv = np.c_[rng.uniform(200, W - 200, n), rng.uniform(0.6 * H, H - 20, n)]
    xy = CAM.backproject(uv).xy_world_m + rng.normal(0, 0.05, (n, 2))
    return [{"object_id": f"g{i}", "u_min_px": u - 30, "v_min_px": v - 60, "u_max_px": u + 30, "v_max_px": v,
             "cov_uu_px2": 1.0, "cov_uv_px2": 0.0, "cov_vv_px2": 1.0, "x_m": x, "y_m": y}
            for i, ((u, v), (x, y)) in enumerate(zip(uv, xy, strict=True))]


#: hostile rows: (field -> value as the text of the file) and a piece of the reason the row must get
HOSTILE = [
    ({"x_m": "inf"}, "truth not finite"),
    ({"y_m": "-inf"}, "truth not finite"),
    ({"x_m": "1e308"}, "truth out of range"),
    ({"y_m": "1e400"}, "truth not finite"),  # overflows to inf when read
    ({"x_m": "3e5"}, "truth out of range"),  # 300 km from the camera
    ({"u_min_px": "inf"}, "box not finite"),
    ({"v_max_px": "1e308"}, "box out of range"),
    ({"u_max_px": "1e400"}, "box not finite"),
    ({"cov_uu_px2": "-4"}, "negative variance"),
    ({"cov_uv_px2": "5"}, "not positive semi-definite"),
    ({"cov_vv_px2": "1e300"}, "pixel covariance out of range"),
    ({"cov_uu_px2": "inf"}, "pixel covariance not finite"),
    ({"cov_uu_px2": "1e400", "cov_vv_px2": "1e400"}, "pixel covariance not finite"),
    # nan: in CSV pyarrow reads it as an empty field (a partial truth / box / covariance: an error row); in JSON
    # Lines and Parquet a NaN value is an error of its own
    ({"x_m": "nan"}, "truth coordinate is empty|field x_m is NaN"),
    ({"u_min_px": "nan"}, "field u_min_px is empty|field u_min_px is NaN"),
    ({"cov_uv_px2": "nan"}, "one or two empty|field cov_uv_px2 is NaN"),
]


def _hostile_rows():
    good = _good_rows(len(HOSTILE), seed=11)
    rows = []
    for g, (change, _) in zip(good, HOSTILE, strict=True):
        r = {k: repr(float(v)) if isinstance(v, float) else v for k, v in g.items()}
        r.update(change)
        rows.append(r)
    return rows


def _csv(path, rows):
    text = ",".join(HEADER) + "\n" + "".join(",".join(str(r[k]) for k in HEADER) + "\n" for r in rows)
    path.write_text(text)
    return path


def _jsonl(path, rows):
    # numbers as JSON number text (1e400 and -0 as written); JSON has no inf/nan tokens: Python's Infinity / NaN
    def val(v):
        t = str(v)
        return {"inf": "Infinity", "-inf": "-Infinity", "nan": "NaN"}.get(t, t)

    lines = ["{" + ",".join(f'"{k}":' + (json.dumps(r[k]) if k == "object_id" else val(r[k])) for k in HEADER) + "}"
             for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _parquet(path, rows):
    cols = {k: [r[k] for r in rows] for k in HEADER}
    table = pa.table({k: (pa.array(v) if k == "object_id" else pa.array([float(x) for x in v], pa.float64()))
                      for k, v in cols.items()})
    pq.write_table(table, path)
    return path


def _table_rows():
    good = [{k: (repr(float(v)) if isinstance(v, float) else v) for k, v in r.items()} for r in _good_rows()]
    # good rows first, hostile ones after, and a -0 (a valid number) in a good row
    good[0]["cov_uv_px2"] = "-0"
    return good + _hostile_rows()


def _first_line(fmt):
    return {"csv": 2, "jsonl": 1, "parquet": 0}[fmt]


def _check_summary_agrees(summary, objects_path):
    """n_pairs, statuses, the per-object file and the refusals agree; no ok row without a finite NEES."""
    rows = pcsv.read_csv(objects_path) if objects_path.suffix == ".csv" else pq.read_table(objects_path)
    status = np.array(rows.column("status").to_pylist(), dtype=object)
    nees = np.array([np.nan if v is None else v for v in rows.column("nees").to_pylist()], dtype=float)
    assert summary["n_pairs"] == summary["rows"].get("ok", 0) == int((status == "ok").sum())
    assert np.isfinite(nees[status == "ok"]).all()
    assert summary["refused"]["rows"] == summary["rows"].get("error", 0) == int((status == "error").sum())
    assert sum(summary["refused"]["by_reason"].values()) == summary["refused"]["rows"]
    assert summary["unpaired"]["error_rows"] == summary["refused"]["rows"]
    assert (summary["verdict"] is None) == (summary["n_pairs"] == 0)
    return rows


@pytest.mark.parametrize("fmt", ["csv", "jsonl", "parquet"])
def test_pairs_table_hostile_numbers_are_error_rows_with_their_line(tmp_path, fmt):
    rows = _table_rows()
    path = {"csv": _csv, "jsonl": _jsonl, "parquet": _parquet}[fmt](tmp_path / f"pairs.{fmt}", rows)
    pairs = collect_pairs(read_pairs_table(path, CAM, chunk_rows=16), BUDGET)
    off = _first_line(fmt)
    by_line = dict(zip(pairs.line.tolist(), zip(pairs.status.tolist(), pairs.reason.tolist(), strict=True),
                       strict=True))
    assert sorted(by_line) == list(range(off, off + len(rows)))  # every row, none dropped
    for k in range(N_GOOD):
        assert by_line[off + k][0] == "ok", (k, by_line[off + k])
    for k, (change, why) in enumerate(HOSTILE):
        st, reason = by_line[off + N_GOOD + k]
        assert st == "error" and re.search(why, reason), (change, st, reason)
    assert np.isfinite(pairs.residual_m[pairs.usable]).all()


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_validate_summary_counts_refusals_and_agrees(tmp_path, fmt):
    rows = _table_rows()
    path = {"csv": _csv, "parquet": _parquet}[fmt](tmp_path / f"pairs.{fmt}", rows)
    cam = tmp_path / "cam.yaml"
    save_camera(CAM, cam)
    summary, files = run_validation(path, tmp_path / "out", BUDGET, camera=cam, report=False, fsync=False)
    _check_summary_agrees(summary, files["objects"])
    assert summary["n_pairs"] == N_GOOD and summary["refused"]["rows"] == len(HOSTILE)
    by = summary["refused"]["by_reason"]
    assert by["truth not finite (a coordinate is inf or NaN)"] == 3
    assert by["pixel covariance not finite (cov_uu_px2, cov_uv_px2, cov_vv_px2)"] == 2
    assert summary["verdict"] in ("consistent", "over-confident", "under-confident")


def test_json_lines_nan_value_is_an_error_not_an_absent_truth(tmp_path):
    good = _good_rows(2)
    text = "".join(json.dumps({**g, "x_m": float("nan")} if i == 1 else g) + "\n" for i, g in enumerate(good))
    (tmp_path / "p.jsonl").write_text(text)
    pairs = collect_pairs(read_pairs_table(tmp_path / "p.jsonl", CAM), BUDGET)
    assert pairs.status.tolist() == ["ok", "error"] and "field x_m is NaN" in pairs.reason[1]


def test_lat_lon_truth_out_of_range_is_an_error_row(tmp_path):
    pytest.importorskip("pyproj")
    from footprint_uq.products.geo import GeoReference

    g = _good_rows(1)[0]
    head = "u_min_px,v_min_px,u_max_px,v_max_px,lat_deg,lon_deg\n"
    box = f"{g['u_min_px']},{g['v_min_px']},{g['u_max_px']},{g['v_max_px']}"
    (tmp_path / "p.csv").write_text(head + f"{box},95,11\n{box},48,1e308\n{box},inf,11\n")
    pairs = collect_pairs(read_pairs_table(tmp_path / "p.csv", CAM, georef=GeoReference(0.0, 48.0, 11.0)), BUDGET)
    assert pairs.status.tolist() == ["error"] * 3
    assert all("lat_deg / lon_deg out of range" in r for r in pairs.reason)


# -- KITTI / Rope3D ---------------------------------------------------------------------------------------
P2 = "P2: 2763.176803 0.000000 970.573255 0 0.000000 2946.604873 550.709977 0 0.000000 0.000000 1.000000 0\n"
DENORM = "-0.01091203 -0.9771157 -0.2124285 7.0043797493\n"


def test_kitti_hostile_numbers_and_calibrations(tmp_path):
    root = tmp_path / "kitti"
    for sub in ("calib", "denorm", "label_2"):
        (root / sub).mkdir(parents=True)
    good_line = "car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1.0 6.5 30.0 0.3"
    hostile = {
        2: ("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1e308 6.5 30 0.3", "truth"),   # overflows in the rotation
        3: ("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1 6.5 1e400 0.3", "not finite"),
        4: ("car 0 0 0.1 900 600 960 1e308 1.5 1.8 4.2 1 6.5 30 0.3", "box out of range"),
        5: ("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1 6.5 3e5 0.3", "truth out of range"),
        6: ("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1 -9e4 30 0.3", "truth height out of range"),
        7: ("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1 6.5 30 nan", "not finite"),
    }
    lines = [good_line] + [hostile[k][0] for k in sorted(hostile)] + ["car -0 -0 -0 900 600 960 700 1.5 1.8 4.2 "
                                                                      "-0 6.5 30 -0"]
    (root / "label_2" / "a.txt").write_text("\n".join(lines) + "\n")
    (root / "calib" / "a.txt").write_text(P2)
    (root / "denorm" / "a.txt").write_text(DENORM)
    bad_calib = {"b": P2.replace("2763.176803", "1e308"), "c": P2.replace("970.573255", "inf"),
                 "d": P2.replace("2946.604873", "nan"), "e": P2.replace("2763.176803", "1e400")}
    for fid, text in bad_calib.items():
        (root / "calib" / f"{fid}.txt").write_text(text)
        (root / "denorm" / f"{fid}.txt").write_text(DENORM)
        (root / "label_2" / f"{fid}.txt").write_text(good_line + "\n")
    (root / "calib" / "f.txt").write_text(P2)
    (root / "denorm" / "f.txt").write_text("0 0 0 7\n")  # a ground plane without a normal
    (root / "label_2" / "f.txt").write_text(good_line + "\n")
    pairs = collect_pairs(read_kitti_folder(root), BUDGET)
    a = pairs.subset(np.array([s.endswith("a.txt") for s in pairs.source]))
    by_line = dict(zip(a.line.tolist(), zip(a.status.tolist(), a.reason.tolist(), strict=True), strict=True))
    assert by_line[1][0] == "ok" and by_line[8][0] == "ok"  # -0 is a number like any other
    for ln, (_, why) in hostile.items():
        assert by_line[ln][0] == "error" and why in by_line[ln][1], (ln, by_line[ln])
    for fid in (*bad_calib, "f"):
        sel = np.array([s.endswith(f"{fid}.txt") for s in pairs.source])
        assert pairs.status[sel].tolist() == ["error"], (fid, pairs.reason[sel])
        assert pairs.line[sel].tolist() == [1]
    cam = camera_from_rope3d(root / "calib" / "a.txt", denorm=root / "denorm" / "a.txt", image_size_px=(1920, 1080))
    assert np.isfinite(cam.T_world_cam).all()


def test_kitti_folder_through_validate_agrees(tmp_path):
    root = tmp_path / "kitti"
    for sub in ("calib", "denorm", "label_2"):
        (root / sub).mkdir(parents=True)
    cam = camera_from_rope3d(_w(root / "calib" / "a.txt", P2), denorm=_w(root / "denorm" / "a.txt", DENORM),
                             image_size_px=(1920, 1080))
    rng = np.random.default_rng(4)
    uv = np.c_[rng.uniform(300, 1600, 30), rng.uniform(650, 1050, 30)]
    xy = cam.backproject(uv).xy_world_m
    T = cam.T_cam_world
    lines = []
    for p, q in zip(xy, uv, strict=True):
        loc = T[:3, :3] @ np.r_[p + rng.normal(0, 0.05, 2), 0.0] + T[:3, 3]
        lines.append(f"car 0 0 0 {q[0] - 30:.6f} {q[1] - 60:.6f} {q[0] + 30:.6f} {q[1]:.6f} 1.5 1.8 4.2 "
                     + " ".join(f"{v:.9f}" for v in loc) + " 0.3")
    lines += ["car 0 0 0 900 600 960 700 1.5 1.8 4.2 1e308 1e308 1e308 0.3",
              "car 0 0 0 900 600 960 700 1.5 1.8 4.2 1 2 1e400 0.3"]
    _w(root / "label_2" / "a.txt", "\n".join(lines) + "\n")
    summary, files = run_validation(root, tmp_path / "out", BUDGET, report=False, fsync=False)
    objects = _check_summary_agrees(summary, files["objects"])
    assert summary["n_pairs"] == 30 and summary["refused"]["rows"] == 2
    assert objects.column("line").to_pylist()[-2:] == [31, 32]


def _w(path, text):
    path.write_text(text)
    return path


# -- OpenLABEL --------------------------------------------------------------------------------------------
def test_openlabel_hostile_numbers(tmp_path):
    T = CAM.T_cam_world
    calib = tmp_path / "s110_camera_test.json"
    calib.write_text(json.dumps({"image_width": 1920, "image_height": 1080, "intrinsic_camera_matrix": CAM.K.tolist(),
                                 "dist_coefficients": [0, 0, 0, 0, 0], "rotation_matrix": T[:3, :3].tolist(),
                                 "translation_matrix": T[:3, 3].tolist()}))
    g = _good_rows(1)[0]
    bb = [(g["u_min_px"] + g["u_max_px"]) / 2, (g["v_min_px"] + g["v_max_px"]) / 2, 60.0, 60.0]
    cub = [g["x_m"], g["y_m"], 0.75, 0, 0, 0, 1, 4.2, 1.8, 1.5]
    objects = {
        "ok": (cub, bb),
        "inf": ([float("inf")] + cub[1:], bb),
        "big": ([1e308] + cub[1:], bb),
        "far": ([cub[0] + 3e5] + cub[1:], bb),
        "zbig": (cub[:2] + [5e4] + cub[3:], bb),
        "hbig": (cub[:9] + [1e308], bb),
        "boxbig": (cub, [1e308, bb[1], 60, 60]),
        "boxinf": (cub, [bb[0], float("inf"), 60, 60]),
        "negzero": (cub[:3] + [-0.0] + cub[4:], bb),
    }
    pairs = collect_pairs(read_openlabel(_openlabel(tmp_path, objects), calibration=calib), BUDGET)
    got = dict(zip(pairs.object_id.tolist(), zip(pairs.status.tolist(), pairs.reason.tolist(), strict=True),
                   strict=True))
    assert got["ok"][0] == "ok" and got["negzero"][0] == "ok"
    for k in ("inf", "big", "far", "zbig", "hbig", "boxbig", "boxinf"):
        assert got[k][0] == "error", (k, got[k])


def _openlabel(tmp_path, objects):
    """An OpenLABEL file; JSON has no inf / 1e308 overflow tokens: Python's Infinity, and 1e308 as written."""
    objs = {uid: {"object_data": {"type": "CAR", "cuboid": {"name": "c", "val": c},
                                  "bbox": [{"name": "b", "val": b}]}} for uid, (c, b) in objects.items()}
    p = tmp_path / "labels.json"
    p.write_text(json.dumps({"openlabel": {"frames": {"0": {"objects": objs}}}}))
    return p


# -- the gate and the accumulator, directly ---------------------------------------------------------------
def _chunk(n, **kw):
    base = {"box_xyxy_px": np.tile([900.0, 600, 960, 700], (n, 1)), "truth_xy_world_m": np.tile([10.0, 20.0], (n, 1)),
            "truth_z_m": np.zeros(n), "yaw_world_rad": np.zeros(n), "cov_uv_px2": np.tile(np.eye(2), (n, 1, 1))}
    base.update(kw)
    o = np.full(n, None, dtype=object)
    return LabelChunk(source="s", camera_key="k", camera=CAM, line=np.arange(1, n + 1), frame=o, object_id=o, cls=o,
                      error=[None] * n, **base)


def test_row_problems_pinned():
    cov = np.tile(np.eye(2), (6, 1, 1))
    cov[1, 0, 0] = -1e-3
    cov[2, 0, 1] = cov[2, 1, 0] = 1.5
    cov[3, 1, 1] = 2e12
    cov[4, 0, 1] = np.nan
    ch = _chunk(6, cov_uv_px2=cov)
    got = row_problems(ch)
    assert got[0] is None and got[5] is None
    assert "negative variance" in got[1] and "not positive semi-definite" in got[2]
    assert "out of range" in got[3] and "not finite" in got[4]
    # NaN is "absent" (the readers decide), -0 is a number
    ch = _chunk(3, truth_xy_world_m=np.array([[np.nan, np.nan], [-0.0, 20.0], [1e5 + 10, 0]]),
                truth_z_m=np.array([np.nan, -0.0, 0.0]))
    got = row_problems(ch)
    assert got[0] is None and got[1] is None and "more than" in got[2]


def test_one_bad_covariance_row_never_stops_the_job():
    cov = np.tile(np.eye(2), (5, 1, 1))
    cov[2] = [[-4.0, 0.0], [0.0, 1.0]]
    p = build_pairs(_chunk(5, cov_uv_px2=cov), BUDGET)
    assert p.status[2] == STATUS_ERROR and "negative variance" in p.reason[2] and p.line[2] == 3
    assert all(s != STATUS_ERROR for i, s in enumerate(p.status) if i != 2)


def test_accumulator_never_counts_an_ok_row_without_a_finite_nees():
    """A Pairs object built by hand (not by build_pairs) with an 'ok' row whose residual is inf: an error row,
    in the counts and in place, never a pair outside n_pairs."""
    p = build_pairs(_chunk(4), BUDGET)
    assert (p.status == "ok").all()
    p.residual_m[1] = [np.inf, 0.0]
    p.cov_m2[3] = [[1.0, 2.0], [2.0, 1.0]]  # indefinite: no NEES
    acc = CoverageAccumulator()
    acc.add(p, {0: BUDGET.param_covariance()}, ["k"])
    s = acc.summary()
    assert s["n_pairs"] == 2 == s["rows"]["ok"] and s["rows"]["error"] == 2 == s["refused"]["rows"]
    assert p.status.tolist() == ["ok", "error", "ok", "error"]


def test_reason_kinds_mask_values():
    assert reason_kind("box [1.0, 2.0, 3.0, 4.0]: expected u_min <= u_max") == "box #: expected u_min <= u_max"
    assert reason_kind("camera_id 'zz' not among the cameras given") == "camera_id # not among the cameras given"
    assert reason_kind("malformed label line (7 fields, expected 15 or 16)") == \
        "malformed label line (# fields, expected # or #)"
    assert reason_kind("field u_min_px is empty") == "field u_min_px is empty"


def test_budget_fit_counts_the_refused_rows_and_fits_the_pairs_only(tmp_path):
    from footprint_uq.viz.budget_fit_run import run_budget_fit

    path = _csv(tmp_path / "pairs.csv", _table_rows())
    cam = tmp_path / "cam.yaml"
    save_camera(CAM, cam)
    summary, _ = run_budget_fit(path, tmp_path / "fit", base_budget=BUDGET, free=["object_m"], camera=cam,
                                cross_validation=False, fsync=False)
    assert summary["statuses"] == {"ok": N_GOOD, "error": len(HOSTILE)}
    assert summary["fit"]["n_objects"] == N_GOOD
    assert summary["refused"]["rows"] == len(HOSTILE) == sum(summary["refused"]["by_reason"].values())
    assert summary["refused"]["by_reason"]["truth out of range (a coordinate beyond # m)"] == 1


# -- DAIR-V2X-I ------------------------------------------------------------------------------------------
def test_dair_v2x_hostile_numbers(tmp_path):
    from footprint_uq.validation.readers import read_dair_v2x_folder

    root = tmp_path / "dair"
    for sub in ("calib/camera_intrinsic", "calib/virtuallidar_to_camera", "label/camera"):
        (root / sub).mkdir(parents=True)
    T = CAM.T_cam_world
    (root / "calib/camera_intrinsic/1.json").write_text(json.dumps(
        {"cam_K": CAM.K.ravel().tolist(), "cam_D": [0, 0, 0, 0, 0], "width": 1920, "height": 1080}))
    (root / "calib/virtuallidar_to_camera/1.json").write_text(json.dumps(
        {"rotation": T[:3, :3].tolist(), "translation": [[v] for v in T[:3, 3]]}))
    g = _good_rows(1)[0]
    box = {"xmin": g["u_min_px"], "ymin": g["v_min_px"], "xmax": g["u_max_px"], "ymax": g["v_max_px"]}
    loc = {"x": g["x_m"], "y": g["y_m"], "z": 0.8}
    dims = {"h": 1.6, "w": 1.8, "l": 4.4}

    def obj(**kw):
        o = {"type": "Car", "2d_box": dict(box), "3d_dimensions": dict(dims), "3d_location": dict(loc),
             "rotation": 0.2}
        for k, v in kw.items():
            part, key = k.split("__")
            o[part][key] = v
        return o

    objs = [obj(), obj(**{"3d_location__x": 1e308}), obj(**{"3d_location__y": float("inf")}),
            obj(**{"3d_dimensions__h": 1e308}), obj(**{"2d_box__xmax": 1e308}), obj(**{"3d_location__x": -0.0})]
    text = json.dumps(objs).replace("Infinity", "1e400")  # 1e400: a number that overflows when read
    (root / "label/camera/1.json").write_text(text)
    pairs = collect_pairs(read_dair_v2x_folder(root), BUDGET)
    assert pairs.status[0] == "ok" and pairs.status[5] in ("ok", "no ground point")
    for i in range(1, 5):
        assert pairs.status[i] == "error" and pairs.line[i] == i, (i, pairs.reason[i])


def test_cli_validate_says_how_many_rows_were_refused_and_why(tmp_path):
    from click.testing import CliRunner

    from footprint_uq.cli.main import main

    path = _csv(tmp_path / "pairs.csv", _table_rows())
    cam = tmp_path / "cam.yaml"
    save_camera(CAM, cam)
    r = CliRunner().invoke(main, ["validate", "--labels", str(path), "--camera", str(cam), "--budget", "basler1",
                                  "--out", str(tmp_path / "out"), "--no-report", "--no-fsync"])
    assert r.exit_code == 0, r.output
    assert f"{N_GOOD} pairs" in r.stdout and f"{len(HOSTILE)} error rows" in r.stdout
    line = [ln for ln in r.stderr.splitlines() if "rows refused" in ln]
    assert len(line) == 1 and line[0].startswith(f"footprint-uq: {len(HOSTILE)} rows refused (3 x truth not finite")


@pytest.mark.parametrize(("kw", "field"), [({"alpha": float("nan")}, "alpha"), ({"alpha": 0.0}, "alpha"),
                                           ({"alpha": 0.7}, "alpha"),
                                           ({"range_bands_m": (0.0, float("nan"))}, "range_bands_m"),
                                           ({"range_bands_m": (0.0, float("inf"))}, "range_bands_m")])
def test_the_library_refuses_a_nan_significance_and_bands(kw, field):
    """The API as the command line: no verdict computed at significance NaN, no band named 0-nan m."""
    from footprint_uq.errors import InputError

    with pytest.raises(InputError, match=field):
        CoverageAccumulator(**kw)
