"""The guarded YAML/JSON parsing of every input file (footprint_uq._parse): alias bombs, sizes, duplicate keys."""

from __future__ import annotations

import pytest
import yaml

from footprint_uq import _parse
from footprint_uq._parse import YAMLSyntaxError, load_yaml
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


@pytest.mark.parametrize("text, line, column", [
    ("model: pan-tilt\nimage_size_px: [1920, 1080\nfocal_px: 1400\n", 3, 9),  # an unclosed list
    ("a: 1\nb: c: d\n", 2, 5),  # a mapping where a value goes
    ("a: 1\n\tb: 2\n", 2, 1),  # a tab
    ("a: 'open\n", 2, 1),  # an unclosed quote
])
def test_yaml_syntax_error_names_file_line_and_column(text, line, column):
    """A YAML syntax error is one ConfigError naming the file, the line and the column (1-based) -- and still a
    yaml.YAMLError for the callers that catch that."""
    with pytest.raises(YAMLSyntaxError) as e:
        load_yaml(text, "site/camera.yaml")
    assert str(e.value).startswith(f"site/camera.yaml: line {line}, column {column}: got "), str(e.value)
    assert "expected valid YAML syntax" in str(e.value) and "\n" not in str(e.value)
    assert isinstance(e.value, ConfigError) and isinstance(e.value, yaml.YAMLError)


def test_yaml_syntax_error_reaches_the_command_line(tmp_path):
    from click.testing import CliRunner

    from footprint_uq.cli.main import main

    bad = tmp_path / "camera.yaml"
    bad.write_text("model: pan-tilt\nimage_size_px: [1920, 1080\nfocal_px: 1400\n")
    r = CliRunner().invoke(main, ["locate", "--camera", str(bad), "--budget", "basler1", "--pixel", "1", "1"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1, r.output
    assert f"{bad}: line 3, column 9" in r.stderr, r.stderr
