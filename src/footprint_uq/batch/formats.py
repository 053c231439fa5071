"""Detector formats in: YOLO / ultralytics labels, YOLOv5 pandas CSV, COCO results, MOTChallenge files, ROS 2 bags.

Each format is one small reader (a :class:`FormatReader`) that turns its files into the canonical
detection table the batch processes (:mod:`footprint_uq.batch.schema`: ``u_min_px, v_min_px, u_max_px,
v_max_px`` and the id columns ``frame, object_id, class, score, image, line``), in chunks of rows, with
the same interface as :class:`~footprint_uq.batch.readers.DetectionReader` (``columns``, ``id_fields``,
``select``, iteration over :class:`~footprint_uq.batch.readers.Chunk`), so that ``objects``, ``validate``
and :func:`read_detections` take them unchanged.  :data:`READERS` is the registry (one line per format);
:func:`detect_input_format` picks a format from what the file says (extension, CSV header, a folder of
``.txt``, the first label line), :func:`open_reader` opens any of them.  The ROS 2 bag's reader
(``ros2-bag``) lives in ``integrations/ros2/``, a layer above this one: its entry is a :class:`LazyFormat`
that names it and imports it only when a bag is opened (docs/integrations.md, "ROS 2 bags and Foxglove").

Nothing is dropped or guessed: every label line / result entry is one row (empty lines included), and a
line that cannot be parsed, a box with ``w <= 0`` or outside ``[0, 1]`` (normalised formats), or a class
id without a name is an error row of that detection with its reason (a malformed line: with its file and
line number); the other rows go on.  Images of another size than the camera's stop the job
(:class:`~footprint_uq.errors.InputError`, one line).

Pixel conventions (docs/conventions.md, section 2: pixel centres at integers): YOLO, ultralytics, COCO and
supervision boxes are continuous coordinates in which the image spans ``[0, W] x [0, H]``, so every
coordinate is shifted by ``-0.5`` px (:data:`EDGE_SHIFT_PX`); MOTChallenge boxes are 1-based (the
top-left pixel is ``(1, 1)``) and are shifted by ``-1`` px (:data:`MOT_SHIFT_PX`).  docs/integrations.md
has an example of every format.
"""

from __future__ import annotations

import configparser
import csv
import importlib
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.compute as pc

from .._files import file_kind, is_stream
from ..errors import InputError
from ..io.class_names import ClassNames, names_from_categories
from . import schema as S
from .readers import FORMATS as TABLE_FORMATS
from .readers import Chunk, DetectionReader

__all__ = ["FormatOptions", "FormatReader", "YoloLabels", "Yolov5Csv", "CocoResults", "MotChallenge", "READERS",
           "INPUT_FORMATS", "EDGE_SHIFT_PX", "MOT_SHIFT_PX", "NORMALISED_TOL", "detect_input_format", "open_reader",
           "read_detections", "NamedClasses", "table_format", "name_classes", "LazyFormat", "is_ros2_bag"]

#: continuous image coordinates (the image spans [0, W]) -> pixel centres at integers
EDGE_SHIFT_PX = 0.5
#: MOTChallenge's 1-based pixel coordinates -> 0-based
MOT_SHIFT_PX = 1.0
#: slack of the [0, 1] test of a normalised box (ultralytics writes 6 significant digits of a clipped box)
NORMALISED_TOL = 1e-6


@dataclass(frozen=True)
class FormatOptions:
    """What a reader needs beyond its files.

    Attributes
    ----------
    class_names : ClassNames, optional    id -> name map (default: the format's own, e.g. COCO for YOLO)
    image_size_px : (int, int), optional  (width, height) of the camera's images: the size normalised boxes
        are scaled to; a file that states another size is refused
    unknown_class : {"error", "unknown"}   the policy of the format's own names (its default map, COCO's
        categories)
    topic : str, optional   the topic of a ROS 2 bag (``ros2-bag``; default: the bag's only Detection2DArray topic)
    """

    class_names: ClassNames | None = None
    image_size_px: tuple[int, int] | None = None
    unknown_class: str = "error"
    topic: str | None = None


def _first_line(e: BaseException) -> str:
    text = str(e).splitlines()
    return (text[0] if text else type(e).__name__)[:100]


def _int(text: str) -> int:
    """An integer field of the 64-bit range (``"3"``, also ``"3.0"``); ValueError otherwise."""
    try:
        v = int(text)
    except ValueError:
        x = float(text)
        if not (math.isfinite(x) and x.is_integer()):
            raise ValueError(f"{text[:40]!r} is not an integer") from None
        v = int(x)
    if not -(2**63) <= v < 2**63:
        raise ValueError(f"{text[:40]!r} is out of the 64-bit integer range")
    return v


def _float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"{text!r} is not finite")
    return x


