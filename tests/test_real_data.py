"""The real data sets the tests use are in the repository (tests/data), so that a fresh clone skips none of them.

Each folder carries where it comes from and its licence; ``shared_data`` (tests/conftest.py) finds the copy even
where ``../shared/data`` is absent (checked here by pointing that location at an empty folder).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REAL_DATA

HERE = Path(__file__).resolve().parent


@pytest.mark.parametrize("name", sorted(REAL_DATA))
def test_every_real_data_set_is_in_the_repository_with_its_origin_and_licence(name):
    folder = REAL_DATA[name]
    assert folder.is_dir(), f"{folder} is missing: a fresh clone would skip the tests that need {name}"
    assert folder.resolve().is_relative_to(HERE / "data")
    texts = [p.read_text(encoding="utf-8") for p in folder.glob("*") if p.suffix in (".txt", ".md")]
    assert any("licen" in t.lower() for t in texts), f"{name}: no SOURCE/README naming its licence"
    assert sum(1 for p in folder.rglob("*") if p.is_file()) >= 3


def test_real_data_tests_run_without_the_shared_folder(tmp_path):
    """A fresh clone has no ../shared: the official-module and real-file tests still run (none skipped)."""
    env = {**os.environ, "FOOTPRINT_UQ_SHARED_DATA": str(tmp_path / "nowhere")}
    env.pop("PYTEST_XDIST_WORKER", None)
    code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import conftest; "
            "print(all(conftest.real_data_folder(n) is not None for n in conftest.REAL_DATA))")
    # FOOTPRINT_UQ_SHARED_DATA pointing nowhere must fall back on the copies
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=HERE, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "True"
