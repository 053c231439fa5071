"""``serve --cp-service`` without a broker: the registry's CP columns, the command's bad-input rules (one line, exit 2),
the stdout event records.  The end-to-end test with Mosquitto is tests/test_cp_serve_mqtt.py."""

from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

import numpy as np
import orjson
import pytest

from cp_traffic import T0, frames, write_site
from footprint_uq.errors import ConfigError
from footprint_uq.io import save_camera
from footprint_uq.io.registry import load_registry
from footprint_uq.service.cp_serve import RECORD_CP_EVENT
from footprint_uq.service.messages.cpm import decode_cpm_uper
from footprint_uq.tracking.rsu_synthetic import intersection_cameras


@pytest.fixture(scope="module")
def camera_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cams")
    paths = []
    for k, cam in enumerate(intersection_cameras()):
        p = d / f"cam{k}.yaml"
        save_camera(cam, p)
        paths.append(p)
    return paths


def _registry(tmp_path, camera_files, header: str, rows: list[str], name: str = "reg.csv"):
    p = tmp_path / name
    p.write_text(header + "\n" + "\n".join(rows) + "\n")
    return p


def test_registry_cp_columns_are_read_and_default(tmp_path, camera_files):
    header = "camera_id,camera,budget,sensor_id,clock_offset_sigma_s,clock_jitter_sigma_s"
    reg = _registry(tmp_path, camera_files, header, [f"n,{camera_files[0]},basler1@deg,7,0.004,0.001",
                                                     f"w,{camera_files[1]},basler1@deg,,,"])
    e = load_registry(reg)
    assert (e["n"].sensor_id, e["n"].clock_offset_sigma_s, e["n"].clock_jitter_sigma_s) == (7, 0.004, 0.001)
    assert (e["w"].sensor_id, e["w"].clock_offset_sigma_s, e["w"].clock_jitter_sigma_s) == (None, 0.0, 0.0)
    y = tmp_path / "reg.yaml"
    y.write_text(f"cameras:\n  - camera_id: a\n    camera: {camera_files[0]}\n    budget: basler1\n    sensor_id: 0\n"
                 f"    clock_offset_sigma_s: 0.01\n")
    a = load_registry(y)["a"]
    assert a.sensor_id == 0 and a.clock_offset_sigma_s == 0.01


@pytest.mark.parametrize("column,value,expected", [
    ("sensor_id", "256", "0..255"), ("sensor_id", "-1", "0..255"), ("sensor_id", "2.5", "0..255"),
    ("sensor_id", "x", "0..255"), ("clock_offset_sigma_s", "-0.1", ">= 0"), ("clock_offset_sigma_s", "nan", ">= 0"),
    ("clock_jitter_sigma_s", "inf", ">= 0"), ("clock_jitter_sigma_s", "fast", ">= 0")])
def test_registry_bad_cp_values_name_the_line_field_and_value(tmp_path, camera_files, column, value, expected):
    reg = _registry(tmp_path, camera_files, f"camera_id,camera,budget,{column}", [f"a,{camera_files[0]},basler1,1",
                                                                                  f"b,{camera_files[1]},basler1,{value}"])
    with pytest.raises(ConfigError) as e:
        load_registry(reg)
    msg = str(e.value)
    assert "line 3" in msg and column in msg and value in msg and expected in msg and "\n" not in msg


def test_registry_repeated_sensor_id_is_refused(tmp_path, camera_files):
    reg = _registry(tmp_path, camera_files, "camera_id,camera,budget,sensor_id",
                    [f"a,{camera_files[0]},basler1,4", f"b,{camera_files[1]},basler1,4"])
    with pytest.raises(ConfigError, match=r"line 3: sensor_id.*4.*no other camera"):
        load_registry(reg)


# -- the command: bad input, one line, exit 2 -----------------------------------------------------------------------
def _cli(args, input_bytes=b""):
    from click.testing import CliRunner

    from footprint_uq.cli.main import main

    return CliRunner().invoke(main, ["serve", *args], input=input_bytes)


@pytest.fixture
def site(tmp_path):
    write_site(tmp_path)
    return tmp_path


_REG = ["--registry", "registry.csv", "--input", "-"]


