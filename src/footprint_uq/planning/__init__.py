"""The site planner: where to mount which cameras so that every zone of a site is covered to its stated
accuracy (``footprint-uq plan``; docs/planning.md).

Layer: above :mod:`footprint_uq.products` (maps, fusion, geo) and the camera models, below
:mod:`footprint_uq.viz` and :mod:`footprint_uq.cli`.

``from footprint_uq.planning import load_site, plan, evaluate_layout`` is the entry of docs/planning.md;
the layout files (``read_layout``, ``write_layout``) and the optimiser's parts (``candidate_grid``,
``precompute``, ``Objective``, ``greedy``, ``milp_select``, ``swap_search``, ``grid_bound``, ``refine``)
are here too.
"""

from .coverage import CameraConfig, LayoutEvaluation, build_camera, camera_information, evaluate_layout
from .geometry import GroundSamples, ground_samples, occluded, points_in_polygon
from .layout import LayoutCamera, evaluate_cameras, layout_from_configs, read_layout, sensitivity, write_layout
from .optimise import (
    METHODS,
    Coverage,
    Objective,
    PlanResult,
    candidate_grid,
    greedy,
    grid_bound,
    milp_select,
    plan,
    precompute,
    refine,
    swap_search,
)
from .site import Site, load_site, site_from_dict

__all__ = ["Site", "load_site", "site_from_dict", "GroundSamples", "ground_samples", "occluded", "points_in_polygon",
           "CameraConfig", "build_camera", "camera_information", "evaluate_layout", "LayoutEvaluation",
           "plan", "PlanResult", "METHODS", "candidate_grid", "precompute", "Coverage", "Objective", "greedy",
           "milp_select", "swap_search", "grid_bound", "refine", "LayoutCamera", "layout_from_configs", "read_layout",
           "write_layout", "evaluate_cameras", "sensitivity"]
