"""One hook for "the compiled kernels are about to be compiled": a command line says so on stderr, a library
user sees nothing.

The command sets a handler (:func:`set_compile_handler`); the library calls :func:`before_kernels` with the
kernel group's name right before it calls a group's kernels, i.e. after every input has been checked -- so a
notice never comes before a one-line input error. The handler runs at most once per group and process, and
decides itself whether anything needs compiling (``products.warmup.compile_notice``).
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["set_compile_handler", "before_kernels"]

_handler: Callable[[str], None] | None = None
_done: set[str] = set()


def set_compile_handler(handler: Callable[[str], None] | None) -> None:
    """``handler(group)`` is called before the first use of each kernel group (None: no handler)."""
    global _handler
    _handler = handler
    _done.clear()


def before_kernels(group: str) -> None:
    """Called by the library right before it runs the kernels of ``group`` ("map", "points", "objects")."""
    if _handler is None or group in _done:
        return
    _done.add(group)
    _handler(group)
