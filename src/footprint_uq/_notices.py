"""One hook for "the compiled kernels are about to run": a command line says so on stderr when they still have
to be compiled (and may run the numpy reference path meanwhile); a library user sees nothing.

The command sets a handler (:func:`set_compile_handler`); the library calls :func:`before_kernels` with the
kernel group's name right before it calls a group's kernels, i.e. after every input has been checked -- so a
notice never comes before a one-line input error.  The handler decides itself whether anything needs
compiling (``products.warmup.KernelGate``) and answers whether the compiled kernels run now: False means the
caller takes its numpy reference path this time (the same numbers, 1e-9 relative) and asks again before its
next chunk or frame.  Without a command's handler (library use) the library's handler answers
(:func:`set_library_handler`; ``products.warmup.LibraryGate``, installed when the package is imported): the
kernels run, compiled on first use -- unless another process is compiling the same group right now; then the
call says so once (a warning naming ``footprint-uq warmup``), waits for it at most a bound, and takes the
reference path until that compile is done.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["set_compile_handler", "set_library_handler", "before_kernels"]

_handler: Callable[[str], bool | None] | None = None
_library_handler: Callable[[str], bool | None] | None = None


def set_compile_handler(handler: Callable[[str], bool | None] | None) -> None:
    """``handler(group)`` is called before every use of a kernel group (None: no handler); it returns whether
    the compiled kernels run now (None counts as True)."""
    global _handler
    _handler = handler


def set_library_handler(handler: Callable[[str], bool | None] | None) -> None:
    """The handler asked when no command set one (library use; None: the kernels always run)."""
    global _library_handler
    _library_handler = handler


def before_kernels(group: str) -> bool:
    """Called by the library right before it runs the kernels of ``group`` ("map", "points", "objects"):
    True to run them (compiled now if they are not in the cache), False to take the reference path this time."""
    handler = _handler if _handler is not None else _library_handler
    if handler is None:
        return True
    return handler(group) is not False
