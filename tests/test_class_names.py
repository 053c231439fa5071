"""The package's one names map of integer class ids (footprint_uq.io.class_names): the built-in maps, every file
layout, the limits, the unknown-id policy.  Its use by the detector formats is tested in tests/test_formats.py,
by the edge service in tests/test_service.py."""

from __future__ import annotations

import json

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import ConfigError, InputError
from footprint_uq.io import class_names as CN
from footprint_uq.io.class_names import (
    COCO80_NAMES,
    COCO91_IDS,
    COCO_NAMES,
    MOT_NAMES,
    ClassNames,
    class_id_of,
    load_class_names,
)


def test_builtin_names():
    assert COCO_NAMES is COCO80_NAMES
    assert len(COCO80_NAMES) == 80 == len(set(COCO80_NAMES)) == len(COCO91_IDS) == len(set(COCO91_IDS))
    assert COCO80_NAMES[2] == "car" and COCO80_NAMES[79] == "toothbrush" and COCO91_IDS[-1] == 90
    assert ClassNames.load("coco").lookup(2) == ("car", None) and len(ClassNames.load("COCO")) == 80
    names = ClassNames.load("coco91")
    assert names.lookup(3) == ("car", None) and names.lookup(90) == ("toothbrush", None)
    assert names.lookup(12) == (None, "class id 12 is not in the names map (coco91, 80 names)")  # one of COCO's gaps
    assert ClassNames.load("mot").lookup(1) == ("pedestrian", None) and ClassNames.load("mot").names == MOT_NAMES
    assert ClassNames.load(["a", "b"]).lookup(1) == ("b", None)
    assert ClassNames.load({"7": "tram", 8: " bus "}).names == {7: "tram", 8: "bus"}


def test_unknown_id_policy():
    err = ClassNames.load("coco")
    unk = load_class_names("coco", unknown="unknown")
    assert err.name_of(80) is None and err.lookup(80)[1] == "class id 80 is not in the names map (coco, 80 names)"
    assert unk.name_of(80) == "unknown" and unk.lookup(80) == ("unknown", None) and unk.name_of(2) == "car"
    assert ClassNames.load(unk).unknown == "unknown" and ClassNames.load(unk, unknown="error").name_of(80) is None
    with pytest.raises(InputError, match="^unknown_class"):
        ClassNames.load("coco", unknown="skip")


def test_class_id_of():
    assert [class_id_of(v) for v in (2, 2.0, True, "2", 2.5, float("nan"), None)] == [2, 2, None, None, None, None,
                                                                                       None]


def test_names_files(tmp_path):
    """An ultralytics data.yaml (list or mapping), a bare YAML list, JSON (list, mapping, {names}, COCO dataset with
    its images), one name per line (trailing blank lines ignored, a BOM too)."""
    files = {"data.yaml": "path: x\nnames:\n  0: car\n  3: Pedestrian\n", "list.yaml": "names: [car, person]\n",
             "bare.yml": "- car\n- person\n", "n.json": '["truck", "bus"]', "m.json": '{"0": "truck", "5": "bus"}',
             "nm.json": '{"names": {"1": "car"}}', "obj.names": "\ufeffcar\nperson\n\n",
             "coco.json": json.dumps({"categories": [{"id": 3, "name": "car"}, {"id": 1, "name": "person"}],
                                      "images": [{"id": 7, "file_name": "a.jpg", "width": 1920, "height": 1080}]})}
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    got = {name: load_class_names(tmp_path / name).names for name in files}
    assert got == {"data.yaml": {0: "car", 3: "Pedestrian"}, "list.yaml": {0: "car", 1: "person"},
                   "bare.yml": {0: "car", 1: "person"}, "n.json": {0: "truck", 1: "bus"},
                   "m.json": {0: "truck", 5: "bus"}, "nm.json": {1: "car"}, "obj.names": {0: "car", 1: "person"},
                   "coco.json": {3: "car", 1: "person"}}
    coco = ClassNames.load(str(tmp_path / "coco.json"))
    assert coco.images[0]["file_name"] == "a.jpg" and coco.source == str(tmp_path / "coco.json")