class FormatReader:
    """Base of the detector-format readers: the canonical chunks of a format's records.

    A subclass sets :attr:`name` and :attr:`id_columns` (the id columns it fills, in
    :data:`~footprint_uq.batch.schema.ID_COLUMNS`) and implements :meth:`records`, which yields one
    ``(ids, box_xyxy_px, error, progress)`` per detection: ``ids`` a tuple aligned with
    ``id_columns``, ``box_xyxy_px`` four floats in the project's pixel convention (or None), ``error`` the
    reason the row is an error row (or None), ``progress`` the units consumed (bytes or rows).

    Attributes (as :class:`~footprint_uq.batch.readers.DetectionReader`)
    ---------------------------------------------------------------------
    path, format, columns, family_columns, id_fields, chunk_rows, total, unit ("B" or "rows"),
    lines (records read so far: every line of a line format is one record)
    """

    name: ClassVar[str] = ""
    id_columns: tuple[str, ...] = ()

    def __init__(self, path, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, options: FormatOptions | None = None):
        self.path = Path(path)
        if not self.path.exists():
            raise InputError("detections", str(path), "an existing file or folder")
        if int(chunk_rows) < 1:
            raise InputError("chunk_rows", chunk_rows, "an integer >= 1")
        self.chunk_rows = int(chunk_rows)
        self.options = options or FormatOptions()
        self.format = self.name
        self.lines = 0
        self.total, self.unit = None, "rows"
        self.numeric: tuple[str, ...] = S.BOX2D_COLUMNS
        self._setup()
        self.columns = list(self.id_columns) + list(S.BOX2D_COLUMNS)
        self.family_columns = list(self.columns)

    def _setup(self) -> None:
        """Open / index the input (sets ``id_columns``, ``total``, ``unit``)."""

    @classmethod
    def sniff(cls, path: Path) -> bool:
        """Does ``path`` say it is in this format?"""
        return False

    def records(self) -> Iterator[tuple[tuple, tuple | None, str | None, int]]:
        """``(ids, box or None, reason or None, bytes)`` of every detection, in input order: each format's own
        parser (every registered subclass defines it; the base class is never instantiated)."""
        raise NotImplementedError(f"{type(self).__name__} defines no records(): every FormatReader subclass must")

    # DetectionReader's interface
    def select(self, numeric) -> None:
        extra = [c for c in numeric if c not in S.BOX2D_COLUMNS]
        if extra:
            raise InputError("box columns", extra, f"the 2-D box columns {list(S.BOX2D_COLUMNS)} ({self.name} "
                             "files hold 2-D boxes)")

    @property
    def id_fields(self) -> list[pa.Field]:
        return [pa.field(c, S.ID_TYPES[c]) for c in self.id_columns]

    def __iter__(self) -> Iterator[Chunk]:
        ids: list[list] = [[] for _ in self.id_columns]
        box: list = []
        pre: list = []
        progress = 0
        for rec_ids, rec_box, err, used in self.records():
            for col, v in zip(ids, rec_ids, strict=True):
                col.append(v)
            box.append(rec_box if rec_box is not None else (math.nan,) * 4)
            pre.append(err)
            progress += used
            if len(box) == self.chunk_rows:
                yield self._chunk(ids, box, pre, progress)
                ids, box, pre, progress = [[] for _ in self.id_columns], [], [], 0
        if box:
            yield self._chunk(ids, box, pre, progress)

    def _chunk(self, ids, box, pre, progress) -> Chunk:
        n = len(box)
        row0 = self.lines
        self.lines += n
        xy = np.asarray(box, dtype=np.float64).reshape(n, 4)
        cols = {c: pa.array(v, type=S.ID_TYPES[c]) for c, v in zip(self.id_columns, ids, strict=True)}
        cols.update({c: pa.array(xy[:, j]) for j, c in enumerate(S.BOX2D_COLUMNS)})
        return Chunk(pa.table(cols), np.arange(row0, row0 + n, dtype=np.int64),
                     pre if any(p is not None for p in pre) else None, [], progress)

    # shared helpers
    def _class_names(self, default: str) -> ClassNames:
        return self.options.class_names or ClassNames.load(default, unknown=self.options.unknown_class)

    def _require_size(self) -> tuple[int, int]:
        if self.options.image_size_px is None:
            raise InputError("image_size_px", None, f"the (width, height) the {self.name} boxes are normalised to: "
                             "the camera's image size, or --image-size W H")
        w, h = self.options.image_size_px
        return int(w), int(h)

    def _check_size(self, size, where: str) -> None:
        want = self.options.image_size_px
        if want is not None and size is not None and tuple(int(v) for v in size) != tuple(int(v) for v in want):
            raise InputError(where, f"{size[0]} x {size[1]} px", f"images of the camera's size {want[0]} x "
                             f"{want[1]} px (calibrate the camera at this size, or give detections of its images)")


def _text_lines(path: Path):
    """``(line number, text or None, reason or None, bytes)`` of every physical line of a text file."""
    with open(path, "rb") as f:
        for i, raw in enumerate(f, 1):
            size = len(raw)
            raw = raw[3:] if i == 1 and raw.startswith(b"\xef\xbb\xbf") else raw
            try:
                yield i, raw.decode("utf-8").rstrip("\r\n"), None, size
            except UnicodeDecodeError as e:
                yield i, None, f"not UTF-8 (byte 0x{e.object[e.start]:02x} at column {e.start + 1})", size


