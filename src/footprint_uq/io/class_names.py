"""Class names of a detector's integer class ids: the COCO 80 names built in, or a names file.

Detectors write classes as integers (YOLO / ultralytics ``cls``, COCO ``category_id``, a supervision
``class_id``); the CPM / SDSM class and every record need the name.  :func:`load_class_names` reads

* ``"coco"``: the 80 COCO detection names in the order of the ultralytics / YOLO models trained on COCO
  (0 ``person``, 1 ``bicycle``, 2 ``car``, 3 ``motorcycle``, 5 ``bus``, 7 ``truck``, ...), :data:`COCO_NAMES`;
* a ``.yaml`` / ``.yml`` / ``.json`` file: an ultralytics ``data.yaml`` (key ``names:``, a list or a mapping
  id -> name), or the list / mapping itself;
* any other file: one name per line, the line number (from 0) the id (Darknet's ``.names``).

A class id the map does not name is that detection's error, never a guess (docs/service.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .._parse import load_yaml
from ..errors import ConfigError

__all__ = ["COCO_NAMES", "ClassNames", "load_class_names", "class_id_of", "MAX_CLASS_NAMES"]

#: the 80 COCO detection classes, id = position (the ultralytics / YOLOv5-v11 COCO models)
COCO_NAMES = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard", "cell phone",
    "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors", "teddy bear",
    "hair drier", "toothbrush")
#: most names a map may hold (a names file is small; this bounds a hostile one)
MAX_CLASS_NAMES = 100_000
#: largest names file read, bytes
_MAX_FILE_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True)
class ClassNames:
    """Integer class id -> class name.

    Attributes
    ----------
    names : dict[int, str]
        The map (ids >= 0, names non-empty text).
    source : str
        Where it came from (``"coco"`` or the file), for messages.
    """

    names: dict
    source: str

    def name_of(self, class_id: int) -> str | None:
        """The name of ``class_id`` (None if the map does not name it)."""
        return self.names.get(class_id)

    def __len__(self) -> int:
        return len(self.names)


def class_id_of(value) -> int | None:
    """``value`` as a class id: an integer (numpy integers too) or an integral finite float (ultralytics writes its
    ``cls`` as floats, ``2.0``); None for anything else (bool, text, 2.5, NaN)."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
        return int(value)
    return None


def load_class_names(spec) -> ClassNames:
    """A names map from ``spec``: ``"coco"``, a :class:`ClassNames` (returned as is), or a file path (the module
    doc lists the layouts).  A bad file is a one-line :class:`~footprint_uq.errors.ConfigError` naming it."""
    if isinstance(spec, ClassNames):
        return spec
    if isinstance(spec, str) and spec.lower() == "coco":
        return ClassNames(dict(enumerate(COCO_NAMES)), "coco")
    path = Path(spec)
    try:
        if path.stat().st_size > _MAX_FILE_BYTES:
            raise ConfigError("--class-names", str(path), f"a names file of at most {_MAX_FILE_BYTES} bytes")
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError("--class-names", str(spec), f"'coco' or a readable UTF-8 names file ({type(e).__name__})"
                          ) from None
    if path.suffix.lower() in (".yaml", ".yml", ".json"):
        try:
            data = load_yaml(text, str(path))
        except (yaml.YAMLError, ValueError, RecursionError) as e:
            first = (str(e).strip().splitlines() or [type(e).__name__])[0]
            raise ConfigError("--class-names", str(path), f"valid YAML/JSON ({first})") from None
        if isinstance(data, dict) and "names" in data:
            data = data["names"]
        names = _from_structure(data, str(path))
    else:
        names = _from_lines(text, str(path))
    if not names:
        raise ConfigError("--class-names", str(path), "at least one class name")
    if len(names) > MAX_CLASS_NAMES:
        raise ConfigError("--class-names", f"{len(names)} names", f"at most {MAX_CLASS_NAMES}")
    return ClassNames(names, str(path))


def _check_name(name, where: str) -> str:
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(where, repr(name), "a class name (non-empty text)")
    return name.strip()


def _from_structure(data, path: str) -> dict:
    """A list (id = position) or a mapping id -> name, checked."""
    if isinstance(data, list):
        return {i: _check_name(n, f"{path}: names[{i}]") for i, n in enumerate(data)}
    if isinstance(data, dict):
        out = {}
        for k, n in data.items():
            cid = class_id_of(k) if not isinstance(k, str) else (int(k) if k.strip().isdigit() else None)
            if cid is None or cid < 0:
                raise ConfigError(f"{path}: names", repr(k), "class ids that are integers >= 0")
            if cid in out:
                raise ConfigError(f"{path}: names", cid, "each class id once")
            out[cid] = _check_name(n, f"{path}: names[{k}]")
        return out
    raise ConfigError(f"{path}: names", type(data).__name__, "a list of names or a mapping class id -> name")


def _from_lines(text: str, path: str) -> dict:
    """One name per line, id = line number from 0; trailing blank lines ignored, a blank line before a name refused
    (it would shift every id after it)."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    return {i: _check_name(n, f"{path}: line {i + 1}") for i, n in enumerate(lines)}
