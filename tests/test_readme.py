"""README.md and docs/*.md: every code block runs as written, standalone, in a fresh process (issue 34); the
README opens with the two set-up commands and stays short; the guide's sample files load and its sample output
is current; links resolve.

A block that cannot run standalone carries a commented marker on the line before its fence, with its reason:
``<!-- test: skip (needs a labelled dataset) -->``; a slow one ``<!-- test: slow -->`` (run with the slow tests).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from footprint_uq import ErrorBudget
from footprint_uq.cli.main import main
from footprint_uq.io import camera_from_dict

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
GUIDE = ROOT / "docs" / "guide.md"
_FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
_MARK = re.compile(r"<!--\s*test:\s*(skip|slow)\b\s*(.*?)-->")
SHELLS = ("bash", "console", "sh", "shell")
#: the longest a block may take (a cold numba cache runs the reference path: slower, never a compile wait)
BLOCK_TIMEOUT_S = 900


def blocks(lang: str, page: Path = README) -> list[str]:
    return [body for kind, body in _FENCE.findall(page.read_text(encoding="utf-8")) if kind == lang]


def _commands(lang: str, body: str) -> list[str]:
    """The command lines of a shell block (a console block: the ``$ `` lines), comments dropped."""
    lines, cont = [], False
    for ln in body.splitlines():
        if lang != "console" or cont:
            lines.append(ln)
        elif ln.startswith("$ "):
            lines.append(ln[2:])
        cont = ln.rstrip().endswith("\\")  # a command continued on the next line (its output follows it)
    return [ln for ln in (x.strip() for x in lines) if ln and not ln.startswith("#")]


def code_blocks() -> list[tuple[str, str, str, str | None]]:
    """Every runnable block of README.md and docs/*.md: (id "page:line", language, code, marker or None).
    Runnable: python blocks, and shell blocks whose commands are footprint-uq calls."""
    out = []
    for page in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        text = page.read_text(encoding="utf-8")
        for m in _FENCE.finditer(text):
            lang, body = m.group(1), m.group(2)
            if lang in SHELLS:
                cmds = _commands(lang, body)
                starts = [c for i, c in enumerate(cmds) if i == 0 or not cmds[i - 1].endswith("\\")]
                if not starts or not all(c.startswith("footprint-uq ") for c in starts):
                    continue
                code = "set -e\n" + "\n".join(cmds) + "\n"
            elif lang == "python":
                code = body
            else:
                continue
            before = text[:m.start()].rstrip().rsplit("\n", 1)[-1]
            mark = _MARK.search(before)
            line = text.count("\n", 0, m.start()) + 1
            out.append((f"{page.relative_to(ROOT).as_posix()}:{line}", lang, code,
                        f"{mark.group(1)} {mark.group(2).strip()}".strip() if mark else None))
    return out


def _params():
    for bid, lang, code, mark in code_blocks():
        marks = []
        if mark is not None and mark.startswith("skip"):
            marks.append(pytest.mark.skip(reason=f"{bid}: marked in the page: {mark}"))
        elif mark is not None and mark.startswith("slow"):
            marks.append(pytest.mark.slow)
        yield pytest.param(lang, code, id=bid, marks=marks)


@pytest.mark.parametrize("lang, code", list(_params()))
def test_code_block_runs_standalone(lang, code, tmp_path):
    """The block, as a script of its own, in a fresh process and an empty folder (the repository's examples/
    and tests/data/ beside it, as from the repository's root); the command line is this checkout's."""
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(ROOT / "tests" / "data", target_is_directory=True)
    script = tmp_path / ("block.py" if lang == "python" else "block.sh")
    script.write_text(code, encoding="utf-8")
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
           "MPLBACKEND": "Agg"}
    cmd = [sys.executable, str(script)] if lang == "python" else ["bash", str(script)]
    p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S)
    assert p.returncode == 0, f"exit {p.returncode}\n{code}\n--- stderr ---\n{p.stderr[-3000:]}"
    assert "Traceback" not in p.stderr, p.stderr[-3000:]


def test_the_block_finder_sees_every_kind_and_a_failing_block_fails(tmp_path):
    """Negative control: the README's blocks are found (python and shell), and a block that fails is reported."""
    ids = [b[0] for b in code_blocks() if b[0].startswith("README.md")]
    langs = {b[1] for b in code_blocks() if b[0].startswith("README.md")}
    assert len(ids) >= 2 and {"python", "bash"} <= langs
    with pytest.raises(AssertionError, match="exit 2"):
        test_code_block_runs_standalone("bash", "set -e\nfootprint-uq locate --camera nowhere.yaml\n", tmp_path)


def test_readme_is_short():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 150


def cli_examples(page: Path = GUIDE) -> list[list[str]]:
    out = []
    for body in blocks("bash", page):
        for line in body.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("footprint-uq "):
                out.append(shlex.split(line)[1:])
    return out


def test_starts_with_make_demo_and_make_test():
    text = README.read_text(encoding="utf-8")
    first = _FENCE.search(text)
    assert first is not None and first.group(1) == "bash"
    assert "##" not in text[: first.start()]  # nothing but the title before the two commands
    cmds = [ln.split("#")[0].strip() for ln in first.group(2).splitlines() if ln.strip()]
    assert cmds == ["make demo", "make test"]
    makefile = (ROOT / "Makefile").read_text()
    assert "footprint-uq demo --out out/demo" in makefile


@pytest.fixture()
def at_root_copy(tmp_path, monkeypatch):
    """An empty folder with the repository's examples/ beside it, as the current directory."""
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_guide_cli_examples_cover_the_commands():
    names = [e[0] for e in cli_examples()]
    for needed in ("locate", "map", "presets", "demo", "objects"):
        assert needed in names


def test_json_sample_is_current(at_root_copy):
    sample = json.loads(blocks("json", GUIDE)[0])
    args = next(a for a in cli_examples() if a[0] == "locate" and "--format" not in a)
    live = json.loads(CliRunner().invoke(main, args).stdout)
    assert len(live) == len(sample)
    for s, lv in zip(sample, live, strict=True):
        assert list(s) == list(lv)
        for k, v in s.items():
            if isinstance(v, float):
                assert lv[k] == pytest.approx(v, abs=1e-4), k
            elif k == "cov_m2" and v[0][0] is not None:
                for row_s, row_l in zip(v, lv[k], strict=True):
                    assert row_l == pytest.approx(row_s, abs=1e-5)
            else:
                assert lv[k] == v, k


def test_sample_files_load():
    """The guide's camera and budget samples load, and examples/data/ holds the same files."""
    ys = [yaml.safe_load(b) for b in blocks("yaml", GUIDE)]
    cams = [d for d in ys if d.get("model")]
    budgets = [d for d in ys if not d.get("model")]
    assert cams and budgets
    for d in cams:
        cam = camera_from_dict(d)
        assert cam.height_m == d["height_m"]
    for d in budgets:
        b = ErrorBudget.from_dict(d)
        assert b.ground_slope_deg == d["ground_slope_deg"]
    data = ROOT / "examples" / "data"
    assert yaml.safe_load((data / "camera.yaml").read_text()) == cams[0]
    assert yaml.safe_load((data / "budget.yaml").read_text()) == budgets[0]


@pytest.mark.parametrize("page", [README, GUIDE, ROOT / "docs" / "glossary.md", ROOT / "docs" / "benchmarks.md",
                                  ROOT / "docs" / "first-run.md", ROOT / "examples" / "data" / "README.md"],
                         ids=lambda p: p.name)
def test_links_exist(page):
    for target in re.findall(r"\]\(([^)#]+)\)", page.read_text(encoding="utf-8")):
        if "://" not in target:
            assert (page.parent / target).exists(), target


def test_glossary_anchors_exist():
    """Every link into the glossary lands on one of its terms."""
    anchors = set(re.findall(r'<a id="([a-z0-9-]+)"></a>', (ROOT / "docs" / "glossary.md").read_text()))
    for page in [README, *(ROOT / "docs").glob("*.md")]:
        for a in re.findall(r"glossary\.md#([a-z0-9-]+)", page.read_text(encoding="utf-8")):
            assert a in anchors, (page.name, a)


def test_reliability_figures_come_from_the_script():
    """The Reliability block of docs/benchmarks.md (the README's until issue 34) is bench/reliability.py's
    rendering of bench/results/reliability.json."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("reliability", ROOT / "bench" / "reliability.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = json.loads((ROOT / "bench" / "results" / "reliability.json").read_text(encoding="utf-8"))
    text = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    block = text[text.index(mod.BEGIN) + len(mod.BEGIN):text.index(mod.END)].strip()
    assert block == mod.render(res).strip()
    assert res["rows_lost"] == 0 and res["tracebacks"] == 0
    assert res["hostile_ok"] == res["hostile_inputs"] and res["kills_survived"] == res["kills"] > 0


def test_extras_table_matches_pyproject():
    """The README's install table names every extra of pyproject.toml, and only those."""
    import tomllib

    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])
    text = README.read_text(encoding="utf-8")
    table = text[text.index("| extra |"):]
    named = set(re.findall(r"^\| `([a-z0-9-]+)` \|", table[:table.index("\n\n")], re.M))
    assert named == extras
