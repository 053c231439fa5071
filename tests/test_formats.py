"""Detector formats in (batch/formats.py, batch/arrays.py, io/class_names.py): every format round-trips to
the canonical CSV path's footprints (1e-12), ids / classes / scores carried, pinned pixel conventions, bad lines
are error rows with file and line (Hypothesis), bad detections are their own errors, other image sizes stop."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera, footprints_from_supervision, footprints_from_xyxy, read_detections
from footprint_uq.batch.formats import READERS, detect_input_format, open_reader, table_format
from footprint_uq.batch.process import process_file
from footprint_uq.errors import InputError
from footprint_uq.io import save_camera
from footprint_uq.io.class_names import COCO80_NAMES, COCO91_IDS

W, H = 1920, 1080
CAM = dict(focal_px=1400.0, image_size_px=(W, H), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1"
#: numeric output columns compared between a format and the canonical CSV
NUM = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "sigma_major_m", "nonlinearity", "largest_x_m")


@pytest.fixture(scope="module")
def cam():
    return PanTiltCamera(**CAM)


def canonical(cam, n=18, seed=3):
    """n boxes on the ground in view (pixel-centre coordinates), 3 frames, COCO class ids, scores, track ids."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(15.0, 60.0, n)
    a = np.deg2rad(30.0 + rng.uniform(-20.0, 20.0, n))
    uv = cam.project(np.stack([d * np.sin(a), d * np.cos(a), np.zeros(n)], 1)).uv_px
    w, h = rng.uniform(30, 80, n), rng.uniform(30, 80, n)
    box = np.stack([uv[:, 0] - w / 2, uv[:, 1] - h, uv[:, 0] + w / 2, uv[:, 1]], 1)
    cid = rng.choice([0, 2, 5, 7], n)
    return {"frame": np.arange(n) // 6 + 1, "cid": cid, "class": [COCO80_NAMES[c] for c in cid],
            "score": np.round(rng.uniform(0.3, 1.0, n), 4), "object_id": np.arange(n) % 7 + 1, "box": box}


def write_canonical(d, path: Path, ids=("frame", "class", "score", "object_id")):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([*ids, "u_min_px", "v_min_px", "u_max_px", "v_max_px"])
        for i in range(len(d["box"])):
            w.writerow([d[k][i] for k in ids] + [repr(float(v)) for v in d["box"][i]])
    return path


def run(cam, src, tmp_path: Path, name: str, **kw):
    out = tmp_path / f"{name}.parquet"
    s = process_file(cam, BUDGET, src, out, progress=False, summary=False, fsync=False, **kw)
    t = pq.read_table(out)
    assert s.rows_in == t.num_rows
    return t


def assert_same_footprints(t, ref):
    assert t.num_rows == ref.num_rows
    assert t.column("status").to_pylist() == ref.column("status").to_pylist()
    for c in NUM:
        np.testing.assert_allclose(t.column(c).to_numpy(), ref.column(c).to_numpy(), rtol=1e-12, atol=1e-12,
                                   err_msg=c)


@pytest.fixture(scope="module")
def ref(cam, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ref")
    d = canonical(cam)
    return d, run(cam, write_canonical(d, tmp / "canon.csv"), tmp, "canon")


# -- writers of the real layouts ------------------------------------------------------------------------
def _r(v) -> str:
    return repr(float(v))


def write_yolo(d, folder: Path, conf=True):
    folder.mkdir(parents=True, exist_ok=True)
    for fr in np.unique(d["frame"]):
        lines = []
        for i in np.flatnonzero(d["frame"] == fr):
            u0, v0, u1, v1 = d["box"][i] + 0.5  # pixel centres -> continuous coordinates
            vals = [(u0 + u1) / 2 / W, (v0 + v1) / 2 / H, (u1 - u0) / W, (v1 - v0) / H]
            lines.append(" ".join([str(d["cid"][i])] + [_r(v) for v in vals] + ([_r(d["score"][i])] if conf else [])))
        (folder / f"{int(fr):06d}.txt").write_text("\n".join(lines) + "\n")
    return folder


def write_yolov5_csv(d, path: Path):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["", "xmin", "ymin", "xmax", "ymax", "confidence", "class", "name", "frame"])
        for i, b in enumerate(d["box"] + 0.5):
            w.writerow([i, *map(repr, b.tolist()), d["score"][i], d["cid"][i], d["class"][i], d["frame"][i]])
    return path


