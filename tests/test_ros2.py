"""ROS 2 bags out and in, and the Foxglove scene (footprint_uq.integrations.ros2; docs/integrations.md).

Every bag written is read back with rosbags (every message deserialised); the single MCAP file also with the
``mcap`` reader (every channel's schema and every message decoded: CDR through the schema's own ros2msg text,
the Foxglove SceneUpdate through its protobuf FileDescriptorSet with the official protobuf library via
mcap-protobuf-support)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("rosbags")
pytest.importorskip("mcap")
pytest.importorskip("foxglove")

from google.protobuf import json_format  # noqa: E402
from google.protobuf.message import DecodeError  # noqa: E402
from google.protobuf.unknown_fields import UnknownFieldSet  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_protobuf.decoder import DecoderFactory  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from footprint_uq.batch.process import process_file, summary_path  # noqa: E402
from footprint_uq.cameras.pantilt import PanTiltCamera  # noqa: E402
from footprint_uq.cli.main import main  # noqa: E402
from footprint_uq.errors import InputError  # noqa: E402
from footprint_uq.integrations.ros2 import messages as M  # noqa: E402
from footprint_uq.integrations.ros2.bag_reader import BagDetectionReader, camera_from_bag  # noqa: E402
from footprint_uq.integrations.ros2.bag_writer import BagOptions, RosBagOut, bag_writer_factory  # noqa: E402
from footprint_uq.integrations.ros2.foxglove_scene import quaternion_x_to  # noqa: E402
from footprint_uq.integrations.ros2.types import default_message, typestore  # noqa: E402
from footprint_uq.io import save_camera  # noqa: E402
from footprint_uq.uncertainty.ellipse import ellipse_axes  # noqa: E402


def _protobuf_dict(decoder, data: bytes) -> dict:
    """A protobuf message decoded with the official library from its channel's schema (mcap-protobuf-support), as
    a dict (snake_case names, enums as numbers); refused where a field of it, or of any message inside it, is
    not in the schema (the library keeps such fields as unknown instead of failing)."""
    msg = decoder(data)

    def known_only(m):
        assert len(UnknownFieldSet(m)) == 0, f"{m.DESCRIPTOR.full_name}: a field outside the schema"
        for fd, v in m.ListFields():
            if fd.message_type is not None:
                for sub in (v if fd.is_repeated else [v]):
                    known_only(sub)

    known_only(msg)
    return json_format.MessageToDict(msg, preserving_proto_field_name=True, use_integers_for_enums=True)

BUDGET = "basler1"
POSE = dict(height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
K = [[1400.0, 0.0, 959.5], [0.0, 1400.0, 539.5], [0.0, 0.0, 1.0]]
DIST = [-0.05, 0.01, 0.0005, -0.0003, 0.0]
T0 = 1714564800.0
OUTS = ["run.mcap", "bag_mcap/", "bag_sqlite3/"]


@pytest.fixture(scope="module")
def cam():
    return PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), **POSE)


def detections(n_frames=6, per_frame=7, seed=3):
    """Rows of a detection table: frames at 30 Hz, ids, classes, scores; one unparseable value, one box above
    the horizon (no centre)."""
    rng = np.random.default_rng(seed)
    rows = []
    for fr in range(n_frames):
        for j in range(per_frame):
            u, v = rng.uniform(200, 1700), rng.uniform(620, 1000)
            w, h = rng.uniform(40, 150), rng.uniform(30, 100)
            rows.append({"camera_id": "cam1", "frame": fr, "timestamp_s": T0 + fr / 30.0, "object_id": f"o{j}",
                         "class": ["car", "truck", "person"][j % 3], "score": round(0.5 + 0.05 * j, 3),
                         "u_min_px": u, "v_min_px": v - h, "u_max_px": u + w, "v_max_px": v})
    rows[3]["u_min_px"] = "abc"
    rows[10]["v_min_px"], rows[10]["v_max_px"] = 2.0, 20.0
    return rows


def write_csv(rows, path):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return path


def write_bag(out: Path, opts: BagOptions, cam, tmp_path, rows=None) -> dict:
    src = write_csv(rows or detections(), tmp_path / "d.csv")
    ref = tmp_path / "ref.parquet"
    process_file(cam, BUDGET, src, ref, progress=False, chunk_rows=5)
    summ = process_file(cam, BUDGET, src, out, progress=False, chunk_rows=5, writer_factory=bag_writer_factory(opts))
    return {"ref": pq.read_table(ref).to_pylist(), "summary": summ}


def read_bag(path) -> dict[str, list]:
    """topic -> (log time, message) of every message, deserialised by rosbags."""
    out: dict[str, list] = {}
    with AnyReader([Path(path)], default_typestore=typestore()) as r:
        for conn, t, raw in r.messages():
            out.setdefault(conn.topic, []).append((t, r.deserialize(raw, conn.msgtype)))
    return out


def _storage(name: str) -> dict:
    return {"storage": "sqlite3"} if "sqlite3" in name else {}


@pytest.mark.parametrize("name", OUTS)
def test_bag_round_trip_covariances_and_ellipses(cam, tmp_path, name):
    out = tmp_path / name
    res = write_bag(Path(str(out) + ("/" if name.endswith("/") else "")), BagOptions(camera=cam, **_storage(name)),
                    cam, tmp_path)
    out = Path(str(out).rstrip("/"))
    if name.endswith("/"):
        assert (out / "metadata.yaml").exists()
        assert next(out.glob("*.db3" if "sqlite3" in name else "*.mcap")).is_file()
    ok = [r for r in res["ref"] if r["status"] == "ok"]
    assert len(ok) == len(res["ref"]) - 2
    msgs = read_bag(out)
    dets = msgs["/footprints/detections"]
    assert len(dets) == 6 and len(msgs["/footprints/ellipses"]) == 6
    got = [(t, arr.header, d) for t, arr in dets for d in arr.detections]
    assert len(got) == len(ok)
    for (t, header, d), r in zip(got, ok, strict=True):
        stamp_ns = round(r["timestamp_s"] * 1e9)
        assert t == stamp_ns and header.stamp.sec * 10**9 + header.stamp.nanosec == stamp_ns
        assert header.frame_id == "map" and d.id == r["object_id"]
        hyp = d.results[0]
        assert hyp.hypothesis.class_id == r["class"] and hyp.hypothesis.score == r["score"]
        p = hyp.pose.pose.position
        assert (p.x, p.y, p.z) == (r["x_m"], r["y_m"], cam.ground_z_m)
        c = np.asarray(hyp.pose.covariance).reshape(6, 6)
        np.testing.assert_array_equal(c[:2, :2], [[r["cov_xx_m2"], r["cov_xy_m2"]], [r["cov_xy_m2"], r["cov_yy_m2"]]])
        np.testing.assert_array_equal(np.diag(c)[2:], M.UNKNOWN_VARIANCE)
        assert np.count_nonzero(c) == 4 + 4 - (r["cov_xy_m2"] == 0) * 2
    cyl = [(m, arr) for _, arr in msgs["/footprints/ellipses"] for m in arr.markers if m.type == m.CYLINDER]
    assert len(cyl) == len(ok)
    assert all(arr.markers[0].action == arr.markers[0].DELETEALL for _, arr in msgs["/footprints/ellipses"])
    for (m, _), r in zip(cyl, ok, strict=True):
        cov = np.array([[r["cov_xx_m2"], r["cov_xy_m2"]], [r["cov_xy_m2"], r["cov_yy_m2"]]])
        a, b, ori = ellipse_axes(cov, confidence=0.95)
        assert m.scale.x / 2 == pytest.approx(a, rel=1e-12) and m.scale.y / 2 == pytest.approx(b, rel=1e-12)
        q = m.pose.orientation
        yaw = np.degrees(2 * np.arctan2(q.z, q.w))
        assert (q.x, q.y) == (0.0, 0.0) and yaw == pytest.approx(ori, abs=1e-9)
        assert (m.pose.position.x, m.pose.position.y) == (r["x_m"], r["y_m"])
    bag = res["summary"].info["bag"]
    assert bag["frames"] == 6 and bag["objects"] == len(ok)
    assert bag["not_in_bag"] == {"no centre (status partial or error)": 2}


def test_mcap_with_foxglove_every_channel_and_message_decodes(cam, tmp_path):
    out = tmp_path / "run.mcap"
    res = write_bag(out, BagOptions(camera=cam, foxglove=True, frame_id="world_enu"), cam, tmp_path)
    ok = [r for r in res["ref"] if r["status"] == "ok"]
    decoded: dict[str, list] = {}
    with open(out, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        stores = {}
        for sid, sc in summary.schemas.items():
            if sc.encoding == "ros2msg":
                ts = get_typestore(Stores.EMPTY)
                ts.register(get_types_from_msg(sc.data.decode(), sc.name))  # the schema alone defines the type
                stores[sid] = ts
            else:
                assert (sc.name, sc.encoding) == ("foxglove.SceneUpdate", "protobuf")
                stores[sid] = DecoderFactory().decoder_for("protobuf", sc)
        for schema, channel, message in reader.iter_messages():
            if schema.encoding == "ros2msg":
                assert channel.message_encoding == "cdr"
                msg = stores[schema.id].deserialize_cdr(message.data, schema.name)
            else:
                assert channel.message_encoding == "protobuf"
                msg = _protobuf_dict(stores[schema.id], message.data)
            decoded.setdefault(channel.topic, []).append(msg)
    assert sorted(decoded) == ["/footprints/detections", "/footprints/ellipses", "/footprints/scene"]
    assert all(len(v) == 6 for v in decoded.values())
    ents = [e for u in decoded["/footprints/scene"] for e in u["entities"]]
    objects = [e for e in ents if e["id"].startswith("object/")]
    assert len(objects) == len(ok) and sum(e["id"] == "camera" for e in ents) == 6
    for e, r in zip(objects, ok, strict=True):
        assert e["frame_id"] == "world_enu" and e["texts"][0]["text"] == r["object_id"]
        assert {kv["key"]: kv["value"] for kv in e["metadata"]} == {"object_id": r["object_id"], "class": r["class"]}
        cov = np.array([[r["cov_xx_m2"], r["cov_xy_m2"]], [r["cov_xy_m2"], r["cov_yy_m2"]]])
        a, b, _ = ellipse_axes(cov, confidence=0.95)
        size = e["cylinders"][0]["size"]
        assert size["x"] == pytest.approx(2 * a, rel=1e-12) and size["y"] == pytest.approx(2 * b, rel=1e-12)
        pos = e["cylinders"][0]["pose"]["position"]
        assert (pos["x"], pos["y"]) == (r["x_m"], r["y_m"])
    with pytest.raises(InputError, match=r"/footprints/scene \(protobuf\) are not ROS 2"):  # as input: one line
        BagDetectionReader(out)
    arrow = next(e for e in ents if e["id"] == "camera")["arrows"][0]["pose"]["position"]
    np.testing.assert_allclose([arrow.get(k, 0.0) for k in "xyz"], cam.T_world_cam[:3, 3], atol=1e-12)  # 0: omitted
    assert all(u["deletions"][0]["type"] == 1 for u in decoded["/footprints/scene"])  # ALL (MATCHING_ID is 0)


def _scene_decoder():
    """The protobuf decoder of foxglove-sdk's SceneUpdate schema, as mcap's reader builds it from a channel."""
    from foxglove import messages as fm

    class _Schema:  # what mcap's reader hands the decoder factory
        id, name, encoding, data = 1, "foxglove.SceneUpdate", "protobuf", fm.SceneUpdate.get_schema().data

    return DecoderFactory().decoder_for("protobuf", _Schema)


def test_protobuf_check_refuses_a_field_outside_the_schema_and_a_truncated_message(tmp_path):
    """The check behind the test above can fail: field 9 is not in SceneUpdate; a cut message does not parse."""
    from foxglove import messages as fm

    decoder = _scene_decoder()
    good = fm.SceneUpdate(entities=[fm.SceneEntity(id="x", frame_id="map")]).encode()
    assert _protobuf_dict(decoder, good)["entities"][0]["id"] == "x"
    with pytest.raises(AssertionError, match="outside the schema"):
        _protobuf_dict(decoder, good + bytes([9 << 3, 1]))
    with pytest.raises(DecodeError):
        decoder(good[:-3])


# -- bags in -------------------------------------------------------------------------------------------------------
def bag_in(path: Path, rows, storage="mcap", camera_info=True, theta_row=None):
    """A rosbag2 folder with Detection2DArray on /detector/detections (one message per frame) and a CameraInfo."""
    ts = typestore()
    T = ts.types
    w = Writer(path, version=9, storage_plugin=getattr(StoragePlugin, storage.upper()))
    w.open()
    c_det = w.add_connection("/detector/detections", "vision_msgs/msg/Detection2DArray", typestore=ts)
    c_img = w.add_connection("/camera/image_raw/compressed", "sensor_msgs/msg/CompressedImage", typestore=ts)
    if camera_info:
        c_info = w.add_connection("/camera/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts)
    frames: dict = {}
    for i, r in enumerate(rows):
        frames.setdefault(r["frame"], []).append((i, r))
    for items in frames.values():
        t_s = items[0][1]["timestamp_s"]
        ns = round(t_s * 1e9)
        header = T["std_msgs/msg/Header"](stamp=M.stamp(ts, ns), frame_id="camera")
        dets = []
        for i, r in items:
            u0, v0, u1, v1 = (float(r[k]) for k in ("u_min_px", "v_min_px", "u_max_px", "v_max_px"))
            centre = T["vision_msgs/msg/Pose2D"](position=T["vision_msgs/msg/Point2D"](x=0.5 * (u0 + u1),
                                                                                       y=0.5 * (v0 + v1)),
                                                 theta=0.3 if i == theta_row else 0.0)
            hyps = [T["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=c, score=s),
                pose=default_message(ts, "geometry_msgs/msg/PoseWithCovariance")) for c, s in
                (("other", 0.1), (r["class"], r["score"]))]
            dets.append(T["vision_msgs/msg/Detection2D"](
                header=header, results=hyps, id=r["object_id"],
                bbox=T["vision_msgs/msg/BoundingBox2D"](center=centre, size_x=u1 - u0, size_y=v1 - v0)))
        w.write(c_det, ns, ts.serialize_cdr(T["vision_msgs/msg/Detection2DArray"](header=header, detections=dets),
                                            "vision_msgs/msg/Detection2DArray"))
        w.write(c_img, ns, ts.serialize_cdr(default_message(ts, "sensor_msgs/msg/CompressedImage"),
                                            "sensor_msgs/msg/CompressedImage"))
        if camera_info:
            info = default_message(ts, "sensor_msgs/msg/CameraInfo", header=header, width=1920, height=1080,
                                     distortion_model="plumb_bob", d=np.array(DIST),
                                     k=np.array(K).ravel(), r=np.eye(3).ravel())
            w.write(c_info, ns, ts.serialize_cdr(info, "sensor_msgs/msg/CameraInfo"))
    w.close()
    return path


def good_rows():
    rows = detections()
    rows[3]["u_min_px"] = 400.0
    return rows


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bag_in_gives_the_footprints_of_the_csv_path(tmp_path, storage):
    rows = good_rows()
    bag = bag_in(tmp_path / "in_bag", rows, storage=storage, theta_row=5)
    cam = camera_from_bag(bag, pose=dict(POSE))
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.dist[:5], DIST)
    ref = write_csv([{**r, "camera_id": None} for r in rows], tmp_path / "d.csv")
    process_file(cam, BUDGET, ref, tmp_path / "csv.parquet", progress=False)
    process_file(cam, BUDGET, bag, tmp_path / "bag.parquet", progress=False,
                 reader=BagDetectionReader(bag, chunk_rows=4))
    a, b = pq.read_table(tmp_path / "csv.parquet").to_pylist(), pq.read_table(tmp_path / "bag.parquet").to_pylist()
    assert len(a) == len(b) == len(rows)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert y["row"] == i and y["frame"] == x["frame"] and y["object_id"] == x["object_id"]
        assert y["class"] == x["class"] and y["score"] == x["score"]  # the best hypothesis
        assert abs(y["timestamp_s"] - x["timestamp_s"]) < 1e-6  # header.stamp's nanoseconds
        if i == 5:
            assert y["status"] == "error" and "bbox.center.theta" in y["reason"]
            continue
        assert y["status"] == x["status"]
        for k in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2"):
            np.testing.assert_allclose(y[k], x[k], rtol=1e-12, atol=1e-12, equal_nan=True)


def _single_mcap(bag: Path) -> Path:
    """The bag folder's one MCAP storage file (a bare .mcap file, as detectors record them)."""
    (f,) = bag.glob("*.mcap")
    return f


