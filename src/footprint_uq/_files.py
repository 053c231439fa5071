"""Input paths that are not regular files: FIFOs (named pipes, ``/dev/stdin`` of a pipe), devices, sockets.

A FIFO is read as a stream where its format allows it (CSV, JSON Lines, YAML/JSON config files, text
label files): opened without blocking, the reader waits at most :func:`fifo_wait_s` seconds for the
first bytes (or for a writer that comes and goes), so a FIFO nobody writes is one line of error, never
a hang; after the first bytes it is read like any stream (a writer that stalls mid-file stalls the
reader, as on standard input).  A format that needs seeking (Parquet) refuses a FIFO up front
(:func:`require_regular`).  Character and block devices (``/dev/zero``: an endless stream), sockets and
directories are refused where a file is expected.

A leaf module (imports only :mod:`footprint_uq.errors`): the file readers of every layer use it.
"""

from __future__ import annotations

import os
import select
import stat
from typing import BinaryIO

from .errors import InputError

__all__ = ["file_kind", "fifo_wait_s", "open_input", "read_input_bytes", "read_input_text", "require_regular",
           "is_stream", "FIFO_WAIT_S", "FIFO_WAIT_ENV"]

#: default wait for the first bytes of a FIFO, seconds (the producer is usually started beside the command)
FIFO_WAIT_S = 30.0
#: environment variable that overrides :data:`FIFO_WAIT_S` (seconds, a finite number > 0)
FIFO_WAIT_ENV = "FOOTPRINT_UQ_FIFO_WAIT_S"

_KINDS = ((stat.S_ISREG, "regular file"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISDIR, "directory"),
          (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"), (stat.S_ISSOCK, "socket"))


def file_kind(path) -> str | None:
    """``"regular file"``, ``"FIFO"``, ``"directory"``, ``"character device"``, ``"block device"``,
    ``"socket"`` (symbolic links followed), or None where nothing exists (or it cannot be examined)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return next((name for test, name in _KINDS if test(mode)), "special file")


def is_stream(path) -> bool:
    """True for a FIFO (a named pipe, or ``/dev/stdin`` connected to a pipe): read once, no seeking."""
    return file_kind(path) == "FIFO"


def fifo_wait_s() -> float:
    """Seconds to wait for a FIFO's first bytes: :data:`FIFO_WAIT_S`, or the environment's
    :data:`FIFO_WAIT_ENV` (InputError when that is not a finite number > 0)."""
    text = os.environ.get(FIFO_WAIT_ENV)
    if text is None or not text.strip():
        return FIFO_WAIT_S
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (v > 0 and v < float("inf")):
        raise InputError(FIFO_WAIT_ENV, text, "a finite number of seconds > 0")
    return v


def require_regular(path, field: str, why: str) -> None:
    """InputError unless ``path`` is a regular file (a FIFO, device, socket or directory is named).

    Parameters
    ----------
    path : the input path
    field : the option or field that names it (``"detections"``, ``"--labels"``)
    why : what the format needs, e.g. ``"Parquet needs a seekable file"``
    """
    kind = file_kind(path)
    if kind is None:
        raise InputError(field, str(path), "an existing file")
    if kind != "regular file":
        raise InputError(field, str(path), f"a regular file ({why}; got a {kind})")


def _wait_fifo(fd: int, wait_s: float) -> bool:
    """True when the FIFO has bytes, or a writer that came and went (EOF), within ``wait_s``."""
    poller = select.poll()
    poller.register(fd, select.POLLIN | select.POLLHUP | select.POLLERR)
    return bool(poller.poll(max(1, round(1000 * wait_s))))


def open_input(path, field: str, *, wait_s: float | None = None) -> BinaryIO:
    """A binary file object on an input: a regular file, or a FIFO as a stream (see the module doc).

    Parameters
    ----------
    path : the input path
    field : the option or field that names it in errors
    wait_s : seconds to wait for a FIFO's first bytes (default :func:`fifo_wait_s`)

    Raises
    ------
    InputError
        Nothing there; a directory, device or socket; a FIFO nobody wrote to within ``wait_s``.
    OSError
        The file cannot be opened (permissions): the command line reports it in one line.
    """
    kind = file_kind(path)
    if kind is None:
        raise InputError(field, str(path), "an existing file")
    if kind == "regular file":
        return open(path, "rb")  # noqa: SIM115 - returned to the caller
    if kind != "FIFO":
        raise InputError(field, str(path), f"a regular file or a FIFO (got a {kind})")
    wait = fifo_wait_s() if wait_s is None else float(wait_s)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # never blocks, writer or not
    try:
        if not _wait_fifo(fd, wait):
            raise InputError(field, str(path), f"a FIFO with a writer (nothing was written to it within {wait:g} s; "
                             f"start the producer first, or set {FIFO_WAIT_ENV})")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_input_bytes(path, field: str, *, max_bytes: int | None = None, wait_s: float | None = None) -> bytes:
    """The whole content of an input (a regular file, or a FIFO read to its end: :func:`open_input`).

    ``max_bytes``: InputError beyond that size (read at most ``max_bytes + 1`` bytes: an endless stream
    never fills the memory).
    """
    with open_input(path, field, wait_s=wait_s) as f:
        data = f.read() if max_bytes is None else f.read(max_bytes + 1)
    if max_bytes is not None and len(data) > max_bytes:
        raise InputError(field, str(path), f"a file of at most {max_bytes} bytes")
    return data


def read_input_text(path, field: str, *, encoding: str = "utf-8", max_bytes: int | None = None,
                    wait_s: float | None = None) -> str:
    """:func:`read_input_bytes` decoded, with universal newlines (CRLF and CR read as LF, as
    :meth:`pathlib.Path.read_text` does); ``UnicodeDecodeError`` passes through: the callers name it."""
    text = read_input_bytes(path, field, max_bytes=max_bytes, wait_s=wait_s).decode(encoding)
    return text.replace("\r\n", "\n").replace("\r", "\n")

