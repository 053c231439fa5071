"""The site planner: where to mount which cameras so that every zone of a site is covered to its stated
accuracy (``footprint-uq plan``; docs/planning.md).

Layer: above :mod:`footprint_uq.products` (maps, fusion, geo) and the camera models, below
:mod:`footprint_uq.viz` and :mod:`footprint_uq.cli`.
"""

from .coverage import CameraConfig, LayoutEvaluation, build_camera, camera_information, evaluate_layout
from .geometry import GroundSamples, ground_samples, occluded, points_in_polygon
from .site import Site, load_site, site_from_dict

__all__ = ["Site", "load_site", "site_from_dict", "GroundSamples", "ground_samples", "occluded", "points_in_polygon",
           "CameraConfig", "build_camera", "camera_information", "evaluate_layout", "LayoutEvaluation"]