def write_coco(d, path: Path, *, dataset: bool):
    res = [{"image_id": int(d["frame"][i]), "category_id": COCO91_IDS[d["cid"][i]],
            "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])], "score": float(d["score"][i])}
           for i, b in enumerate(d["box"] + 0.5)]
    images = [{"id": int(f), "file_name": f"img_{int(f):04d}.jpg", "width": W, "height": H}
              for f in np.unique(d["frame"])]
    cats = [{"id": cid, "name": name} for cid, name in zip(COCO91_IDS, COCO80_NAMES, strict=True)]
    path.write_text(json.dumps({"images": images, "categories": cats, "annotations": res} if dataset else res))
    return path, {"images": images, "categories": cats, "annotations": []}


def write_mot(d, path: Path, *, gt: bool):
    lines = []
    for i, b in enumerate(d["box"] + 1.0):  # 1-based
        head = [int(d["frame"][i]), int(d["object_id"][i]), *map(_r, [b[0], b[1], b[2] - b[0], b[3] - b[1]])]
        tail = [1, 3, 0.8] if gt else [d["score"][i], -1, -1, -1]  # gt: consider, class 3 (car), visibility
        lines.append(",".join(map(str, head + tail)))
    path.write_text("\n".join(lines) + "\n")
    return path


# -- round trips -----------------------------------------------------------------------------------------
def test_yolo_round_trip(cam, ref, tmp_path):
    d, want = ref
    folder = write_yolo(d, tmp_path / "run" / "labels")
    assert detect_input_format(tmp_path / "run") == "yolo" == detect_input_format(folder)
    t = run(cam, tmp_path / "run", tmp_path, "yolo")
    assert_same_footprints(t, want)
    assert t.column("class").to_pylist() == d["class"] and t.column("frame").to_pylist() == d["frame"].tolist()
    assert t.column("score").to_pylist() == d["score"].tolist()
    assert t.column("image").to_pylist()[:2] == ["000001", "000001"] and t.column("line").to_pylist()[:3] == [1, 2, 3]
    # a LabelImg classes.txt beside the labels: the names, never a label file; the summary says which map
    (folder / "classes.txt").write_text("".join(f"k{i}\n" for i in range(80)))
    out = tmp_path / "k.parquet"
    s = process_file(cam, BUDGET, folder, out, progress=False, fsync=False)
    assert pq.read_table(out).column("class").to_pylist() == [f"k{c}" for c in d["cid"]]
    assert s.info["class_names"] == str(folder / "classes.txt") and s.rows_in == len(d["cid"])
    (folder / "classes.txt").unlink()
    # a data.yaml with other names: the names follow it
    names = tmp_path / "data.yaml"
    names.write_text("names:\n" + "".join(f"  {i}: c{i}\n" for i in range(80)))
    t2 = run(cam, folder, tmp_path, "yolo2", class_names=names)
    assert t2.column("class").to_pylist() == [f"c{c}" for c in d["cid"]]


def test_yolov5_csv_round_trip_and_cli(cam, ref, tmp_path):
    """The pandas CSV `objects` used to refuse ("exactly one complete box family") now works, by itself."""
    d, want = ref
    src = write_yolov5_csv(d, tmp_path / "yolov5.csv")
    assert detect_input_format(src) == "yolov5-csv"
    assert_same_footprints(run(cam, src, tmp_path, "v5"), want)
    camf = tmp_path / "cam.yaml"
    save_camera(cam, camf)
    out = tmp_path / "cli.csv"
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections", str(src),
                                    "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert f"rows in {len(d['box'])}" in r.output and "rows with errors 0" in r.output
    rows = list(csv.DictReader(open(out)))
    assert [r["class"] for r in rows] == d["class"] and [float(r["score"]) for r in rows] == d["score"].tolist()


@pytest.mark.parametrize("dataset", [True, False])
def test_coco_round_trip(cam, ref, tmp_path, dataset):
    d, want = ref
    src, ds = write_coco(d, tmp_path / "results.json", dataset=dataset)
    assert detect_input_format(src) == "coco"
    kw = {}
    if not dataset:  # a results list: categories and images from the dataset JSON given as the class names
        (tmp_path / "instances.json").write_text(json.dumps(ds))
        kw = {"class_names": tmp_path / "instances.json"}
    t = run(cam, src, tmp_path, "coco", **kw)
    assert_same_footprints(t, want)
    assert t.column("class").to_pylist() == d["class"]
    assert t.column("image").to_pylist()[0] == "img_0001.jpg" and t.column("frame").to_pylist() == d["frame"].tolist()
    if not dataset:  # the built-in COCO category ids give the same names
        assert run(cam, src, tmp_path, "coco91").column("class").to_pylist() == d["class"]


@pytest.mark.parametrize("gt", [True, False])
def test_mot_round_trip(cam, ref, tmp_path, gt):
    d, want = ref
    seq = tmp_path / "MOT17-02"
    (seq / ("gt" if gt else "det")).mkdir(parents=True)
    src = write_mot(d, seq / ("gt/gt.txt" if gt else "det/det.txt"), gt=gt)
    (seq / "seqinfo.ini").write_text(f"[Sequence]\nname=MOT17-02\nframeRate=30\nimWidth={W}\nimHeight={H}\n")
    assert detect_input_format(src) == "mot"
    t = run(cam, src, tmp_path, "mot")
    assert_same_footprints(t, want)
    oid = t.column("object_id").to_pylist()
    assert oid == [str(v) for v in d["object_id"]]
    assert t.column("timestamp_s").to_pylist() == pytest.approx(((d["frame"] - 1) / 30.0).tolist(), abs=1e-15)
    assert t.column("class").to_pylist() == (["car"] * len(oid) if gt else [None] * len(oid))
    if gt:  # the ids and the seqinfo.ini's frame rate are what --tracks needs
        tr = run(cam, src, tmp_path, "tracks", tracks=True)
        assert tr.column("track_id").null_count == 0 and tr.column("age_s").to_numpy().max() > 0


def test_supervision_and_xyxy_round_trip(cam, ref):
    sv = pytest.importorskip("supervision")
    d, want = ref
    for fr in np.unique(d["frame"]):
        sel = d["frame"] == fr
        dets = sv.Detections(xyxy=d["box"][sel] + 0.5, confidence=d["score"][sel], class_id=d["cid"][sel],
                             tracker_id=d["object_id"][sel])
        out = footprints_from_supervision(cam, BUDGET, dets, frame=int(fr))
        assert_same_footprints(out, want.filter(np.asarray(sel)))
        assert out.column("class").to_pylist() == [d["class"][i] for i in np.flatnonzero(sel)]
        assert out.column("object_id").to_pylist() == [str(v) for v in d["object_id"][sel]]
        plain = footprints_from_xyxy(cam, BUDGET, d["box"][sel], class_id=d["cid"][sel],
                                     box_coordinates="pixel-centres")
        assert_same_footprints(plain, want.filter(np.asarray(sel)))
    # data["class_name"] wins over the ids; an id without a name is that detection's error only
    dets = sv.Detections(xyxy=d["box"][:3] + 0.5, class_id=np.array([2, 500, 0]))
    out = footprints_from_supervision(cam, BUDGET, dets)
    assert out.column("status").to_pylist() == ["ok", "error", "ok"]
    assert out.column("reason").to_pylist()[1] == "class id 500 is not in the names map (coco, 80 names)"
    dets.data["class_name"] = np.array(["car", "tram", "person"])
    assert footprints_from_supervision(cam, BUDGET, dets).column("class").to_pylist() == ["car", "tram", "person"]
    with pytest.raises(InputError, match="^class_id: got 'dtype float64'"):
        footprints_from_xyxy(cam, BUDGET, d["box"][:2], class_id=np.array([1.0, 2.0]))
    with pytest.raises(InputError, match="^xyxy_px"):
        footprints_from_xyxy(cam, BUDGET, d["box"][:, :3])


# -- pinned conventions ----------------------------------------------------------------------------------------
def test_pixel_conventions_pinned(tmp_path):
    """Hand-checked: continuous coordinates (image [0, W]) - 0.5 px; MOT's 1-based - 1 px."""
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "a.txt").write_text("0 0.5 0.5 0.25 0.5 0.75\n")
    t = read_detections(tmp_path / "y", image_size_px=(W, H))
    # u: (0.5 -+ 0.125) * 1920 - 0.5; v: (0.5 -+ 0.25) * 1080 - 0.5
    assert [t.column(c)[0].as_py() for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px")] == [
        719.5, 269.5, 1199.5, 809.5]
    assert t.column("class")[0].as_py() == "person" and t.column("score")[0].as_py() == 0.75
    (tmp_path / "det.txt").write_text("1,3,101,201,50,80,0.9,-1,-1,-1\n")
    t = read_detections(tmp_path / "det.txt")
    assert [t.column(c)[0].as_py() for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px")] == [100, 200, 150, 280]
    assert t.column("object_id")[0].as_py() == "3" and t.column("class")[0].as_py() is None
    (tmp_path / "r.json").write_text('[{"image_id": 4, "category_id": 3, "bbox": [100, 200, 50, 80], "score": 0.5}]')
    t = read_detections(tmp_path / "r.json")
    assert [t.column(c)[0].as_py() for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px")] == [
        99.5, 199.5, 149.5, 279.5]
    assert t.column("class")[0].as_py() == "car" and t.column("frame")[0].as_py() == 4


# -- bad input -----------------------------------------------------------------------------------------------
def test_bad_detections_are_their_own_errors(cam, tmp_path):
    (tmp_path / "y").mkdir()
    good = "2 0.5 0.8 0.05 0.1 0.9"
    (tmp_path / "y" / "000007.txt").write_text("\n".join([
        good, "2 0.5 0.8 0.0 0.1 0.9", "2 0.98 0.8 0.05 0.1", "95 0.5 0.8 0.05 0.1", "2 0.5 0.8 0.05", good]) + "\n")
    t = run(cam, tmp_path / "y", tmp_path, "bad")
    st_, why = t.column("status").to_pylist(), t.column("reason").to_pylist()
    assert st_ == ["ok", "error", "error", "error", "error", "ok"]
    assert why[1].startswith("box width or height <= 0") and why[2].startswith("normalised box outside [0, 1]")
    assert why[3] == "class id 95 is not in the names map (coco, 80 names)"
    assert why[4] == "000007.txt line 5: malformed YOLO label line (4 fields; expected 5 or 6: class cx cy w h [conf])"
    assert t.column("line").to_pylist() == [1, 2, 3, 4, 5, 6] and set(t.column("frame").to_pylist()) == {7}
    t2 = run(cam, tmp_path / "y", tmp_path, "unk", unknown_class="unknown")
    assert t2.column("status").to_pylist()[3] == "ok" and t2.column("class").to_pylist()[3] == "unknown"
    # COCO: w <= 0 and an unknown category are that detection's errors
    (tmp_path / "r.json").write_text(json.dumps([
        {"image_id": 1, "category_id": 3, "bbox": [900, 700, 0, 40], "score": 0.5},
        {"image_id": 1, "category_id": 12, "bbox": [900, 700, 40, 40], "score": 0.5},
        {"image_id": 1, "category_id": 3, "bbox": [900, 700, 40], "score": 0.5},
        {"image_id": 1, "category_id": 3, "bbox": [900, 700, 40, 40], "score": 0.5}]))
    t = run(cam, tmp_path / "r.json", tmp_path, "coco")
    assert t.column("status").to_pylist() == ["error", "error", "error", "ok"]
    assert t.column("reason").to_pylist()[2] == "r.json detection 2: bbox [900, 700, 40] is not 4 numbers [x, y, w, h]"


def test_other_image_size_stops_the_job(cam, tmp_path):
    src, _ = write_coco(canonical(cam, 3), tmp_path / "c.json", dataset=True)
    doc = json.loads(src.read_text())
    doc["images"][0]["width"] = 1280
    src.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"image 'img_0001.jpg': got '1280 x 1080 px', expected images of the "
                                         r"camera's size 1920 x 1080 px"):
        run(cam, src, tmp_path, "x")
    seq = tmp_path / "seq"
    (seq / "det").mkdir(parents=True)
    write_mot(canonical(cam, 3), seq / "det" / "det.txt", gt=False)
    (seq / "seqinfo.ini").write_text("[Sequence]\nimWidth=1280\nimHeight=720\nframeRate=25\n")
    camf = tmp_path / "cam.yaml"
    save_camera(cam, camf)
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections",
                                    str(seq / "det" / "det.txt"), "--out", str(tmp_path / "o.csv")])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1 and "1280 x 720 px" in r.output
    r = CliRunner().invoke(_cli(), ["objects", "--camera", str(camf), "--budget", BUDGET, "--detections",
                                    str(seq / "det" / "det.txt"), "--out", str(tmp_path / "o.csv"),
                                    "--image-size", "1280", "720"])
    assert r.exit_code == 2 and "--image-size" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "o.csv").exists()
    with pytest.raises(InputError, match="^image_size_px"):
        read_detections(write_yolo(canonical(cam, 3), tmp_path / "yy"))