@pytest.mark.parametrize("args,words", [
    ([*_REG, "--cp-service"], "--tracks"),
    ([*_REG, "--tracks", "--t-gen-cpm-ms", "200"], "--cp-service too"),
    ([*_REG, "--tracks", "--no-per-camera-output"], "--cp-service too"),
    ([*_REG, "--tracks", "--cp-service", "--t-gen-cpm-ms", "50"], "--t-gen-cpm-ms"),
    ([*_REG, "--tracks", "--cp-service", "--t-gen-cpm-ms", "1001"], "--t-gen-cpm-ms"),
    ([*_REG, "--tracks", "--cp-service", "--region-max-semi-major-m", "nan"], "--region-max-semi-major-m"),
    ([*_REG, "--tracks", "--cp-service", "--region-max-semi-major-m", "0"], "--region-max-semi-major-m"),
    ([*_REG, "--tracks", "--cp-service", "--cpm-max-bytes", "10"], "--cpm-max-bytes"),
    ([*_REG, "--tracks", "--cp-service", "--cpm-max-bytes", "150"], "Sensor Information"),  # one camera + object: 213 B
    (["--registry", "registry.csv", "--mqtt", "mqtt://127.0.0.1:9", "--tracks", "--cp-service", "--workers", "2"],
     "--workers"),
    (["--registry", "nopose.csv", "--input", "-", "--tracks", "--cp-service"], "pose"),
    (["--registry", "rsu.csv", "--input", "-", "--tracks", "--cp-service"], "camera_id"),
    (["--registry", "tilted.csv", "--input", "-", "--tracks", "--cp-service"], "heading_offset_deg"),
])
def test_cp_service_bad_options_exit_2_with_one_line(site, monkeypatch, args, words):
    monkeypatch.chdir(site)
    (site / "intrinsics.yaml").write_text("model: opencv\nK: [[1000, 0, 960], [0, 1000, 540], [0, 0, 1]]\n"
                                          "image_size_px: [1920, 1080]\n")  # no pose (R, t)
    (site / "nopose.csv").write_text("camera_id,camera,budget\ncam0,cam0.yaml,basler1\ncam9,intrinsics.yaml,basler1\n")
    (site / "rsu.csv").write_text("camera_id,camera,budget\nrsu,cam0.yaml,basler1\n")
    (site / "tilted.csv").write_text("camera_id,camera,budget,heading_offset_deg\ncam0,cam0.yaml,basler1,12\n")
    r = _cli(args)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.startswith("footprint-uq: error")]
    assert len(lines) == 1 and words in lines[0], r.output
    assert "Traceback" not in r.output


# -- the command on stdin: events, rules, bad frames -----------------------------------------------------------------
def _serve_stdin(site, frames_, *extra):
    data = b"".join(orjson.dumps(f) + b"\n" for f in frames_)
    r = _cli(["--registry", str(site / "registry.csv"), "--input", "-", "--tracks", "--cp-service",
              "--health-interval-s", "0", *extra], data)
    assert r.exit_code == 0, r.output
    return [orjson.loads(ln) for ln in r.stdout_bytes.splitlines() if ln.startswith(b"{")]


def _segments_ok(ev: dict) -> None:
    """The event's CPM segments (hex) decode; every object the record says is sent is in exactly the segment it
    names, and no other object is; the segments' numbering."""
    where = {}
    n = len(ev["cpm_uper_hex"])
    for k, hx in enumerate(ev["cpm_uper_hex"]):
        cpm = decode_cpm_uper(hx)
        assert cpm["payload"]["managementContainer"]["referenceTime"] == ev["reference_time_ms"]
        seg = cpm["payload"]["managementContainer"].get("segmentationInfo")
        assert (seg is None) == (n == 1) and (seg is None or (seg["thisMsgNo"], seg["totalMsgNo"]) == (k + 1, n))
        for c in cpm["payload"]["cpmContainers"]:
            if c["containerId"] == 5:
                for o in c["containerData"]["perceivedObjects"]:
                    assert o["objectId"] not in where
                    where[o["objectId"]] = k + 1
    assert where == {o["objectId"]: o["segment"] for o in ev["objects"] if o["segment"] is not None}


