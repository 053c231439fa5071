"""Error-size presets: the six cameras measured in the paper (Tables 2 and 3).

Values are standard deviations copied exactly as printed in the paper.

**Axes.**  Table 3's sigma X and sigma Y are in the paper's earth frame G, whose
X points **north** and Y **east** (``docs/conventions.md``).  The world frame W
of footprint-uq is (x east, y north), so a preset's budget ``position_m`` (which
is ``[sigma along world x (east), sigma along world y (north)]``) is
``[sigma_Y, sigma_X]`` of the table.

**Angle reading.**  Table 3 heads the sigma alpha (pan) and sigma theta (tilt)
columns "(10^-3 deg)", so Basler1's "0.1524" is 0.0001524 deg: the *printed*
reading, the default.  Read that way the angular errors are negligible next to
the height error; read as plain degrees (0.1524 deg) they dominate far from the
camera, and only then do the paper's own remarks hold (Basler ranks best, see
``docs/paper-reproduction.md``).  Both readings are available wherever a preset
name is accepted, one way only: the name alone (``basler1``) is the printed
reading, the suffix ``@deg`` (``basler1@deg``) reads the two columns as degrees
(:data:`ANGLE_READINGS`, :func:`parse_preset_name`).

sigma f is the paper's column "sigma f" (it equals the root-sum-square of sigma
fx and sigma fy, e.g. 0.1992 and 0.1923 give 0.2768); sigma c, sigma r are the
principal-point errors.  Imaging (0.1 px) and resolution (0.01 px) errors are
the paper's relaxed values from digital image correlation (Section III-D).
Roll and ground-plane errors are not measured in the paper and are 0.
"""

from __future__ import annotations

import difflib

#: per camera: (sigma fx, sigma fy, sigma f, sigma c, sigma r, k1, k2, p1, p2, k3) -- Table 2
PAPER_TABLE2 = {
    "basler1": (0.1992, 0.1923, 0.2768, 0.1713, 0.1314, 5e-4, 0.0019, 3e-5, 5e-5, 0.0002),
    "basler2": (0.1479, 0.1470, 0.2085, 0.1486, 0.1465, 0.0004, 0.0011, 2e-5, 3e-5, 0.0009),
    "bw-cube1": (0.3057, 0.3180, 0.4411, 0.3031, 0.2437, 0.0004, 0.0005, 7e-5, 8e-5, 0.0005),
    "bw-cube2": (0.670, 0.680, 0.9546, 0.3075, 0.3656, 0.0001, 0.0001, 1e-5, 3e-5, 0.0003),
    "bw-bullet1": (0.4225, 0.4255, 0.5996, 0.4115, 0.3405, 0.001, 0.0014, 6e-5, 1e-5, 0.0009),
    "bw-bullet2": (0.332, 0.325, 0.4645, 0.416, 0.299, 0.0001, 4e-5, 5e-5, 7e-5, 0.0001),
}

#: per camera: (sigma X m (north), sigma Y m (east), sigma h m, sigma alpha 1e-3 deg, sigma theta 1e-3 deg) -- Table 3
PAPER_TABLE3 = {
    "basler1": (0.1061, 0.0861, 0.1936, 0.1524, 0.1480),
    "basler2": (0.1106, 0.1077, 0.2483, 0.1488, 0.1354),
    "bw-cube1": (0.4912, 0.1910, 0.8484, 0.8032, 0.7049),
    "bw-cube2": (0.1396, 0.1103, 0.1876, 0.3311, 0.2784),
    "bw-bullet1": (0.0802, 0.0632, 0.1744, 0.3543, 0.2558),
    "bw-bullet2": (0.0658, 0.0588, 0.1546, 0.3123, 0.2239),
}

PAPER_IMAGING_PX = 0.1
PAPER_RESOLUTION_PX = 0.01

DISPLAY_NAMES = {
    "basler1": "Basler1", "basler2": "Basler2", "bw-cube1": "BW-Cube1", "bw-cube2": "BW-Cube2",
    "bw-bullet1": "BW-Bullet1", "bw-bullet2": "BW-Bullet2",
}

PRESET_NAMES = tuple(PAPER_TABLE2)

#: how Table 3's sigma alpha / sigma theta columns are read: suffix -> (degrees per printed unit, description)
ANGLE_READINGS = {
    "printed": (1e-3, "as printed: the column unit is 10^-3 deg (0.1524 -> 0.0001524 deg)"),
    "deg": (1.0, "read as degrees (0.1524 -> 0.1524 deg), the reading under which Basler ranks best"),
}
#: the reading of a preset name without a suffix
DEFAULT_ANGLE_READING = "printed"
#: separator of the angle-reading suffix in a preset name (``basler1@deg``)
READING_SEPARATOR = "@"


