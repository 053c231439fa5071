"""The paper's case study: intersection, left-turn trajectory, roadside cameras, analysis.

See :mod:`footprint_uq.scenario.case_study` for the pipeline and ``docs/case-study.md``.
"""

from .cameras import CAMERA_TYPES, CameraSpec, default_camera_specs, focal_from_hfov, hfov_from_focal
from .case_study import (
    AXIS_SYSTEMS,
    CaseStudyConfig,
    CaseStudyResult,
    FootprintHeatmap,
    Scene,
    analyse,
    axis_components,
    build_scene,
    centre_contributions,
    footprint_heatmap,
    load_config,
)
from .intersection import ARMS, Intersection, Marking, RoadLayout
from .trajectory import SEGMENTS, LeftTurnPath, Trajectory, Vehicle, box_corners, left_turn_path, sample_trajectory

__all__ = [
    "CAMERA_TYPES", "CameraSpec", "default_camera_specs", "focal_from_hfov", "hfov_from_focal", "AXIS_SYSTEMS",
    "CaseStudyConfig", "CaseStudyResult", "FootprintHeatmap", "Scene", "analyse", "axis_components", "build_scene",
    "centre_contributions", "footprint_heatmap", "load_config", "ARMS", "Intersection", "Marking", "RoadLayout",
    "SEGMENTS", "LeftTurnPath", "Trajectory", "Vehicle", "box_corners", "left_turn_path", "sample_trajectory",
]
