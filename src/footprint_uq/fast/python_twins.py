"""Pure-Python twins of compiled functions, for a first run that must not wait for a compile.

:func:`python_twin` returns a compiled function's own Python source (``py_func``), re-bound so that every
compiled function it calls by a global name is replaced by that one's twin, recursively: the same
arithmetic executed by CPython, nothing compiled.  ~60 us per undistorted point on the 2026-11-26 VM, so
worth it only for a few points (a command line's first ``locate`` or frame of detections on a camera with lens
distortion, while :mod:`footprint_uq.products.warmup` compiles the kernels in the background).

Where the compiled code would give inf or NaN (``error_model="numpy"``) CPython raises
(``ZeroDivisionError``, ``ValueError``, ``OverflowError``): callers catch those and run the compiled function.
Results agree with the compiled ones to rounding (the kernels may contract ``a * b + c`` into one FMA).
"""

from __future__ import annotations

import types

from numba.core.registry import CPUDispatcher

__all__ = ["python_twin", "TWIN_ERRORS"]

#: what a twin raises where its compiled original returns inf or NaN
TWIN_ERRORS = (ArithmeticError, ValueError)

_twins: dict = {}


def python_twin(fn):
    """The pure-Python twin of the compiled function ``fn`` (a numba dispatcher; other callables as they are)."""
    f = fn.py_func if isinstance(fn, CPUDispatcher) else fn
    if not isinstance(f, types.FunctionType):
        return f
    twin = _twins.get(f)
    if twin is None:
        g = dict(f.__globals__)
        twin = types.FunctionType(f.__code__, g, f.__name__, f.__defaults__, f.__closure__)
        _twins[f] = twin  # before the callees: recursion ends here
        for name in f.__code__.co_names:
            if isinstance(g.get(name), CPUDispatcher):
                g[name] = python_twin(g[name])
    return twin
