"""Integer class ids -> class names: the ONE names map of the package (the batch's detector formats, the
supervision arrays, ``objects`` / ``validate`` and the edge service alike).

A detector writes class ids (YOLO / ultralytics ``cls``, COCO ``category_id``, a supervision ``class_id``; ``0``
for a person in a COCO-trained YOLO); the footprint table, the records and the CPM / SDSM class need the name.
:class:`ClassNames` holds one map and its policy for an id without a name: that detection's error
(``unknown="error"``, the default) or the class ``"unknown"`` (``unknown="unknown"``) -- never the file's or the
frame's error, never a guess (docs/integrations.md, "Detector formats"; docs/service.md).

Sources (:meth:`ClassNames.load`, :func:`load_class_names`; ``--class-names`` of ``objects``, ``validate`` and
``serve``):

* ``"coco"``: the 80 COCO classes by their 0-based index (YOLO / ultralytics, supervision), :data:`COCO80_NAMES`;
* ``"coco91"``: the same 80 classes by their COCO *category id* (1 ... 90 with gaps: COCO results files);
* ``"mot"``: the MOTChallenge ground-truth classes (1 pedestrian ... 12 reflection, 13 crowd);
* a ``.yaml`` / ``.yml`` file: an ultralytics ``data.yaml`` (key ``names:``, a list, 0-based, or a mapping
  id -> name), or the list / mapping itself;
* a ``.json`` file: a list, a mapping id -> name, ``{"names": ...}``, or a COCO dataset (``categories: [{id,
  name}, ...]``; its ``images`` are kept, :attr:`ClassNames.images`);
* any other file: one name per line, the first line is id 0 (darknet ``.names``, ``classes.txt``);
* in Python, also a sequence (0-based) or a mapping ``{id: name}``.

Limits (a hostile file is refused in one line naming it, :class:`~footprint_uq.errors.ConfigError`): a names file
of at most :data:`MAX_NAMES_FILE_BYTES` (a JSON file, which may be a whole COCO dataset with its annotations, at
most :data:`MAX_JSON_FILE_BYTES`), at most :data:`MAX_CLASS_NAMES` names, ids integers >= 0 each once, names
non-empty text; a blank line before a name in a text file is refused (it would shift every id after it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson
import yaml

from .._parse import load_yaml
from ..errors import ConfigError, InputError

__all__ = ["ClassNames", "load_class_names", "class_id_of", "names_from_json", "names_from_categories",
           "COCO80_NAMES", "COCO_NAMES", "COCO91_IDS", "MOT_NAMES", "UNKNOWN_CLASS", "UNKNOWN_POLICIES",
           "BUILTIN_NAMES", "MAX_CLASS_NAMES", "MAX_NAMES_FILE_BYTES", "MAX_JSON_FILE_BYTES"]

#: the 80 COCO classes in YOLO / ultralytics order (index = class id)
COCO80_NAMES = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard", "cell phone",
    "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors", "teddy bear",
    "hair drier", "toothbrush")
#: the same tuple under the service's older name
COCO_NAMES = COCO80_NAMES
#: the COCO category id of each of the 80 classes (COCO's ids run 1 ... 90 with 10 gaps)
COCO91_IDS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 27, 28, 31, 32,
              33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 46, 47, 48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58,
              59, 60, 61, 62, 63, 64, 65, 67, 70, 72, 73, 74, 75, 76, 77, 78, 79, 80, 81, 82, 84, 85, 86, 87, 88,
              89, 90)
#: MOTChallenge ground-truth classes (MOT16/17/20 ``gt.txt``, column 8)
MOT_NAMES = {1: "pedestrian", 2: "person on vehicle", 3: "car", 4: "bicycle", 5: "motorbike",
             6: "non motorized vehicle", 7: "static person", 8: "distractor", 9: "occluder",
             10: "occluder on the ground", 11: "occluder full", 12: "reflection", 13: "crowd"}
#: the class written for an id without a name when the user asks for it (``unknown="unknown"``)
UNKNOWN_CLASS = "unknown"
#: what an id without a name becomes: that detection's error, or the class :data:`UNKNOWN_CLASS`
UNKNOWN_POLICIES = ("error", "unknown")
#: the built-in maps by name (the ``--class-names`` choices besides a file)
BUILTIN_NAMES = {"coco": dict(enumerate(COCO80_NAMES)), "coco91": dict(zip(COCO91_IDS, COCO80_NAMES, strict=True)),
                 "mot": dict(MOT_NAMES)}
#: most names a map may hold (a names file is small; this bounds a hostile one)
MAX_CLASS_NAMES = 100_000
#: largest YAML / text names file read, bytes
MAX_NAMES_FILE_BYTES = 16 * 1024 * 1024
#: largest JSON names file read, bytes (a COCO dataset JSON carries its annotations: val2017's is ~25 MB)
MAX_JSON_FILE_BYTES = 512 * 1024 * 1024


@dataclass(frozen=True)
class ClassNames:
    """A map of integer class ids to names, with the policy for an id it does not name.

    Attributes
    ----------
    names : dict int -> str
        The map (ids >= 0, names non-empty text).
    source : str
        Where it comes from (``"coco"``, a file path, ``"the names given"``): named in the errors.
    unknown : {"error", "unknown"}
        An id without a name: that detection's error, or the class ``"unknown"``.
    images : list, optional
        The ``images`` of a COCO dataset JSON given as the names (file names and sizes of the image ids of
        COCO results).
    """

    names: dict
    source: str
    unknown: str = "error"
    images: list | None = None

    def __post_init__(self):
        if self.unknown not in UNKNOWN_POLICIES:
            raise InputError("unknown_class", self.unknown, f"one of {UNKNOWN_POLICIES}")

    @classmethod
    def load(cls, spec, *, unknown: str | None = None) -> ClassNames:
        """A :class:`ClassNames` from a built-in name, a file, a sequence, a mapping or a :class:`ClassNames`,
        with the policy ``unknown`` (None: a given :class:`ClassNames`' own, else ``"error"``); see the module
        doc.  A bad source is a one-line :class:`~footprint_uq.errors.InputError` (a bad file:
        :class:`~footprint_uq.errors.ConfigError`)."""
        if isinstance(spec, ClassNames):
            return cls(spec.names, spec.source, unknown or spec.unknown, spec.images)
        unknown = unknown or "error"
        if isinstance(spec, str) and spec.lower() in BUILTIN_NAMES:
            return cls(BUILTIN_NAMES[spec.lower()], spec.lower(), unknown)
        if isinstance(spec, Mapping):
            return cls(_id_map(spec, "class_names"), "the names given", unknown)
        if isinstance(spec, Sequence) and not isinstance(spec, str | bytes):
            return cls(_id_map(dict(enumerate(spec)), "class_names"), "the names given", unknown)
        if isinstance(spec, str | Path):
            names, images = _names_from_file(Path(spec))
            return cls(names, str(spec), unknown, images)
        raise InputError("class_names", spec, f"one of {sorted(BUILTIN_NAMES)}, a names file, a list or a mapping")

    def name_of(self, class_id) -> str | None:
        """The name of ``class_id`` under the policy: its name, :data:`UNKNOWN_CLASS` for an id without one when
        ``unknown="unknown"``, else None."""
        name = self.names.get(class_id)
        if name is None and self.unknown == "unknown":
            return UNKNOWN_CLASS
        return name

    def lookup(self, class_id) -> tuple[str | None, str | None]:
        """``(name, None)`` of ``class_id`` (:meth:`name_of`), or ``(None, reason)`` when it has none
        (``unknown="error"``)."""
        name = self.name_of(class_id)
        if name is not None:
            return name, None
        return None, f"class id {class_id} is not in the names map ({self.source}, {len(self.names)} names)"

    def __len__(self) -> int:
        return len(self.names)


def load_class_names(spec, *, unknown: str | None = None) -> ClassNames:
    """:meth:`ClassNames.load` (the service's and the CLI's entry: ``--class-names``, ``--unknown-class``)."""
    return ClassNames.load(spec, unknown=unknown)


def class_id_of(value) -> int | None:
    """``value`` as a class id: an integer (numpy integers too) or an integral finite float (ultralytics writes its
    ``cls`` as floats, ``2.0``); None for anything else (bool, text, 2.5, NaN)."""
    if isinstance(value, bool | np.bool_):
        return None
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating) and math.isfinite(value) and float(value).is_integer():
        return int(value)
    return None


def _first_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return (text[0] if text else type(e).__name__)[:100]


def _int_key(k, where: str) -> int:
    """A class id of a mapping: an integer (not bool) or the text of one, >= 0."""
    cid = class_id_of(k) if not isinstance(k, str) else (int(k.strip()) if k.strip().isdigit() else None)
    if cid is None or cid < 0 or isinstance(k, float):
        raise ConfigError(where, repr(k), "class ids that are integers >= 0")
    return cid


def _check_name(name, where: str) -> str:
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(where, repr(name), "a class name (non-empty text)")
    return name.strip()


def _id_map(mapping: Mapping, where: str) -> dict:
    """``mapping`` checked: ids integers >= 0 each once, names non-empty text, 1 to :data:`MAX_CLASS_NAMES`."""
    if len(mapping) > MAX_CLASS_NAMES:
        raise ConfigError(where, f"{len(mapping)} names", f"at most {MAX_CLASS_NAMES}")
    out = {}
    for k, v in mapping.items():
        cid = _int_key(k, where)
        if cid in out:
            raise ConfigError(where, cid, "each class id once")
        out[cid] = _check_name(v, f"{where}[{k!r}]")
    if not out:
        raise ConfigError(where, "no names", "at least one class name")
    return out


def _structure(data, where: str) -> dict:
    """A list (id = position) or a mapping id -> name, checked."""
    if isinstance(data, list):
        return _id_map(dict(enumerate(data)), where)
    if isinstance(data, Mapping):
        return _id_map(data, where)
    raise ConfigError(where, type(data).__name__, "a list of names or a mapping class id -> name")


def _read(path: Path, limit: int) -> bytes:
    try:
        if not path.is_file():
            raise FileNotFoundError(path)
        if path.stat().st_size > limit:
            raise ConfigError("class_names", str(path), f"a names file of at most {limit} bytes")
        return path.read_bytes()
    except OSError as e:
        raise ConfigError("class_names", str(path), f"one of {sorted(BUILTIN_NAMES)} or a readable names file "
                          f"(data.yaml, .json, .names / .txt; {type(e).__name__})") from None


def _names_from_file(path: Path) -> tuple[dict, list | None]:
    """``(id -> name, COCO images or None)`` of a names file."""
    suffix = path.suffix.lower()
    data = _read(path, MAX_JSON_FILE_BYTES if suffix == ".json" else MAX_NAMES_FILE_BYTES)
    if suffix == ".json":
        try:
            doc = orjson.loads(data)
        except orjson.JSONDecodeError as e:
            raise ConfigError("class_names", str(path), f"a JSON names file ({_first_line(e)})") from None
        images = doc.get("images") if isinstance(doc, Mapping) and isinstance(doc.get("images"), list) else None
        return names_from_json(doc, str(path)), images
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ConfigError("class_names", str(path), "a UTF-8 names file") from None
    if suffix in (".yaml", ".yml"):
        try:
            doc = load_yaml(text, str(path))
        except (yaml.YAMLError, ValueError, RecursionError) as e:
            raise ConfigError("class_names", str(path), f"valid YAML ({_first_line(e)})") from None
        if isinstance(doc, Mapping) and "names" in doc:
            doc = doc["names"]
        return _structure(doc, f"{path}: names"), None
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) > MAX_CLASS_NAMES:
        raise ConfigError(str(path), f"{len(lines)} names", f"at most {MAX_CLASS_NAMES}")
    return _id_map({i: _check_name(n, f"{path}: line {i + 1}") for i, n in enumerate(lines)}, str(path)), None


def names_from_categories(cats, where: str) -> dict:
    """The id -> name map of a COCO ``categories`` list ``[{id, name}, ...]``, checked (empty for an empty list)."""
    if not isinstance(cats, list) or not all(isinstance(c, Mapping) and isinstance(c.get("id"), int)
                                             and not isinstance(c["id"], bool) and "name" in c for c in cats):
        raise ConfigError(f"{where}: categories", str(cats)[:60], "a list of {id, name} objects (integer ids)")
    if len({c["id"] for c in cats}) != len(cats):
        raise ConfigError(f"{where}: categories", str(cats)[:60], "each category id once")
    if not cats:  # a COCO file's own empty list: every category id is its detection's error (a names file: refused)
        return {}
    return _id_map({c["id"]: c["name"] for c in cats}, f"{where}: categories")


def names_from_json(doc, where: str) -> dict:
    """The id -> name map of a JSON document: a COCO dataset's ``categories``, ``{"names": ...}``, a list or a
    mapping."""
    if isinstance(doc, Mapping) and "categories" in doc:
        names = names_from_categories(doc["categories"], where)
        if not names:
            raise ConfigError(f"{where}: categories", "[]", "at least one category {id, name}")
        return names
    if isinstance(doc, Mapping) and "names" in doc:
        return _structure(doc["names"], f"{where}: names")
    return _structure(doc, where)
