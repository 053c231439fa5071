"""The jobs behind ``footprint-uq plan`` and ``plan --evaluate``: options -> files written.

``out_dir`` receives ``layout.yaml`` and ``cameras/*.yaml`` (plan only), ``plan.json`` (or
``evaluation.json``) and ``report.html``, as one set: built in a hidden folder beside ``out_dir`` and
swapped in together (:func:`footprint_uq.io.atomic.output_set`), so that a reader never sees the report
of one layout beside the evaluation of another.  ``out_dir`` must be new or hold only a previous run's
files of the same job (:data:`PLAN_OWN`, :data:`EVALUATE_OWN`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..io.atomic import check_output_folder, final_paths, output_set
from ..planning.geometry import ground_samples
from ..planning.layout import evaluate_cameras, layout_from_configs, read_layout, sensitivity, write_json, write_layout
from ..planning.optimise import plan
from ..planning.site import load_site
from .planning import write_plan_report

__all__ = ["PlanOptions", "run_plan", "run_evaluate", "PLAN_OWN", "EVALUATE_OWN"]

#: the names a ``plan`` run writes into its folder (anything else there: the folder is refused, not replaced)
PLAN_OWN = ("layout.yaml", "cameras", "plan.json", "report.html")
#: the names a ``plan --evaluate`` run writes
EVALUATE_OWN = ("evaluation.json", "report.html")


@dataclass
class PlanOptions:
    """Options of ``footprint-uq plan`` (None: the site file's ``search`` section)."""

    method: str = "best"
    max_cameras: int | None = None
    max_cost: float | None = None
    fusion: bool = True
    refine: bool = True
    seed: int = 0
    screen_step: int = 1
    max_refine_evals: int = 200
    sensitivity: bool = True
    progress: bool = False
    dpi: int = 100
    workers: int | None = 1
    time_limit_s: float | None = 300.0


def _summary(evaluation) -> dict:
    return {"fraction_met": evaluation.fraction, "weighted_met_area_m2": evaluation.value,
            "zones": [z.row() for z in evaluation.zones]}


def _finish(site, samples, cameras, out: Path, name: str, extra: dict, opts: PlanOptions) -> dict[str, Path]:
    ev, infos = evaluate_cameras(site, samples, cameras, fusion=opts.fusion)
    sens = sensitivity(site, samples, cameras, fusion=opts.fusion) if opts.sensitivity else None
    files = {name: write_json(out / f"{name}.json", {**extra, **_summary(ev), "sensitivity": sens})}
    info = {k: v for k, v in extra.items() if not isinstance(v, list | dict)}
    files["report"] = write_plan_report(out / "report.html", site, samples, cameras, ev, infos,
                                        sensitivity_rows=sens, plan_info=info, dpi=opts.dpi)
    return files


def run_plan(site_path, out_dir, opts: PlanOptions | None = None):
    """Plan the site of ``site_path`` and write the layout, ``plan.json`` and the report.

    Returns ``(PlanResult, files)``.
    """
    opts = opts or PlanOptions()
    site = load_site(site_path)
    check_output_folder(out_dir, PLAN_OWN, "plan")  # before the search, not after
    res = plan(site, method=opts.method, max_cameras=opts.max_cameras, max_cost=opts.max_cost, fusion=opts.fusion,
               refine_layout=opts.refine, seed=opts.seed, screen_step=opts.screen_step,
               max_refine_evals=opts.max_refine_evals, workers=opts.workers, progress=opts.progress,
               time_limit_s=opts.time_limit_s)
    cameras = layout_from_configs(site, res.configs)
    extra = {"site": str(Path(site_path).resolve()), "method": res.method, "candidates": res.n_candidates,
             "samples": len(res.samples), "seed": opts.seed, "screen_step": opts.screen_step,
             "fusion": opts.fusion, "discrete_value_m2": res.discrete_value, "refined_value_m2": res.value,
             "seconds_total": res.seconds.get("total"), "grid_upper_bound_m2": res.bound.get("upper_bound_m2"),
             "grid_gap": res.bound.get("gap"), "grid_bound_kind": res.bound.get("kind"), "grid_bound": res.bound,
             "starts": res.starts,
             "cameras": [c.__dict__ for c in res.configs]}
    with output_set(out_dir, PLAN_OWN, "plan") as stage:
        files = write_layout(cameras, stage, site_path=Path(site_path).resolve())
        files.update(_finish(site, res.samples, cameras, stage, "plan", extra, opts))
    return res, final_paths(files, stage, out_dir)


def run_evaluate(site_path, layout_path, out_dir, opts: PlanOptions | None = None):
    """Evaluate the layout of ``layout_path`` on the site: ``evaluation.json`` and the report.

    Returns ``(LayoutEvaluation, files)``.
    """
    opts = opts or PlanOptions()
    site = load_site(site_path)
    cameras = read_layout(layout_path, site)
    samples = ground_samples(site)
    with output_set(out_dir, EVALUATE_OWN, "plan --evaluate") as stage:
        files = _finish(site, samples, cameras, stage, "evaluation",
                        {"site": str(Path(site_path).resolve()), "layout": str(Path(layout_path).resolve()),
                         "fusion": opts.fusion, "samples": len(samples)}, opts)
    files = final_paths(files, stage, out_dir)
    return evaluate_cameras(site, samples, cameras, fusion=opts.fusion)[0], files
