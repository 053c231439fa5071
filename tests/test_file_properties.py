"""Hypothesis properties of the file readers (issue 11): camera files, budget files, detection rows.

* camera and budget files built from any mix of plausible and hostile values load, or are refused
  with a one-line :class:`~footprint_uq.errors.InputError`; nothing else escapes, and what loads
  gives finite numbers;
* detection files made of any lines (quotes, separators, line breaks, non-UTF-8 bytes, huge
  numbers) keep every physical line as exactly one row, in order.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from footprint_uq.errors import InputError  # noqa: E402

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# -- values: plausible ones and the hostile ones of the issue -------------------------------------
hostile_numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e308, -1e308, 1e200, 5e-324, 10**400, -(10**23), 2**63, True, False]),
    st.integers(min_value=-(10**30), max_value=10**30),
)
hostile_values = st.one_of(hostile_numbers, st.none(), st.text(max_size=12),
                           st.lists(hostile_numbers, max_size=4), st.dictionaries(st.text(max_size=5),
                                                                                   hostile_numbers, max_size=2))


def _maybe(plausible, p_hostile: float = 0.3):
    """A plausible value, or (sometimes) a hostile one."""
    return st.one_of(plausible, hostile_values) if p_hostile else plausible


camera_mappings = st.fixed_dictionaries(
    {"model": st.sampled_from(["pan-tilt", "pan-tilt", "opencv", "fisheye", 5]),
     "image_size_px": _maybe(st.tuples(st.integers(1, 4000), st.integers(1, 3000)).map(list)),
     "focal_px": _maybe(st.floats(100, 5000)),
     "height_m": _maybe(st.floats(0.5, 50)),
     "pan_deg": _maybe(st.floats(-360, 360)),
     "tilt_deg": _maybe(st.floats(-90, 90))},
    optional={"position_m": _maybe(st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)).map(list)),
              "roll_deg": _maybe(st.floats(-180, 180)), "ground_z_m": _maybe(st.floats(-100, 100)),
              "principal_point_px": _maybe(st.tuples(st.floats(0, 4000), st.floats(0, 3000)).map(list)),
              "K": hostile_values, "unknown_key": st.just(1)})

sigma = st.floats(0, 10)
budget_mappings = st.fixed_dictionaries(
    {"name": st.text(max_size=8)},
    optional={"focal_px": _maybe(sigma), "principal_point_px": _maybe(st.tuples(sigma, sigma).map(list)),
              "position_m": _maybe(st.tuples(sigma, sigma).map(list)), "height_m": _maybe(sigma),
              "pan_deg": _maybe(sigma), "tilt_deg": _maybe(sigma), "imaging_px": _maybe(st.tuples(sigma, sigma)
                                                                                        .map(list)),
              "distortion": _maybe(st.lists(sigma, min_size=5, max_size=5)),
              "covariance": st.one_of(hostile_values,
                                      st.fixed_dictionaries({"names": _maybe(st.just(["pan_deg", "tilt_deg"])),
                                                             "matrix": _maybe(st.just([[1e-4, 0], [0, 1e-4]]))}))})


def _dump(data, fmt: str) -> bytes:
    if fmt == "json":
        return json.dumps(data, default=str).encode()
    return yaml.safe_dump(data, default_flow_style=None).encode()


@SETTINGS
@given(camera_mappings, st.sampled_from(["yaml", "json"]))
def test_camera_files_load_or_refuse_in_one_line(tmp_path, d, fmt):
    from footprint_uq.io import load_camera

    p = tmp_path / f"cam.{fmt}"
    p.write_bytes(_dump(d, fmt))
    try:
        cam = load_camera(p)
    except InputError as e:
        assert "\n" not in str(e)
        return
    assert np.all(np.isfinite(cam.params))
    assert all(0 < s <= 1_000_000 for s in cam.image_size_px)


@SETTINGS
@given(budget_mappings, st.sampled_from(["yaml", "json"]))
def test_budget_files_load_or_refuse_in_one_line(tmp_path, d, fmt):
    from footprint_uq.uncertainty.budget import load_budget

    p = tmp_path / f"budget.{fmt}"
    p.write_bytes(_dump(d, fmt))
    try:
        b = load_budget(p)
    except InputError as e:
        assert "\n" not in str(e)
        return
    assert np.all(np.isfinite(b.param_covariance()))
    assert np.all(np.isfinite(b.pixel_covariance()))


def _physical_lines(body: bytes) -> int:
    """Lines ended by LF (CRLF included), plus an unterminated last one."""
    return body.count(b"\n") + (1 if body and not body.endswith(b"\n") else 0)


# -- detection rows ----------------------------------------------------------------------------
HEADER = "frame,object_id,u_min_px,v_min_px,u_max_px,v_max_px"
field_text = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
                       st.sampled_from(['"', '"a', 'a"b', '""', ",", "\r", "1" + "0" * 400, "1e999", "-0", ""]),
                       st.text(max_size=6))
csv_lines = st.one_of(
    st.lists(field_text, min_size=6, max_size=6).map(",".join),       # the right field count (maybe broken)
    st.lists(field_text, min_size=0, max_size=9).map(",".join),       # any field count
)
raw_bytes = st.binary(max_size=20).filter(lambda b: b"\n" not in b)


@SETTINGS
@given(st.lists(st.one_of(csv_lines.map(lambda s: s.encode("utf-8")), raw_bytes), max_size=25),
       st.booleans(), st.booleans(), st.integers(1, 7))
def test_csv_every_physical_line_is_one_row(tmp_path, lines, crlf, final_newline, chunk_rows):
    from footprint_uq.batch.readers import open_detections

    lines = [ln.replace(b"\n", b"") for ln in lines]
    eol = b"\r\n" if crlf else b"\n"
    body = eol.join(lines) + (eol if final_newline and lines else b"")
    p = tmp_path / "d.csv"
    p.write_bytes(HEADER.encode() + b"\n" + body)
    r = open_detections(p, chunk_rows=chunk_rows)
    r.select(("u_min_px", "v_min_px", "u_max_px", "v_max_px"))
    rows = []
    for ch in r:
        assert ch.rows.size == ch.table.num_rows
        rows += ch.rows.tolist() + [m for m, _ in ch.malformed]
    n = _physical_lines(body)
    assert sorted(rows) == list(range(n)) and r.lines == n


json_values = st.one_of(hostile_numbers.filter(lambda v: not (isinstance(v, float) and not math.isfinite(v))),
                        st.text(max_size=5), st.none(), st.lists(st.integers(), max_size=2))
jsonl_lines = st.one_of(
    st.fixed_dictionaries({"frame": json_values, "u_min_px": json_values, "v_min_px": json_values,
                           "u_max_px": json_values, "v_max_px": json_values}).map(json.dumps),
    st.sampled_from(["", "   ", "{", "[1, 2]", "null", '{"frame": 1e23}', "[" * 3000, '{"a": 1} {"b": 2}']),
)


@SETTINGS
@given(st.lists(st.one_of(jsonl_lines.map(str.encode), raw_bytes), max_size=25), st.integers(1, 7))
def test_jsonl_every_physical_line_is_one_row(tmp_path, lines, chunk_rows):
    from footprint_uq.batch.readers import open_detections

    p = tmp_path / "d.jsonl"
    lines = [ln.replace(b"\n", b"") for ln in lines]
    body = b"\n".join(lines) + (b"\n" if lines else b"")
    p.write_bytes(body)
    r = open_detections(p, chunk_rows=chunk_rows)
    r.select(("u_min_px", "v_min_px", "u_max_px", "v_max_px"))
    rows = []
    for ch in r:
        assert ch.rows.size == ch.table.num_rows
        rows += ch.rows.tolist() + [m for m, _ in ch.malformed]
    n = _physical_lines(body)
    assert sorted(rows) == list(range(n)) and r.lines == n
