"""Per-thread working buffers of the fast paths.

A buffer that a call needs only while it runs (the per-frame kernel's scratch, a map's status
codes when the caller does not want them) is kept per thread and reused: a fresh large array
every call is fresh pages from the kernel, first touched inside the kernel (page faults, ~9 us
per frame for the scratch, up to 40 % of a two-thread full-HD map for the status codes).  A
buffer is never returned to a caller: whoever gets an array owns it.
"""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["thread_buffer"]

_TLS = threading.local()


def thread_buffer(name: str, shape: tuple, dtype=np.float64) -> np.ndarray:
    """This thread's uninitialised buffer ``name`` of ``shape`` and ``dtype`` (allocated again when either
    differs from the last call's)."""
    buf = getattr(_TLS, name, None)
    if buf is None or buf.shape != shape or buf.dtype != dtype:
        buf = np.empty(shape, dtype=dtype)
        setattr(_TLS, name, buf)
    return buf
