"""Where numba keeps the compiled kernels: beside the sources when that folder is writable (numba's default),
else in the user's cache folder -- ``$XDG_CACHE_HOME/footprint-uq/numba`` (``~/.cache/footprint-uq/numba``) --
so that an install into a read-only site-packages compiles once, not on every run.

:func:`configure` runs when the package is imported, before any kernel module (numba reads the folder when a
kernel is defined); an explicit ``NUMBA_CACHE_DIR`` always wins.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["configure", "user_cache_dir", "cache_dir"]

_FAST = Path(__file__).parent / "fast"


def user_cache_dir(environ=os.environ) -> Path:
    """``$XDG_CACHE_HOME/footprint-uq/numba``, ``~/.cache/footprint-uq/numba`` without it."""
    base = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "footprint-uq" / "numba"


def _writable(folder: Path) -> bool:
    probe = folder / "__pycache__"
    return os.access(probe if probe.is_dir() else folder, os.W_OK)


def configure(environ=os.environ) -> Path | None:
    """Set ``NUMBA_CACHE_DIR`` to :func:`user_cache_dir` when it is unset and the package folder is not writable;
    returns the folder set (None: numba's default, beside the sources, or the caller's own setting)."""
    if environ.get("NUMBA_CACHE_DIR") or _writable(_FAST):
        return None
    d = user_cache_dir(environ)
    environ["NUMBA_CACHE_DIR"] = str(d)
    config = getattr(sys.modules.get("numba.core.config"), "__dict__", None)
    if config is not None:  # numba imported before us: its configuration was read already
        config["CACHE_DIR"] = str(d)
    return d


def cache_dir() -> Path:
    """The folder the kernels are cached in now."""
    d = os.environ.get("NUMBA_CACHE_DIR")
    return Path(d) if d else _FAST / "__pycache__"


configure()  # on import: the package imports this module before any kernel module