def test_bag_through_the_format_registry_gives_the_csv_footprints(tmp_path):
    """read_detections / process_file of a bag with no reader given: the registry's ros2-bag (detected from a bag
    folder and a bare .mcap) gives the CSV path's table and footprints (1e-12); --class-names names integer ids."""
    from footprint_uq import read_detections
    from footprint_uq.batch.formats import detect_input_format

    rows = good_rows()
    bag = bag_in(tmp_path / "in_bag", rows, theta_row=5)
    cam = camera_from_bag(bag, pose=dict(POSE))
    ref = write_csv([{**r, "camera_id": None} for r in rows], tmp_path / "d.csv")
    assert detect_input_format(bag) == detect_input_format(_single_mcap(bag)) == "ros2-bag"
    want, got = read_detections(ref), read_detections(_single_mcap(bag))
    assert got.column("row").to_pylist() == list(range(len(rows)))
    for c in ("frame", "object_id", "class", "score"):
        assert got.column(c).to_pylist() == want.column(c).to_pylist(), c
    for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px"):
        np.testing.assert_allclose(got.column(c).to_numpy(), want.column(c).to_numpy(), rtol=1e-12, atol=1e-9)
    err = got.column("error").to_pylist()
    assert "bbox.center.theta" in err[5] and err[:5] + err[6:] == [None] * (len(rows) - 1)
    process_file(cam, BUDGET, ref, tmp_path / "csv.parquet", progress=False)
    process_file(cam, BUDGET, bag, tmp_path / "bag.parquet", progress=False, chunk_rows=4)
    a, b = pq.read_table(tmp_path / "csv.parquet").to_pylist(), pq.read_table(tmp_path / "bag.parquet").to_pylist()
    assert len(a) == len(b) == len(rows)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert (y["row"], y["frame"], y["object_id"], y["class"]) == (i, x["frame"], x["object_id"], x["class"])
        if i == 5:
            assert y["status"] == "error" and "bbox.center.theta" in y["reason"]
            continue
        assert y["status"] == x["status"]
        for k in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2"):
            np.testing.assert_allclose(y[k], x[k], rtol=1e-12, atol=1e-12, equal_nan=True)
    ids = bag_in(tmp_path / "ids_bag", [{**r, "class": ["2", "0", "95"][i % 3]} for i, r in enumerate(rows[:6])])
    named = read_detections(ids, class_names="coco")
    assert named.column("class").to_pylist() == ["car", "person", "95"] * 2
    assert named.column("error").to_pylist()[2] == "class id 95 is not in the names map (coco, 80 names)"
    with pytest.raises(InputError, match="^topic"):
        read_detections(bag, topic="/yolo/detections")
    with pytest.raises(InputError, match="CameraInfo: got '1920 x 1080 px'"):
        read_detections(bag, image_size_px=(1280, 720))


