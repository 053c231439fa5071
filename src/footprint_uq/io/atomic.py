"""Atomic outputs: write under a temporary name in the same folder, flush + fsync, then rename.

After any failure (an exception, a full disk, a killed process) nothing new stands under
the final name and the previous file of that name is intact; a temporary file left by a
killed process is hidden (its name starts with ``.``, which pyarrow datasets and globbing
skip) and carries :data:`TMP_MARK` (``.<stem>.tmp-<hex><suffix>``), so :func:`clean_temporaries` can remove it.

* :func:`atomic_path` -- a context manager yielding the temporary path to write (by any
  library: matplotlib, numpy, pyarrow), committed on a clean exit;
* :func:`atomic_write_text` / :func:`atomic_write_bytes` -- one call for small files;
* :func:`path_component` -- a name from data (a camera id) made safe to be one path component;
* :func:`swap_in_folder` / :func:`recover_folder` -- a folder of outputs built under a hidden name
  (``temp_path(out)``) put in place of ``out`` as one unit (an atomic exchange where the system has
  one), and what a killed swap left behind put right;
* :func:`output_set` -- a job's several files as one set: the context manager every multi-file command
  writes through (recover, check the folder holds only the job's own files, build hidden, swap in).
"""

from __future__ import annotations

import contextlib
import ctypes
import fnmatch
import glob
import os
import re
import shutil
import sys
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path
from urllib.parse import quote

from ..errors import InputError

__all__ = ["TMP_MARK", "atomic_path", "atomic_write_text", "atomic_write_bytes", "commit", "discard", "temp_path",
           "clean_temporaries", "clean_temporaries_of", "fsync_dir", "path_component", "same_file", "swap_in_folder",
           "recover_folder", "remove_tree", "OLD_MARK", "output_set", "check_output_folder", "final_paths"]

#: part of every temporary name (``.<stem>.tmp-<hex><suffix>``)
TMP_MARK = ".tmp-"
#: part of the hidden name a replaced output folder has until it is removed (``.<name>.old-<hex>``)
OLD_MARK = ".old-"


def temp_path(final) -> Path:
    """A fresh hidden temporary name next to ``final``: ``.<stem>.tmp-<8 hex><suffix>``.

    The extension is kept, so writers that choose their format by it (matplotlib, numpy's
    ``savez``, OpenCV's FileStorage) write the same bytes as under the final name.
    """
    final = Path(final)
    return final.with_name(f".{final.stem}{TMP_MARK}{uuid.uuid4().hex[:8]}{final.suffix}")


def fsync_dir(folder) -> None:
    """fsync a folder (makes a rename in it durable); a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - e.g. Windows
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - some file systems refuse fsync on folders
        pass
    finally:
        os.close(fd)


def commit(tmp, final, *, fsync: bool = True) -> None:
    """fsync ``tmp``, rename it to ``final`` (replacing it), fsync the folder.

    ``fsync=False`` only renames: the output is still never partial under its final name for a killed
    process (the rename follows the last write), but after a power loss or an operating-system crash
    it may be empty or missing -- for scratch outputs and tmpfs, where the fsyncs cost time for nothing.
    """
    if fsync:
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
    os.replace(tmp, final)
    if fsync:
        fsync_dir(Path(final).parent or ".")


def discard(tmp) -> None:
    """Remove a temporary file (never raises)."""
    with contextlib.suppress(OSError):
        Path(tmp).unlink()


@contextlib.contextmanager
def atomic_path(final, *, fsync: bool = True) -> Iterator[Path]:
    """Yield a temporary path next to ``final``; on a clean exit it replaces ``final``, else it is removed.

    Examples
    --------
    >>> with atomic_path("fig.png") as tmp:
    ...     fig.savefig(tmp)    # the temporary name keeps the extension
    """
    final = Path(final)
    tmp = temp_path(final)
    try:
        yield tmp
        commit(tmp, final, fsync=fsync)
    except BaseException:
        discard(tmp)
        raise


def atomic_write_bytes(path, data: bytes, *, parents: bool = False, fsync: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (``parents``: create missing folders; ``fsync`` as in
    :func:`commit`); returns the path."""
    path = Path(path)
    if parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, fsync=fsync) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
    return path


