"""Figures and the HTML report of ``footprint-uq validate`` (docs/validation.md).

Figures are :class:`matplotlib.figure.Figure` objects (no pyplot; Agg):

* :func:`plot_calibration` -- empirical against nominal coverage of the ellipses (a reliability diagram),
  with the Wilson band at the number of objects and the intervals at the effective number of objects;
* :func:`plot_nees` -- the NEES distribution against the chi-square with 2 degrees of freedom;
* :func:`plot_residuals` -- residuals in the ellipses' own axes, in sigma units, with the 95 % circle;
* :func:`plot_by_range` -- error and 95 % semi-major axis against range, and coverage per range band.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..uncertainty.ellipse import chi2_scale
from ..validation.coverage import LEVELS
from .report import esc, html_page, html_table, img_tag, lead_block

__all__ = ["plot_calibration", "plot_nees", "plot_residuals", "plot_by_range", "validation_figures",
           "validation_html"]

#: below this effective number of objects the report calls the evidence weak
WEAK_N_EFF = 10.0
_VERDICT_COLOUR = {"consistent": "#2a7a2a", "over-confident": "#b02020", "under-confident": "#b07000"}


def plot_calibration(summary: dict, *, title: str = "") -> Figure:
    """Empirical vs nominal coverage: the grid curve with its Wilson band, the four levels with their
    intervals (thin: objects independent; thick: at the effective number of objects)."""
    fig = Figure(figsize=(5.2, 5.0))
    ax = fig.add_subplot()
    cc = summary["calibration_curve"]
    x = np.asarray(cc["nominal"])
    ax.fill_between(x, cc["low"], cc["high"], color="#9ecae1", alpha=0.6, lw=0, label="Wilson 95 % (independent)")
    ax.plot(x, cc["empirical"], color="#08519c", lw=1.8, label="empirical")
    ax.plot([0, 1], [0, 1], color="k", lw=0.8, ls="--", label="ideal")
    for row in summary["coverage"]:
        p, e = row["nominal"], row["empirical"]
        lo_e, hi_e = row["interval_n_eff"]
        ax.plot([p, p], [lo_e, hi_e], color="#d95f02", lw=4, alpha=0.45, solid_capstyle="butt")
        ax.errorbar([p], [e], yerr=[[max(e - row["interval"][0], 0.0)], [max(row["interval"][1] - e, 0.0)]], fmt="o",
                    color="#d95f02",
                    ms=5, capsize=3, lw=1)
    ax.plot([], [], color="#d95f02", lw=4, alpha=0.45, label="levels: interval at n_eff")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("nominal coverage of the ellipse")
    ax.set_ylabel("fraction of truths inside")
    n, neff = summary["n_pairs"], summary["nees_test"].get("n_eff", float("nan"))
    ax.set_title(title or f"Coverage calibration (n = {n}, n_eff = {neff:.3g})", fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_nees(sample: dict) -> Figure:
    """Empirical CDF of the NEES against the chi-square(2) CDF ``1 - exp(-q / 2)``."""
    fig = Figure(figsize=(5.2, 4.0))
    ax = fig.add_subplot()
    q = np.sort(sample["nees"][np.isfinite(sample["nees"])])
    if q.size:
        ax.step(q, np.arange(1, q.size + 1) / q.size, where="post", color="#08519c", label="empirical")
        hi = max(float(np.percentile(q, 99)), 14.0)
        xs = np.linspace(0, hi, 300)
        ax.plot(xs, 1 - np.exp(-xs / 2), color="k", ls="--", lw=1, label=r"$\chi^2_2$ (model)")
        for lv in (0.5, 0.95):
            ax.axvline(-2 * np.log1p(-lv), color="#999", lw=0.7)
        ax.set_xlim(0, hi)
    ax.set_xlabel("NEES = r' C^-1 r")
    ax.set_ylabel("cumulative fraction")
    ax.set_title("NEES distribution", fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_residuals(sample: dict) -> Figure:
    """Residuals along each ellipse's major / minor axis divided by its sigmas, with the 95 % circle."""
    fig = Figure(figsize=(5.2, 5.0))
    ax = fig.add_subplot()
    with np.errstate(invalid="ignore", divide="ignore"):
        a = sample["r_major_m"] / sample["sigma_major_m"]
        b = sample["r_minor_m"] / np.maximum(sample["sigma_minor_m"], 1e-12 * sample["sigma_major_m"])
    ax.scatter(b, a, s=6, alpha=0.5, color="#08519c", lw=0)
    t = np.linspace(0, 2 * np.pi, 200)
    k = chi2_scale(0.95)
    ax.plot(k * np.cos(t), k * np.sin(t), color="#d95f02", lw=1.2, label="95 % ellipse")
    lim = max(3.5, float(np.nanpercentile(np.abs(np.r_[a, b]), 98)) * 1.1) if a.size else 3.5
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("residual along the minor axis / sigma_minor")
    ax.set_ylabel("residual along the major axis / sigma_major")
    ax.set_title("Residuals in the ellipses' own axes", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_by_range(summary: dict, sample: dict) -> Figure:
    """Left: horizontal error and 95 % semi-major axis against range; right: 95 % coverage per band."""
    fig = Figure(figsize=(9.0, 3.8))
    ax, bx = fig.subplots(1, 2)
    k = chi2_scale(0.95)
    ax.scatter(sample["range_m"], sample["error_m"], s=6, alpha=0.5, lw=0, color="#08519c", label="|error|")
    ax.scatter(sample["range_m"], k * sample["sigma_major_m"], s=6, alpha=0.5, lw=0, color="#d95f02",
               label="95 % semi-major axis")
    ax.set_xlabel("range from the camera's foot point (m)")
    ax.set_ylabel("metres")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    rows = summary["by_range"]
    x = np.arange(len(rows))
    cov = np.array([r["coverage_95"] for r in rows])
    lo = np.array([r["interval_95"][0] for r in rows])
    hi = np.array([r["interval_95"][1] for r in rows])
    bx.bar(x, cov, color="#9ecae1")
    bx.errorbar(x, cov, yerr=[np.clip(cov - lo, 0, None), np.clip(hi - cov, 0, None)], fmt="none", color="k",
                capsize=3, lw=1)
    bx.axhline(0.95, color="#d95f02", ls="--", lw=1)
    bx.set_xticks(x, [f"{r['range']}\n(n={r['n']})" for r in rows], fontsize=7)
    bx.set_ylim(0, 1.05)
    bx.set_ylabel("coverage of the 95 % ellipse")
    fig.tight_layout()
    return fig


def validation_figures(summary: dict, sample: dict | None) -> dict:
    """The report's figures by name (only the calibration figure without a sample)."""
    figs = {"calibration": plot_calibration(summary)}
    if sample is not None and len(sample["nees"]):
        figs.update(nees=plot_nees(sample), residuals=plot_residuals(sample), by_range=plot_by_range(summary, sample))
    return figs


def _pct(x) -> str:
    return "&ndash;" if x is None or not np.isfinite(x) else f"{100 * x:.1f} %"


def _coverage_rows(summary):
    out = []
    for r in summary["coverage"]:
        out.append({"nominal": _pct(r["nominal"]), "inside": f"{r['inside']} / {r['n']}",
                    "empirical": _pct(r["empirical"]),
                    "Wilson 95 % (independent)": f"{_pct(r['interval'][0])} &ndash; {_pct(r['interval'][1])}",
                    "at n_eff": f"{_pct(r['interval_n_eff'][0])} &ndash; {_pct(r['interval_n_eff'][1])}",
                    "SE at n_eff": _pct(r.get("se_n_eff")), "cluster SE": _pct(r.get("se_cluster"))})
    return out


def _raw_table(rows, columns) -> str:
    """A table whose cells are already HTML (percentages with entities)."""
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{r[c]}</td>" for c in columns) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _breakdown(rows, key) -> str:
    cols = [key, "n", "nees_mean"] + [f"coverage_{round(lv * 100)}" for lv in LEVELS]
    return html_table([{c: r[c] for c in cols} for r in rows], cols, floatfmt=".3g")


def _lead_html(summary, figures: dict, dpi: int) -> str:
    """The report's opening: the coverage calibration figure and the verdict in one sentence."""
    t = summary["nees_test"]
    v = summary.get("verdict")
    if v is None or "calibration" not in figures:
        return _verdict_html(summary)
    col = _VERDICT_COLOUR.get(v, "#555")
    c95 = next((c for c in summary["coverage"] if c["nominal"] == 0.95), None)
    cover = (f"the 95&nbsp;% ellipses contain {100 * c95['empirical']:.0f}&nbsp;% of the {summary['n_pairs']} "
             "true positions, " if c95 is not None else "")
    verdict = (f'Verdict: <b style="color:{col}">{esc(v)}</b> &mdash; {cover}mean NEES {t["nees_mean"]:.3g} '
               f"(expected 2 if the uncertainty is right; effective number of independent objects "
               f"{t['n_eff']:.3g}).")
    return lead_block(figures["calibration"], "Coverage calibration: the fraction of true positions inside the "
                      "ellipse against the ellipse's nominal coverage (on the diagonal: the uncertainty is right; "
                      "above: over-cautious; below: over-confident).", verdict, dpi=dpi)


def _verdict_html(summary) -> str:
    t = summary["nees_test"]
    v = summary.get("verdict")
    col = _VERDICT_COLOUR.get(v, "#555")
    if v is None:
        return '<p class="verdict">No usable pair: no verdict.</p>'
    weak = ""
    if t["n_eff"] < WEAK_N_EFF:
        weak = (f'<p class="note">Weak evidence: the pairs carry the information of about {t["n_eff"]:.2g} independent '
                "objects (their calibration draws are shared), so only a gross misfit can be detected; "
                f"&ldquo;{esc(v)}&rdquo; means &ldquo;not refuted by these data&rdquo;. More cameras or calibration "
                "campaigns, not more objects, make the test sharper (docs/validation.md).</p>")
    return (f'<p>Verdict in detail: <b style="color:{col}">{esc(v)}</b> '
            f"(mean NEES {t['nees_mean']:.3g}, expected 2; p(too large) = {t['p_value_too_large']:.3g}, "
            f"p(too small) = {t['p_value_too_small']:.3g}; n = {t['n']}, effective n = {t['n_eff']:.3g}).</p>" + weak)


_NOTE = ("The verdict tests the sum of the NEES against its distribution under the model, with the correlation "
         "of objects that share one calibration draw (one draw per calibration group: a camera, or identical "
         "calibration files): it assumes Gaussian, first-order errors and the budget's parameter covariance, and "
         "approximates the sum by a chi-square of the same mean and variance. The effective number of objects "
         "n_eff says how much the data can tell: with one camera whose calibration error dominates, it is close "
         "to 1 whatever the number of objects. The Wilson intervals at n (objects independent) are too narrow "
         "when the calibration part dominates; those at n_eff and the cluster standard error (several groups) "
         "account for it (docs/validation.md).")


def validation_html(summary: dict, figures: dict, *, title: str = "Validation of the uncertainty",
                    dpi: int = 110) -> str:
    """The self-contained report page (figures embedded)."""
    un = summary.get("unpaired", {})
    err = summary.get("error", {})
    b = summary["bias"]
    detail = summary.get("verdict") is not None and "calibration" in figures
    parts = [_lead_html(summary, figures, dpi), _verdict_html(summary) if detail else "",
             f"<p>Budget <code>{esc(summary.get('budget'))}</code>, contact model "
             f"<code>{esc(summary.get('contact'))}</code>, {summary.get('n_groups', 0)} calibration group(s).</p>",
             "<h2>Coverage of the ellipses</h2>",
             _raw_table(_coverage_rows(summary), ["nominal", "inside", "empirical", "Wilson 95 % (independent)",
                                                  "at n_eff", "SE at n_eff", "cluster SE"]),
             f'<p class="note">{esc(_NOTE)}</p>',
             "<h2>Pairs</h2>",
             html_table([{"rows": sum(summary["rows"].values()), "pairs used": summary["n_pairs"],
                          "detections without truth": un.get("detections_without_truth", 0),
                          "truths without detection": un.get("truth_without_detection", 0),
                          "no ground point": un.get("no_ground_point", 0), "error rows": un.get("error_rows", 0)}]),
             _folder_note(summary.get("folder")),
             "<h2>Errors and bias</h2>",
             html_table([{"median |error| (m)": err.get("median_m"), "95th percentile (m)": err.get("p95_m"),
                          "max (m)": err.get("max_m"),
                          "bias x, y (m)": ", ".join(f"{v:.3g}" for v in b.get("bias_m", [])),
                          "95 % interval x (m)": _interval(b, 0), "95 % interval y (m)": _interval(b, 1),
                          "bias p-value": b.get("p_value")}], floatfmt=".3g")]
    for name, cap in (("nees", "NEES distribution against the model's chi-square(2)"),
                      ("residuals", "Residuals in the ellipses' own axes (sigma units)"),
                      ("by_range", "Error, ellipse size and coverage against range")):
        if name in figures:
            parts.append(img_tag(figures[name], cap, dpi=dpi))
    parts += ["<h2>Coverage by range band</h2>", _breakdown(summary["by_range"], "range"),
              "<h2>Coverage by class</h2>", _breakdown(summary["by_class"], "class"),
              "<h2>Coverage by linear_ok</h2>", _breakdown(summary["by_linear_ok"], "linear_ok")]
    groups = summary.get("groups", [])
    if groups:
        parts += [f"<h2>Calibration groups ({len(groups)})</h2>",
                  html_table(groups[:100], ["group", "n", "nees_mean", "coverage_95"], floatfmt=".3g")]
    if "motion" in summary:
        parts += _motion_html(summary["motion"])
    return html_page(title, parts)


_MOTION_NOTE = ("Velocity: NEES = dv^T C_v^-1 dv against chi-square(2); heading: ((truth - track) / sigma)^2 against "
                "chi-square(1), only where the tracker states a heading sigma and the truth moves. The verdict tests "
                "the mean NEES with a cluster-robust standard error (tracks, and cameras from 5 on, as clusters: "
                "consecutive estimates of one track are correlated); n_eff is the number of independent objects "
                "with the same information (docs/validation.md, \"Velocity and heading\").")


def _motion_rows(block: dict) -> list[dict]:
    return [{"nominal": _pct(r["nominal"]), "inside": r["inside"], "n": r["n"], "empirical": _pct(r["empirical"]),
             "at n_eff": f"{_pct(r['interval_n_eff'][0])} &ndash; {_pct(r['interval_n_eff'][1])}"}
            for r in block["coverage"]]


def _motion_line(what: str, block: dict) -> str:
    t = block["test"]
    v = t.get("verdict")
    if v is None:
        return f"<p>{esc(what)}: no verdict ({t['n']} scored).</p>"
    col = _VERDICT_COLOUR.get(v, "#555")
    weak = " (weak evidence)" if t.get("evidence") == "weak" else ""
    return (f'<p>{esc(what)}: <b style="color:{col}">{esc(v)}</b>{weak} (mean NEES {t["nees_mean"]:.3g}, expected '
            f'{t["nees_expected"]:.0f}; p = {t["p_value"]:.3g}; n = {t["n"]}, {t["n_tracks"]} tracks, '
            f'effective n = {t["n_eff"]:.3g}).</p>')


def _motion_html(motion: dict | None) -> list[str]:
    """The report's "Velocity and heading" section (``summary["motion"]``)."""
    if motion is None:
        return ["<h2>Velocity and heading</h2>", '<p class="note">No row carries a truth velocity: velocity and '
                "heading not scored.</p>"]
    cols = ["nominal", "inside", "n", "empirical", "at n_eff"]
    parts = ["<h2>Velocity and heading</h2>", _motion_line("Velocity", motion["velocity"]),
             _raw_table(_motion_rows(motion["velocity"]), cols), _motion_line("Heading", motion["heading"]),
             _raw_table(_motion_rows(motion["heading"]), cols),
             html_table([{k.replace("_", " "): v for k, v in motion["counts"].items()}]),
             f'<p class="note">{esc(_MOTION_NOTE)}</p>']
    rows = []
    for cls, b in motion.get("by_class", {}).items():
        for what in ("velocity", "heading"):
            t = b[what]["test"]
            c95 = next((r for r in b[what]["coverage"] if r["nominal"] == 0.95), None)
            rows.append({"class": cls, "quantity": what, "n": t["n"], "nees_mean": t["nees_mean"],
                         "coverage_95": None if c95 is None else c95["empirical"], "verdict": t.get("verdict")})
    if rows:
        parts += ["<h3>Velocity and heading by class</h3>",
                  html_table(rows, ["class", "quantity", "n", "nees_mean", "coverage_95", "verdict"], floatfmt=".3g")]
    return parts


def _folder_note(folder) -> str:
    """Frames that could not be paired (label files without calibration, calibration without labels)."""
    if not folder:
        return ""
    parts = []
    for key, what in (("labels_without_calibration", "label files without calibration (their rows are errors)"),
                      ("calibration_without_labels", "calibration files without labels")):
        ids = folder.get(key) or []
        if ids:
            shown = ", ".join(str(i) for i in ids[:10]) + (f", ... ({len(ids)} in all)" if len(ids) > 10 else "")
            parts.append(f"{len(ids)} {what}: {shown}")
    return f'<p class="note">Frames: {esc(folder.get("frames", 0))} read; {esc("; ".join(parts))}.</p>' if parts \
        else ""


def _interval(b, j) -> str:
    if "interval_m" not in b:
        return "\u2013"
    return f"{b['interval_m'][0][j]:.3g} to {b['interval_m'][1][j]:.3g}"
