"""docs/paper-reproduction.md is what the code generates (text equal, numbers within one unit of their last digit).

Regenerate after a deliberate change with
``python -m footprint_uq.scenario.reproduction docs/paper-reproduction.md``.
"""

from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import pytest

from footprint_uq.scenario.reproduction import render_markdown, reproduction_data, write_paper_reproduction

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "paper-reproduction.md"
_NUM = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")


@pytest.fixture(scope="module")
def generated():
    return render_markdown(reproduction_data())


def _split(text: str):
    nums = _NUM.findall(text)
    return _NUM.sub("#", text), nums


def test_committed_page_is_generated(generated):
    committed = DOC.read_text(encoding="utf-8")
    t_gen, n_gen = _split(generated)
    t_doc, n_doc = _split(committed)
    assert t_doc == t_gen, "docs/paper-reproduction.md differs in text: regenerate it (see module doc)"
    assert len(n_doc) == len(n_gen)
    for a, b in zip(n_doc, n_gen, strict=True):
        unit = float(10 ** Decimal(a).as_tuple().exponent) if "e" not in a.lower() else abs(float(a)) * 1e-3
        assert abs(float(a) - float(b)) <= unit + 1e-12, (a, b)


def test_page_states_every_table_and_statement(generated):
    for needle in ("Tables 2 and 3", "half a pixel", "vertical and angular", "(a) xy sequence", "(b) lane width",
                   "(c) ranking", "Which reading reproduces the paper", "README claims, with their camera",
                   "benchmark camera", "demo camera"):
        assert needle in generated, needle
    assert generated.count("**FAIL**") >= 3 and generated.count("**PASS**") >= 3


def test_written_atomically(tmp_path, generated):
    data = reproduction_data()
    p = write_paper_reproduction(tmp_path / "sub" / "page.md", data)
    assert p.read_text(encoding="utf-8") == render_markdown(data)
    assert not list((tmp_path / "sub").glob("*.tmp"))


def test_links_from_readme_and_case_study_doc():
    assert "docs/paper-reproduction.md" in (ROOT / "README.md").read_text(encoding="utf-8")
    assert "paper-reproduction.md" in (ROOT / "docs" / "case-study.md").read_text(encoding="utf-8")