def atomic_write_text(path, text: str, *, encoding: str = "utf-8", parents: bool = False, fsync: bool = True) -> Path:
    """Write ``text`` to ``path`` atomically (``parents``: create missing folders; ``fsync`` as in
    :func:`commit`); returns the path."""
    return atomic_write_bytes(path, text.encode(encoding), parents=parents, fsync=fsync)


def clean_temporaries(folder, *, recursive: bool = True) -> int:
    """Remove the temporary files :func:`temp_path` names under ``folder``; returns how many."""
    folder = Path(folder)
    if not folder.is_dir():
        return 0
    it = folder.rglob(f".*{TMP_MARK}*") if recursive else folder.glob(f".*{TMP_MARK}*")
    n = 0
    for p in it:
        if p.is_file() and not p.is_symlink():
            discard(p)
            n += 1
    return n


def _temporaries_of(final) -> list[Path]:
    """The names :func:`temp_path` gives ``final`` that exist beside it: exactly ``.<stem>.tmp-<8 hex><suffix>``
    (a looser pattern would take ``fp.d``'s temporaries for those of ``fp``)."""
    final = Path(final)
    parent = final.parent if str(final.parent) else Path(".")
    if not parent.is_dir():
        return []
    exact = re.compile(re.escape(f".{final.stem}{TMP_MARK}") + "[0-9a-f]{8}" + re.escape(final.suffix))
    return [p for p in parent.glob(f".{glob.escape(final.stem)}{TMP_MARK}*") if exact.fullmatch(p.name)]


def clean_temporaries_of(final) -> int:
    """Remove the temporaries of ``final`` left by killed runs (``.<stem>.tmp-<8 hex><suffix>`` beside it)."""
    n = 0
    for p in _temporaries_of(final):
        if p.is_file() and not p.is_symlink():
            discard(p)
            n += 1
    return n


def path_component(name) -> str:
    """``name`` (text from data: a camera id) as one safe path component, percent-encoded.

    Every character but ASCII letters, digits and ``-_.~`` is encoded as ``%XX`` of its UTF-8
    bytes (what hive partitioning does), so ``/``, ``\\``, ``..``-tricks and control characters
    cannot leave the folder; ``.`` and ``..`` themselves and a leading ``.`` are encoded too.
    Distinct names give distinct components (``urllib.parse.unquote`` inverts it).
    """
    text = quote(str(name), safe="-_~")
    text = text.replace(".", "%2E") if text.strip(".") == "" or text.startswith(".") else text
    return text if text else "%00empty"


def same_file(a, b) -> bool:
    """True when ``a`` and ``b`` are the same file (hard links and symlinks included), by identity."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).absolute() == Path(b).absolute()


def _exchange(a, b) -> bool:
    """Swap two existing paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def remove_tree(p) -> None:
    """Remove a folder and everything under it, or a file or symbolic link (never follows a link; never raises)."""
    p = Path(p)
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        discard(p)


def swap_in_folder(staging, out, *, fsync: bool = True) -> None:
    """Put the finished folder ``staging`` in place of the folder ``out`` as one unit.

    Where the system can swap two names atomically (Linux), ``out`` holds the old folder or the new
    one at every moment; elsewhere the old folder is first renamed to ``.<name>.old-<hex>`` and, for a
    process killed between the two renames, :func:`recover_folder` puts it back.  The old folder is
    removed afterwards.
    """
    staging, out = Path(staging), Path(out)
    parent = out.parent if str(out.parent) else Path(".")
    if out.exists() and _exchange(staging, out):
        if fsync:
            fsync_dir(parent)
        remove_tree(staging)  # now the old folder
        return
    old = None
    if out.exists():
        old = out.with_name(f".{out.name}{OLD_MARK}{uuid.uuid4().hex[:8]}")
        os.rename(out, old)
    os.rename(staging, out)
    if fsync:
        fsync_dir(parent)
    if old is not None:
        remove_tree(old)


