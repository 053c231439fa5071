"""Figures of uncertainty maps and small HTML report helpers.

Every function returns a :class:`matplotlib.figure.Figure` built without
``pyplot`` (no global state, no GUI backend: rendering uses Agg), so figures can
be produced from threads, servers and notebooks alike.  Save with
:func:`save_figure` or ``fig.savefig(path)``.
"""

from .maps import (
    DEFAULT_LEVELS_M,
    GSD_LEVELS_M,
    plot_ground_map,
    plot_gsd_maps,
    plot_image_map,
    plot_nonlinearity_map,
    plot_range_profile,
    save_figure,
)
from .report import esc, fig_to_png_bytes, html_page, html_table, img_tag, png_data_uri, write_html

__all__ = [
    "DEFAULT_LEVELS_M", "GSD_LEVELS_M", "plot_ground_map", "plot_gsd_maps", "plot_image_map",
    "plot_range_profile", "plot_nonlinearity_map", "save_figure", "fig_to_png_bytes", "html_page", "html_table",
    "png_data_uri", "write_html", "img_tag", "esc",
]
