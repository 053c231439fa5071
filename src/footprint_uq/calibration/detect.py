"""Chessboard corner detection over many frames (image files, folders, globs, videos).

Every input frame ends up in the returned list: frames where no board is found,
unreadable files and missing paths are kept with ``found=False`` and a
``reason``, never dropped.  Detection runs in parallel over frames (a process
pool; video frames are decoded in the calling process, in order, and sent to
the pool) with a tqdm progress bar.

Corner detector: :func:`cv2.findChessboardCorners` (adaptive threshold,
normalised image) refined by :func:`cv2.cornerSubPix`, or
:func:`cv2.findChessboardCornersSB` (sector-based, already sub-pixel), or
``"auto"``: the first, falling back to the second when it finds nothing.

The sub-pixel search window adapts to the board's size in the image: its
half-size is 40 % of the smallest spacing between neighbouring corners, clipped
to 2..11 px, so that the window never reaches the next corner (a window larger
than the squares biases the refined corner).

Corner order: OpenCV's row-major order, oriented so that the first corner is
the one nearer the image's upper-left (smaller ``u + v``) of the two ends; the
two detectors otherwise may start at opposite ends of the board.
"""

from __future__ import annotations

import glob
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm.auto import tqdm

from .._files import require_regular
from ..errors import InputError
from .boards import Checkerboard, parse_board

__all__ = ["mp_context", "FrameSource", "Detection", "expand_inputs", "detect_corners", "detect_frames",
           "IMAGE_EXTENSIONS", "VIDEO_EXTENSIONS", "METHODS"]

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv")
METHODS = ("auto", "classic", "sb")


@dataclass(frozen=True)
class FrameSource:
    """Where one frame comes from: an image file, or frame ``frame_index`` of a video."""

    path: str
    frame_index: int | None = None

    @property
    def label(self) -> str:
        name = os.path.basename(self.path) or self.path
        return name if self.frame_index is None else f"{name}#frame={self.frame_index}"


@dataclass
class Detection:
    """Result of corner detection on one frame.

    Attributes
    ----------
    source : FrameSource
    found : bool
        True when the whole board (all inner corners) was found.
    corners_px : ndarray (N, 2) or None
        Sub-pixel corner positions ``(u, v)``, px, in the board's corner order.
    image_size_px : (int, int) or None
        ``(width, height)`` of the frame; None when unreadable.
    reason : str
        Empty when found; otherwise why not (``"no board found"``, ``"unreadable image: ..."``, ...).
    method : str
        Detector that found the board (``"classic"`` or ``"sb"``), empty if none.
    """

    source: FrameSource
    found: bool
    corners_px: np.ndarray | None = None
    image_size_px: tuple[int, int] | None = None
    reason: str = ""
    method: str = ""

    @property
    def label(self) -> str:
        return self.source.label


# ---------------------------------------------------------------------------------- inputs
def _is_video(path: str) -> bool:
    return Path(path).suffix.lower() in VIDEO_EXTENSIONS


def expand_inputs(inputs, *, video_step: int = 1) -> list[FrameSource]:
    """Expand files, folders, globs and videos into frame sources.

    Parameters
    ----------
    inputs : str, Path or sequence of them
        Image files, folders (their images, sorted by name, not recursive),
        glob patterns (``"calib/*.png"``) or video files.
    video_step : int
        Keep every ``video_step``-th frame of videos (>= 1).

    Returns
    -------
    list of FrameSource
        In input order.  A path that does not exist or a glob that matches
        nothing is kept as a source (detection then reports it as unreadable),
        never dropped.  Video entries are expanded lazily: one source with
        ``frame_index=-1`` stands for the whole video until :func:`detect_frames`
        decodes it.
    """
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    try:
        step = int(video_step)
    except (TypeError, ValueError):
        raise InputError("video_step", video_step, "an integer >= 1") from None
    if step < 1:
        raise InputError("video_step", video_step, "an integer >= 1")
    out: list[FrameSource] = []
    for item in inputs:
        s = os.fspath(item)
        if os.path.isdir(s):
            files = sorted(p for p in Path(s).iterdir()
                           if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS + VIDEO_EXTENSIONS)
            for p in files:
                out.append(FrameSource(str(p), -1 if _is_video(str(p)) else None))
        elif os.path.exists(s):  # a FIFO or device: refused (OpenCV would wait on it for a writer)
            require_regular(s, "images", "an image or video file, which OpenCV reads with seeking")
            out.append(FrameSource(s, -1 if _is_video(s) else None))
        elif glob.has_magic(s):
            matches = sorted(glob.glob(s))
            if not matches:
                out.append(FrameSource(s))
            for p in matches:
                if os.path.isfile(p):
                    out.append(FrameSource(p, -1 if _is_video(p) else None))
        else:
            out.append(FrameSource(s))
    return out