# -- YOLO / ultralytics ------------------------------------------------------------------------------------
class YoloLabels(FormatReader):
    """YOLO / ultralytics labels and predictions: one ``.txt`` per image, ``class cx cy w h [conf]``.

    ``cx cy w h`` are normalised to the image size (``FormatOptions.image_size_px``: the camera's); the
    path is a folder of ``.txt`` files (or one with a ``labels/`` folder of them, as ultralytics writes
    with ``save_txt=True``) or one label file.  Files are read in name order; ``frame`` is the number the
    file names end in when every name ends in one and those numbers are distinct (``000123.txt``,
    ``frame_17.txt``), else the file's 0-based position in name order; ``image`` is the file name without
    ``.txt``, ``line`` the 1-based line.  Class names: ``FormatOptions.class_names`` (a ``data.yaml``), else
    the ``classes.txt`` beside the labels (LabelImg, darknet tools; never read as a label file), else COCO's 80.
    """

    name = "yolo"
    id_columns = ("frame", "class", "score", "image", "line")

    @classmethod
    def sniff(cls, path: Path) -> bool:
        if path.is_dir():
            return bool(cls._files(path))
        if path.suffix.lower() != ".txt":
            return False
        first = _first_content_line(path)
        return first is not None and "," not in first and len(first.split()) in (5, 6)

    #: the class list LabelImg / darknet tools write beside the labels: not a label file
    NAMES_FILE = "classes.txt"

    @classmethod
    def _files(cls, path: Path) -> list[Path]:
        files = sorted(p for p in path.glob("*.txt") if p.is_file() and p.name != cls.NAMES_FILE)
        if not files and (path / "labels").is_dir():
            files = sorted(p for p in (path / "labels").glob("*.txt") if p.is_file() and p.name != cls.NAMES_FILE)
        return files

    def _setup(self) -> None:
        self.files = self._files(self.path) if self.path.is_dir() else [self.path]
        if not self.files:
            raise InputError("detections", str(self.path), "a folder of YOLO label files (*.txt, or labels/*.txt)")
        self.frames = _frames_of(self.files)
        self.total, self.unit = sum(p.stat().st_size for p in self.files), "B"
        self.size = self._require_size()
        beside = self.files[0].parent / self.NAMES_FILE
        if self.options.class_names is None and beside.is_file():
            self.names = ClassNames.load(beside, unknown=self.options.unknown_class)
        else:
            self.names = self._class_names("coco")

    def records(self):
        for path, frame in zip(self.files, self.frames, strict=True):
            for lineno, text, why, used in _text_lines(path):
                ids, box, err = self._line(text, why, path, lineno, frame)
                yield ids, box, err, used

    def _line(self, text, why, path: Path, lineno: int, frame: int):
        image = path.stem
        where = f"{path.name} line {lineno}"
        if why is not None:
            return (frame, None, None, image, lineno), None, f"{where}: malformed YOLO label line ({why})"
        fields = text.split()
        if len(fields) not in (5, 6):
            got = "empty line" if not fields else f"{len(fields)} fields"
            return (frame, None, None, image, lineno), None, \
                f"{where}: malformed YOLO label line ({got}; expected 5 or 6: class cx cy w h [conf])"
        try:
            cid = _int(fields[0])
            cx, cy, w, h = (_float(t) for t in fields[1:5])
            score = _float(fields[5]) if len(fields) == 6 else None
        except ValueError as e:
            return (frame, None, None, image, lineno), None, f"{where}: malformed YOLO label line ({e})"
        name, err = self.names.lookup(cid)
        ids = (frame, name, score, image, lineno)
        if err is None and not (w > 0 and h > 0):
            err = f"box width or height <= 0 (normalised w {w:g}, h {h:g})"
        lo_u, hi_u, lo_v, hi_v = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
        if err is None and not (min(lo_u, lo_v) >= -NORMALISED_TOL and max(hi_u, hi_v) <= 1 + NORMALISED_TOL):
            err = "normalised box outside [0, 1] (the labels are not normalised to the image size, or the box " \
                  "leaves the image)"
        W, H = self.size
        box = (lo_u * W - EDGE_SHIFT_PX, lo_v * H - EDGE_SHIFT_PX, hi_u * W - EDGE_SHIFT_PX, hi_v * H - EDGE_SHIFT_PX)
        return ids, box, err


def _first_content_line(path: Path) -> str | None:
    try:
        with open(path, "rb") as f:
            for i, raw in enumerate(f):
                if i > 100:
                    return None
                text = raw.decode("utf-8", "replace").strip()
                if text:
                    return text
    except OSError:
        return None
    return None


_TRAILING_NUMBER = re.compile(r"(\d+)$")


def _frames_of(files: list[Path]) -> list[int]:
    """The number each file name ends in, when all do and they are distinct; else the position in the list."""
    nums = [_TRAILING_NUMBER.search(p.stem) for p in files]
    if all(nums):
        values = [int(m.group(1)) for m in nums]
        if len(set(values)) == len(values) and all(v < 2**63 for v in values):
            return values
    return list(range(len(files)))