def test_canonical_csv_integer_classes_through_names(cam, tmp_path):
    d = canonical(cam, 4)
    d["class"] = [str(c) for c in d["cid"][:3]] + ["900"]
    src = write_canonical(d, tmp_path / "c.csv")
    t = run(cam, src, tmp_path, "named", class_names="coco")
    assert t.column("class").to_pylist()[:3] == [COCO80_NAMES[c] for c in d["cid"][:3]]
    assert t.column("status").to_pylist() == ["ok", "ok", "ok", "error"]
    assert run(cam, src, tmp_path, "plain").column("class").to_pylist() == d["class"]  # no map: kept as written


EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "data"


@pytest.mark.parametrize("name", ["yolo_labels", "yolov5.csv", "coco_results.json", "mot_det.txt"])
def test_example_files(name, tmp_path):
    """The example of each format (docs/integrations.md): five lines, every detection on the ground, the same
    footprints whatever the format (the boxes are the same ones, rounded to 0.1 px)."""
    from footprint_uq import load_camera

    src = EXAMPLES / name
    files = sorted(src.glob("*.txt")) if src.is_dir() else [src]
    assert sum(len(p.read_text().splitlines()) for p in files) == 5
    cam = load_camera(EXAMPLES / "camera.yaml")
    t = run(cam, src, tmp_path, "ex")
    assert set(t.column("status").to_pylist()) == {"ok"}
    assert t.column("class").to_pylist()[:2] == (["car", "car"] if name != "mot_det.txt" else [None, None])
    x = t.column("x_m").to_numpy()
    assert x[:4] == pytest.approx([12.0, 20.0, 8.0, 25.0], abs=0.01)  # the ground points the boxes were drawn at