@pytest.mark.parametrize("name, text, field", [
    ("gap.names", "car\n\nperson\n", "line 2"),
    ("neg.yaml", "names: {-1: car}\n", "names"),
    ("float.yaml", "names: {1.5: car}\n", "names"),
    ("empty.txt", "", "at least one class name"),
    ("num.yaml", "names: [car, 3]\n", "names[1]"),
    ("dup.yaml", "names: {0: a, 0: b}\n", "dup.yaml"),
    ("dupstr.json", '{"0": "a", " 0": "b"}', "dupstr.json"),
    ("scalar.yaml", "names: car\n", "names"),
    ("bad.yaml", "names: [car\n", "class_names"),
    ("bad.json", "[\"car\"", "class_names"),
    ("cats.json", '{"categories": [{"id": "x", "name": "car"}]}', "categories"),
    ("dupcats.json", '{"categories": [{"id": 1, "name": "a"}, {"id": 1, "name": "b"}]}', "categories"),
    ("nocats.json", '{"categories": []}', "at least one category"),
    ("latin1.names", b"caf\xe9\n", "class_names"),
])
def test_bad_names_files_are_one_line_naming_the_file(tmp_path, name, text, field):
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ConfigError) as e:
        load_class_names(p)
    msg = str(e.value)
    assert "\n" not in msg and field in msg and (name in msg or str(p) in msg)


def test_missing_file_and_bad_spec():
    with pytest.raises(ConfigError, match="^class_names: got 'nope-not-a-file.yaml'"):
        ClassNames.load("nope-not-a-file.yaml")
    with pytest.raises(InputError, match="^class_names"):
        ClassNames.load(3.5)
    assert issubclass(ConfigError, InputError)


def test_size_limits(tmp_path, monkeypatch):
    """A file over the byte limit and a map over the name limit are refused before being used."""
    p = tmp_path / "big.names"
    p.write_text("a\nb\nc\n")
    monkeypatch.setattr(CN, "MAX_NAMES_FILE_BYTES", 5)
    with pytest.raises(ConfigError, match="at most 5 bytes"):
        load_class_names(p)
    monkeypatch.setattr(CN, "MAX_NAMES_FILE_BYTES", 1 << 20)
    monkeypatch.setattr(CN, "MAX_CLASS_NAMES", 2)
    with pytest.raises(ConfigError, match="at most 2"):
        load_class_names(p)
    with pytest.raises(ConfigError, match="at most 2"):
        ClassNames.load(["a", "b", "c"])
    (tmp_path / "j.json").write_text('["a", "b", "c"]')
    monkeypatch.setattr(CN, "MAX_JSON_FILE_BYTES", 4)
    with pytest.raises(ConfigError, match="at most 4 bytes"):
        load_class_names(tmp_path / "j.json")


_NAME = st.text(st.characters(categories=("Lu", "Ll", "Lo", "Nd"), max_codepoint=0x2FFF),
                min_size=1, max_size=12)


@settings(max_examples=40, deadline=None)
@given(st.dictionaries(st.integers(0, 10_000), _NAME, min_size=1, max_size=20), st.sampled_from(["yaml", "json"]))
def test_any_map_round_trips_through_a_file(tmp_path_factory, names, kind):
    """Any map written as data.yaml or JSON reads back unchanged (and as lines, when its ids are 0..n-1)."""
    d = tmp_path_factory.mktemp("n")
    p = d / f"names.{kind}"
    p.write_text(yaml.safe_dump({"names": names}, allow_unicode=True) if kind == "yaml"
                 else json.dumps({str(k): v for k, v in names.items()}), encoding="utf-8")
    assert load_class_names(p).names == names
    listed = sorted(names.values())
    (d / "n.names").write_text("\n".join(listed) + "\n", encoding="utf-8")
    assert load_class_names(d / "n.names").names == dict(enumerate(listed))
