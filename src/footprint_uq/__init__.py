"""footprint-uq: ground position and 2x2 covariance of roadside-camera detections.

Implements Kusari et al., "Object level footprint uncertainty quantification in
infrastructure based sensing": the pan-tilt ground back-projection, its
closed-form Jacobians, ``Cov = J Sigma J^T`` and the footprint uncertainty of
detected objects, generalised to OpenCV cameras with distortion.
"""

import importlib

from . import _moved, _notices, _numba_cache  # noqa: F401 - _numba_cache: numba's cache folder, set before any kernel module
from .cameras.opencv import OpenCVCamera
from .cameras.pantilt import PanTiltCamera
from .errors import ConfigError, ConsistencyWarning, FootprintUQError, InputError
from .io import load_camera, save_budget, save_camera
from .params import PARAM_NAMES
from .products.footprints import (
    FootprintEstimate,
    FrameProcessor,
    footprints_from_boxes2d,
    footprints_from_boxes3d,
    footprints_from_corners,
)
from .products.fusion import fuse_by_id
from .products.geo import GeoReference, footprints_geojson
from .products.v2x import cpm_fields, j2735_fields  # noqa: E402
from .products.warmup import LibraryGate
from .uncertainty.budget import ErrorBudget, load_budget
from .uncertainty.ellipse import chi2_scale, ellipse_axes, ellipse_points
from .uncertainty.propagation import (
    GroundEstimate,
    JointEstimate,
    linearity_ratio,
    monte_carlo,
    propagate,
    propagate_joint,
    unscented,
)

__version__ = "0.1.0"

_moved.install(__name__)  # the module paths of 0.1 stay importable (DeprecationWarning)
_notices.set_library_handler(LibraryGate())  # a library call never waits silently on another process's compile

__all__ = [
    "ErrorBudget", "load_budget", "OpenCVCamera", "PanTiltCamera", "chi2_scale", "ellipse_axes",
    "ellipse_points", "ConfigError", "ConsistencyWarning", "FootprintUQError", "InputError",
    "PARAM_NAMES",
    "load_camera", "save_camera", "save_budget",
    "GroundEstimate", "JointEstimate", "linearity_ratio", "monte_carlo", "propagate",
    "propagate_joint", "unscented", "__version__",
    "FootprintEstimate", "FrameProcessor", "footprints_from_boxes2d", "footprints_from_boxes3d",
    "footprints_from_corners", "fuse_by_id", "GeoReference", "footprints_geojson", "cpm_fields", "j2735_fields",
    "read_detections", "footprints_from_supervision", "footprints_from_xyxy",
]

#: detector files and in-memory detections (docs/integrations.md): loaded on first use, so that
#: ``import footprint_uq`` does not pay for the batch package (~0.2 s) when they are not used
_LAZY = {"read_detections": "footprint_uq.batch.formats", "footprints_from_supervision": "footprint_uq.batch.arrays",
         "footprints_from_xyxy": "footprint_uq.batch.arrays"}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
