"""Draw the architecture figure: the path of a pixel and of a detection through the package.

    python examples/architecture_figure.py --out DIR     # writes DIR/architecture_figure/architecture.png

(docs/figures/architecture.png is this figure.)

One picture, layers top to bottom (CLI, library entry points, products, uncertainty, cameras, fast
core), the pixel path (``locate``) in blue and the detection path (``objects`` / ``serve``) in orange,
down to the scalar core and back up to the outputs.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

PIXEL = "#1f77b4"
DETECTION = "#d95f02"
LAYERS = [  # (y, label, colour)
    (9.0, "cli/  (parse, call one function, print)", "#eeeeee"),
    (7.3, "products/ , batch/ , service/  (what users take away)", "#f3f7ee"),
    (5.6, "uncertainty/  (budget, propagation, ellipse)", "#eef3f9"),
    (3.9, "cameras/  (models, distortion, rotation, ground)", "#f9f3ee"),
    (2.2, "fast/  (numba kernels on the scalar core)", "#f6eef6"),
    (0.6, "io/ , batch/writers  (files in and out, atomic)", "#eeeeee"),
]
BOXES = {  # name: (x, y, text)
    "cli_locate": (1.6, 9.0, "cli/locate.py\nfootprint-uq locate"),
    "cli_map": (4.6, 9.0, "cli/map.py\nfootprint-uq map"),
    "cli_objects": (8.8, 9.0, "cli/objects.py, cli/serve.py\nfootprint-uq objects | serve"),
    "locate": (1.6, 7.3, "products/locate.py\nlocate_records"),
    "maps": (4.6, 7.3, "products/maps.py\nuncertainty_map"),
    "batch": (7.5, 7.3, "batch/process.py\nBatchProcessor"),
    "service": (10.3, 7.3, "service/core.py\nService.process_frame"),
    "propagate": (1.6, 5.6, "uncertainty/propagation.py\npropagate: J Sigma J^T"),
    "budget": (5.0, 5.6, "uncertainty/budget.py\nErrorBudget: Sigma (22x22),\nparam_factor (one PSD factor)"),
    "footprints": (8.6, 5.6, "products/footprints.py\nFrameProcessor"),
    "v2x": (11.4, 5.6, "products/v2x.py, geo.py\nCPM / J2735 fields"),
    "general": (1.6, 3.9, "cameras/general.py\nbackproject (+ dxy_dp, dxy_duv)"),
    "ground": (5.0, 3.9, "cameras/ground.py, distortion.py,\nrotation.py, lens_domain.py"),
    "core": (2.9, 2.2, "fast/core.py  (written once)\nundistort_point, in-domain test,\n"
             "distort + Jacobian, status codes"),
    "mkern": (6.0, 2.2, "fast/map_kernels.py\nmap_into / points_into"),
    "fkern": (9.2, 2.2, "fast/footprint_kernels.py\nprocess_corners"),
    "out_json": (1.6, 0.6, "JSON / CSV record\nxy_world_m, cov_m2, nonlinearity"),
    "out_map": (5.4, 0.6, "map.npz, PNG figures,\nsummary.json"),
    "out_batch": (10.3, 0.6, "Parquet / CSV / JSONL rows,\nCPM (UPER) + SDSM messages"),
}
PATHS = [  # (from, side, to, side, colour, label, curvature); sides: t(op), b(ottom), l(eft), r(ight)
    ("cli_locate", "b", "locate", "t", PIXEL, "pixels", 0.0),
    ("cli_map", "b", "maps", "t", PIXEL, "step_px", 0.0),
    ("locate", "b", "propagate", "t", PIXEL, "", 0.0),
    ("budget", "l", "propagate", "r", PIXEL, "Sigma", 0.0),
    ("propagate", "b", "general", "t", PIXEL, "params, uv", 0.0),
    ("general", "b", "core", "t", PIXEL, "undistort, domain", 0.0),
    ("propagate", "l", "out_json", "l", PIXEL, "", 0.5),
    ("maps", "r", "mkern", "t", PIXEL, "KernelCamera", -0.25),
    ("budget", "b", "mkern", "t", PIXEL, "", 0.0),
    ("mkern", "l", "core", "r", PIXEL, "inlined", 0.0),
    ("mkern", "b", "out_map", "t", PIXEL, "", 0.0),
    ("cli_objects", "b", "batch", "t", DETECTION, "rows", 0.0),
    ("cli_objects", "b", "service", "t", DETECTION, "frames", 0.0),
    ("batch", "b", "footprints", "t", DETECTION, "", 0.0),
    ("service", "b", "footprints", "t", DETECTION, "", 0.0),
    ("footprints", "b", "fkern", "t", DETECTION, "corners", 0.0),
    ("budget", "r", "fkern", "t", DETECTION, "param_factor", -0.2),
    ("fkern", "b", "core", "b", DETECTION, "inlined", -0.14),
    ("footprints", "r", "v2x", "l", DETECTION, "", 0.0),
    ("v2x", "b", "out_batch", "t", DETECTION, "centre, cov, codes", 0.0),
]


def _anchor(name: str, side: str) -> tuple[float, float]:
    """A point on the edge of a box (its size estimated from its text)."""
    x, y, text = BOXES[name]
    lines = text.split("\n")
    hw = 0.034 * max(len(t) for t in lines) + 0.14
    hh = 0.13 * len(lines) + 0.12
    y -= 0.1
    return {"t": (x, y + hh), "b": (x, y - hh), "l": (x - hw, y), "r": (x + hw, y)}[side]


def draw(out: Path) -> Path:
    fig = Figure(figsize=(13.0, 8.6))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(-0.6, 12.6)
    ax.set_ylim(-0.3, 10.0)
    ax.axis("off")
    for y, label, colour in LAYERS:
        ax.add_patch(FancyBboxPatch((-0.3, y - 0.75), 12.8, 1.5, boxstyle="round,pad=0.02", fc=colour,
                                    ec="0.8", lw=0.8, zorder=0))
        ax.text(-0.2, y + 0.62, label, fontsize=8.5, color="0.35", va="top", zorder=1)
    for x, y, text in BOXES.values():
        ax.text(x, y - 0.1, text, ha="center", va="center", fontsize=8.2, zorder=3,
                bbox={"boxstyle": "round,pad=0.35", "fc": "white", "ec": "0.3", "lw": 0.9})
    for a, sa, b, sb, colour, label, rad in PATHS:
        (xa, ya), (xb, yb) = _anchor(a, sa), _anchor(b, sb)
        arrow = FancyArrowPatch((xa, ya), (xb, yb), arrowstyle="-|>", mutation_scale=13, lw=1.6, color=colour,
                                shrinkA=2, shrinkB=2, connectionstyle=f"arc3,rad={rad}", zorder=4)
        ax.add_patch(arrow)
        if label:
            xm, ym = (xa + xb) / 2, (ya + yb) / 2
            if rad:  # the arc's midpoint
                xm, ym = xm + rad * (yb - ya) / 2 * 1.0, ym - rad * (xb - xa) / 2 * 1.0
            ax.text(xm + 0.08, ym, label, fontsize=7.5, color=colour, zorder=5, style="italic",
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.text(0.1, 3.0, "xy_world_m,\ncov_m2", color=PIXEL, fontsize=7.5, style="italic", zorder=5)
    ax.text(12.4, 9.75, "pixel path (locate, map)", color=PIXEL, ha="right", fontsize=9.5, weight="bold")
    ax.text(12.4, 9.45, "detection path (objects, batch, serve)", color=DETECTION, ha="right", fontsize=9.5,
            weight="bold")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


if __name__ == "__main__":
    from _common import output_dir

    out_dir = output_dir(__doc__.splitlines()[0], "architecture_figure")
    print(f"boxes {len(BOXES)}, arrows {len(PATHS)}; wrote {draw(out_dir / 'architecture.png')}")