# ---------------------------------------------------------------------------------- detection
def _to_gray(image) -> np.ndarray:

    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY if a.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise InputError("image", f"shape {a.shape}", "a grey (H, W) or colour (H, W, 3) image")
    if a.dtype != np.uint8:
        if np.issubdtype(a.dtype, np.floating) and np.nanmax(a) <= 1.0:
            a = a * 255.0
        elif a.dtype == np.uint16:
            a = a / 257.0
        a = np.clip(np.nan_to_num(a), 0, 255).astype(np.uint8)
    return a


def _orient(corners: np.ndarray) -> np.ndarray:
    if corners[0].sum() > corners[-1].sum():
        return corners[::-1].copy()
    return corners


def _subpix_half_window(corners: np.ndarray, board: Checkerboard) -> int:
    g = corners.reshape(board.rows, board.cols, 2)
    d = np.concatenate([np.linalg.norm(np.diff(g, axis=1), axis=-1).ravel(),
                        np.linalg.norm(np.diff(g, axis=0), axis=-1).ravel()])
    return int(np.clip(np.floor(0.4 * d.min()), 2, 11))


def detect_corners(image, board, *, method: str = "auto", subpix: bool = True) -> tuple[np.ndarray | None, str]:
    """Find the inner corners of ``board`` in one image.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3)
        Grey or BGR image (uint8, uint16 or float in [0, 1]).
    board : Checkerboard or str
        E.g. ``"9x6"``.
    method : {"auto", "classic", "sb"}
    subpix : bool
        Refine classic detections with :func:`cv2.cornerSubPix`.

    Returns
    -------
    corners_px : ndarray (N, 2) or None
        ``N = board.n_corners``, px; None when not found.
    method : str
        The detector that found the board, or ``""``.
    """

    board = parse_board(board)
    if method not in METHODS:
        raise InputError("method", method, f"one of {METHODS}")
    gray = _to_gray(image)
    size = board.pattern_size
    if method in ("auto", "classic"):
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        ok, c = cv2.findChessboardCorners(gray, size, flags=flags)
        if ok and c is not None and len(c) == board.n_corners:
            c = c.reshape(-1, 2).astype(np.float32)
            if subpix:
                w = _subpix_half_window(c, board)
                crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
                c = cv2.cornerSubPix(gray, c.reshape(-1, 1, 2), (w, w), (-1, -1), crit).reshape(-1, 2)
            return _orient(c.astype(np.float64)), "classic"
    if method in ("auto", "sb"):
        flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY
        ok, c = cv2.findChessboardCornersSB(gray, size, flags=flags)
        if ok and c is not None and len(c) == board.n_corners:
            return _orient(c.reshape(-1, 2).astype(np.float64)), "sb"
    return None, ""


def _detect_one(source: FrameSource, gray, board: Checkerboard, method: str, subpix: bool) -> Detection:

    if gray is None:
        if not os.path.exists(source.path):
            return Detection(source, False, reason="unreadable image: file not found")
        try:
            gray = cv2.imread(source.path, cv2.IMREAD_GRAYSCALE)
        except cv2.error as e:  # pragma: no cover - depends on codec
            return Detection(source, False, reason=f"unreadable image: {str(e).splitlines()[0]}")
        if gray is None:
            return Detection(source, False, reason="unreadable image: not a decodable image file")
    size = (int(gray.shape[1]), int(gray.shape[0]))
    try:
        corners, used = detect_corners(gray, board, method=method, subpix=subpix)
    except cv2.error as e:
        return Detection(source, False, image_size_px=size, reason=f"detector error: {str(e).splitlines()[0]}")
    if corners is None:
        return Detection(source, False, image_size_px=size, reason=f"no board found ({board.label()} inner corners)")
    if not np.all(np.isfinite(corners)):
        return Detection(source, False, image_size_px=size, reason="detector returned non-finite corners")
    return Detection(source, True, corners, size, "", used)