def test_events_follow_t_gen_cpm_with_sensor_information_every_second(site):
    out = _serve_stdin(site, frames(30), "--t-gen-cpm-ms", "200")
    kinds = Counter(r["type"] for r in out)
    assert kinds["footprints"] == 90 and kinds["error"] == 0  # the per-camera records stay (a debugging output)
    ev = [r for r in out if r["type"] == RECORD_CP_EVENT]
    t = np.array([e["time_s"] for e in ev]) - T0
    # 3 s of data at T_GenCpm = 200 ms: 15 events, each at the first frame (10 Hz) at or after its point of the grid
    assert len(ev) == 15 and np.all((np.diff(t) > 0.2 - 1e-6) & (np.diff(t) < 0.3 + 1e-6))
    info = [e["time_s"] for e in ev if e["sensor_information"]]
    # at the first event once 1 s has passed since the last Sensor Information (events fall on frames)
    gaps = np.diff(info)
    assert info[0] == ev[0]["time_s"] and len(info) >= 3 and np.all((gaps > 1.0 - 1e-6) & (gaps < 1.3 + 1e-6))
    for a, b in zip(info, info[1:], strict=False):
        assert not any(e["sensor_information"] for e in ev if a < e["time_s"] < b)
        assert b == min(e["time_s"] for e in ev if e["time_s"] - a > 1.0 - 1e-6)
    for e in ev:
        _segments_ok(e)
        first = decode_cpm_uper(e["cpm_uper_hex"][0]) if e["cpm_uper_hex"] else None
        has_info = first is not None and any(c["containerId"] == 3 for c in first["payload"]["cpmContainers"])
        assert has_info == e["sensor_information"]
    # the parked car (truth id 100 at (3, -12)): new at the first event, then not due until 1 s has passed
    parked = [(e["time_s"] - T0, o["reason"], o["segment"]) for e in ev for o in e["objects"]
              if np.hypot(o["xy_m"][0] - 3, o["xy_m"][1] + 12) < 1.5]
    assert parked[0] == (0.0, "new", 1) and all(r == "not_due" and s is None for t, r, s in parked if 0 < t < 1 - 1e-6)
    assert next(r for t, r, s in parked if t > 1 - 1e-6) == "interval"
    # every object the record says is not sent is in no segment, and every included one in one
    assert all((o["segment"] is None) == (o["reason"] in ("not_due", "not_sent")) for e in ev for o in e["objects"])
    health = _serve_stdin(site, frames(5), "--no-per-camera-output")
    assert Counter(r["type"] for r in health) == {RECORD_CP_EVENT: 5, "health": 1}
    cp = health[-1]["cp_service"]
    assert cp["events"] == 5 and cp["frames_ingested"] == 15 and cp["internal_errors"] == 0 and cp["cpms"] == sum(
        len(r["cpm_uper_hex"]) for r in health[:-1])


def test_clock_backwards_late_and_dropped_frames_are_reported_never_reordered(site):
    fr = frames(40, skip={(10, 2), (11, 2), (12, 2), (13, 2)} | {(k, 2) for k in range(20, 31)})
    by = {(f["frame"], f["camera_id"]): f for f in frames(40)}
    out_frames = []
    for f in fr:
        out_frames.append(f)
        if (f["frame"], f["camera_id"]) == (13, "cam1"):
            out_frames.append(by[(10, "cam2")])           # 0.3 s late: fused as late data
        if (f["frame"], f["camera_id"]) == (16, "cam1"):
            out_frames.append(by[(15, "cam1")])           # cam1's clock goes back 0.1 s
        if (f["frame"], f["camera_id"]) == (30, "cam1"):
            out_frames.append(by[(20, "cam2")])           # 1 s late: dropped, counted
    out = _serve_stdin(site, out_frames, "--no-per-camera-output")
    errors = [r for r in out if r["type"] == "error"]
    assert [(e["camera_id"], e["frame"], e["field"], e["source"]) for e in errors] == [
        ("cam1", 15, "timestamp_s", "cp-service"), ("cam2", 20, "timestamp_s", "cp-service")]
    assert "earlier than its previous frame" in errors[0]["reason"] and "dropped" in errors[1]["reason"]
    cp = out[-1]["cp_service"]
    # (stdin frames are served in the order they were read: the one late frame is (10, cam2))
    assert (cp["frames_clock_backwards"], cp["frames_dropped_late"], cp["frames_late"]) == (1, 1, 1)
    assert cp["frame_errors"] == 2 and cp["frames_ingested"] == len(out_frames) == sum(
        cp[f"frames_{k}"] for k in ("ok", "late", "dropped_late", "clock_backwards"))
    ev = [r for r in out if r["type"] == RECORD_CP_EVENT]
    assert sum(e["counts"]["dropped"] for e in ev) == 1 and sum(e["counts"]["clock_backwards"] for e in ev) == 1
    # cam1's tracks were kept: the objects keep their ids across the backwards frame, and no duplicate appears
    # (at 1.5 s, not earlier: cam2's objects are listed again once its frame 14 is fused, report_timeout_s after
    # its last frame 10; the event at 1.4 s comes with cam0's frame 14, before cam2's)
    ids = [sorted(o["objectId"] for o in e["objects"]) for e in ev]
    k = int(np.argmin(np.abs(np.array([e["time_s"] for e in ev]) - (T0 + 1.6))))
    assert len(ids[k - 2]) == 4 and ids[k - 1] == ids[k + 3] and len(ids[k + 3]) == len(set(ids[k + 3])) == 6
    t = [e["time_s"] for e in ev]
    assert t == sorted(t)