def test_the_registry_imports_the_bag_reader_only_to_read_a_bag(tmp_path):
    """batch/ does not import integrations/: detecting a bag leaves it unimported, reading one imports it."""
    import subprocess
    import sys

    bag = bag_in(tmp_path / "b", good_rows()[:7])
    code = ("import sys; from footprint_uq.batch.formats import detect_input_format, read_detections\n"
            f"assert detect_input_format({str(bag)!r}) == 'ros2-bag'\n"
            "assert not [m for m in sys.modules if m.startswith('footprint_uq.integrations')]\n"
            f"assert read_detections({str(bag)!r}).num_rows == 7\n"
            "assert 'footprint_uq.integrations.ros2.bag_reader' in sys.modules\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


def test_cli_validate_pairs_a_bag_with_a_truth_table(tmp_path, cam):
    """validate --detections bag.mcap: the bag's detections paired with a truth table by frame and object_id."""
    rows = good_rows()
    bag = _single_mcap(bag_in(tmp_path / "in_bag", rows))
    ref = write_csv([{**r, "camera_id": None} for r in rows], tmp_path / "d.csv")
    process_file(cam, BUDGET, ref, tmp_path / "csv.parquet", progress=False)
    ok = [r for r in pq.read_table(tmp_path / "csv.parquet").to_pylist() if r["status"] == "ok"]
    (tmp_path / "truth.csv").write_text("frame,object_id,x_m,y_m\n" + "".join(
        f"{r['frame']},{r['object_id']},{r['x_m']!r},{r['y_m']!r}\n" for r in ok))
    save_camera(cam, tmp_path / "cam.yaml")
    r = CliRunner().invoke(main, ["validate", "--labels", str(tmp_path / "truth.csv"), "--detections", str(bag),
                                  "--camera", str(tmp_path / "cam.yaml"), "--budget", BUDGET, "--out",
                                  str(tmp_path / "val"), "--no-report", "--no-fsync"])
    assert r.exit_code == 0, r.output
    summary = json.loads((tmp_path / "val" / "summary.json").read_text())
    assert summary["n_pairs"] == len(ok) and summary["unpaired"]["truth_without_detection"] == 0
    objects = list(csv.DictReader(open(tmp_path / "val" / "objects.csv")))
    assert max(float(o["error_m"]) for o in objects if o["status"] == "ok") < 1e-9


def test_bag_without_the_topic_names_its_topics(tmp_path):
    bag = bag_in(tmp_path / "b", good_rows()[:7])
    with pytest.raises(InputError) as e:
        BagDetectionReader(bag, topic="/yolo/detections")
    msg = str(e.value)
    assert "/yolo/detections" in msg and "/detector/detections (vision_msgs/msg/Detection2DArray)" in msg
    assert "/camera/camera_info (sensor_msgs/msg/CameraInfo)" in msg and "\n" not in msg


# -- the command line ---------------------------------------------------------------------------------------------
def _objects(*args):
    return CliRunner().invoke(main, ["objects", "--budget", BUDGET, "--quiet", *map(str, args)])


def test_cli_bag_in_mcap_out_with_foxglove(tmp_path):
    bag = bag_in(tmp_path / "in_bag", good_rows())
    out = tmp_path / "run.mcap"
    r = _objects("--detections", bag, "--out", out, "--foxglove", "--height-m", 8, "--pan-deg", 30, "--tilt-deg", 20)
    assert r.exit_code == 0, r.output
    js = json.loads(summary_path(out).read_text())
    assert js["bag"]["frames"] == 6 and js["bag"]["topics"][-1] == "/footprints/scene"
    assert js["camera"].endswith("(CameraInfo)") and js["format_in"] == "rosbag"
    assert not list(tmp_path.glob(".*"))  # no temporary left


def test_cli_bag_in_with_class_names(tmp_path):
    """objects --detections bag --class-names coco --unknown-class unknown: the bag's integer class ids named (an id
    without a name: the class 'unknown'); --format other than ros2-bag with a bag: one line, exit 2."""
    rows = [{**r, "class": ["2", "0", "95"][i % 3]} for i, r in enumerate(good_rows()[:6])]
    bag = bag_in(tmp_path / "in_bag", rows)
    pose = ["--height-m", 8, "--pan-deg", 30, "--tilt-deg", 20]
    r = _objects("--detections", bag, "--out", tmp_path / "o.csv", "--format", "ros2-bag", "--class-names", "coco",
                 "--unknown-class", "unknown", *pose)
    assert r.exit_code == 0, r.output
    got = list(csv.DictReader(open(tmp_path / "o.csv")))
    assert [g["class"] for g in got] == ["car", "person", "unknown"] * 2
    r = _objects("--detections", bag, "--out", tmp_path / "p.csv", "--format", "coco", *pose)
    assert r.exit_code == 2 and "--format" in r.output and len(r.output.strip().splitlines()) == 1


@pytest.mark.parametrize("args, field", [
    (["--topic", "/nope"], "topic"),
    (["--camera", "CAMFILE"], "--camera"),  # 1280 x 720 camera, 1920 x 1080 CameraInfo
])
def test_cli_bad_bag_input_is_one_line_exit_2(tmp_path, cam, args, field):
    bag = bag_in(tmp_path / "in_bag", good_rows()[:7])
    small = PanTiltCamera(focal_px=1000.0, image_size_px=(1280, 720), **POSE)
    save_camera(small, tmp_path / "cam.yaml")
    args = [str(tmp_path / "cam.yaml") if a == "CAMFILE" else a for a in args]
    r = _objects("--detections", bag, "--out", tmp_path / "o.parquet", *args, "--height-m", 8, "--pan-deg", 30,
                 "--tilt-deg", 20) if "--camera" not in args else \
        _objects("--detections", bag, "--out", tmp_path / "o.parquet", *args)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output


def test_cli_bag_folder_out_refuses_a_folder_of_other_files(tmp_path, cam):
    save_camera(cam, tmp_path / "cam.yaml")
    src = write_csv(detections(), tmp_path / "d.csv")
    other = tmp_path / "results"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    r = _objects("--camera", tmp_path / "cam.yaml", "--detections", src, "--out", f"{other}/")
    assert r.exit_code == 2 and "holds other files" in r.output
    assert (other / "notes.txt").read_text() == "mine"
    r = _objects("--camera", tmp_path / "cam.yaml", "--detections", src, "--out", tmp_path / "o.parquet", "--foxglove")
    assert r.exit_code == 2 and "--foxglove" in r.output


def test_cli_bag_folder_replaces_a_bag(tmp_path, cam):
    save_camera(cam, tmp_path / "cam.yaml")
    src = write_csv(detections(), tmp_path / "d.csv")
    for storage in ("mcap", "sqlite3"):
        r = _objects("--camera", tmp_path / "cam.yaml", "--detections", src, "--out", f"{tmp_path / 'bag'}/",
                     "--bag-storage", storage, "--frame-id", "odom")
        assert r.exit_code == 0, r.output
        files = sorted(p.name for p in (tmp_path / "bag").iterdir())
        assert files == ["bag.db3" if storage == "sqlite3" else "bag.mcap", "metadata.yaml"]
    msgs = read_bag(tmp_path / "bag")
    assert msgs["/footprints/detections"][0][1].header.frame_id == "odom"


def test_a_killed_runs_staging_is_cleaned(tmp_path, cam):
    """What a killed run left (a hidden staging folder of the bag folder, a temporary of the MCAP file) is removed by
    the next run on the same output; other hidden files are not touched."""
    save_camera(cam, tmp_path / "cam.yaml")
    src = write_csv(detections(), tmp_path / "d.csv")
    (tmp_path / ".bag.tmp-0123abcd" / "bag").mkdir(parents=True)
    (tmp_path / ".bag.tmp-0123abcd" / "bag" / "bag.mcap").write_bytes(b"partial")
    (tmp_path / ".run.tmp-0123abcd.mcap").write_bytes(b"partial")
    (tmp_path / ".keep").write_text("mine")
    for out in (f"{tmp_path / 'bag'}/", tmp_path / "run.mcap"):
        r = _objects("--camera", tmp_path / "cam.yaml", "--detections", src, "--out", out)
        assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob(".*")) == [".keep"]


