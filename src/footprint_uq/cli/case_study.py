"""``footprint-uq case-study``: the paper's left-turn case study -> figures, CSV and report.html.

Registered in :mod:`footprint_uq.cli.main` (``main.add_command(case_study)``); ``make demo`` runs it.
"""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["case_study", "run_case_study"]


def run_case_study(out_dir, *, config=None, recording=None, camera_types=None, ellipse_every: int = 4,
                   dpi: int = 130, write_recording_to=None, reproduction: bool = True) -> dict:
    """Run the case study and write its report; returns the paths and the result.

    Parameters
    ----------
    out_dir : path
    config : path or CaseStudyConfig, optional   scenario settings (YAML/JSON)
    recording : path, optional   analyse a recording (docs/carla-recording.md) instead of the generator
    camera_types : list of budget specs, optional   override the config's camera types
    ellipse_every : int   draw every n-th frame's ellipse
    dpi : int
    write_recording_to : path, optional   also save the generated scene as a recording
    reproduction : bool   also write ``paper-reproduction.md`` (the paper's tables and statements under both
        readings of Table 3's angles, default scene; :mod:`footprint_uq.scenario.reproduction`) and link it
    """
    import matplotlib

    matplotlib.use("Agg")
    from ..integrations.carla.bridge import read_recording, scene_to_recording
    from ..scenario.case_study import CaseStudyConfig, analyse, build_scene, load_config
    from ..scenario.reproduction import write_paper_reproduction
    from ..viz.case_study import write_case_study_report

    if config is None:
        cfg = CaseStudyConfig()
    elif isinstance(config, CaseStudyConfig):
        cfg = config
    else:
        cfg = load_config(config)
    types = cfg.camera_types if not camera_types else {str(k): k for k in camera_types}
    scene = read_recording(recording) if recording is not None else build_scene(cfg)
    if write_recording_to is not None:
        scene_to_recording(scene, write_recording_to)
    result = analyse(scene, types, confidence=cfg.confidence)
    settings = cfg.to_dict() if recording is None else {"heatmap": cfg.heatmap}
    repro = write_paper_reproduction(Path(out_dir) / "paper-reproduction.md") if reproduction else None
    paths = write_case_study_report(result, out_dir, settings=settings, ellipse_every=ellipse_every,
                                    heatmap=cfg.heatmap, dpi=dpi,
                                    reproduction_link=repro.name if repro is not None else None)
    paths["result"] = result
    paths["reproduction"] = repro
    return paths


@click.command("case-study")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output directory (figures, case_study_frames.csv, summary.json, report.html).")
@click.option("--config", "config", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Scenario settings, YAML or JSON (docs/case-study.md); default: the paper-like set-up.")
@click.option("--recording", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Analyse a CARLA recording (JSON Lines, docs/carla-recording.md) instead of the generator.")
@click.option("--camera-type", "camera_types", multiple=True,
              help="Budget preset or file; repeat to compare several (default: basler1, bw-bullet1, bw-cube1).")
@click.option("--ellipse-every", default=4, show_default=True, type=click.IntRange(1, 1000),
              help="Draw the ellipse of every n-th frame.")
@click.option("--dpi", default=130, show_default=True, type=click.IntRange(50, 600), help="PNG resolution.")
@click.option("--save-recording", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the analysed scene as a recording (JSON Lines).")
def case_study(out_dir, config, recording, camera_types, ellipse_every, dpi, save_recording):
    """The paper's left-turn case study: two roadside cameras, three camera types.

    Writes one PNG per figure, a CSV of every per-frame value, a self-contained
    report.html with the paper's statements tested (PASS/FAIL, tolerances fixed in
    footprint_uq.scenario.claims) and paper-reproduction.md (every table and statement
    of the paper under both readings of Table 3's angles). Camera types accept
    NAME@deg (Table 3's angles read as degrees).
    """
    from ..scenario.claims import evaluate_claims

    paths = run_case_study(out_dir, config=config, recording=recording, camera_types=list(camera_types) or None,
                           ellipse_every=ellipse_every, dpi=dpi, write_recording_to=save_recording)
    res = paths["result"]
    click.echo(f"case study: {len(res.scene)} frames, {len(res.camera_names)} cameras x {len(res.type_names)} "
               f"camera types")
    for c in evaluate_claims(res):
        click.echo(f"  {c['id']}: {c['verdict']} ({', '.join(f'{k} {v}' for k, v in c['per_camera'].items())})")
    click.echo(f"figures: {len(paths['figures'])} PNG in {out_dir}")
    click.echo(f"csv: {paths['csv']}")
    click.echo(f"report: {paths['report']}")
    click.echo(f"paper reproduction: {paths['reproduction']}")
