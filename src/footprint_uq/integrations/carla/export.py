"""Our generated left-turn scenario as a CARLA recording (``footprint-uq carla export``)."""

from __future__ import annotations

from ...scenario.case_study import CaseStudyConfig, build_scene, load_config
from .bridge import scene_to_recording

__all__ = ["export_scenario"]


def export_scenario(out_file, config=None):
    """Build the case study's scene and write it as a recording (CARLA coordinates).

    Parameters
    ----------
    out_file : path
        Recording to write (JSON Lines, ``docs/carla-recording.md``).
    config : path or CaseStudyConfig, optional
        Scenario settings (``docs/case-study.md``); default the paper-like set-up.

    Returns
    -------
    Scene
        The scene written (``len(scene)`` frames, ``scene.cameras``).
    """
    if config is None:
        cfg = CaseStudyConfig()
    elif isinstance(config, CaseStudyConfig):
        cfg = config
    else:
        cfg = load_config(config)
    scene = build_scene(cfg)
    scene_to_recording(scene, out_file)
    return scene
