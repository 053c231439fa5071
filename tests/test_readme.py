"""README.md: its code runs, its CLI examples work, its sample files load and its sample output is current."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from footprint_uq import ErrorBudget
from footprint_uq.cli.main import main
from footprint_uq.io import camera_from_dict

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
_FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def blocks(lang: str) -> list[str]:
    return [body for kind, body in _FENCE.findall(README.read_text(encoding="utf-8")) if kind == lang]


def cli_examples() -> list[list[str]]:
    out = []
    for body in blocks("bash"):
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


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    """Run every python block in order, in one namespace, inside a scratch directory."""
    work = tmp_path_factory.mktemp("readme")
    ns: dict = {"__name__": "__readme__"}
    old = Path.cwd()
    import os

    os.chdir(work)
    try:
        for code in blocks("python"):
            exec(compile(code, str(README), "exec"), ns)  # noqa: S102
    finally:
        os.chdir(old)
    return work, ns


def test_python_blocks_run(executed):
    work, ns = executed
    assert len(blocks("python")) >= 1
    assert (work / "camera.yaml").is_file()
    assert (work / "uncertainty_image.png").stat().st_size > 10_000
    # the numbers the README prints are sensible: 95 % axes of the two ground pixels between 0.2 m and 10 m
    a = ns["semi_major_m"][:2]
    assert ((a > 0.2) & (a < 10)).all()


def test_cli_examples_run(executed, monkeypatch):
    work, _ = executed
    monkeypatch.chdir(work)
    examples = cli_examples()
    names = [e[0] for e in examples]
    for needed in ("locate", "map", "presets", "demo"):
        assert needed in names
    for args in examples:
        if args[0] in ("demo", "case-study"):  # slow; exercised by tests/test_cli.py and the case-study tests
            assert main.get_command(None, args[0]) is not None
            continue
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 0, (args, r.output)


def test_json_sample_is_current(executed, monkeypatch):
    work, _ = executed
    monkeypatch.chdir(work)
    sample = json.loads(blocks("json")[0])
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
    ys = [yaml.safe_load(b) for b in blocks("yaml")]
    cams = [d for d in ys if d.get("model")]
    budgets = [d for d in ys if not d.get("model")]
    assert cams and budgets
    for d in cams:
        cam = camera_from_dict(d)
        assert cam.height_m == d["height_m"]
    for d in budgets:
        b = ErrorBudget.from_dict(d)
        assert b.ground_slope_deg == d["ground_slope_deg"]


def test_links_exist():
    for target in re.findall(r"\]\(([^)#]+)\)", README.read_text(encoding="utf-8")):
        if "://" not in target:
            assert (ROOT / target).exists(), target


def test_reliability_figures_come_from_the_script():
    """The README's Reliability block is bench/reliability.py's rendering of bench/results/reliability.json."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("reliability", ROOT / "bench" / "reliability.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = json.loads((ROOT / "bench" / "results" / "reliability.json").read_text(encoding="utf-8"))
    text = README.read_text(encoding="utf-8")
    block = text[text.index(mod.BEGIN) + len(mod.BEGIN):text.index(mod.END)].strip()
    assert block == mod.render(res).strip()
    assert res["rows_lost"] == 0 and res["tracebacks"] == 0
    assert res["hostile_ok"] == res["hostile_inputs"] and res["kills_survived"] == res["kills"] > 0