def recover_folder(out) -> None:
    """After a killed job on ``out``: remove its hidden staging folders, and restore the previous folder
    if a swap was killed between its two renames (``out`` missing, ``.<name>.old-*`` present)."""
    out = Path(out)
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        return
    for p in _temporaries_of(out):  # staging folders are named by temp_path
        remove_tree(p)
    olds = sorted(parent.glob(f".{out.name}{OLD_MARK}*"), key=lambda q: q.stat().st_mtime)
    if olds and not out.exists() and olds[-1].is_dir():
        os.rename(olds.pop(), out)
    for p in olds:
        remove_tree(p)


def check_output_folder(out, own: Iterable[str], command: str) -> None:
    """Refuse an output that is a file, or a folder holding anything but ``command``'s own files.

    ``own`` are the names (``fnmatch`` patterns: ``objects.*``) a previous run of the job writes; hidden
    temporaries of killed runs are ignored (the swap replaces the whole folder, so anything else in it
    -- the user's own files -- would be lost: refused, with the first such name).
    """
    out = Path(out)
    here = Path(os.path.abspath(out))
    if here.parent == here or here == Path.cwd() or Path.cwd().is_relative_to(here):
        raise InputError("--out", str(out), "a folder of its own (not the current folder, one above it or a root: "
                         "the whole folder is replaced)")
    if out.exists() and not out.is_dir():
        raise InputError("--out", str(out), "a folder (this is a file)")
    if out.is_dir():
        pats = tuple(own)
        other = sorted(p.name for p in out.iterdir()
                       if TMP_MARK not in p.name and not any(fnmatch.fnmatchcase(p.name, q) for q in pats))
        if other:
            raise InputError(f"--out {out}", f"a folder holding {other[0]!r}",
                             f"a new folder or one holding only a previous `{command}` run's files "
                             "(the whole folder is replaced)")


@contextlib.contextmanager
def output_set(out, own: Iterable[str], command: str, *, fsync: bool = True) -> Iterator[Path]:
    """A job's several output files as one set: yield a hidden staging folder beside ``out``; on a clean
    exit it replaces ``out`` as one unit (:func:`swap_in_folder`), else it is removed and ``out`` is untouched.

    Before it yields: what a killed run left is put right (:func:`recover_folder`) and ``out`` is checked
    (:func:`check_output_folder`: new, empty, or holding only ``own`` files of a previous run).  A reader of
    ``out`` sees the previous set or the new one at every moment, never a mix.

    Examples
    --------
    >>> with output_set(out_dir, ("summary.json", "objects.*"), "validate") as stage:
    ...     write_summary(stage / "summary.json"); write_objects(stage / "objects.csv")
    """
    out = Path(os.path.abspath(out))  # "dir/." and "dir/.." named as the folder they are
    check_output_folder(out, own, command)
    recover_folder(out)
    check_output_folder(out, own, command)
    parent = out.parent if str(out.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    staging = temp_path(out)
    staging.mkdir()
    try:
        yield staging
        swap_in_folder(staging, out, fsync=fsync)
    except BaseException:
        remove_tree(staging)
        raise


def final_paths(files, staging, out):
    """The paths of ``files`` (a dict or list of paths under ``staging``) once ``staging`` is ``out``."""
    staging, out = Path(staging), Path(out)

    def one(p):
        if p is None:
            return None
        p = Path(p)
        try:
            return out / p.relative_to(staging)
        except ValueError:
            return p

    if isinstance(files, dict):
        return {k: final_paths(v, staging, out) if isinstance(v, dict | list) else one(v) for k, v in files.items()}
    return [one(p) for p in files]
