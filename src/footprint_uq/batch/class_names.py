"""Integer class ids -> class names: the built-in COCO and MOTChallenge maps, ``data.yaml`` and name files.

A detector writes class ids (``0`` for a person in a COCO-trained YOLO); the footprint table carries
names.  :class:`ClassNames` holds one map and turns an id into its name; an id without a name is that
detection's error (``unknown="error"``, the default) or the class ``"unknown"`` (``unknown="unknown"``),
never the file's or the frame's error (docs/integrations.md, "Detector formats").

Sources (:meth:`ClassNames.load`):

* ``"coco"``: the 80 COCO classes by their 0-based index (YOLO / ultralytics, supervision);
* ``"coco91"``: the same 80 classes by their COCO *category id* (1 ... 90 with gaps: COCO results files);
* ``"mot"``: the MOTChallenge ground-truth classes (1 pedestrian ... 12 reflection, 13 crowd);
* a YAML file with ``names:`` (a list, 0-based, or a mapping id -> name: ultralytics ``data.yaml``);
* a JSON file: a list, a mapping id -> name, or a COCO dataset (``categories: [{id, name}, ...]``);
* a text file: one name per line, the first line is id 0 (darknet ``.names``, ``classes.txt``);
* in Python, also a sequence (0-based) or a mapping ``{id: name}``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import orjson
import yaml

from .._parse import load_yaml
from ..errors import InputError

__all__ = ["ClassNames", "COCO80_NAMES", "COCO91_IDS", "MOT_NAMES", "UNKNOWN_CLASS", "UNKNOWN_POLICIES",
           "BUILTIN_NAMES"]

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
UNKNOWN_POLICIES = ("error", "unknown")

BUILTIN_NAMES = {"coco": dict(enumerate(COCO80_NAMES)), "coco91": dict(zip(COCO91_IDS, COCO80_NAMES, strict=True)),
                 "mot": dict(MOT_NAMES)}


@dataclass(frozen=True)
class ClassNames:
    """A map of integer class ids to names.

    Attributes
    ----------
    names : dict int -> str
    source : str          where the map comes from (``"coco"``, a file path): named in the errors
    unknown : {"error", "unknown"}   an id without a name: that detection's error, or the class ``"unknown"``
    images : list, optional   the ``images`` of a COCO dataset JSON given as the names (file names and sizes of
        the image ids of COCO results)
    """

    names: dict
    source: str
    unknown: str = "error"
    images: list | None = None

    def __post_init__(self):
        if self.unknown not in UNKNOWN_POLICIES:
            raise InputError("unknown_class", self.unknown, f"one of {UNKNOWN_POLICIES}")

    @classmethod
    def load(cls, spec, *, unknown: str = "error") -> ClassNames:
        """A :class:`ClassNames` from a built-in name, a file, a sequence or a mapping (see the module doc)."""
        if isinstance(spec, ClassNames):
            return cls(spec.names, spec.source, unknown, spec.images)
        if isinstance(spec, str) and spec in BUILTIN_NAMES:
            return cls(BUILTIN_NAMES[spec], spec, unknown)
        if isinstance(spec, Mapping):
            return cls(_id_map(spec, "class_names"), "the names given", unknown)
        if isinstance(spec, Sequence) and not isinstance(spec, str | bytes):
            return cls(_id_map(dict(enumerate(spec)), "class_names"), "the names given", unknown)
        if isinstance(spec, str | Path):
            names, images = _names_from_file(Path(spec))
            return cls(names, str(spec), unknown, images)
        raise InputError("class_names", spec, f"one of {sorted(BUILTIN_NAMES)}, a names file, a list or a mapping")

    def lookup(self, class_id) -> tuple[str | None, str | None]:
        """``(name, None)`` of ``class_id``, or ``(None, reason)`` when it has none (``unknown="error"``)."""
        name = self.names.get(class_id)
        if name is not None:
            return name, None
        if self.unknown == "unknown":
            return UNKNOWN_CLASS, None
        return None, f"class id {class_id} has no name in {self.source}"


def _first_line(e: BaseException) -> str:
    text = str(e).splitlines()
    return (text[0] if text else type(e).__name__)[:100]


def _int_key(k, where: str) -> int:
    if isinstance(k, bool):
        raise InputError(where, k, "integer class ids")
    if isinstance(k, int):
        return k
    try:
        return int(str(k).strip())
    except ValueError:
        raise InputError(where, k, "integer class ids") from None


def _id_map(mapping: Mapping, where: str) -> dict:
    out = {}
    for k, v in mapping.items():
        if not isinstance(v, str) or not v.strip():
            raise InputError(f"{where}[{k!r}]", v, "a class name (non-empty text)")
        out[_int_key(k, where)] = v.strip()
    if not out:
        raise InputError(where, dict(mapping), "at least one class name")
    return out


def _names_from_file(path: Path) -> tuple[dict, list | None]:
    """``(id -> name, COCO images or None)`` of a names file."""
    if not path.is_file():
        raise InputError("class_names", str(path), f"one of {sorted(BUILTIN_NAMES)} or an existing names file "
                         "(data.yaml, .json, .txt)")
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        try:
            doc = load_yaml(path.read_text(encoding="utf-8"), str(path))
        except (yaml.YAMLError, UnicodeDecodeError) as e:
            raise InputError("class_names", str(path), f"a YAML names file ({_first_line(e)})") from None
        names = doc.get("names") if isinstance(doc, Mapping) else None
        if names is None:
            raise InputError(f"{path}: names", "missing", "a 'names:' list or mapping (ultralytics data.yaml)")
        return _id_map(names if isinstance(names, Mapping) else dict(enumerate(names)) if isinstance(names, list)
                       else {}, f"{path}: names"), None
    if suffix == ".json":
        try:
            doc = orjson.loads(path.read_bytes())
        except orjson.JSONDecodeError as e:
            raise InputError("class_names", str(path), f"a JSON names file ({_first_line(e)})") from None
        images = doc.get("images") if isinstance(doc, Mapping) and isinstance(doc.get("images"), list) else None
        return names_from_json(doc, str(path)), images
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError:
        raise InputError("class_names", str(path), "a UTF-8 text file of class names, one per line") from None
    while lines and not lines[-1].strip():
        lines.pop()
    return _id_map(dict(enumerate(lines)), str(path)), None


def names_from_json(doc, where: str) -> dict:
    """The id -> name map of a JSON document: a list, a mapping, or a COCO dataset's ``categories``."""
    if isinstance(doc, Mapping) and "categories" in doc:
        cats = doc["categories"]
        if not isinstance(cats, list) or not all(isinstance(c, Mapping) and "id" in c and "name" in c for c in cats):
            raise InputError(f"{where}: categories", str(cats)[:60], "a list of {id, name} objects")
        return _id_map({c["id"]: c["name"] for c in cats}, f"{where}: categories")
    if isinstance(doc, list):
        return _id_map(dict(enumerate(doc)), where)
    if isinstance(doc, Mapping):
        return _id_map(doc, where)
    raise InputError("class_names", where, "a JSON list of names, a mapping id -> name or a COCO 'categories' list")