# -- YOLOv5 / pandas CSV ----------------------------------------------------------------------------------
class Yolov5Csv(FormatReader):
    """YOLOv5 / pandas-style CSV: ``xmin,ymin,xmax,ymax,confidence,class,name`` (``results.pandas().xyxy``).

    Boxes in pixels (continuous coordinates, shifted by :data:`EDGE_SHIFT_PX`); optional ``frame`` (an
    integer) and ``image`` columns; an unnamed pandas index column and other columns are ignored.  The
    class is ``name`` where it is given, else the ``class`` id through the names map (default COCO's 80).
    """

    name = "yolov5-csv"
    BOX = ("xmin", "ymin", "xmax", "ymax")

    @classmethod
    def sniff(cls, path: Path) -> bool:
        return path.suffix.lower() == ".csv" and all(c in _csv_header_names(path) for c in cls.BOX)

    def _setup(self) -> None:
        if not self.path.is_file():
            raise InputError("detections", str(self.path), "a YOLOv5 CSV file")
        header = _csv_header_names(self.path)
        missing = [c for c in self.BOX if c not in header]
        if missing:
            raise InputError(f"{self.path}: columns", missing, "the YOLOv5 box columns xmin, ymin, xmax, ymax")
        self.header = header
        self.idx = {c: header.index(c) for c in (*self.BOX, "confidence", "class", "name", "frame", "image")
                    if c in header}
        has_class = "class" in self.idx or "name" in self.idx
        self.id_columns = tuple(c for c, on in (("frame", "frame" in self.idx), ("class", has_class),
                                                ("score", "confidence" in self.idx), ("image", "image" in self.idx),
                                                ("line", True)) if on)
        self.total, self.unit = self.path.stat().st_size, "B"
        self.names = self._class_names("coco")

    def records(self):
        lines = _text_lines(self.path)
        next(lines, None)  # the header
        for lineno, text, why, used in lines:
            yield (*self._line(text, why, lineno), used)

    def _line(self, text, why, lineno):
        values = {"line": lineno}
        where = f"{self.path.name} line {lineno}"
        if why is None:
            try:
                fields = next(csv.reader([text], strict=True)) if text else []
            except csv.Error as e:
                fields, why = [], f"{e}"
            if why is None and len(fields) != len(self.header):
                why = "empty line" if not fields else f"{len(fields)} fields, expected {len(self.header)}"
        if why is not None:
            return self._ids(values), None, f"{where}: malformed CSV line ({why})"
        err = None
        get = {c: fields[j].strip() for c, j in self.idx.items()}
        if "image" in get:
            values["image"] = get["image"] or None
        try:
            if get.get("frame"):
                values["frame"] = _int(get["frame"])
            box = tuple(_float(get[c]) - EDGE_SHIFT_PX for c in self.BOX)
            if get.get("confidence"):
                values["score"] = _float(get["confidence"])
        except ValueError as e:
            return self._ids(values), None, f"{where}: {e}"
        if get.get("name"):
            values["class"] = get["name"]
        elif get.get("class"):
            try:
                values["class"], err = self.names.lookup(_int(get["class"]))
            except ValueError as e:
                err = f"field class: {e}"
        return self._ids(values), box, err

    def _ids(self, values: dict) -> tuple:
        return tuple(values.get(c) for c in self.id_columns)


def _csv_header_names(path: Path) -> list[str]:
    try:
        with open(path, "rb") as f:
            raw = f.readline()
        text = (raw[3:] if raw.startswith(b"\xef\xbb\xbf") else raw).decode("utf-8").rstrip("\r\n")
        return [c.strip() for c in next(csv.reader([text], strict=True))] if text else []
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


# -- COCO --------------------------------------------------------------------------------------------------
class CocoResults(FormatReader):
    """COCO detection results (``[{image_id, category_id, bbox: [x, y, w, h], score}, ...]``) or a COCO
    dataset's ``annotations``.

    ``frame`` is the ``image_id``; where the dataset's ``images`` are known (in the file, or in the COCO
    dataset JSON given as class names) ``image`` is its ``file_name`` and its ``width x height`` must be
    the camera's.  Class names: the ``categories`` (file or class-names dataset), default COCO's category
    ids (``coco91``).  ``bbox`` in pixels, continuous coordinates (shifted by :data:`EDGE_SHIFT_PX`);
    ``w <= 0`` or ``h <= 0`` is that detection's error.
    """

    name = "coco"
    id_columns = ("frame", "class", "score", "image")

    @classmethod
    def sniff(cls, path: Path) -> bool:
        return path.is_file() and path.suffix.lower() == ".json"

    def _setup(self) -> None:
        if not self.path.is_file():
            raise InputError("detections", str(self.path), "a COCO results JSON file")
        try:
            doc = orjson.loads(self.path.read_bytes())
        except orjson.JSONDecodeError as e:
            raise InputError("detections", str(self.path), f"a COCO JSON file ({_first_line(e)})") from None
        if isinstance(doc, dict) and isinstance(doc.get("annotations"), list):
            self.dets = doc["annotations"]
        elif isinstance(doc, list):
            self.dets, doc = doc, {}
        else:
            raise InputError("detections", str(self.path), "a COCO results list [{image_id, category_id, bbox, "
                             "score}, ...] or a COCO dataset with 'annotations'")
        names = self.options.class_names
        images = doc.get("images") if isinstance(doc.get("images"), list) else None
        if names is None and isinstance(doc.get("categories"), list):
            names = ClassNames(names_from_categories(doc["categories"], str(self.path)), f"{self.path.name} categories",
                               self.options.unknown_class)
        if images is None and names is not None and names.images is not None:
            images = names.images
        self.names = names or self._class_names("coco91")
        self.images = _image_index(images, str(self.path)) if images is not None else None
        self.id_columns = ("frame", "class", "score") + (("image",) if self.images is not None else ())
        if self.images is not None:
            used = {d.get("image_id") for d in self.dets if isinstance(d, dict)}
            for iid, (fname, size) in self.images.items():
                if iid in used:
                    self._check_size(size, f"{self.path}: image {fname!r}")
        self.total, self.unit = len(self.dets), "rows"

    def records(self):
        for i, d in enumerate(self.dets):
            ids, box, err = self._entry(i, d)
            yield ids, box, err, 1

    def _entry(self, i: int, d):
        ids, box, err = self._parse_entry(i, d)
        return ids[:len(self.id_columns)], box, err

    def _parse_entry(self, i: int, d):
        where = f"{self.path.name} detection {i}"
        if not isinstance(d, dict):
            return (None, None, None, None), None, f"{where}: not a JSON object"
        iid = d.get("image_id")
        frame = iid if isinstance(iid, int) and not isinstance(iid, bool) and abs(iid) < 2**63 else None
        image = None
        err = None if frame is not None else f"{where}: image_id {iid!r} is not an integer"
        if err is None and self.images is not None:
            if frame in self.images:
                image = self.images[frame][0]
            else:
                err = f"image_id {frame} is not among the dataset's images"
        score = d.get("score")
        if score is not None and not (isinstance(score, int | float) and not isinstance(score, bool)
                                      and math.isfinite(score)):
            err = err or f"{where}: score {score!r} is not a finite number"
            score = None
        cat = d.get("category_id")
        name = None
        if isinstance(cat, int) and not isinstance(cat, bool):
            name, cerr = self.names.lookup(cat)
            err = err or cerr
        else:
            err = err or f"{where}: category_id {cat!r} is not an integer"
        box, berr = _coco_box(d.get("bbox"))
        if err is None and berr is not None:
            err = berr if box is not None else f"{where}: {berr}"
        return (frame, name, None if score is None else float(score), image), box, err