def test_writer_abort_leaves_nothing(tmp_path, cam):
    from footprint_uq.batch.process import BatchProcessor

    bp = BatchProcessor(cam, BUDGET)
    schema = bp.resolve(["timestamp_s", "u_min_px", "v_min_px", "u_max_px", "v_max_px"])
    for out in (tmp_path / "a.mcap", Path(f"{tmp_path / 'b'}/")):
        w = RosBagOut(out, schema, BagOptions())
        w.abort()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="frame_id"):
        RosBagOut(tmp_path / "d.mcap", schema, BagOptions(frame_id=" "))
    with pytest.raises(InputError, match="timestamp_s"):
        RosBagOut(tmp_path / "c.mcap", bp.resolve(["u_min_px", "v_min_px", "u_max_px", "v_max_px"]), BagOptions())


# -- pinned values ------------------------------------------------------------------------------------------------
def test_pose_covariance_6x6_pinned():
    c = M.pose_covariance_6x6(np.array([[[0.04, -0.01], [-0.01, 0.09]]]))
    assert c.shape == (1, 36)
    expect = np.zeros(36)
    expect[[0, 1, 6, 7]] = [0.04, -0.01, -0.01, 0.09]
    expect[[14, 21, 28, 35]] = 1e6
    np.testing.assert_array_equal(c[0], expect)