def test_more_than_255_objects_are_all_sent_in_segments_and_counted(tmp_path):
    cam = intersection_cameras()[0]
    save_camera(cam, tmp_path / "cam.yaml")
    u, v = np.meshgrid(np.linspace(200, 1700, 20), np.linspace(600, 1050, 15))
    dets = [{"object_id": i, "class": "car", "u0_px": float(a), "v0_px": float(b)}
            for i, (a, b) in enumerate(zip(u.ravel(), v.ravel(), strict=True))]
    fr = [{"camera_id": "c", "frame": k, "timestamp_s": T0 + 0.1 * k, "detections": dets} for k in range(2)]
    data = b"".join(orjson.dumps(f) + b"\n" for f in fr)
    r = _cli(["--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg", "--input", "-", "--tracks",
              "--cp-service", "--no-per-camera-output", "--health-interval-s", "0"], data)
    assert r.exit_code == 0, r.output
    out = [orjson.loads(ln) for ln in r.stdout_bytes.splitlines()]
    ev = out[0]
    assert ev["type"] == RECORD_CP_EVENT and len(ev["objects"]) == 300
    assert ev["counts"]["sent"] == 300 and ev["counts"]["not_sent"] == 0 and 2 <= ev["counts"]["segments"] <= 8
    assert all(len(bytes.fromhex(h)) <= 1100 for h in ev["cpm_uper_hex"])
    _segments_ok(ev)
    assert len(ev["sdsm"]["objects"]) == 255 and ev["counts"]["sdsm_not_sent"] == 45
    ev = [r for r in out if r["type"] == RECORD_CP_EVENT]
    cp = out[-1]["cp_service"]
    assert len(ev) == 2 and cp["sdsm_not_sent"] == 90 and cp["sent"] == sum(e["counts"]["sent"] for e in ev)
    assert cp["cpms"] == sum(len(e["cpm_uper_hex"]) for e in ev)


# -- docs/service.md: the decoded CPM is one the service wrote ------------------------------------------------------
DOC = Path(__file__).resolve().parents[1] / "docs" / "service.md"
DOC_MARK = "<!-- generated by tests/test_cp_serve.py::test_docs_cpm_example_is_a_real_cpm_of_the_service -->"


def _compact(v, indent: int = 0, width: int = 118, lead: int = 0) -> str:
    """JSON text of ``v`` (its first line starts ``lead`` characters after ``indent``): a value whose one-line form
    fits stays on one line; a list of such values is packed several to a line; other containers break one entry per
    line, one space of indent per level."""
    one = json.dumps(v, separators=(", ", ": "))
    if indent + lead + len(one) <= width or not isinstance(v, (dict, list)):
        return one
    inner = " " * (indent + 1)
    if isinstance(v, dict):
        parts = [f"{inner}{json.dumps(k)}: " + _compact(x, indent + 1, width, len(json.dumps(k)) + 2)
                 for k, x in v.items()]
        return "{\n" + ",\n".join(parts) + "}"
    lines, cur = [], ""
    for it in (_compact(x, indent + 1, width) for x in v):
        if "\n" in it or (cur and indent + 1 + len(cur) + 2 + len(it) > width):
            if cur:
                lines.append(cur)
            cur = it
        else:
            cur = f"{cur}, {it}" if cur else it
    lines.append(cur)
    return "[" + (",\n" + inner).join(lines) + "]"


