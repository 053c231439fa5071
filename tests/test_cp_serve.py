"""``serve --cp-service`` without a broker: the registry's CP columns, the command's bad-input rules (one line, exit 2),
the stdout event records.  The end-to-end test with Mosquitto is tests/test_cp_serve_mqtt.py."""

from __future__ import annotations

import pytest

from footprint_uq.errors import ConfigError
from footprint_uq.io import save_camera
from footprint_uq.io.registry import load_registry
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
    reg = _registry(tmp_path, camera_files, "camera_id,camera,budget,sensor_id,clock_offset_sigma_s,clock_jitter_sigma_s",
                    [f"n,{camera_files[0]},basler1@deg,7,0.004,0.001", f"w,{camera_files[1]},basler1@deg,,,"])
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
