"""Error-size presets: the six cameras measured in the paper (Tables 2 and 3).

Values are standard deviations copied exactly as printed in the paper.  Note
the units of the printed angular errors: Table 3 gives sigma alpha (pan) and
sigma theta (tilt) in **10^-3 degrees**, so Basler1's "0.1524" is
0.0001524 deg.  These angular errors are very small compared with the position
errors; we keep them as printed and say so, rather than guess a unit.

sigma f is the paper's column "sigma f" (it equals the root-sum-square of sigma
fx and sigma fy, e.g. 0.1992 and 0.1923 give 0.2768); sigma c, sigma r are the
principal-point errors.  Imaging (0.1 px) and resolution (0.01 px) errors are
the paper's relaxed values from digital image correlation (Section III-D).
Roll and ground-plane errors are not measured in the paper and are 0.
"""

from __future__ import annotations

#: per camera: (sigma fx, sigma fy, sigma f, sigma c, sigma r, k1, k2, p1, p2, k3) -- Table 2
PAPER_TABLE2 = {
    "basler1": (0.1992, 0.1923, 0.2768, 0.1713, 0.1314, 5e-4, 0.0019, 3e-5, 5e-5, 0.0002),
    "basler2": (0.1479, 0.1470, 0.2085, 0.1486, 0.1465, 0.0004, 0.0011, 2e-5, 3e-5, 0.0009),
    "bw-cube1": (0.3057, 0.3180, 0.4411, 0.3031, 0.2437, 0.0004, 0.0005, 7e-5, 8e-5, 0.0005),
    "bw-cube2": (0.670, 0.680, 0.9546, 0.3075, 0.3656, 0.0001, 0.0001, 1e-5, 3e-5, 0.0003),
    "bw-bullet1": (0.4225, 0.4255, 0.5996, 0.4115, 0.3405, 0.001, 0.0014, 6e-5, 1e-5, 0.0009),
    "bw-bullet2": (0.332, 0.325, 0.4645, 0.416, 0.299, 0.0001, 4e-5, 5e-5, 7e-5, 0.0001),
}

#: per camera: (sigma X m, sigma Y m, sigma h m, sigma alpha 1e-3 deg, sigma theta 1e-3 deg) -- Table 3
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


def preset_dict(name: str) -> dict:
    """Budget-file dictionary of a preset (keys as in the budget file)."""
    fx, fy, f, c, r, k1, k2, p1, p2, k3 = PAPER_TABLE2[name]
    X, Y, h, a, t = PAPER_TABLE3[name]
    return {
        "name": name,
        "description": f"{DISPLAY_NAMES[name]}, Kusari et al. Tables 2-3 (angles printed in 1e-3 deg)",
        "focal_px": f,
        "principal_point_px": [c, r],
        "distortion": [k1, k2, p1, p2, k3],
        "position_m": [X, Y],
        "height_m": h,
        "pan_deg": a * 1e-3,
        "tilt_deg": t * 1e-3,
        "roll_deg": 0.0,
        "ground_height_m": 0.0,
        "ground_slope_deg": 0.0,
        "imaging_px": [PAPER_IMAGING_PX, PAPER_IMAGING_PX],
        "resolution_px": [PAPER_RESOLUTION_PX, PAPER_RESOLUTION_PX],
    }
