"""``footprint-uq plan``: where to mount which cameras (docs/planning.md).

Three modes: plan a site (default), ``--evaluate LAYOUT`` (a given layout, as a planner checks it before
buying), ``--serve`` (an interactive page on the loopback interface: sliders for one camera's height, pan
and tilt that re-draw the map).  The work is :mod:`footprint_uq.viz.planning_run` and
:mod:`footprint_uq.viz.plan_server`.
"""

from __future__ import annotations

import math

import click

from ..errors import InputError
from ..viz.plan_server import serve_plan
from ..viz.planning_run import PlanOptions, run_evaluate, run_plan
from .common import FiniteFloatRange, warn

__all__ = ["plan_cmd"]


def _pct(x):
    return f"{100 * x:.1f} %"


def _echo_zones(ev):
    for z in ev.zones:
        worst = f"{z.worst_semi_major_m:.3g} m" if math.isfinite(z.worst_semi_major_m) else "not seen"
        click.echo(f"  {z.name}: {_pct(z.fraction_met)} of {z.area_m2:.0f} m^2 met (<= {z.max_semi_major_m:g} m); "
                   f"worst {worst} at ({z.worst_xy_m[0]:.1f}, {z.worst_xy_m[1]:.1f})")


@click.command("plan")
@click.option("--site", "site_path", required=True, metavar="FILE", help="Site file (YAML/JSON; docs/planning.md).")
@click.option("--out", "out_dir", default=None, metavar="DIR",
              help="Output directory: layout.yaml, cameras/*.yaml, plan.json (or evaluation.json), report.html.")
@click.option("--evaluate", "layout_path", default=None, metavar="LAYOUT",
              help="Evaluate this layout.yaml instead of planning.")
@click.option("--serve", is_flag=True, help="Serve the interactive page on 127.0.0.1 (with --layout or a plan).")
@click.option("--layout", "serve_layout", default=None, metavar="LAYOUT", help="Layout to start --serve from.")
@click.option("--port", type=click.IntRange(0, 65535), default=8765, show_default=True,
              help="--serve: port on 127.0.0.1 (0: any free port).")
@click.option("--cameras", "max_cameras", type=click.IntRange(min=1), default=None,
              help="Number of cameras K (default: search.max_cameras of the site file).")
@click.option("--max-cost", type=FiniteFloatRange(min=0), default=None, help="Largest total cost (mounts + cameras).")
@click.option("--method", type=click.Choice(["best", "greedy", "milp", "both"]), default="best", show_default=True,
              help="Discrete stage: best (milp where the grid allows it, greedy, swap search, each refined, the "
                   "best kept, with a bound on the distance to the grid's optimum), lazy greedy, scipy milp "
                   "(exact over the grid for pairs), or greedy and milp.")
@click.option("--time-limit-s", type=FiniteFloatRange(min=0, min_open=True), default=300.0, show_default=True,
              help="Time limit of the discrete stage (best: all of it; milp: the integer program).")
@click.option("--fusion/--no-fusion", default=True, show_default=True,
              help="Count a sample as met by the fused covariance of every camera that sees it (or one camera).")
@click.option("--refine/--no-refine", default=True, show_default=True,
              help="Continuous refinement of pan, tilt and height after the discrete stage.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the refinement.")
@click.option("--screen-step", type=click.IntRange(min=1), default=1, show_default=True,
              help="Screen the candidates on every N-th sample (faster); refinement and evaluation use all.")
@click.option("--max-refine-evals", type=click.IntRange(min=0), default=200, show_default=True,
              help="Largest number of layouts the refinement evaluates.")
@click.option("--sensitivity/--no-sensitivity", default=True, show_default=True,
              help="Sensitivity table (+-1 m height, +-2 deg tilt, budget sigmas x2).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Processes screening the candidates (e.g. the number of cores).")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
def plan_cmd(site_path, out_dir, layout_path, serve, serve_layout, port, max_cameras, max_cost, method, time_limit_s,
             fusion, refine, seed, screen_step, max_refine_evals, sensitivity, workers, progress):
    """Choose K mounts and, for each, camera, lens, height, pan and tilt to maximise the weighted area whose
    95 % position uncertainty meets its zone's requirement; or evaluate / interactively adjust a layout."""
    opts = PlanOptions(method, max_cameras, max_cost, fusion, refine, seed, screen_step, max_refine_evals,
                       sensitivity, progress, workers=workers, time_limit_s=time_limit_s)
    if serve:
        serve_plan(site_path, serve_layout, port=port, fusion=fusion)
        return
    if out_dir is None:
        raise InputError("--out", None, "an output directory (or --serve)")
    if layout_path is not None:
        ev, files = run_evaluate(site_path, layout_path, out_dir, opts)
    else:
        res, files = run_plan(site_path, out_dir, opts)
        ev = res.evaluation
        click.echo(f"{res.n_candidates} candidates, {res.method}: {res.discrete_value:.0f} m^2 -> refined "
                   f"{res.value:.0f} m^2 (weighted) in {res.seconds['total']:.1f} s")
        b = res.bound
        if b.get("upper_bound_m2") is not None:
            click.echo(f"  over the candidate grid: {b['value_m2']:.0f} m^2 of at most {b['upper_bound_m2']:.0f} m^2 "
                       f"(gap {_pct(b['gap'])}, bound: {b['kind']}"
                       + (f", on every {b['screen_step']}th sample" if b.get("screen_step", 1) > 1 else "") + ")")
        if not res.configs:
            warn("no candidate camera meets any sample's requirement within the constraints (cost, count): "
                 "the layout is empty")
        for c in res.configs:
            click.echo(f"  {c.mount}: {c.camera_type}/{c.lens} at {c.height_m:.2f} m, pan {c.pan_deg:.1f} deg, "
                       f"tilt {c.tilt_deg:.1f} deg")
    click.echo(f"weighted met area {_pct(ev.fraction)}")
    _echo_zones(ev)
    for p in files.values():
        click.echo(f"wrote {p}")