def parse_preset_name(name) -> tuple[str, str] | None:
    """``(preset, angle_reading)`` of a preset name, or None if ``name`` is not one.

    ``"basler1"`` -> ``("basler1", "printed")``; ``"BW-Cube1@deg"`` -> ``("bw-cube1", "deg")``.
    Case and surrounding blanks are ignored.  The only suffix is ``@deg``: the printed reading
    is the name alone (no second spelling of it).
    """
    key = str(name).strip().lower()
    base, sep, suffix = key.partition(READING_SEPARATOR)
    base = base.strip()
    if base not in PAPER_TABLE2:
        return None
    if not sep:
        return base, DEFAULT_ANGLE_READING
    suffix = suffix.strip()
    if suffix != "deg":
        return None
    return base, suffix


def suggest_preset(name) -> str | None:
    """The preset name closest to ``name`` (a typo's "did you mean"), or None when nothing is close:
    ``"basler"`` -> ``"basler1"``, ``"bw-cub1@deg"`` -> ``"bw-cube1@deg"``, ``"basler1@rad"`` -> ``"basler1@deg"``."""
    if parse_preset_name(name) is not None:
        return None
    key = str(name).strip().lower()
    base, sep, _ = key.partition(READING_SEPARATOR)
    if base.strip() in PAPER_TABLE2:
        return f"{base.strip()}{READING_SEPARATOR}deg" if sep else None
    scores = [difflib.SequenceMatcher(None, base.strip(), p).ratio() for p in PAPER_TABLE2]
    best = max(range(len(scores)), key=lambda i: (scores[i], -i))  # ties: the first in the table's order
    if scores[best] < 0.6:
        return None
    close = list(PAPER_TABLE2)[best]
    return f"{close}{READING_SEPARATOR}deg" if sep else close


def preset_label(name: str, angle_reading: str = DEFAULT_ANGLE_READING) -> str:
    """Canonical preset name: ``"basler1"`` (printed reading) or ``"basler1@deg"``."""
    return name if angle_reading == DEFAULT_ANGLE_READING else f"{name}{READING_SEPARATOR}{angle_reading}"


def display_name(name: str) -> str:
    """Display name of a preset label: ``"bw-cube1"`` -> ``"BW-Cube1"``, ``"basler1@deg"`` -> ``"Basler1@deg"``."""
    parsed = parse_preset_name(name)
    if parsed is None:
        return str(name)
    base, reading = parsed
    return DISPLAY_NAMES[base] + ("" if reading == DEFAULT_ANGLE_READING else f"{READING_SEPARATOR}{reading}")


def preset_dict(name: str, angle_reading: str | None = None) -> dict:
    """Budget-file dictionary of a preset (keys as in the budget file).

    Parameters
    ----------
    name : str
        A preset name, optionally with the ``@deg`` suffix (:func:`parse_preset_name`).
    angle_reading : {"printed", "deg"}, optional
        Overrides the reading given by the name's suffix.

    ``position_m`` is ``[sigma_Y, sigma_X]`` of Table 3: world (east, north) from the
    paper's (X north, Y east).
    """
    parsed = parse_preset_name(name)
    if parsed is None:
        raise KeyError(name)
    base, reading = parsed
    reading = reading if angle_reading is None else angle_reading
    if reading not in ANGLE_READINGS:
        raise KeyError(angle_reading)
    scale, how = ANGLE_READINGS[reading]
    fx, fy, f, c, r, k1, k2, p1, p2, k3 = PAPER_TABLE2[base]
    X, Y, h, a, t = PAPER_TABLE3[base]
    return {
        "name": preset_label(base, reading),
        "description": f"{DISPLAY_NAMES[base]}, Kusari et al. Tables 2-3 (sigma X north, sigma Y east; "
                       f"angles {how})",
        "focal_px": f,
        "principal_point_px": [c, r],
        "distortion": [k1, k2, p1, p2, k3],
        "position_m": [Y, X],  # world (east, north) = paper (Y, X): G has X north, Y east
        "height_m": h,
        "pan_deg": a * scale,
        "tilt_deg": t * scale,
        "roll_deg": 0.0,
        "ground_height_m": 0.0,
        "ground_slope_deg": 0.0,
        "imaging_px": [PAPER_IMAGING_PX, PAPER_IMAGING_PX],
        "resolution_px": [PAPER_RESOLUTION_PX, PAPER_RESOLUTION_PX],
    }