def test_detection_of_formats(tmp_path):
    (tmp_path / "a.csv").write_text("u_min_px,v_min_px,u_max_px,v_max_px\n1,2,3,4\n")
    (tmp_path / "one.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    (tmp_path / "x.bin").write_text("?")
    assert detect_input_format(tmp_path / "a.csv") == "csv"
    assert detect_input_format(tmp_path / "one.txt") == "yolo"
    with pytest.raises(InputError, match="^detections"):
        detect_input_format(tmp_path / "x.bin")
    with pytest.raises(InputError, match="^format"):
        open_reader(tmp_path / "a.csv", format="kitti")
    assert set(READERS) == {"ros2-bag", "yolo", "yolov5-csv", "coco", "mot"}


def test_lazy_entries_name_a_reader_of_their_format():
    """A registry entry above batch/ (integrations/) is a module path in text: it still names a FormatReader of its
    own format (a rename there fails here, with or without the ROS extra installed)."""
    from footprint_uq.batch.formats import FormatReader, LazyFormat

    lazy = {name: e for name, e in READERS.items() if isinstance(e, LazyFormat)}
    assert set(lazy) == {"ros2-bag"}
    for name, entry in lazy.items():
        cls = entry.load()
        assert issubclass(cls, FormatReader) and cls.name == name


# -- malformed lines (Hypothesis) ------------------------------------------------------------------------------
_ONE_LINE = st.text(max_size=40).filter(lambda s: "\n" not in s and "\r" not in s)
_JUNK = st.one_of(_ONE_LINE, st.lists(st.sampled_from(["0", "1.5", "nan", "-1", "x", "1e400", "", "0.5"]),
                                      max_size=8).map(" ".join))


def _yolo_line_ok(s: str) -> bool:
    f = s.split()
    if len(f) not in (5, 6):
        return False
    try:
        vals = [float(v) for v in f]
    except ValueError:
        return False
    return all(math.isfinite(v) for v in vals)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(junk=_JUNK, where=st.integers(0, 3))
@example(junk="0 0.5 0.5 0.1", where=1).via("four numbers")
@example(junk="0 0.5 0.5 0.1 0.1 0.9 0.3", where=0).via("seven numbers (a segment)")
@example(junk="0.5 0.5 0.5 0.1 0.1", where=3).via("a class id that is not an integer")
@example(junk="", where=2).via("an empty line")
def test_malformed_yolo_line_is_one_error_row(tmp_path_factory, junk, where):
    """Any line among valid ones: one row per line, valid rows unchanged, a line that does not parse is an error
    row naming the file and the line, never a stop."""
    good = ["2 0.5 0.8 0.05 0.1 0.9", "0 0.3 0.7 0.04 0.1", "7 0.6 0.9 0.1 0.1 0.5"]
    lines = good[:where] + [junk] + good[where:]
    folder = tmp_path_factory.mktemp("h")
    (folder / "000003.txt").write_text("\n".join(lines) + "\n")
    t = read_detections(folder, image_size_px=(W, H))
    assert t.num_rows == 4 and t.column("line").to_pylist() == [1, 2, 3, 4]
    err = t.column("error").to_pylist()
    assert all(e is None for i, e in enumerate(err) if i != where)
    ref = read_detections_lines(good, tmp_path_factory)
    keep = [i for i in range(4) if i != where]
    for c in ("u_min_px", "v_max_px", "class"):
        assert [t.column(c)[i].as_py() for i in keep] == ref.column(c).to_pylist()
    if not _yolo_line_ok(junk):
        assert err[where] is not None and err[where].startswith(f"000003.txt line {where + 1}: malformed YOLO")


def read_detections_lines(lines, factory):
    folder = factory.mktemp("r")
    (folder / "000003.txt").write_text("\n".join(lines) + "\n")
    return read_detections(folder, image_size_px=(W, H))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(junk=st.one_of(_ONE_LINE, st.lists(st.sampled_from(["1", "2.5", "-1", "x", "", "nan", "1e400"]),
                                          max_size=11).map(",".join)))
@example(junk="1,3,101,201,50,80").via("six numbers")
@example(junk="1,3,101,201,50,80,1,1,1,1,1").via("eleven numbers")
@example(junk="1,3,101,201,50,80,1,2.5,1").via("a class id that is not an integer")
@example(junk="1,3,101,201,50,80,1,-1,-1").via("gt with class -1")
def test_malformed_mot_line_is_one_error_row(tmp_path_factory, junk):
    good = "1,3,101,201,50,80,0.9,-1,-1,-1"
    path = tmp_path_factory.mktemp("m") / "det.txt"
    path.write_text("\n".join([good, junk, good]) + "\n")
    t = read_detections(path, format="mot")
    assert t.num_rows == 3 and t.column("line").to_pylist() == [1, 2, 3]
    err = t.column("error").to_pylist()
    assert err[0] is None and err[2] is None and t.column("u_min_px")[2].as_py() == 100.0
    f = [x.strip() for x in junk.split(",")]
    parses = 7 <= len(f) <= 10 and _mot_numbers(f)
    assert (err[1] is None or not err[1].startswith("det.txt line 2: malformed")) == parses


def _mot_numbers(f) -> bool:
    try:
        vals = [float(v) for v in f[:7]] + ([float(f[7])] if len(f) == 9 else [])
    except ValueError:
        return False
    ints = [vals[0], vals[1]] + ([vals[7]] if len(f) == 9 else [])
    return all(math.isfinite(v) for v in vals) and all(v.is_integer() for v in ints)


def _cli():
    from footprint_uq.cli.main import main

    return main


# -- validate with a detector's own files ------------------------------------------------------------------------
def test_validate_pairs_detector_files_with_a_truth_table(cam, tmp_path):
    """MOT gt.txt + truth table by (frame, object_id): pairs, a detection without truth, a truth without
    detection, a duplicate truth (error row); the residuals of exact boxes are ~0 (the pixel shifts agree)."""
    from footprint_uq.viz.validation_run import run_validation

    rng = np.random.default_rng(11)
    n = 8
    d, a = rng.uniform(15.0, 50.0, n), np.deg2rad(30.0 + rng.uniform(-15.0, 15.0, n))
    xy = np.stack([d * np.sin(a), d * np.cos(a)], 1)
    uv = cam.project(np.c_[xy, np.zeros(n)]).uv_px
    box = np.stack([uv[:, 0] - 20, uv[:, 1] - 40, uv[:, 0] + 20, uv[:, 1]], 1)
    det = {"frame": np.arange(n) // 2 + 1, "object_id": np.arange(n) + 1, "box": box, "score": np.ones(n)}
    src = write_mot(det, tmp_path / "gt.txt", gt=True)
    lines = ["frame,object_id,x_m,y_m"] + [f"{det['frame'][i]},{i + 1},{_r(xy[i, 0])},{_r(xy[i, 1])}"
                                           for i in range(n - 1)]  # object 8: no truth
    lines += ["9,99,1.0,2.0", f"1,1,{_r(xy[0, 0])},{_r(xy[0, 1])}"]  # a truth without detection; a duplicate
    (tmp_path / "truth.csv").write_text("\n".join(lines) + "\n")
    camf = tmp_path / "cam.yaml"
    save_camera(cam, camf)
    summary, files = run_validation(tmp_path / "truth.csv", tmp_path / "val", BUDGET, camera=camf, detections=src,
                                    report=False, fsync=False)
    un = summary["unpaired"]
    assert summary["n_pairs"] == n - 1 and summary["detections"] == str(src)
    assert (un["detections_without_truth"], un["truth_without_detection"], un["error_rows"]) == (1, 1, 1)
    rows = list(csv.DictReader(open(files["objects"])))
    ok = [r for r in rows if r["status"] == "ok"]
    assert max(float(r["error_m"]) for r in ok) < 1e-6 and {r["class"] for r in ok} == {"car"}
    dup = next(r for r in rows if r["status"] == "error")
    assert "a second truth of frame 1 object '1'" in dup["reason"] and dup["line"] == "10"
    r = CliRunner().invoke(_cli(), ["validate", "--labels", str(tmp_path / "truth.csv"), "--detections", str(src),
                                    "--camera", str(camf), "--budget", BUDGET, "--out", str(tmp_path / "v2"),
                                    "--no-report", "--no-fsync", "--format", "mot", "--class-names", "coco"])
    assert r.exit_code == 0, r.output
    assert {row["class"] for row in csv.DictReader(open(tmp_path / "v2" / "objects.csv"))} >= {"motorcycle"}
    r = CliRunner().invoke(_cli(), ["validate", "--labels", str(tmp_path / "truth.csv"), "--camera", str(camf),
                                    "--budget", BUDGET, "--out", str(tmp_path / "v3"), "--format", "mot"])
    assert r.exit_code == 2 and "--detections too" in r.output and len(r.output.strip().splitlines()) == 1


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(junk=_ONE_LINE)
@example(junk='900,"500,980,560,0.9,2,car').via("a stray quote")
@example(junk="900,500,980,560,0.9,2").via("a field short")
@example(junk="900,500,980,560,0.9,x,").via("a class that is not an integer, no name")
def test_malformed_yolov5_csv_line_is_one_error_row(tmp_path_factory, junk):
    good = "900,500,980,560,0.9,2,car"
    path = tmp_path_factory.mktemp("v") / "y.csv"
    path.write_text("\n".join(["xmin,ymin,xmax,ymax,confidence,class,name", good, junk, good]) + "\n")
    t = read_detections(path)
    assert t.num_rows == 3 and t.column("line").to_pylist() == [2, 3, 4]
    err = t.column("error").to_pylist()
    assert err[0] is None and err[2] is None and t.column("class").to_pylist()[2] == "car"
    try:
        fields = next(csv.reader([junk], strict=True)) if junk else []
    except csv.Error:
        fields = None
    if fields is None or len(fields) != 7:
        assert err[1].startswith("y.csv line 3: malformed CSV line")


_JSON = st.recursive(st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats(allow_nan=False,
                                                                                       allow_infinity=False)
                     | st.text(max_size=8), lambda c: st.lists(c, max_size=5) | st.dictionaries(st.text(max_size=8), c,
                                                                                                 max_size=5),
                     max_leaves=12)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(entry=st.one_of(_JSON, st.fixed_dictionaries({"image_id": _JSON, "category_id": _JSON, "bbox": _JSON,
                                                     "score": _JSON})))
def test_any_coco_entry_is_one_row(tmp_path_factory, entry):
    """Whatever an entry holds, it is one row (an error row when it is not a detection); its neighbours stay."""
    good = {"image_id": 1, "category_id": 3, "bbox": [900, 500, 80, 60], "score": 0.9}
    path = tmp_path_factory.mktemp("c") / "r.json"
    path.write_text(json.dumps([good, entry, good]))
    t = read_detections(path)
    assert t.num_rows == 3 and t.column("row").to_pylist() == [0, 1, 2]
    err = t.column("error").to_pylist()
    assert err[0] is None and err[2] is None and t.column("u_min_px")[2].as_py() == 899.5
    if not isinstance(entry, dict):
        assert err[1] == "r.json detection 1: not a JSON object"


def test_a_format_from_a_table_function_is_one_line(cam, ref, tmp_path, monkeypatch):
    """A reader that returns canonical tables (the ROS 2 bag reader's shape) registers with one line and gives the
    canonical path's footprints; its ``error`` column becomes error rows."""
    import pyarrow as pa

    d, want = ref

    def tables(path, options):
        box = d["box"]
        n = len(box)
        for lo in range(0, n, 7):
            sl = slice(lo, min(n, lo + 7))
            yield pa.table({"frame": d["frame"][sl], "class": d["class"][sl], "object_id": d["object_id"][sl],
                            **{c: box[sl, j] for j, c in enumerate(("u_min_px", "v_min_px", "u_max_px", "v_max_px"))},
                            "error": [None] * (sl.stop - lo)})

    src = _w_bytes(tmp_path / "run.fake", b"FAKE")
    monkeypatch.setitem(READERS, "fake", table_format("fake", tables, sniff=lambda p: p.suffix == ".fake",
                                                      id_columns=("frame", "object_id", "class", "score")))
    assert detect_input_format(src) == "fake"
    t = run(cam, src, tmp_path, "fake")
    assert_same_footprints(t, want)
    assert t.column("object_id").to_pylist() == [str(v) for v in d["object_id"]] and t.column("score").null_count == 18
    with pytest.raises(InputError, match="^id_columns"):
        table_format("bad", tables, id_columns=("speed",))


def _w_bytes(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path