def test_quaternions_pinned():
    np.testing.assert_allclose(M.yaw_quaternion(np.pi / 2), [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-15)
    # +x onto +y: a quarter turn about z; onto -z (a camera looking straight down): a quarter turn about +y
    np.testing.assert_allclose(quaternion_x_to([0, 2, 0]), [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(quaternion_x_to([0, 0, -1]), [0, np.sqrt(0.5), 0, np.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(quaternion_x_to([-1, 0, 0]), [0, 0, 1, 0], atol=1e-15)


# -- serve --output rosbag:PATH -----------------------------------------------------------------------------------
def _serve(cam, frames: list[dict], output: str) -> tuple[int, list[dict]]:
    import io

    import orjson

    from footprint_uq.service.core import Service
    from footprint_uq.service.runner import serve

    stdin = io.BytesIO(b"".join(orjson.dumps(f) + b"\n" for f in frames))
    stdout = io.BytesIO()
    rc = serve(Service(cam, BUDGET), input="-", output=output, stdin=stdin, stdout=stdout, install_signals=False,
               health_interval_s=0)
    return rc, [orjson.loads(ln) for ln in stdout.getvalue().splitlines()]


@pytest.mark.parametrize("name", ["live.mcap", "live_bag/"])
def test_serve_records_the_footprints_into_a_bag(cam, tmp_path, name):
    rows = good_rows()
    frames = []
    for fr in range(4):
        dets = [{k: r[k] for k in ("object_id", "class", "u_min_px", "v_min_px", "u_max_px", "v_max_px")}
                for r in rows if r["frame"] == fr]
        frames.append({"camera_id": "cam1", "frame": fr, "timestamp_s": T0 + fr / 30.0, "detections": dets})
    frames.insert(2, {"camera_id": "cam1", "frame": 9, "timestamp_s": "late"})  # an error record: on stdout
    rc, records = _serve(cam, frames, "-")
    assert rc == 0
    out = tmp_path / name
    rc, rest = _serve(cam, frames, f"rosbag:{out}")
    assert rc == 0 and [r["type"] for r in rest] == ["error", "health"]
    foot = [r for r in records if r["type"] == "footprints"]
    msgs = read_bag(Path(str(out).rstrip("/")))
    dets = msgs["/footprints/detections"]
    assert len(dets) == len(foot) == 4
    for (t, arr), rec in zip(dets, foot, strict=True):
        ok = [o for o in rec["objects"] if o.get("status", "ok") == "ok"]
        assert t == round(rec["timestamp_s"] * 1e9) and len(arr.detections) == len(ok)
        for d, o in zip(arr.detections, ok, strict=True):
            c = np.asarray(d.results[0].pose.covariance).reshape(6, 6)
            np.testing.assert_array_equal(c[:2, :2], o["cov_m2"])
            assert d.id == str(o["object_id"]) and d.results[0].pose.pose.position.x == o["x_m"]
    assert not list(tmp_path.glob(".*"))


def test_serve_rosbag_output_refuses_a_folder_of_other_files(cam, tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match="holds other files"):
        _serve(cam, [], f"rosbag:{tmp_path / 'x'}/")
    assert (tmp_path / "x" / "keep.txt").exists()


def test_the_documented_example_runs(tmp_path, monkeypatch):
    """docs/integrations.md's copy-paste example of "ROS 2 bags and Foxglove", as written, from the repository's
    root."""
    import re
    import shlex

    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "integrations.md").read_text().split("\n## ROS 2 bags and Foxglove\n", 1)[1]
    cmd = re.search(r"```sh\n(footprint-uq objects .*?)\n```", text, re.S).group(1).replace("\\\n", " ")
    argv = shlex.split(cmd)
    assert argv[:2] == ["footprint-uq", "objects"]
    monkeypatch.chdir(root)
    out = tmp_path / "run.mcap"
    argv = [str(out) if a == "run.mcap" else a for a in argv]
    r = CliRunner().invoke(main, argv[1:] + ["--quiet"])
    assert r.exit_code == 0, r.output
    assert json.loads(summary_path(out).read_text())["bag"]["messages"] == {
        "/footprints/detections": 2, "/footprints/ellipses": 2, "/footprints/scene": 2}


def test_without_the_ros_extra_one_line_names_it(tmp_path, monkeypatch, cam):
    """rosbags / mcap / foxglove-sdk missing: a ConfigError naming the extra (the CLI's one line, exit 2)."""
    import sys

    from footprint_uq.errors import ConfigError
    from footprint_uq.integrations.ros2 import foxglove_scene, types

    monkeypatch.setitem(sys.modules, "rosbags.typesys", None)
    types.typestore.cache_clear()
    try:
        with pytest.raises(ConfigError, match=r"footprint-uq\[ros\]"):
            types.typestore()
        save_camera(cam, tmp_path / "cam.yaml")
        src = write_csv(detections(), tmp_path / "d.csv")
        r = _objects("--camera", tmp_path / "cam.yaml", "--detections", src, "--out", tmp_path / "o.mcap")
        assert r.exit_code == 2 and r.output.count("\n") == 1 and "footprint-uq[ros]" in r.output
        assert not list(tmp_path.glob("*.mcap*")) and not list(tmp_path.glob(".*"))
    finally:
        types.typestore.cache_clear()
    monkeypatch.setitem(sys.modules, "foxglove", None)
    foxglove_scene._fm.cache_clear()
    try:
        with pytest.raises(ConfigError, match=r"footprint-uq\[ros\]"):
            foxglove_scene.scene_schema()
    finally:
        foxglove_scene._fm.cache_clear()


@settings(max_examples=60, deadline=None)
@given(sx=st.floats(1e-3, 30.0), sy=st.floats(1e-3, 30.0), theta=st.floats(-np.pi, np.pi),
       x=st.floats(-1e4, 1e4), y=st.floats(-1e4, 1e4))
def test_markers_and_scene_give_back_the_covariance(sx, sy, theta, x, y):
    """Over SPD covariances of any shape and orientation: the marker's and the Foxglove cylinder's full axes and
    yaw rebuild ``chi2_scale(0.95)^2 cov`` (the 95 % ellipse), and the 6x6 block is ``cov`` itself."""
    from footprint_uq.integrations.ros2.foxglove_scene import scene_update
    from footprint_uq.uncertainty.ellipse import chi2_scale

    c, s = np.cos(theta), np.sin(theta)
    R = np.array([[c, -s], [s, c]])
    cov = R @ np.diag([sx**2, sy**2]) @ R.T
    f = M.FrameFootprints(0, "map", ["a"], ["car"], np.array([0.5]), np.array([[x, y]]), cov[None])
    ts = typestore()
    k2 = chi2_scale(0.95) ** 2

    def rebuilt(half_x, half_y, qz, qw):
        yaw = 2 * np.arctan2(qz, qw)
        Ry = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        return Ry @ np.diag([half_x**2, half_y**2]) @ Ry.T / k2

    m = ts.deserialize_cdr(ts.serialize_cdr(M.ellipse_marker_array(ts, f), "visualization_msgs/msg/MarkerArray"),
                           "visualization_msgs/msg/MarkerArray").markers[1]
    tol = 1e-9 * max(sx, sy) ** 2
    np.testing.assert_allclose(rebuilt(m.scale.x / 2, m.scale.y / 2, m.pose.orientation.z, m.pose.orientation.w),
                               cov, atol=tol)
    assert m.scale.x >= m.scale.y

    upd = _protobuf_dict(_scene_decoder(), scene_update(f).encode())
    cyl = upd["entities"][0]["cylinders"][0]
    q = cyl["pose"].get("orientation", {})
    np.testing.assert_allclose(rebuilt(cyl["size"]["x"] / 2, cyl["size"]["y"] / 2, q.get("z", 0.0), q.get("w", 0.0)),
                               cov, atol=tol)
    d = M.detection3d_array(ts, f).detections[0]
    np.testing.assert_array_equal(np.asarray(d.results[0].pose.covariance).reshape(6, 6)[:2, :2], cov)


#: vision_msgs 3 (ROS 2 Foxy / Galactic), the definitions of its foxy branch (fields only)
FOXY_VISION_MSGS = {
    "Detection2DArray": "std_msgs/Header header\nDetection2D[] detections\n",
    "Detection2D": "std_msgs/Header header\nObjectHypothesisWithPose[] results\nBoundingBox2D bbox\n"
                   "sensor_msgs/Image source_img\nbool is_tracking\nstring tracking_id\n",
    "ObjectHypothesisWithPose": "string id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n",
    "BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
}


def test_bag_in_of_vision_msgs_3(tmp_path, cam):
    """A Foxy-era bag (vision_msgs 3: center.x, results[].id / score, tracking_id) reads as the same rows."""
    ts = get_typestore(Stores.ROS2_FOXY)
    for name, text in FOXY_VISION_MSGS.items():
        ts.register(get_types_from_msg(text, f"vision_msgs/msg/{name}"))
    T = ts.types
    rows = good_rows()[:7]
    w = Writer(tmp_path / "foxy", version=8)
    w.open()
    conn = w.add_connection("/dets", "vision_msgs/msg/Detection2DArray", typestore=ts)
    header = T["std_msgs/msg/Header"](stamp=M.stamp(ts, round(T0 * 1e9)), frame_id="camera")
    dets = []
    for r in rows:
        u0, v0, u1, v1 = (float(r[k]) for k in ("u_min_px", "v_min_px", "u_max_px", "v_max_px"))
        hyp = T["vision_msgs/msg/ObjectHypothesisWithPose"](
            id=r["class"], score=r["score"], pose=default_message(ts, "geometry_msgs/msg/PoseWithCovariance"))
        dets.append(default_message(
            ts, "vision_msgs/msg/Detection2D", header=header, results=[hyp], is_tracking=True,
            tracking_id=r["object_id"], bbox=T["vision_msgs/msg/BoundingBox2D"](
                center=T["geometry_msgs/msg/Pose2D"](x=0.5 * (u0 + u1), y=0.5 * (v0 + v1), theta=0.0),
                size_x=u1 - u0, size_y=v1 - v0)))
    w.write(conn, round(T0 * 1e9), ts.serialize_cdr(T["vision_msgs/msg/Detection2DArray"](header=header,
                                                                                          detections=dets),
                                                    "vision_msgs/msg/Detection2DArray"))
    w.close()
    from footprint_uq.integrations.ros2.bag_reader import read_bag_detections

    t, pre = read_bag_detections(tmp_path / "foxy")
    assert pre is None and t.num_rows == 7
    got = t.to_pylist()
    for g, r in zip(got, rows, strict=True):
        assert (g["object_id"], g["class"], g["score"], g["frame"]) == (r["object_id"], r["class"], r["score"], 0)
        for k in ("u_min_px", "v_min_px", "u_max_px", "v_max_px"):
            assert g[k] == pytest.approx(float(r[k]), abs=1e-9)


def test_frames_without_a_time_are_counted_not_recorded(tmp_path, cam):
    rows = good_rows()
    for r in rows:
        if r["frame"] == 2:
            r["timestamp_s"] = ""  # empty: null
        if r["frame"] == 4:
            r["timestamp_s"] = -1.0
    res = write_bag(tmp_path / "t.mcap", BagOptions(), cam, tmp_path, rows=rows)
    bag = res["summary"].info["bag"]
    assert bag["frames"] == 4 and bag["not_in_bag"] == {"timestamp_s nan is not a time >= 0": 7,
                                                        "timestamp_s -1.0 is not a time >= 0": 7,
                                                        "no centre (status partial or error)": 1}
    stamps = [t for t, _ in read_bag(tmp_path / "t.mcap")["/footprints/detections"]]
    assert stamps == [round((T0 + k / 30.0) * 1e9) for k in (0, 1, 3, 5)]