def _coco_box(b):
    """``(box_xyxy_px or None, error or None)`` of a COCO ``bbox`` ``[x, y, w, h]``."""
    if not (isinstance(b, list) and len(b) == 4 and all(isinstance(v, int | float) and not isinstance(v, bool)
                                                         for v in b)):
        return None, f"bbox {str(b)[:40]} is not 4 numbers [x, y, w, h]"
    x, y, w, h = (float(v) for v in b)
    if not all(math.isfinite(v) for v in (x, y, w, h)):
        return None, f"bbox {b} is not finite"
    box = (x - EDGE_SHIFT_PX, y - EDGE_SHIFT_PX, x + w - EDGE_SHIFT_PX, y + h - EDGE_SHIFT_PX)
    if not (w > 0 and h > 0):
        return box, f"box width or height <= 0 (bbox w {w:g}, h {h:g})"
    return box, None


def _image_index(images, where: str) -> dict:
    """``image_id -> (file_name, (width, height) or None)`` of a COCO ``images`` list."""
    out = {}
    for im in images:
        if not (isinstance(im, dict) and isinstance(im.get("id"), int)):
            raise InputError(f"{where}: images", str(im)[:60], "objects with an integer 'id'")
        w, h = im.get("width"), im.get("height")
        size = (w, h) if isinstance(w, int) and isinstance(h, int) else None
        out[im["id"]] = (str(im.get("file_name", im["id"])), size)
    return out


