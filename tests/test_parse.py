"""The guarded YAML/JSON parsing of every input file (footprint_uq._parse): alias bombs, sizes, duplicate keys."""

from __future__ import annotations

import pytest

from footprint_uq import _parse
from footprint_uq.errors import ConfigError
from hostile_cases import ANCHOR_BOMB


def test_alias_bomb_refused_at_once_and_ordinary_anchors_kept():
    with pytest.raises(ConfigError, match="alias bomb"):  # measured before anything is built (no timing asserted)
        _parse.load_yaml(ANCHOR_BOMB, "bomb.yaml")
    doc = "base: &b {focal_px: 0.5, tilt_deg: 0.1}\nsite:\n  <<: *b\n  tilt_deg: 0.2\nlist: [*b, *b]\n"
    d = _parse.load_yaml(doc, "ok.yaml")
    assert d["site"] == {"focal_px": 0.5, "tilt_deg": 0.2}  # a merge key may be overridden
    assert d["list"] == [d["base"], d["base"]]


def test_expanded_count_is_exact_below_the_limit():
    doc = "a: &a [1, 2, 3]\nb: [*a, *a, *a]\n"
    node = _parse._Loader(doc).get_single_node()
    # root mapping 1 + keys 2 + a (1 + 3) + b (1 + 3 * 4)
    assert _parse._expanded_nodes(node) == 1 + 2 + 4 + 13


@pytest.mark.parametrize("text, is_json", [("a: 1\nb: 2\na: 3\n", False), ('{"a": 1, "b": {"c": 1, "c": 2}}', True),
                                           ("x: {c: 1, c: 2}\n", False)])
def test_duplicate_keys_are_named(text, is_json):
    with pytest.raises(ConfigError, match=r"f.txt: [ac]: got 'given twice'"):
        _parse.load_yaml_or_json(text, "f.txt", is_json=is_json)


def test_size_limit(monkeypatch):
    monkeypatch.setattr(_parse, "MAX_CHARS", 10)
    with pytest.raises(ConfigError, match="at most 10 characters"):
        _parse.load_yaml("a: 12345678901\n", "big.yaml")
    assert _parse.load_json("[1, 2]", "small.json") == [1, 2]