def mp_context():
    """Process start method of the pools: ``spawn``.

    ``fork`` deadlocks once OpenCV's thread pool (or a video decoder) has run in
    the parent process.  With ``spawn``, a script calling these functions needs
    the usual ``if __name__ == "__main__":`` guard.
    """

    return multiprocessing.get_context("spawn")


def _worker_init():

    cv2.setNumThreads(1)


def _worker(args):
    source, gray, board, method, subpix = args
    return _detect_one(source, gray, board, method, subpix)


def _iter_tasks(sources: list[FrameSource], video_step: int, report):
    """Yield ``(source, gray or None)``; videos are decoded here, in order."""

    for src in sources:
        if src.frame_index != -1:
            yield src, None
            continue
        cap = cv2.VideoCapture(src.path)
        if not cap.isOpened():
            report(Detection(FrameSource(src.path), False, reason="unreadable video: cannot open"))
            continue
        idx = 0
        n_read = 0
        try:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                if idx % video_step == 0:
                    n_read += 1
                    yield FrameSource(src.path, idx), _to_gray(frame)
                idx += 1
        finally:
            cap.release()
        if n_read == 0:
            report(Detection(FrameSource(src.path), False, reason="unreadable video: no frame decoded"))


def detect_frames(inputs, board, *, video_step: int = 1, workers: int | None = None, method: str = "auto",
                  subpix: bool = True, progress: bool = True) -> list[Detection]:
    """Detect the board in every frame of ``inputs``.

    Parameters
    ----------
    inputs : path, glob, folder, video, or a sequence of them (see :func:`expand_inputs`)
    board : Checkerboard or str
    video_step : int
        Use every ``video_step``-th frame of videos.
    workers : int or None
        Processes (None: ``os.cpu_count()``; 1: no pool).
    method : {"auto", "classic", "sb"}
    subpix : bool
    progress : bool
        Show a tqdm progress bar (on stderr).

    Returns
    -------
    list of Detection
        One per frame, in input order (video frames in frame order); failures
        included with their reason.
    """

    board = parse_board(board)
    if method not in METHODS:
        raise InputError("method", method, f"one of {METHODS}")
    sources = expand_inputs(inputs, video_step=video_step)
    if not sources:
        raise InputError("images", inputs, "at least one image file, folder, glob or video")
    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if n_workers < 1:
        raise InputError("workers", workers, "an integer >= 1")
    n_known = sum(1 for s in sources if s.frame_index != -1)
    has_video = n_known < len(sources)
    results: list[tuple[int, Detection]] = []
    order = 0

    def report(det):
        nonlocal order
        results.append((order, det))
        order += 1
        bar.update(1)

    bar = tqdm(total=None if has_video else len(sources), desc="detect", unit="frame", disable=not progress)
    try:
        if n_workers == 1 or (len(sources) == 1 and not has_video):
            for src, gray in _iter_tasks(sources, int(video_step), report):
                report(_detect_one(src, gray, board, method, subpix))
        else:
            with ProcessPoolExecutor(max_workers=n_workers, initializer=_worker_init,
                                     mp_context=mp_context()) as ex:
                pending = {}
                window = 4 * n_workers
                for src, gray in _iter_tasks(sources, int(video_step), report):
                    pending[ex.submit(_worker, (src, gray, board, method, subpix))] = order
                    order += 1
                    if len(pending) >= window:
                        done, _ = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in done:
                            results.append((pending.pop(fut), fut.result()))
                            bar.update(1)
                for fut in list(pending):
                    results.append((pending.pop(fut), fut.result()))
                    bar.update(1)
    finally:
        bar.close()
    results.sort(key=lambda r: r[0])
    return [d for _, d in results]