# -- MOTChallenge ------------------------------------------------------------------------------------------
class MotChallenge(FormatReader):
    """MOTChallenge ``det.txt`` / ``gt.txt``: ``frame, id, bb_left, bb_top, bb_width, bb_height, conf, ...``.

    ``id`` is kept as ``object_id`` (``-1``, a detection without identity: empty); ``conf`` is ``score``
    (in ``gt.txt`` the "consider" flag).  Nine fields (MOT16/17/20 ``gt.txt``): the 8th is the class id
    (names: ``mot``, or ``FormatOptions.class_names``); 7, 8 or 10 fields: no class.  Boxes are 1-based
    (shifted by :data:`MOT_SHIFT_PX`).  A ``seqinfo.ini`` beside the file or one folder up gives the image
    size (checked against the camera's) and ``frameRate`` (then ``timestamp_s = (frame - 1) / frameRate``).
    """

    name = "mot"

    @classmethod
    def sniff(cls, path: Path) -> bool:
        if not (path.is_file() and path.suffix.lower() == ".txt"):
            return False
        first = _first_content_line(path)
        return first is not None and 7 <= len(first.split(",")) <= 10

    def _setup(self) -> None:
        if not self.path.is_file():
            raise InputError("detections", str(self.path), "a MOTChallenge det.txt / gt.txt file")
        self.rate_hz = None
        ini = next((p for p in (self.path.parent / "seqinfo.ini", self.path.parent.parent / "seqinfo.ini")
                    if p.is_file()), None)
        if ini is not None:
            self._seqinfo(ini)
        self.id_columns = ("frame",) + (("timestamp_s",) if self.rate_hz else ()) + (
            "object_id", "class", "score", "line")
        self.names = self._class_names("mot")
        self.total, self.unit = self.path.stat().st_size, "B"

    def _seqinfo(self, ini: Path) -> None:
        cp = configparser.ConfigParser()
        try:
            cp.read(ini, encoding="utf-8")
            seq = cp["Sequence"]
            size = (int(seq["imWidth"]), int(seq["imHeight"])) if "imWidth" in seq and "imHeight" in seq else None
            rate = float(seq["frameRate"]) if "frameRate" in seq else None
        except (configparser.Error, KeyError, ValueError, UnicodeDecodeError) as e:
            raise InputError(str(ini), _first_line(e), "a MOTChallenge seqinfo.ini ([Sequence] imWidth, imHeight, "
                             "frameRate)") from None
        self._check_size(size, f"{ini}: imWidth x imHeight")
        if rate is not None and not (math.isfinite(rate) and rate > 0):
            raise InputError(f"{ini}: frameRate", rate, "a frame rate > 0 (Hz)")
        self.rate_hz = rate

    def records(self):
        for lineno, text, why, used in _text_lines(self.path):
            yield (*self._line(text, why, lineno), used)

    def _line(self, text, why, lineno):
        v = {"line": lineno}
        fields = [] if text is None else [t.strip() for t in text.split(",")] if text.strip() else []
        if why is None and not 7 <= len(fields) <= 10:
            why = "empty line" if not fields else f"{len(fields)} fields; expected 7 to 10: frame, id, bb_left, " \
                                                  "bb_top, bb_width, bb_height, conf, ..."
        err, box = None, None
        if why is None:
            try:
                v["frame"] = _int(fields[0])
                oid = _int(fields[1])
                x, y, w, h = (_float(t) for t in fields[2:6])
                v["score"] = _float(fields[6])
                cid = _int(fields[7]) if len(fields) == 9 else None
            except ValueError as e:
                why = str(e)
        if why is not None:
            return self._ids(v), None, f"{self.path.name} line {lineno}: malformed MOTChallenge line ({why})"
        v["object_id"] = None if oid == -1 else str(oid)
        if self.rate_hz:
            v["timestamp_s"] = (v["frame"] - 1) / self.rate_hz
        if cid is not None:
            v["class"], err = self.names.lookup(cid)
        if err is None and not (w > 0 and h > 0):
            err = f"box width or height <= 0 (bb_width {w:g}, bb_height {h:g})"
        s = MOT_SHIFT_PX
        box = (x - s, y - s, x + w - s, y + h - s)
        return self._ids(v), box, err

    def _ids(self, values: dict) -> tuple:
        return tuple(values.get(c) for c in self.id_columns)


# -- readers from functions that return tables ------------------------------------------------------------
def table_format(name: str, tables, *, sniff=None, id_columns: tuple[str, ...] = ()) -> type[FormatReader]:
    """A :class:`FormatReader` class from a function that returns canonical tables (e.g. a ROS 2 bag reader).

    Parameters
    ----------
    name : the ``--format`` name
    tables : callable ``(path, options: FormatOptions) -> iterable of pyarrow.Table``; each table holds
        ``u_min_px, v_min_px, u_max_px, v_max_px`` (pixel centres at integers), the id columns it has (of
        ``id_columns``; missing ones are null) and optionally ``error`` (text, null where the row is fine)
    sniff : callable ``(Path) -> bool`` for ``--format auto`` (default: never detected)
    id_columns : the id columns of :data:`~footprint_uq.batch.schema.ID_COLUMNS` the tables carry

    Registering it is one line: ``READERS["ros2-bag"] = table_format("ros2-bag", bag_tables, sniff=is_bag,
    id_columns=("frame", "timestamp_s", "object_id", "class", "score"))``.
    """
    bad = [c for c in id_columns if c not in S.ID_COLUMNS]
    if bad:
        raise InputError("id_columns", bad, f"columns of {S.ID_COLUMNS}")

    class _TableFormat(FormatReader):
        def __iter__(self) -> Iterator[Chunk]:
            for t in tables(self.path, self.options):
                yield self._table_chunk(t)

        def _table_chunk(self, t: pa.Table) -> Chunk:
            """A :class:`Chunk` of a canonical table (id columns typed, absent ones null; ``error``: pre-errors)."""
            n = t.num_rows
            missing = [c for c in S.BOX2D_COLUMNS if c not in t.column_names]
            if missing:
                raise InputError(f"{self.name} table", missing, f"the box columns {list(S.BOX2D_COLUMNS)}")
            cols = {c: (t.column(c).cast(S.ID_TYPES[c]) if c in t.column_names else pa.nulls(n, S.ID_TYPES[c]))
                    for c in self.id_columns}
            cols.update({c: t.column(c).cast(pa.float64()) for c in S.BOX2D_COLUMNS})
            pre = t.column("error").to_pylist() if "error" in t.column_names else None
            row0 = self.lines
            self.lines += n
            ch = Chunk(pa.table(cols), np.arange(row0, row0 + n, dtype=np.int64),
                       pre if pre is not None and any(p is not None for p in pre) else None, [], n)
            names = self.options.class_names
            return ch if names is None or "class" not in self.id_columns else name_classes(ch, names)

    tag = re.sub(r"\W", "_", name)
    _TableFormat.name = name
    _TableFormat.id_columns = tuple(id_columns)
    _TableFormat.sniff = classmethod(lambda cls, path: bool(sniff(path)) if sniff is not None else False)
    _TableFormat.__name__ = _TableFormat.__qualname__ = f"TableFormat_{tag}"
    return _TableFormat


