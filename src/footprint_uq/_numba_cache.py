"""Where numba keeps the compiled kernels: beside the sources when that folder is writable (numba's default),
else in the user's cache folder -- ``$XDG_CACHE_HOME/footprint-uq/numba`` (``~/.cache/footprint-uq/numba``) --
so that an install into a read-only site-packages compiles once, not on every run.

:func:`configure` runs when the package is imported, before any kernel module (numba reads the folder when a
kernel is defined); an explicit ``NUMBA_CACHE_DIR`` always wins.

**When a cached kernel is stale.** numba keys each cached kernel on its own file's source only, but a kernel
compiles into itself every kernel it calls from other files (``fast/core.py``'s scalar functions are in nearly
all of them): after an edit of ``core.py`` the kernels of ``footprint_kernels.py`` would load their cached code,
the old core, from disk -- silently, in a notebook or a test run of a checkout.  :func:`install_sources_stamp`
therefore adds to the key of every kernel of the package a hash of *all* the package's kernel sources (the files
that mention ``njit``): any edit of one of them makes every cached kernel of the package stale, and each is
compiled again on its first use.  It is installed for the package on import (a cache locator in front of
numba's own, which it otherwise defers to); an explicit ``NUMBA_CACHE_LOCATOR_CLASSES`` bypasses it.
"""

from __future__ import annotations

import hashlib
import os
import sys
import warnings
from pathlib import Path

from numba.core import caching  # (configure() below sets numba's configuration after this import)

__all__ = ["configure", "user_cache_dir", "cache_dir", "install_sources_stamp", "sources_stamp"]

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


def sources_stamp(root: Path) -> str:
    """SHA-256 (hex) of the kernel sources under ``root``: every ``*.py`` file whose text mentions ``njit``, with
    its path relative to ``root``, in path order (a file that gains or loses a kernel changes it too)."""
    h = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        name = path.relative_to(root).as_posix().encode()
        try:
            text = path.read_bytes()
        except OSError:  # (numba could not compile a kernel from it either; its name still counts)
            h.update(name + b"\0?\0")
            continue
        if b"njit" in text:
            h.update(name + b"\0" + text + b"\0")
    return h.hexdigest()


def install_sources_stamp(root: Path) -> None:
    """Key every cached numba kernel defined in a file under ``root`` also on :func:`sources_stamp` of ``root``
    (see the module doc); kernels elsewhere are left to numba.  Must run before the kernels are defined; once per
    root (a second call does nothing)."""
    root_s = os.path.normcase(os.path.join(os.path.abspath(root), ""))
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)  # (public from 0.6x on)
    impls = getattr(impl, "_locator_classes", None)
    base = getattr(caching, "_CacheLocator", None)
    if not isinstance(impls, list) or base is None:  # a numba whose cache is laid out otherwise: say so, go on
        warnings.warn("footprint-uq: this numba's cache locators are not where expected; a cached kernel may "
                      "keep the code of a kernel it calls after an edit (delete the *.nbi / *.nbc files then)",
                      RuntimeWarning, stacklevel=2)
        return
    if any(getattr(c, "sources_root", None) == root_s for c in impls):
        return
    stamp: list[str] = []  # computed on the first kernel's use, once per process

    class SourcesStampLocator(base):
        """numba's own locator for the file (where the cache lives), with ``(its stamp, the sources' stamp)``."""

        sources_root = root_s

        def __init__(self, inner):
            self._inner = inner
            self._py_file = getattr(inner, "_py_file", None)  # (numba's warnings name it)

        def ensure_cache_path(self):
            self._inner.ensure_cache_path()

        def get_cache_path(self):
            return self._inner.get_cache_path()

        def get_disambiguator(self):
            return self._inner.get_disambiguator()

        def get_source_stamp(self):
            if not stamp:
                stamp.append(sources_stamp(Path(root_s)))
            return self._inner.get_source_stamp(), stamp[0]

        @classmethod
        def from_function(cls, py_func, py_file):
            if not os.path.normcase(os.path.abspath(py_file)).startswith(cls.sources_root):
                return None
            for other in impls:
                if getattr(other, "sources_root", None) is None:  # numba's (the first that takes the file)
                    inner = other.from_function(py_func, py_file)
                    if inner is not None:
                        return cls(inner)
            return None

    impls.insert(0, SourcesStampLocator)


configure()  # on import: the package imports this module before any kernel module
install_sources_stamp(Path(__file__).parent)
