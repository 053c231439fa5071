"""Before/after: the same benchmark sections of two work trees, measured in one run.

Usage::

    git worktree add /tmp/fuq-base <old commit>
    .venv/bin/python bench/compare.py --base /tmp/fuq-base [--sections maps,footprints,batch] [--rounds 2]

Each round runs ``bench/run.py --sections ...`` of the base tree, then of this tree, each in a
subprocess whose ``PYTHONPATH`` is that tree's ``src`` (numba caches of both are cleared first, so
each tree compiles its own kernels).  Rounds alternate A B A B, so slow drift of a shared machine
hits both.  Printed per case: the best of the rounds' medians for each tree and the ratio
new/base (< 1: faster now); and, where the new tree has a row measured like for like with the
base (``parity_of`` names the base's case: the same work with the features the base did not
have switched off, e.g. ``linearity=False``), that figure and its ratio to the base ("at parity").
Nothing is asserted: the machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: the measured column of a row, in order of preference
_KEYS = ("median_ms", "median_us")


def _clear_numba_cache(tree: Path) -> None:
    for p in list((tree / "src").rglob("*.nbi")) + list((tree / "src").rglob("*.nbc")):
        p.unlink()


def _run(tree: Path, sections: str, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    subprocess.run([sys.executable, str(tree / "bench" / "run.py"), "--sections", sections, "--out", str(out)],
                   check=False, env=env, cwd=tree, stdout=subprocess.DEVNULL)
    data = json.loads((out / "latest.json").read_text())
    figures = {}
    for name, rows in data["sections"].items():
        for r in rows if isinstance(rows, list) else []:
            for k in _KEYS:
                if k in r:
                    figures[(name, r["case"], k)] = float(r[k])
                    if "parity_of" in r:
                        figures[(name, r["parity_of"], k, "parity")] = float(r[k])
                    break
    return figures


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="work tree of the commit to compare against")
    ap.add_argument("--sections", default="maps,footprints,batch")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    base = Path(args.base).resolve()
    best: dict[str, dict] = {"base": {}, "new": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for tree in (base, ROOT):
            _clear_numba_cache(tree)
        for r in range(args.rounds):
            for label, tree in (("base", base), ("new", ROOT)):
                figs = _run(tree, args.sections, Path(tmp) / f"{label}{r}")
                for key, v in figs.items():
                    best[label][key] = min(v, best[label].get(key, float("inf")))
    print(f"{'section':<11} {'case':<92} {'base':>10} {'new':>10} {'new/base':>8} {'at parity':>10} "
          f"{'parity/base':>11}")
    for key in sorted(k for k in set(best["base"]) & set(best["new"]) if len(k) == 3):
        name, case, unit = key
        b, n = best["base"][key], best["new"][key]
        u = unit.split("_")[1]
        line = f"{name:<11} {case[:92]:<92} {b:>8.2f}{u:>2} {n:>8.2f}{u:>2} {n / b:>8.3f}"
        p = best["new"].get(key + ("parity",))
        if p is not None:
            line += f" {p:>8.2f}{u:>2} {p / b:>11.3f}"
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
