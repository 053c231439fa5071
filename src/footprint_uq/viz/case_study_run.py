"""The paper's left-turn case study from settings to report (the ``footprint-uq case-study`` output).

:func:`run_case_study` builds the scene (the generator of :mod:`footprint_uq.scenario`, or a
CARLA recording), analyses it for each camera type and writes the figures, the per-frame CSV,
``summary.json``, ``report.html`` (:func:`footprint_uq.viz.case_study.write_case_study_report`)
and ``paper-reproduction.md`` (:mod:`footprint_uq.scenario.reproduction`), as one set: built in a hidden
folder and swapped in together (:func:`footprint_uq.io.atomic.output_set`; the folder must be new or hold
only a previous run's files, :data:`CASE_STUDY_OWN`).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

from ..integrations.carla.bridge import read_recording, scene_to_recording
from ..io.atomic import check_output_folder, final_paths, output_set
from ..scenario.case_study import CaseStudyConfig, analyse, build_scene, load_config
from ..scenario.claims import evaluate_claims
from ..scenario.reproduction import write_paper_reproduction
from .case_study import write_case_study_report

__all__ = ["run_case_study", "CASE_STUDY_OWN"]

#: the names a run writes into its folder (figures are named after cameras and types: every PNG)
CASE_STUDY_OWN = ("*.png", "case_study_frames.csv", "summary.json", "report.html", "paper-reproduction.md")


def run_case_study(out_dir, *, config=None, recording=None, camera_types=None, ellipse_every: int = 4,
                   dpi: int = 130, write_recording_to=None, reproduction: bool = True, progress=None) -> dict:
    """Run the case study and write its report.

    Parameters
    ----------
    out_dir : path
        Output directory (created).
    config : path or CaseStudyConfig, optional
        Scenario settings (YAML/JSON file, ``docs/case-study.md``); default the paper-like set-up.
    recording : path, optional
        Analyse a recording (``docs/carla-recording.md``) instead of the generator's scene.
    camera_types : list of str or ErrorBudget, optional
        Budget specs overriding the config's camera types.
    ellipse_every : int
        Draw the ellipse of every n-th frame.
    dpi : int
        Resolution of the PNG figures.
    write_recording_to : path, optional
        Also save the analysed scene as a recording.
    reproduction : bool
        Also write ``paper-reproduction.md`` (the paper's tables and statements under both
        readings of Table 3's angles, default scene) and link it from the report.
    progress : callable(str), optional
        Called with a short message as each stage starts (scene, analysis, reproduction, figures and report).

    Returns
    -------
    dict
        The paths of :func:`~footprint_uq.viz.case_study.write_case_study_report` (``figures``,
        ``csv``, ``report``, ...), plus ``result`` (the
        :class:`~footprint_uq.scenario.case_study.CaseStudyResult`), ``claims`` (the paper's
        statements tested, :func:`footprint_uq.scenario.claims.evaluate_claims`) and
        ``reproduction`` (the path of ``paper-reproduction.md``, or None).
    """
    matplotlib.use("Agg")
    check_output_folder(out_dir, CASE_STUDY_OWN, "case-study")  # before the work, not after
    say = progress or (lambda msg: None)
    if config is None:
        cfg = CaseStudyConfig()
    elif isinstance(config, CaseStudyConfig):
        cfg = config
    else:
        cfg = load_config(config)
    types = cfg.camera_types if not camera_types else {str(k): k for k in camera_types}
    say("scene: reading the recording" if recording is not None else "scene: the left turn")
    scene = read_recording(recording) if recording is not None else build_scene(cfg)
    if write_recording_to is not None:
        scene_to_recording(scene, write_recording_to)
    say(f"analysis: {len(scene)} frames x {len(types)} camera types")
    result = analyse(scene, types, confidence=cfg.confidence)
    settings = cfg.to_dict() if recording is None else {"heatmap": cfg.heatmap}
    with output_set(out_dir, CASE_STUDY_OWN, "case-study") as stage:
        if reproduction:
            say("paper reproduction: every table and statement, both readings of Table 3's angles")
        repro = write_paper_reproduction(stage / "paper-reproduction.md") if reproduction else None
        say("figures and report")
        paths = write_case_study_report(result, stage, settings=settings, ellipse_every=ellipse_every,
                                        heatmap=cfg.heatmap, dpi=dpi,
                                        reproduction_link=repro.name if repro is not None else None)
    paths = final_paths(paths, stage, out_dir)
    repro = None if repro is None else Path(out_dir) / repro.name
    paths["result"] = result
    paths["claims"] = evaluate_claims(result)
    paths["reproduction"] = repro
    return paths
