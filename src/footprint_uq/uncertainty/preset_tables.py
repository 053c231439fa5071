"""The paper's error-budget presets as a table (the ``footprint-uq presets`` output).

:func:`presets_table` gives one flat row per preset (1-sigma values, units in the keys);
:func:`presets_text` and :func:`presets_csv` print those rows.  (A module of its own because it
builds :class:`~footprint_uq.uncertainty.budget.ErrorBudget` objects, and ``budget`` itself reads
:mod:`.presets`.)
"""

from __future__ import annotations

import csv
import io

from .budget import ErrorBudget
from .presets import PRESET_NAMES, display_name

__all__ = ["PRESET_ROWS", "presets_table", "presets_text", "presets_csv"]

#: rows of the text table: (row key, unit, description), in print order
PRESET_ROWS = (
    ("focal_px", "px", "focal length"), ("pp_c_px", "px", "principal point, column"),
    ("pp_r_px", "px", "principal point, row"), ("k1", "-", "radial k1"), ("k2", "-", "radial k2"),
    ("p1", "-", "tangential p1"), ("p2", "-", "tangential p2"), ("k3", "-", "radial k3"),
    ("x_m", "m", "position east (Table 3 sigma Y)"), ("y_m", "m", "position north (Table 3 sigma X)"),
    ("height_m", "m", "height"),
    ("pan_deg", "deg", "pan (alpha)"), ("tilt_deg", "deg", "tilt (theta)"), ("roll_deg", "deg", "roll"),
    ("ground_height_m", "m", "ground height"), ("ground_slope_deg", "deg", "ground slope"),
    ("imaging_px", "px", "imaging noise (per point)"), ("resolution_px", "px", "resolution (per point)"),
)

_HEADER = (
    "Error-budget presets: Kusari et al., Tables 2 (intrinsic) and 3 (extrinsic); imaging/resolution "
    "from Sec. III-D.",
    "Table 3's sigma X is north, sigma Y east (the paper's earth frame): world position (east, north) = "
    "(sigma Y, sigma X).",
    "Angles: NAME reads Table 3's sigma alpha/theta as printed, in 1e-3 deg (0.1524 -> 0.0001524 deg); "
    "NAME@deg reads them as degrees.",
    "Roll and ground-plane errors were not measured (0).",
    "",
)


def presets_table(names=None) -> list[dict]:
    """One row per preset: :meth:`ErrorBudget.table_row`, 1-sigma values, units in the keys.

    Parameters
    ----------
    names : iterable of str, optional
        Preset names, each optionally with the ``@deg`` suffix; default the six presets with
        Table 3's angles as printed.

    Returns
    -------
    list of dict
        One row per name, in the order given.

    Raises
    ------
    ConfigError
        A name is not a preset.
    """
    names = list(names) if names else list(PRESET_NAMES)
    return [ErrorBudget.preset(n).table_row() for n in names]


def presets_text(rows: list[dict]) -> str:
    """A text table of :func:`presets_table` rows: one column per preset, one line per source.

    Parameters
    ----------
    rows : list of dict
        Output of :func:`presets_table`.

    Returns
    -------
    str
        A header explaining the axes and the angle reading, then the table (no final newline).
    """
    names = [display_name(r["name"]) for r in rows]
    header = ["parameter (1 sigma)", "unit"] + names
    body = [[desc, unit] + [f"{r[key]:.4g}" for r in rows] for key, unit, desc in PRESET_ROWS]
    widths = [max(len(str(x)) for x in col) for col in zip(header, *body, strict=True)]

    def fmt_row(cells):
        return "  ".join((c.ljust(w) if i < 2 else c.rjust(w)) for i, (c, w) in enumerate(zip(cells, widths,
                                                                                                 strict=True)))

    lines = list(_HEADER)
    lines.append(fmt_row(header))
    lines.append("  ".join("-" * w for w in widths))
    lines += [fmt_row(b) for b in body]
    return "\n".join(lines)


def presets_csv(rows: list[dict]) -> str:
    """:func:`presets_table` rows as CSV text (header included, floats printed in full).

    Parameters
    ----------
    rows : list of dict
        Output of :func:`presets_table` (at least one row).

    Returns
    -------
    str
        One line per row, columns in the rows' key order.
    """
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()
