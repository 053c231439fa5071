"""The package's architecture, checked: no import cycles, no private names across modules, imports at
the top of modules (function-local imports only for optional extras), and the old module paths of
0.1 only as aliases (``footprint_uq._moved``).  See docs/architecture.md."""

from __future__ import annotations

import ast
import importlib
import sys
import warnings
from collections import defaultdict
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = "footprint_uq"
#: optional extras: imported where used, so that the core runs without them
OPTIONAL = {"dask", "distributed", "carla", "pyproj", "paho", "asn1tools", "uncertainties", "atheris", "rosbags",
            "mcap", "foxglove"}


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for f in sorted((SRC / PKG).rglob("*.py")):
        parts = list(f.relative_to(SRC).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return out


MODS = _modules()


def _base(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    b = mod.split(".") if is_pkg else mod.split(".")[:-1]
    b = b[: len(b) - (node.level - 1)] if node.level > 1 else b
    return ".".join(b + ([node.module] if node.module else []))


class _Scan:
    """Every import of one module: (node, inside a function?, under TYPE_CHECKING?, internal targets)."""

    def __init__(self, mod: str):
        self.mod = mod
        path, self.is_pkg = MODS[mod]
        self.tree = ast.parse(path.read_text(), str(path))
        parents = {c: n for n in ast.walk(self.tree) for c in ast.iter_child_nodes(n)}
        self.imports = []
        for n in ast.walk(self.tree):
            if not isinstance(n, ast.Import | ast.ImportFrom):
                continue
            p, in_func, type_only = parents.get(n), False, False
            while p is not None:
                in_func |= isinstance(p, ast.FunctionDef | ast.AsyncFunctionDef)
                type_only |= isinstance(p, ast.If) and "TYPE_CHECKING" in ast.unparse(p.test)
                p = parents.get(p)
            self.imports.append((n, in_func, type_only, self._targets(n)))

    def _targets(self, n) -> list[tuple[str, str | None] | None]:
        """Per imported name: (internal module, imported name or None for a module), or None (external)."""
        if isinstance(n, ast.Import):
            return [(a.name, None) if a.name.split(".")[0] == PKG else None for a in n.names]
        base = _base(self.mod, self.is_pkg, n)
        if base.split(".")[0] != PKG:
            return [None] * len(n.names)
        return [(f"{base}.{a.name}", None) if f"{base}.{a.name}" in MODS else (base, a.name) for a in n.names]


SCANS = {m: _Scan(m) for m in MODS}


def _ancestors(mod: str) -> list[str]:
    parts = mod.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts) + 1)]


def _runtime_graph() -> dict[str, set[str]]:
    """Module -> modules whose execution its top-level imports start (a package's __init__ runs before
    any of its modules; a module's own ancestors are already running, so they are not edges)."""
    g = defaultdict(set)
    for mod, scan in SCANS.items():
        own = set(_ancestors(mod))
        for _, in_func, type_only, targets in scan.imports:
            if in_func or type_only:
                continue
            for target, _ in filter(None, targets):
                g[mod].update(a for a in _ancestors(target)[1:] if a in MODS and a not in own)
    return g


def _cycles(g: dict[str, set[str]]) -> list[list[str]]:
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles(_runtime_graph()) == []


def test_cycle_finder_finds_a_cycle():
    """The check above can fail: a two-module cycle and one through a package's __init__."""
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert _cycles({"p": {"p.x"}, "p.x": {"q"}, "q": {"p"}}) == [["p", "p.x", "q"]]


def test_imports_are_at_module_top_except_optional_extras():
    bad = []
    for mod, scan in SCANS.items():
        for n, in_func, _, _ in scan.imports:
            if not in_func:
                continue
            names = [n.module or ""] if isinstance(n, ast.ImportFrom) and n.level == 0 else \
                [a.name for a in n.names] if isinstance(n, ast.Import) else [PKG]
            if not all(name.split(".")[0] in OPTIONAL for name in names):
                bad.append(f"{mod}:{n.lineno}: {ast.unparse(n)}")
    assert bad == []


