"""Compare files and strings that hold numbers by their numbers, with a tolerance, never by their text.

The last digits of a float printed by ``repr``/``json``/``yaml`` depend on the CPU and the
libraries (an AMD EPYC prints another last digit than the machine that wrote a fixture):
:func:`assert_same_numbers` parses both sides (JSON, YAML, CSV or free text) and compares every
number with ``rtol``/``atol`` and everything else exactly.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

#: a number in free text (integers, decimals, exponents, inf/nan spelled as Python/JSON/YAML do)
NUMBER_RE = re.compile(r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|\.?inf|\.?nan)",
                       re.IGNORECASE)


def _close(a: float, b: float, rtol: float, atol: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b or abs(a - b) <= atol + rtol * max(abs(a), abs(b))


def _compare(a, b, rtol, atol, where):
    num = (int, float)
    if isinstance(a, bool) or isinstance(b, bool):
        assert a == b, f"{where}: {a!r} != {b!r}"
    elif isinstance(a, num) and isinstance(b, num):
        assert _close(float(a), float(b), rtol, atol), f"{where}: {a!r} != {b!r} (rtol {rtol})"
    elif isinstance(a, dict) and isinstance(b, dict):
        assert list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for k in a:
            _compare(a[k], b[k], rtol, atol, f"{where}.{k}")
    elif isinstance(a, list | tuple) and isinstance(b, list | tuple):
        assert len(a) == len(b), f"{where}: length {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _compare(x, y, rtol, atol, f"{where}[{i}]")
    elif isinstance(a, str) and isinstance(b, str):
        assert_same_text_numbers(a, b, rtol=rtol, atol=atol, where=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_same_text_numbers(a: str, b: str, *, rtol: float = 1e-12, atol: float = 0.0, where: str = "text"):
    """Free text: equal once every number is replaced by a placeholder, and the numbers close."""
    na, nb = NUMBER_RE.findall(a), NUMBER_RE.findall(b)
    assert NUMBER_RE.sub("#", a) == NUMBER_RE.sub("#", b), f"{where}: text differs:\n{a[:400]}\n---\n{b[:400]}"
    assert len(na) == len(nb), f"{where}: {len(na)} numbers != {len(nb)}"
    for i, (x, y) in enumerate(zip(na, nb, strict=True)):
        fx, fy = float(x.replace(".inf", "inf").replace(".nan", "nan")), float(y.replace(".inf", "inf")
                                                                                  .replace(".nan", "nan"))
        assert _close(fx, fy, rtol, atol), f"{where}: number {i}: {x} != {y} (rtol {rtol})"


def assert_same_numbers(a, b, *, rtol: float = 1e-12, atol: float = 0.0, kind: str | None = None,
                        where: str = "") -> None:
    """Two files (paths) or texts hold the same data: numbers within ``rtol``/``atol``, the rest equal.

    ``kind``: "json", "yaml" or "text" (default: from the path's extension, else text).
    """
    if isinstance(a, Path):
        kind = kind or {".json": "json", ".yaml": "yaml", ".yml": "yaml"}.get(a.suffix.lower(), "text")
        where = where or a.name
        a = a.read_text(encoding="utf-8")
    if isinstance(b, Path):
        b = b.read_text(encoding="utf-8")
    kind = kind or "text"
    if kind == "json":
        _compare(json.loads(a), json.loads(b), rtol, atol, where or "json")
    elif kind == "yaml":
        import yaml

        _compare(yaml.safe_load(a), yaml.safe_load(b), rtol, atol, where or "yaml")
        # comments and layout must match too (the header comment of our own files)
        assert_same_text_numbers(a, b, rtol=rtol, atol=atol, where=where or "yaml")
    else:
        assert_same_text_numbers(a, b, rtol=rtol, atol=atol, where=where or "text")


def _last_digit_unit(token: str) -> float:
    """One unit in the last printed decimal of ``token`` (0 for integers: they must match exactly)."""
    mant = re.split(r"[eE]", token)[0]
    if "." not in mant:
        return 0.0
    decimals = len(mant.split(".")[1])
    exp = int(re.split(r"[eE]", token)[1]) if re.search(r"[eE]", token) else 0
    return 10.0 ** (exp - decimals)


def contains_numeric(text: str, expected: str, *, whole_line: bool = False) -> bool:
    """``expected`` occurs in ``text`` with every decimal number within one unit of its last printed digit.

    The words must match exactly; a rounded number may differ by one unit in its last digit (the
    value under it can fall on the other side of a rounding boundary on another CPU), an integer
    must be equal.
    """
    parts = NUMBER_RE.split(expected)
    nums = NUMBER_RE.findall(expected)
    rx = "(" + NUMBER_RE.pattern + ")"
    pattern = rx.join(re.escape(p) for p in parts)
    if whole_line:
        pattern = "^" + pattern + "$"
    for m in re.finditer(pattern, text, flags=re.MULTILINE | re.IGNORECASE):
        ok = True
        for want, got in zip(nums, m.groups(), strict=True):
            try:
                w, g = float(want), float(got)
            except ValueError:
                ok = want.lower() == got.lower()
            else:
                ok = _close(w, g, 1e-12, 1.000001 * _last_digit_unit(want))
            if not ok:
                break
        if ok:
            return True
    return False