# -- formats whose reader lives above batch/ ------------------------------------------------------------------
def is_ros2_bag(path) -> bool:
    """A ROS 2 bag: a ``.mcap`` or ``.db3`` file, or a folder with ``metadata.yaml`` (rosbag2)."""
    p = Path(path)
    return p.suffix.lower() in (".mcap", ".db3") or (p.is_dir() and (p / "metadata.yaml").is_file())


@dataclass(frozen=True)
class LazyFormat:
    """A registry entry whose reader class lives in a layer above ``batch/`` (``integrations/``), which
    ``batch/`` never imports: the class is named by its module and attribute and imported when a file of the
    format is opened, never to detect one (:meth:`sniff` is this entry's own test of the path).

    Calling the entry opens a reader as calling a :class:`FormatReader` class does.
    """

    module: str
    attr: str
    sniff_path: object  # callable (Path) -> bool

    def sniff(self, path: Path) -> bool:
        return bool(self.sniff_path(path))

    def load(self) -> type[FormatReader]:
        """The reader class (its module imported on first use)."""
        return getattr(importlib.import_module(self.module), self.attr)

    def __call__(self, path, **kwargs) -> FormatReader:
        return self.load()(path, **kwargs)


# -- the registry ------------------------------------------------------------------------------------------
#: detector formats by name: registering one more is one line here (a FormatReader subclass, or
#: :func:`table_format` of a function returning canonical tables; a reader above batch/: a :class:`LazyFormat`).
#: Detection tries them in this order: a bag folder may hold other files, so the bag comes first.
READERS: dict[str, type[FormatReader] | LazyFormat] = {
    "ros2-bag": LazyFormat("footprint_uq.integrations.ros2.bag_reader", "BagFormat", is_ros2_bag),
    "yolo": YoloLabels,
    "yolov5-csv": Yolov5Csv,
    "coco": CocoResults,
    "mot": MotChallenge,
}
#: every ``--format`` (the CLI's choices): the canonical tables (csv, jsonl, parquet) and the detector formats
INPUT_FORMATS = ("csv", "jsonl", "parquet", *READERS)


def detect_input_format(path) -> str:
    """The format of ``path`` from what it says: a ROS 2 bag (``.mcap``, ``.db3``, a folder with ``metadata.yaml``),
    a folder of ``.txt`` (YOLO), a ``.json`` (COCO), a ``.txt``
    whose first line has 7-10 comma-separated fields (MOTChallenge) or 5-6 blank-separated ones (one YOLO
    label file), a CSV whose header has ``xmin, ymin, xmax, ymax`` (YOLOv5), else the canonical table of
    the extension (``.csv``, ``.jsonl``, ``.ndjson``, ``.parquet``, ``.pq``)."""
    p = Path(path)
    if not p.exists():
        raise InputError("detections", str(path), "an existing file or folder")
    if is_stream(p) or file_kind(p) not in ("regular file", "directory"):
        # a FIFO is read once: sniffing its first bytes would take them from the reader (and wait on a writer);
        # its extension says which canonical table it streams (the table reader waits, then reads or refuses)
        if p.suffix.lower() in TABLE_FORMATS:
            return TABLE_FORMATS[p.suffix.lower()]
        raise InputError("detections", str(path), f"a regular file (this is a {file_kind(p)}): a detector format "
                         "is sniffed and read more than once; stream a canonical table (.csv, .jsonl) instead")
    for name, cls in READERS.items():
        if cls.sniff(p):
            return name
    if p.is_file() and p.suffix.lower() in TABLE_FORMATS:
        return TABLE_FORMATS[p.suffix.lower()]
    raise InputError("detections", str(path), f"a detections file in one of {list(INPUT_FORMATS)} (--format), "
                     "e.g. .csv, .jsonl, .parquet, a folder of YOLO .txt labels, a COCO .json, a MOT det.txt, a ROS 2 "
                     "bag")


def open_reader(path, *, format: str | None = None, chunk_rows: int = S.DEFAULT_CHUNK_ROWS,
                class_names=None, unknown_class: str = "error", image_size_px=None, topic: str | None = None):
    """A reader of ``path`` in any input format: a :class:`FormatReader` or a
    :class:`~footprint_uq.batch.readers.DetectionReader` (canonical tables; with ``class_names``, its integer
    ``class`` values are mapped to names, :class:`NamedClasses`).

    Parameters
    ----------
    path : file or folder
    format : one of :data:`INPUT_FORMATS`, or None / ``"auto"`` (:func:`detect_input_format`)
    chunk_rows : rows per chunk
    class_names : ``"coco"``, ``"coco91"``, ``"mot"``, a names file, a list or a mapping (:class:`ClassNames`);
        None: the format's own
    unknown_class : ``"error"`` (a class id without a name is that detection's error) or ``"unknown"``
    image_size_px : (width, height) of the camera's images (normalised boxes; sizes a file states are checked)
    topic : the Detection2DArray topic of a ROS 2 bag (default: its only one); only with a bag
    """
    fmt = detect_input_format(path) if format in (None, "auto") else format
    if topic is not None and fmt != "ros2-bag":
        raise InputError("topic", topic, f"a ROS 2 bag as the detections (the format is {fmt})")
    if fmt not in TABLE_FORMATS.values() and fmt not in READERS:
        raise InputError("format", format, f"one of {['auto', 'csv', 'jsonl', 'parquet', *READERS]}")
    names = None if class_names is None else ClassNames.load(class_names, unknown=unknown_class)
    if fmt in READERS:
        if file_kind(path) not in ("regular file", "directory"):
            raise InputError("detections", str(path), f"a regular file or folder for --format {fmt} (this is a "
                             f"{file_kind(path)}): stream a canonical table (.csv, .jsonl) instead")
        size = None if image_size_px is None else tuple(int(v) for v in image_size_px)
        return READERS[fmt](path, chunk_rows=chunk_rows, options=FormatOptions(names, size, unknown_class, topic))
    reader = DetectionReader(path, chunk_rows=chunk_rows, format=fmt)
    return reader if names is None else NamedClasses(reader, names)