def doc_cpm_example(site) -> tuple[str, dict]:
    """The decoded first segment of the first event after 1 s that carries the Sensor Information (3 cameras of the
    intersection, 2 s of tests/cp_traffic.py frames, origin 42.2808 N 83.7430 W), and that event's record."""
    out = _serve_stdin(site, frames(20), "--no-per-camera-output", "--origin-lat", "42.2808", "--origin-lon",
                       "-83.7430")
    ev = next(r for r in out if r["type"] == RECORD_CP_EVENT and r["sensor_information"] and r["time_s"] > T0 + 0.5)
    return _compact(decode_cpm_uper(ev["cpm_uper_hex"][0])), ev


def test_docs_cpm_example_is_a_real_cpm_of_the_service(site):
    """The decoded CPM in docs/service.md is the service's (FOOTPRINT_UQ_WRITE_DOCS=1 writes it there)."""
    text, ev = doc_cpm_example(site)
    page = DOC.read_text(encoding="utf-8")
    i = page.index(DOC_MARK)
    start = page.index("```json\n", i) + len("```json\n")
    end = page.index("```", start)
    if os.environ.get("FOOTPRINT_UQ_WRITE_DOCS") == "1":
        DOC.write_text(page[:start] + text + "\n" + page[end:], encoding="utf-8")
        page = DOC.read_text(encoding="utf-8")
    assert page[start:page.index("```", start)] == text + "\n"
    assert json.loads(text)["payload"]["managementContainer"]["referenceTime"] == ev["reference_time_ms"]
    # what the page says of it
    assert ev["time_s"] == pytest.approx(T0 + 1.0) and ev["counts"]["perceived"] == 6 and ev["counts"]["sent"] == 6
    assert [o["reason"] for o in ev["objects"] if o["class"] == "person"] == ["interval"]


def test_sensor_ids_default_to_the_sorted_index_plus_one_and_never_meet(tmp_path, camera_files):
    from footprint_uq.service.cp_serve import cp_cameras

    reg = _registry(tmp_path, camera_files, "camera_id,camera,budget,sensor_id",
                    [f"z,{camera_files[0]},basler1@deg,", f"a,{camera_files[1]},basler1@deg,",
                     f"m,{camera_files[2]},basler1@deg,9"])
    cams = cp_cameras(load_registry(reg))
    assert [(c.camera_id, c.sensor_id) for c in cams] == [("a", 1), ("m", 9), ("z", 3)]
    assert all(c.region is not None and c.region.max_semi_major_inside_m <= 1.0 for c in cams)
    clash = _registry(tmp_path, camera_files, "camera_id,camera,budget,sensor_id",
                      [f"a,{camera_files[0]},basler1@deg,", f"b,{camera_files[1]},basler1@deg,1"], "clash.csv")
    with pytest.raises(ConfigError, match=r"registry: b: sensor_id.*camera 'a' has it"):
        cp_cameras(load_registry(clash))


def test_a_parked_car_is_sent_once_a_second_whatever_its_fused_speed_noise(site):
    """The parked car of the traffic (fused speed noise of 0.3-1.5 m/s) is included at its first event and then by
    the 1 s rule only: neither the speed nor the heading rule fires on a speed the data cannot tell from zero."""
    out = _serve_stdin(site, frames(50), "--no-per-camera-output")
    evs = [r for r in out if r["type"] == RECORD_CP_EVENT]
    parked = {}
    for e in evs:
        for o in e["objects"]:
            if o["segment"] is not None and np.hypot(o["xy_m"][0] - 3.0, o["xy_m"][1] + 12.0) < 0.5:
                parked.setdefault(o["objectId"], []).append((round(e["time_s"] - T0, 3), o["reason"]))
    (sent,) = parked.values()  # one fused object
    assert [r for _, r in sent] == ["new"] + ["interval"] * (len(sent) - 1)
    assert [t for t, _ in sent] == pytest.approx([0.0, 1.0, 2.0, 3.0, 4.0][:len(sent)]) and len(sent) >= 4
