"""The rosbags type store of the ROS 2 bags: a distribution's store plus ``vision_msgs`` from its ``.msg`` texts.

rosbags ships the message types of the ROS 2 core (``std_msgs``, ``geometry_msgs``, ``sensor_msgs``,
``visualization_msgs``...) but not ``vision_msgs``; its definitions (vision_msgs 4.1.1, Apache-2.0) are kept
unchanged in ``msg/`` beside this module (``msg/SOURCE.txt``) and registered here.  :func:`default_message`
builds a message with every field at its zero value, so that the writers set only the fields they mean.
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np

from ...errors import ConfigError, InputError

__all__ = ["DISTROS", "DEFAULT_DISTRO", "VISION_MSGS", "EXTRA", "typestore", "default_message", "zero_fields"]

#: the optional extra of the ROS 2 / Foxglove integration (rosbags, mcap, foxglove-sdk)
EXTRA = "pip install 'footprint-uq[ros]' (rosbags, mcap, foxglove-sdk)"

#: the ROS 2 distributions whose message definitions a bag can be written with
DISTROS = ("humble", "iron", "jazzy", "kilted")
#: the default: Humble, the long-term release most roadside stacks run (Autoware, CARMA)
DEFAULT_DISTRO = "humble"
#: the vision_msgs types kept in ``msg/`` (registered in dependency order by rosbags)
VISION_MSGS = ("BoundingBox2D", "BoundingBox3D", "Detection2D", "Detection2DArray", "Detection3D",
               "Detection3DArray", "ObjectHypothesis", "ObjectHypothesisWithPose", "Point2D", "Pose2D")

_NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
          "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
          "uint64": np.uint64, "float32": np.float32, "float64": np.float64}


@functools.cache
def typestore(distro: str = DEFAULT_DISTRO):
    """The rosbags ``Typestore`` of ``distro`` (one of :data:`DISTROS`) with vision_msgs registered (cached)."""
    if distro not in DISTROS:
        raise InputError("ros_distro", distro, f"one of {list(DISTROS)}")
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError as e:
        raise ConfigError("ROS 2 bags", f"{e.name} not installed", EXTRA) from None
    ts = get_typestore(getattr(Stores, f"ROS2_{distro.upper()}"))
    folder = resources.files(__package__) / "msg"
    types = {}
    for name in VISION_MSGS:
        types.update(get_types_from_msg((folder / f"{name}.msg").read_text(encoding="utf-8"),
                                        f"vision_msgs/msg/{name}"))
    ts.register(types)
    return ts


def _zero(ts, node: tuple):
    kind, spec = node
    kind = int(kind)
    if kind == 1:  # BASE: (type, string bound)
        typ = spec[0]
        return "" if typ == "string" else (False if typ == "bool" else (0.0 if typ.startswith("float") else 0))
    if kind == 2:  # NAME: a nested message
        return default_message(ts, spec)
    sub, length = spec  # ARRAY (fixed length) or SEQUENCE / BOUNDED SEQUENCE
    if int(sub[0]) == 1 and sub[1][0] in _NUMPY:
        return np.zeros(length if kind == 3 else 0, dtype=_NUMPY[sub[1][0]])
    return [_zero(ts, sub) for _ in range(length)] if kind == 3 else []


def zero_fields(ts, typename: str) -> dict:
    """Every field of a ``typename`` message of ``ts`` at its zero value (numbers 0, strings empty, sequences
    empty, fixed arrays of zeros, nested messages likewise): ``ts.types[typename](**{**zero, **given})`` builds
    a message from the fields given (the zero values may be shared by the messages of one call: serialising
    does not change them)."""
    _, defs = ts.fielddefs[typename]
    return {name: _zero(ts, node) for name, node in defs}


def default_message(ts, typename: str, **fields):
    """A ``typename`` message of ``ts`` with ``fields`` set and every other field at its zero value."""
    values = zero_fields(ts, typename)
    unknown = sorted(set(fields) - set(values))
    if unknown:
        raise TypeError(f"{typename} has no field(s) {unknown}")
    return ts.types[typename](**{**values, **fields})