class NamedClasses:
    """A canonical-table reader whose integer ``class`` values (``"0"``, ``"2"``) become names.

    Wraps a :class:`~footprint_uq.batch.readers.DetectionReader` (every attribute is the reader's); a value
    that is not an integer stays as it is (already a name), an integer without a name is that row's error.
    """

    def __init__(self, reader: DetectionReader, names: ClassNames):
        self._reader = reader
        self.names = names

    def __getattr__(self, name):
        return getattr(self._reader, name)

    def select(self, numeric) -> None:
        self._reader.select(numeric)

    def __iter__(self) -> Iterator[Chunk]:
        for ch in self._reader:
            if "class" in ch.table.column_names:
                ch = self._map(ch)
            yield ch

    def _map(self, ch: Chunk) -> Chunk:
        return name_classes(ch, self.names)


def name_classes(ch: Chunk, names: ClassNames) -> Chunk:
    """``ch`` with its integer ``class`` values (``"0"``, ``"2"``) turned into names through ``names``: a value that
    is not an integer stays as it is (already a name), an integer without a name is that row's error (or the class
    ``"unknown"``, as the map's policy says)."""
    col = ch.table.column("class")
    values = col.to_pylist()
    lookup: dict = {}
    pre = list(ch.pre_errors) if ch.pre_errors is not None else [None] * len(values)
    out = []
    for i, v in enumerate(values):
        if v is None:
            out.append(None)
            continue
        if v not in lookup:
            try:
                lookup[v] = names.lookup(int(str(v).strip()))
            except ValueError:
                lookup[v] = (v, None)
        name, err = lookup[v]
        out.append(name if name is not None else v)
        if err is not None and pre[i] is None:
            pre[i] = err
    j = ch.table.column_names.index("class")
    table = ch.table.set_column(j, ch.table.schema.field(j), pa.array(out, type=col.type))
    return Chunk(table, ch.rows, pre if any(p is not None for p in pre) else None, ch.malformed, ch.progress)


# -- Python entry ------------------------------------------------------------------------------------------
def read_detections(path, format: str | None = None, *, class_names=None, unknown_class: str = "error",
                    image_size_px=None, topic: str | None = None) -> pa.Table:
    """Every detection of a detector file (or folder) as one canonical table.

    Parameters
    ----------
    path : file or folder (YOLO labels, YOLOv5 CSV, COCO results, MOTChallenge, a ROS 2 bag, or a canonical table)
    format : one of :data:`INPUT_FORMATS`, or None (detected from the file: :func:`detect_input_format`)
    class_names, unknown_class, image_size_px, topic : as :func:`open_reader` (YOLO needs ``image_size_px``: the
        camera's ``image_size_px``)

    Returns
    -------
    pyarrow.Table
        ``row`` (0-based index of the detection in the input), the id columns the format carries (``frame``,
        ``timestamp_s``, ``object_id``, ``class``, ``score``, ``image``, ``line``), the box ``u_min_px, v_min_px,
        u_max_px, v_max_px`` (pixel centres at integers) and ``error`` (why the row cannot be used; null when
        it can).  Pass it to :func:`footprint_uq.batch.process_table` with ``rows=`` and ``pre_errors=``, or use
        ``footprint-uq objects --format ...`` for files.
    """
    reader = open_reader(path, format=format, class_names=class_names, unknown_class=unknown_class,
                         image_size_px=image_size_px, topic=topic)
    if isinstance(reader, DetectionReader | NamedClasses) and not all(c in reader.columns for c in S.BOX2D_COLUMNS):
        raise InputError(f"{path}: columns", sorted(reader.columns)[:12], f"the 2-D box columns "
                         f"{list(S.BOX2D_COLUMNS)}")
    reader.select(S.BOX2D_COLUMNS)
    parts = []
    for ch in reader:
        t = ch.table
        err = list(ch.pre_errors) if ch.pre_errors is not None else [None] * t.num_rows
        t = t.add_column(0, "row", pa.array(ch.rows, pa.int64())).append_column("error", pa.array(err, pa.string()))
        if ch.malformed:
            bad = {"row": pa.array([r for r, _ in ch.malformed], pa.int64()),
                   "error": pa.array([why for _, why in ch.malformed], pa.string())}
            t = pa.concat_tables([t, pa.table(bad)], promote_options="default")
        parts.append(t)
    if not parts:
        fields = [pa.field("row", pa.int64()), *reader.id_fields,
                  *(pa.field(c, pa.float64()) for c in S.BOX2D_COLUMNS), pa.field("error", pa.string())]
        return pa.schema(fields).empty_table()
    out = pa.concat_tables(parts, promote_options="default")
    return out.take(pc.sort_indices(out.column("row")))
