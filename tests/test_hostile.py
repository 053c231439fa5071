"""Hostile inputs (issue 11): every known one gives one line and exit 2, or error rows with nothing lost.

The catalogue is ``tests/hostile_cases.py`` (also run by ``bench/reliability.py`` for the README
figures).  A case fails if it exits otherwise, prints a traceback or more than one line, leaves a
file under the output name (exit 2), or loses a row (detection files: rows out == physical lines,
``consistent`` and ``lines_in`` in the summary).
"""

from __future__ import annotations

import pytest

from hostile_cases import build, run


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    return {c.name: c for c in build(tmp_path_factory.mktemp("hostile"))}


def _names():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        return [c.name for c in build(Path(d))]


@pytest.mark.parametrize("name", _names())
def test_hostile_input(cases, name):
    res = run(cases[name])
    assert not res["traceback"], res["stderr"]
    assert res["ok"], res
    assert res["rows_lost"] == 0


def test_last_resort_handler(monkeypatch):
    """An unexpected exception (a bug) is one line and exit 3; --debug adds the traceback."""
    from click.testing import CliRunner

    from footprint_uq.cli import presets as presets_cli
    from footprint_uq.cli.main import EXIT_BUG, main

    def boom(*a, **k):
        raise ZeroDivisionError("simulated bug")

    monkeypatch.setattr(presets_cli, "presets_table", boom)
    r = CliRunner().invoke(main, ["presets"])
    assert r.exit_code == EXIT_BUG
    err = r.stderr
    assert "internal error (ZeroDivisionError: simulated bug)" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    r = CliRunner().invoke(main, ["--debug", "presets"])
    assert r.exit_code == EXIT_BUG and "Traceback" in r.stderr
