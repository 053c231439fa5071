"""An uncertainty map on disk: its arrays, three figures and a summary (the ``footprint-uq map`` output).

:func:`write_map_report` computes (or takes) an :class:`~footprint_uq.products.maps.UncertaintyMap`
and writes the files named in :data:`MAP_FILES` into one directory as one set (built in a hidden folder
beside it and swapped in together, :func:`footprint_uq.io.atomic.output_set`; the folder must be new or
hold only a previous map's files, :data:`MAP_OWN`).
"""

from __future__ import annotations

import json
from pathlib import Path

from ..io import camera_to_dict
from ..io.atomic import atomic_write_text, check_output_folder, final_paths, output_set
from ..products.gcp_support import save_support_map
from ..products.maps import uncertainty_map
from .maps import plot_ground_map, plot_gsd_maps, plot_image_map, plot_nonlinearity_map, save_figure

__all__ = ["MAP_FILES", "MAP_OWN", "write_map_report"]

#: the files of a map report: key -> file name inside the output directory
MAP_FILES = {
    "npz": "map.npz",
    "image_png": "uncertainty_image.png",
    "ground_png": "uncertainty_ground.png",
    "gsd_png": "gsd.png",
    "nonlinearity_png": "nonlinearity.png",
    "summary_json": "summary.json",
}
#: every name a map run writes into its folder (``gcp_support.npz``: ``map --gcp-summary``)
MAP_OWN = (*MAP_FILES.values(), "gcp_support.npz")


def write_map_report(camera, budget, out_dir, *, step_px: int = 4, max_range_m: float | None = None,
                     confidence: float | None = None, vmin_m: float | None = None, vmax_m: float | None = None,
                     dpi: int = 150, umap=None, linearity: bool = True, linear_threshold: float = 0.05,
                     gcp_support: dict | None = None, progress=None):
    """Compute an uncertainty map and write its arrays, figures and summary into ``out_dir``.

    Parameters
    ----------
    camera : Camera
        The camera.
    budget : ErrorBudget or str
        Error budget (or a preset name / budget file).
    out_dir : path
        Output directory (created).
    step_px : int
        Grid step in pixels (1 = every pixel).
    max_range_m : float, optional
        Mask ground points farther than this from the camera foot point.
    confidence : float, optional
        Draw the semi-axes of this confidence ellipse instead of 1 sigma, and summarise them.
    vmin_m, vmax_m : float, optional
        Colour scale of the two semi-major-axis figures (default: from the data).
    dpi : int
        Resolution of the PNG figures.
    umap : UncertaintyMap, optional
        Already computed for this camera and budget (then ``step_px`` and ``max_range_m`` are
        not used).
    linearity : bool
        Carry the linearity flag (default; it costs little, bench section "maps"): the figures
        hatch the pixels that are not ``linear_ok`` and draw the threshold's contour, and
        ``nonlinearity.png`` shows the layer.
    linear_threshold : float
        ``linear_ok`` where the predicted relative error of the linear semi-major axis is at most this.
    gcp_support : dict, optional
        The support of a GCP solve (:func:`footprint_uq.products.gcp_support.load_gcp_support`): also
        ``gcp_support.npz`` (key ``gcp_support``), in the same set.
    progress : callable(str), optional
        Called with a short message as each stage starts (the map, the figures).

    Returns
    -------
    umap : UncertaintyMap
        The map.
    files : dict
        The :data:`MAP_FILES` keys mapped to the written paths.  ``summary.json`` holds
        :meth:`UncertaintyMap.summary`, the camera, the budget and the file names (no
        ``nonlinearity_png`` when the map has no flag).
    """
    check_output_folder(out_dir, MAP_OWN, "map")  # before the map is computed, not after
    say = progress or (lambda msg: None)
    if umap is None:
        w, h = camera.image_size_px
        say(f"computing {-(-w // step_px)} x {-(-h // step_px)} pixels (every {step_px} px)")
        umap = uncertainty_map(camera, budget, step_px, max_range_m=max_range_m, linearity=linearity,
                               linear_threshold=linear_threshold)
    with output_set(out_dir, MAP_OWN, "map") as stage:
        files = _write_files(umap, camera, stage, confidence, vmin_m, vmax_m, dpi, say)
        if gcp_support is not None:
            files["gcp_support"] = save_support_map(stage / "gcp_support.npz", camera, umap.budget, gcp_support,
                                                    umap.uv_px)
    return umap, final_paths(files, stage, out_dir)


def _write_files(umap, camera, out: Path, confidence, vmin_m, vmax_m, dpi, say) -> dict:
    """The map's arrays, figures and summary written into ``out`` (the staging folder)."""
    files = {k: out / v for k, v in MAP_FILES.items()}
    say("figures and arrays")
    if umap.nonlinearity is None:
        del files["nonlinearity_png"]
    else:
        save_figure(plot_nonlinearity_map(umap), files["nonlinearity_png"], dpi=dpi)
    umap.save_npz(files["npz"])
    save_figure(plot_image_map(umap, confidence=confidence, vmin_m=vmin_m, vmax_m=vmax_m), files["image_png"],
                dpi=dpi)
    save_figure(plot_ground_map(umap, confidence=confidence, vmin_m=vmin_m, vmax_m=vmax_m), files["ground_png"],
                dpi=dpi)
    save_figure(plot_gsd_maps(umap), files["gsd_png"], dpi=dpi)
    summary = umap.summary(confidence=confidence)
    summary["camera"] = camera_to_dict(camera)
    summary["budget_parameters"] = umap.budget.to_dict()
    summary["files"] = {k: p.name for k, p in files.items()}
    atomic_write_text(files["summary_json"], json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return files
