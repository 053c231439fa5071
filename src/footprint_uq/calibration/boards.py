"""Checkerboard geometry: inner corners, square size, object points, outline.

Board frame B (metres): origin at the first inner corner, x along the columns
(``cols`` inner corners), y along the rows (``rows`` inner corners), z = 0 on
the board (OpenCV's convention for ``calibrateCamera`` object points).  Corner
``(i, j)`` (column i, row j) sits at ``(i s, j s, 0)`` with ``s = square_m``;
corners are listed row by row (index ``j * cols + i``), the order in which
:func:`cv2.findChessboardCorners` returns them.

The printed squares extend one square beyond the inner corners on every side
(``cols + 1`` by ``rows + 1`` squares), and the board has a white ``margin_m``
around the squares.  The square at the first inner corner's upper-left
(``x, y in (-s, 0)``) is black.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Checkerboard", "parse_board", "PAPER_BOARD"]


@dataclass(frozen=True)
class Checkerboard:
    """A planar checkerboard target.

    Parameters
    ----------
    cols, rows : int
        Inner corners along the board's x (columns) and y (rows); OpenCV's
        ``patternSize = (cols, rows)``.  Both must be >= 2.
    square_m : float
        Side of one square, metres (> 0).
    margin_m : float
        White border around the outer squares, metres (>= 0).  Used by the
        renderer and by the board outline; not needed for intrinsic calibration.
    """

    cols: int
    rows: int
    square_m: float = 0.025
    margin_m: float = 0.0

    def __post_init__(self):
        for name in ("cols", "rows"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 2:
                raise InputError(f"board {name}", v, "an integer >= 2 (inner corners)")
        if not (np.isfinite(self.square_m) and self.square_m > 0):
            raise InputError("board square_m", self.square_m, "a finite square size > 0 m")
        if not (np.isfinite(self.margin_m) and self.margin_m >= 0):
            raise InputError("board margin_m", self.margin_m, "a finite margin >= 0 m")

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` as OpenCV's ``patternSize``."""
        return (int(self.cols), int(self.rows))

    @property
    def n_corners(self) -> int:
        return int(self.cols * self.rows)

    @property
    def size_m(self) -> tuple[float, float]:
        """Outer size ``(width, height)`` of the board including squares and margin, metres."""
        s = self.square_m
        return ((self.cols + 1) * s + 2 * self.margin_m, (self.rows + 1) * s + 2 * self.margin_m)

    def label(self) -> str:
        return f"{self.cols}x{self.rows}"

    def object_points(self, dtype=np.float64) -> np.ndarray:
        """Inner corners in the board frame, shape ``(rows * cols, 3)``, metres, OpenCV order."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        pts = np.zeros((self.n_corners, 3), dtype=dtype)
        pts[:, 0] = i.ravel() * self.square_m
        pts[:, 1] = j.ravel() * self.square_m
        return pts

    def outline(self, *, include_margin: bool = False, n_per_edge: int = 16) -> np.ndarray:
        """Points along the outer edge of the squares (or of the board with margin), ``(4 n, 3)``, metres.

        Sampled densely so that, once projected through a distorting lens, the
        convex hull of the points follows the curved edges.
        """
        s = self.square_m
        e = s + (self.margin_m if include_margin else 0.0)
        x0, x1 = -e, (self.cols - 1) * s + e
        y0, y1 = -e, (self.rows - 1) * s + e
        t = np.linspace(0.0, 1.0, int(n_per_edge), endpoint=False)
        top = np.stack([x0 + (x1 - x0) * t, np.full_like(t, y0)], -1)
        right = np.stack([np.full_like(t, x1), y0 + (y1 - y0) * t], -1)
        bottom = np.stack([x1 - (x1 - x0) * t, np.full_like(t, y1)], -1)
        left = np.stack([np.full_like(t, x0), y1 - (y1 - y0) * t], -1)
        xy = np.concatenate([top, right, bottom, left])
        return np.concatenate([xy, np.zeros((len(xy), 1))], axis=1)


#: the paper's target: 14 x 9 inner corners (square size not given in the paper; 0.1 m assumed)
PAPER_BOARD = Checkerboard(14, 9, square_m=0.1, margin_m=0.05)

_BOARD_RE = re.compile(r"^\s*(\d+)\s*[xX*,]\s*(\d+)\s*$")


def parse_board(spec, square_m: float = 0.025, margin_m: float = 0.0) -> Checkerboard:
    """A :class:`Checkerboard` from ``"9x6"`` (inner corners ``cols x rows``), a pair or a Checkerboard."""
    if isinstance(spec, Checkerboard):
        return spec
    if isinstance(spec, str):
        m = _BOARD_RE.match(spec)
        if not m:
            raise InputError("board", spec, "inner corners as COLSxROWS, e.g. 9x6")
        cols, rows = int(m.group(1)), int(m.group(2))
    else:
        try:
            cols, rows = (int(v) for v in spec)
        except (TypeError, ValueError):
            raise InputError("board", spec, "inner corners as COLSxROWS, e.g. 9x6, or a pair (cols, rows)") from None
    try:
        sq = float(square_m)
    except (TypeError, ValueError):
        raise InputError("square_m", square_m, "a square size in metres (> 0)") from None
    return Checkerboard(cols, rows, sq, float(margin_m))