def test_no_private_names_across_modules():
    """``from .x import _y`` and ``x._y`` on an imported module are private reach-ins.  Private
    *modules* (``_common``, ``_checks``) are the package's shared internals and may be imported."""
    bad = []
    for mod, scan in SCANS.items():
        aliases = {}
        for n, _, _, targets in scan.imports:
            for t, alias in zip(targets, n.names, strict=True):
                if t is None:
                    continue
                target, name = t
                if name is not None and name.startswith("_") and not name.startswith("__"):
                    bad.append(f"{mod}:{n.lineno}: {ast.unparse(n)}")
                if name is None and target != mod:
                    aliases[alias.asname or alias.name.split(".")[-1]] = target
        for node in ast.walk(scan.tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                bad.append(f"{mod}:{node.lineno}: {node.value.id}.{node.attr}")
    assert bad == []


def test_every_internal_import_resolves_to_a_module_of_the_new_layout():
    bad = []
    for mod, scan in SCANS.items():
        for n, _, _, targets in scan.imports:
            bad += [f"{mod}:{n.lineno}: {t[0]}" for t in targets if t is not None and t[0] not in MODS]
    assert bad == []


@pytest.mark.parametrize("old", ["kernels", "maps", "footprints", "budget", "propagation", "carla_bridge"])
def test_old_module_paths_are_aliases_of_the_moved_modules(old, monkeypatch):
    from footprint_uq._moved import MOVED

    new = importlib.import_module(f"{PKG}.{MOVED[old]}")
    monkeypatch.delitem(sys.modules, f"{PKG}.{old}", raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mod = importlib.import_module(f"{PKG}.{old}")
    assert mod is new and mod.__name__ == f"{PKG}.{MOVED[old]}" and mod.__spec__.name == f"{PKG}.{MOVED[old]}"
    assert any(issubclass(w.category, DeprecationWarning) and MOVED[old] in str(w.message) for w in caught)


#: the planner's layer (docs/architecture.md): above products / scenario, below viz and cli
PLANNING_MAY_NOT_IMPORT = ("viz", "cli", "batch", "service", "integrations", "calibration")
BELOW_PLANNING = ("params", "errors", "status", "_checks", "fast", "cameras", "uncertainty", "products", "io",
                  "scenario")


def test_planning_layer():
    bad = []
    for mod, scan in SCANS.items():
        top = mod.split(".")[1] if mod.count(".") else ""
        for n, _, _, targets in scan.imports:
            for t in filter(None, targets):
                target_top = t[0].split(".")[1] if t[0].count(".") else ""
                if top == "planning" and target_top in PLANNING_MAY_NOT_IMPORT:
                    bad.append(f"{mod}:{n.lineno}: {t[0]} (above planning)")
                if top in BELOW_PLANNING and target_top == "planning":
                    bad.append(f"{mod}:{n.lineno}: {t[0]} (planning is above {top})")
    assert any(m.startswith(f"{PKG}.planning.") for m in MODS)
    assert bad == []


#: the tracker's layer: above products/ and uncertainty/ (it builds on FrameProcessor), below service/, batch/ and cli/
TRACKING_MAY_IMPORT = ("params", "errors", "status", "_checks", "fast", "cameras", "uncertainty", "products",
                       "tracking")
#: validation/ too: `validate --tracks` scores the tracker's velocity and heading against labelled truth
#: (validation.motion), and its synthetic sequences use the tracker's trajectories (validation.synthetic)
TRACKING_IMPORTED_BY = ("tracking", "service", "batch", "cli", "validation")


def test_tracking_layer():
    """footprint_uq.tracking imports only from its own layer and the ones below; only service, batch and cli (and
    itself) import it."""
    bad = []
    for mod, scan in SCANS.items():
        layer = mod.split(".")[1] if mod.count(".") else ""
        for n, _, _, targets in scan.imports:
            for t in filter(None, targets):
                tl = t[0].split(".")[1] if t[0].count(".") else ""
                if layer == "tracking" and tl not in TRACKING_MAY_IMPORT:
                    bad.append(f"{mod}:{n.lineno}: imports {t[0]}")
                if tl == "tracking" and layer not in TRACKING_IMPORTED_BY:
                    bad.append(f"{mod}:{n.lineno}: imports {t[0]}")
    assert any(m.startswith(f"{PKG}.tracking.") for m in MODS) and bad == []


#: the compiled layer is the floor: fast/ imports only itself and the floor's leaf modules (which import nothing of
#: the package), never cameras/, uncertainty/, products/ or anything above (docs/architecture.md)
FLOOR_LEAVES = ("params", "status", "v2x_codes")
FAST_MAY_IMPORT = ("fast",) + FLOOR_LEAVES


def _layer(target: str) -> str:
    return target.split(".")[1] if target.count(".") else ""


def _imports_above(layer: str, allowed: tuple[str, ...]) -> list[str]:
    """Every import (at the top, in a function or for type checking alike) of a module of ``layer`` whose
    target's layer is not in ``allowed``."""
    bad = []
    for mod, scan in SCANS.items():
        if _layer(mod) != layer:
            continue
        for n, _, _, targets in scan.imports:
            for t in filter(None, targets):
                if _layer(t[0]) not in allowed:
                    bad.append(f"{mod}:{n.lineno}: {t[0]}")
    return bad


def test_fast_is_the_floor():
    """fast/ (the compiled core) imports nothing above it: constants it needs live in params / status /
    v2x_codes, the rotations it needs in fast/rotation.py, the public map/points API in products/covariance.py."""
    assert any(m.startswith(f"{PKG}.fast.") for m in MODS)
    assert _imports_above("fast", FAST_MAY_IMPORT) == []


def test_floor_leaves_import_no_layer():
    """The floor modules fast/ may import are leaves: they import nothing of the package."""
    for leaf in FLOOR_LEAVES:
        assert f"{PKG}.{leaf}" in MODS
        assert _imports_above(leaf, ()) == [], leaf


def test_floor_check_can_fail(monkeypatch):
    """The check above sees an import of products from fast/ (a scan of a synthetic module)."""
    scan = _Scan.__new__(_Scan)
    scan.mod, scan.is_pkg = f"{PKG}.fast.fake", False
    scan.tree = ast.parse("from ..products import v2x\nfrom .. import status\n")
    scan.imports = [(n, False, False, scan._targets(n)) for n in scan.tree.body]
    monkeypatch.setitem(SCANS, f"{PKG}.fast.fake", scan)
    assert _imports_above("fast", FAST_MAY_IMPORT) == [f"{PKG}.fast.fake:1: {PKG}.products.v2x"]


MAX_FUNCTION_LINES = 80


def _code_lines(fn: ast.FunctionDef) -> int:
    """A function's lines without its docstring (signature and body)."""
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
            and isinstance(body[0].value.value, str):
        doc = body[0].end_lineno - body[0].lineno + 1
    else:
        doc = 0
    return fn.end_lineno - fn.lineno + 1 - doc


def test_no_function_over_80_lines_of_code():
    """Each function small enough to hold in one's head: at most 80 lines without its docstring."""
    long = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _code_lines(node) > MAX_FUNCTION_LINES:
                long.append(f"{path.relative_to(SRC)}:{node.lineno} {node.name} ({_code_lines(node)} lines)")
    assert not long, long
