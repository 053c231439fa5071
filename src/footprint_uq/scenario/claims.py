"""The paper's case-study statements as quantitative tests that can fail.

Each statement of the paper's Section "Case study" becomes one measure with a tolerance
fixed in this module (the constants below, set before the results were looked at), a
verdict per camera and an overall verdict ``"PASS"`` or ``"FAIL"`` with the reason.
:data:`FAILING_EXAMPLES` holds, per statement, a configuration under which it fails, so
that the tests can show each check is able to say FAIL.

(a) **X/Y sequence** -- "the uncertainty in X dominating in the beginning and equaling the
    uncertainty in Y in the middle of the intersection. The uncertainty in Y dominates
    from that point onward."  X and Y are the paper's earth-frame axes: X is where the
    camera looks at pan alpha = 0 and Y is 90 deg clockwise of it (Z down).  footprint-uq
    reads alpha as a compass heading (``docs/conventions.md``), so **X = north and Y =
    east**, for every camera whatever its pan; the "north-east" columns of the case-study
    table.  Measure, per camera and camera type, on the footprint centre:
    sigma_X > sigma_Y in at least :data:`XY_MAJORITY` of the entry-lane frames,
    sigma_Y > sigma_X in at least :data:`XY_MAJORITY` of the exit-lane frames, and the
    first X-to-Y crossing within the middle third (:data:`XY_MIDDLE`) of the arc length
    the vehicle travels inside the intersection box.  A camera passes if every type
    passes; the statement passes if every camera passes.
(b) **Lane width** -- "the uncertainty in BW-Cube cameras being almost equivalent to the
    lane width".  The paper plots the X/Y uncertainties "as ellipses"; a covariance
    ellipse is its 1-sigma ellipse, and its size across is its full major axis.  Measure:
    ``2 sigma_major`` of the BW-Cube footprint centre, median over the frames inside the
    intersection box, per camera; "almost equivalent" = within +/- :data:`LANE_BAND` of
    the lane width (3.5 m in the default scene, a 12-ft US lane is 3.66 m).
(c) **Ranking** -- "the uncertainty of parameters is higher in the BW-Cube and BW-Bullet
    cameras as opposed to the Basler cameras" (Tables 2-3) and "the differences in
    uncertainties between the cameras" (case study).  Measure: median over all usable
    frames of the footprint centre's 1-sigma semi-major axis, per camera; each BW type
    must exceed Basler by at least :data:`RANK_MARGIN` (10 %: a difference worth stating
    in a figure).

(d) **Farthest corner** (Section "Estimating uncertainty of bounding box") -- "unless the
    center of the bounding box coincides with the center of the camera coordinate system,
    the four extreme points will have different uncertainties with the points away from the
    center having largest uncertainties".  The camera coordinate system is centred on the
    camera, so: the footprint corner with the largest 1-sigma semi-major axis is the one
    farthest (horizontally) from the camera's foot, in at least :data:`FARTHEST_SHARE` of
    the frames of every camera and type.

Camera types are recognised by their preset name (``basler1``, ``bw-bullet1``,
``bw-cube1``, with or without ``@deg``): :func:`type_roles`.
"""

from __future__ import annotations

import numpy as np

from ..uncertainty import presets

__all__ = ["XY_MAJORITY", "XY_MIDDLE", "LANE_BAND", "RANK_MARGIN", "FARTHEST_SHARE", "XY_AXES", "FAILING_EXAMPLES",
           "PAPER_QUOTES", "evaluate_claims", "xy_sequence_claim", "lane_width_claim", "ranking_claim",
           "farthest_corner_claim", "type_roles"]

#: share of the entry (exit) frames where X (Y) must dominate
XY_MAJORITY = 0.8
#: the crossing must fall in this part of the arc length travelled inside the intersection box
XY_MIDDLE = (1.0 / 3.0, 2.0 / 3.0)
#: "almost a lane width": within +/- 25 % of it
LANE_BAND = 0.25
#: "higher": at least 10 % more
RANK_MARGIN = 1.10
#: share of the frames in which the farthest corner must be the most uncertain one
FARTHEST_SHARE = 0.9
#: the paper's X and Y in the world (pan read as a compass heading): the case-study table's reading
XY_AXES = "north-east"

PAPER_QUOTES = {
    "xy_sequence": "we can observe the transition of uncertainties over the trajectories, with the uncertainty in X "
                   "dominating in the beginning and equaling the uncertainty in Y in the middle of the intersection. "
                   "The uncertainty in Y dominates from that point onward.",
    "lane_width": "We can also clearly see the differences in uncertainties between the cameras with the uncertainty "
                  "in BW-Cube cameras being almost equivalent to the lane width.",
    "farthest_corner": "unless the center of the bounding box coincides with the center of the camera coordinate "
                       "system, the four extreme points will have different uncertainties with the points away from "
                       "the center having largest uncertainties.",
    "ranking": "the uncertainty of parameters is higher in the BW-Cube and BW-Bullet cameras as opposed to the Basler "
               "cameras (Tables 2-3; the case study: 'the differences in uncertainties between the cameras')",
}

#: per statement, a case-study configuration (CaseStudyConfig.from_dict) under which it fails
FAILING_EXAMPLES = {
    "xy_sequence": {
        "why": "one camera on the west arm looking east: on most of the approach the line of sight, and with it "
               "the long axis of the ellipses, is nearer east-west than north-south, so Y (east) dominates early "
               "and X falls below Y before the vehicle reaches the junction",
        "config": {"cameras": [{"name": "west", "position_m": [-30.0, 9.0], "height_m": 8.0, "pan_deg": 100.0,
                                "tilt_deg": 12.0, "hfov_deg": 90.0}]},
    },
    "lane_width": {
        "why": "camera 1 moved 45 m back along the diagonal: at that range the height error alone spreads the "
               "BW-Cube ellipse over several lane widths",
        "config": {"cameras": [{"name": "far", "position_m": [40.0, 40.0], "height_m": 8.0, "pan_deg": 225.0,
                                "tilt_deg": 8.0, "hfov_deg": 60.0}]},
    },
    "ranking": {
        "why": "the Basler camera with its mount height known to 1 m only (a pole that was not surveyed): the camera "
               "type no longer decides the ranking, the survey does",
        "config": {"camera_types": {
            "basler1": {**presets.preset_dict("basler1"), "height_m": 1.0, "name": "basler1-unsurveyed"},
            "bw-bullet1": "bw-bullet1", "bw-cube1": "bw-cube1"}},
    },
    "farthest_corner": {
        "why": "a budget with a camera-position error only: every corner moves by the same offset, the uncertainty "
               "does not grow with distance and no corner is the most uncertain",
        "config": {"camera_types": {"position-only": {"name": "position-only", "position_m": [0.5, 0.5]}}},
    },
}


def type_roles(type_names) -> dict[str, str]:
    """Preset base name -> camera-type label of a result (``{"basler1": "basler1@deg", ...}``)."""
    out = {}
    for label in type_names:
        parsed = presets.parse_preset_name(label)
        if parsed is not None:
            out.setdefault(parsed[0], label)
    return out


def _verdict(ok) -> str:
    return "PASS" if ok else "FAIL"


def _junction_window(r, box):
    """Arc-length-like coordinate of the frames (cumulative distance) and the part inside ``box``."""
    x, y = r["box_x_m"].to_numpy(), r["box_y_m"].to_numpy()
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    if box is None:
        inside = r["segment"].to_numpy() == 1
    else:
        x0, y0, x1, y1 = box
        inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    return s, inside


def xy_sequence_claim(result, *, axes: str = XY_AXES) -> dict:
    """Statement (a): X dominates on the entry, X = Y in the middle of the intersection, Y after (module doc)."""
    box = result.scene.layout.junction_box_m
    per = []
    for cam in result.camera_names:
        for ct in result.type_names:
            r = result.rows(cam, ct)
            sx = r[f"centre_sigma_X_{axes}_m"].to_numpy()
            sy = r[f"centre_sigma_Y_{axes}_m"].to_numpy()
            seg = r["segment"].to_numpy()
            ok = np.isfinite(sx) & np.isfinite(sy)
            ent, ext = ok & (seg == 0), ok & (seg == 2)
            f_entry = float(np.mean(sx[ent] > sy[ent])) if ent.any() else float("nan")
            f_exit = float(np.mean(sy[ext] > sx[ext])) if ext.any() else float("nan")
            s, inside = _junction_window(r, box)
            diff = sx - sy
            cross_s = float("nan")
            for a in range(len(diff) - 1):
                if ok[a] and ok[a + 1] and diff[a] > 0 and diff[a + 1] <= 0:
                    w = diff[a] / (diff[a] - diff[a + 1])
                    cross_s = float(s[a] + w * (s[a + 1] - s[a]))
                    break
            if inside.any():
                s_in, s_out = float(s[inside][0]), float(s[inside][-1])
                pos = (cross_s - s_in) / (s_out - s_in) if s_out > s_in else float("nan")
            else:
                pos = float("nan")
            holds = bool(f_entry >= XY_MAJORITY and f_exit >= XY_MAJORITY and XY_MIDDLE[0] <= pos <= XY_MIDDLE[1])
            per.append({"camera": cam, "camera_type": ct, "share_X_gt_Y_entry": f_entry,
                        "share_Y_gt_X_exit": f_exit, "crossing_position_in_junction": pos,
                        "frames_entry": int(ent.sum()), "frames_exit": int(ext.sum()), "pass": holds})
    cams = {c: all(p["pass"] for p in per if p["camera"] == c) for c in result.camera_names}
    failed = [c for c, v in cams.items() if not v]
    why_parts = []
    for c in failed:
        bad = [p for p in per if p["camera"] == c and not p["pass"]]
        p = bad[0]
        why_parts.append(
            f"{c} ({len(bad)} of {len(result.type_names)} types fail; {p['camera_type']}: X>Y in "
            f"{_pct(p['share_X_gt_Y_entry'])} of the entry frames, Y>X in {_pct(p['share_Y_gt_X_exit'])} of the exit "
            f"frames, X-to-Y crossing at {_frac(p['crossing_position_in_junction'])} of the junction passage, wanted "
            f"{XY_MIDDLE[0]:.2f}-{XY_MIDDLE[1]:.2f})")
    why = "holds for every camera and type" if not failed else "fails for " + "; ".join(why_parts)
    return {"id": "xy_sequence", "paper": PAPER_QUOTES["xy_sequence"],
            "measure": f"X = north, Y = east (the paper's frame G, pan a compass heading); footprint-centre sigma: "
                       f"X > Y in >= {XY_MAJORITY:.0%} of the entry frames, Y > X in >= {XY_MAJORITY:.0%} of the exit "
                       f"frames, first X-to-Y crossing in the middle third of the passage through the junction box",
            "per_camera": {c: _verdict(v) for c, v in cams.items()}, "details": per,
            "verdict": _verdict(all(cams.values()) and bool(cams)), "why": why}


def _pct(x) -> str:
    return "n/a" if not np.isfinite(x) else f"{100 * x:.0f} %"


def _frac(x) -> str:
    return "none" if not np.isfinite(x) else f"{x:.2f}"


def _junction_median(result, cam, ct) -> float:
    r = result.rows(cam, ct)
    _, inside = _junction_window(r, result.scene.layout.junction_box_m)
    a = r["centre_semi_major_m"].to_numpy()
    sel = inside & r["centre_valid"].to_numpy(bool)
    return float(np.median(a[sel])) if sel.any() else float("nan")


def lane_width_claim(result) -> dict:
    """Statement (b): the BW-Cube footprint-centre 1-sigma ellipse is about a lane wide (module doc)."""
    lane = float(result.scene.layout.lane_width_m)
    lo, hi = (1 - LANE_BAND) * lane, (1 + LANE_BAND) * lane
    roles = type_roles(result.type_names)
    ct = roles.get("bw-cube1")
    per = []
    for cam in result.camera_names:
        v = 2.0 * _junction_median(result, cam, ct) if ct is not None else float("nan")
        per.append({"camera": cam, "camera_type": ct, "value_m": v, "ratio_to_lane_width": v / lane,
                    "pass": bool(lo <= v <= hi)})
    ok = bool(per) and all(p["pass"] for p in per)
    why = "; ".join(f"{p['camera']}: {p['value_m']:.2f} m = {p['ratio_to_lane_width']:.2f} lane widths "
                    f"({'inside' if p['pass'] else 'outside'} {lo:.2f}-{hi:.2f} m)" for p in per)
    if ct is None:
        why = "no BW-Cube camera type in this run"
    return {"id": "lane_width", "paper": PAPER_QUOTES["lane_width"],
            "measure": f"full 1-sigma major axis (2 sigma_major) of the BW-Cube footprint centre, median over the "
                       f"frames in the junction box, per camera, within +/-{LANE_BAND:.0%} of the lane width "
                       f"{lane:g} m",
            "per_camera": {p["camera"]: _verdict(p["pass"]) for p in per}, "details": per,
            "verdict": _verdict(ok), "why": why}


def ranking_claim(result) -> dict:
    """Statement (c): BW-Cube and BW-Bullet footprint uncertainty at least 10 % above Basler's (module doc)."""
    roles = type_roles(result.type_names)
    ref = roles.get("basler1")
    others = [roles[k] for k in ("bw-bullet1", "bw-cube1") if k in roles]
    per = []
    for cam in result.camera_names:
        med = {}
        for ct in [ref, *others]:
            if ct is None:
                continue
            r = result.rows(cam, ct)
            a = r["centre_semi_major_m"].to_numpy()[r["centre_valid"].to_numpy(bool)]
            med[ct] = float(np.median(a)) if a.size else float("nan")
        ratios = {ct: med[ct] / med[ref] for ct in others} if ref is not None else {}
        per.append({"camera": cam, "median_sigma_major_m": med, "ratio_to_basler": ratios,
                    "basler_lowest": bool(ref is not None and all(med[ref] < med[c] for c in others)),
                    "pass": bool(ratios) and all(v >= RANK_MARGIN for v in ratios.values())})
    ok = bool(per) and all(p["pass"] for p in per)
    why = "; ".join(f"{p['camera']}: " + ", ".join(f"{c} / {ref} = {v:.3f}" for c, v in p["ratio_to_basler"].items())
                    + (" (Basler lowest)" if p["basler_lowest"] else " (Basler not lowest)") for p in per)
    if ref is None or not others:
        why = "the run lacks a Basler or a BW camera type"
    return {"id": "ranking", "paper": PAPER_QUOTES["ranking"],
            "measure": f"median footprint-centre sigma_major over the usable frames, per camera: every BW type >= "
                       f"{RANK_MARGIN:.2f} x Basler",
            "per_camera": {p["camera"]: _verdict(p["pass"]) for p in per}, "details": per,
            "verdict": _verdict(ok), "why": why}


def farthest_corner_claim(result) -> dict:
    """Statement (d): the footprint corner farthest from the camera is the most uncertain (module doc)."""
    per = []
    for cam in result.camera_names:
        foot = result.scene.cameras[cam].position_world_m[:2]
        shares = {}
        for ct in result.type_names:
            r = result.rows(cam, ct)
            dist = np.stack([np.hypot(r[f"corner{k}_x_m"].to_numpy() - foot[0],
                                      r[f"corner{k}_y_m"].to_numpy() - foot[1]) for k in range(4)], 1)
            li = r["largest_index"].to_numpy()
            ok = (li >= 0) & np.isfinite(dist).all(1)
            shares[ct] = float(np.mean(np.argmax(dist[ok], 1) == li[ok])) if ok.any() else float("nan")
        per.append({"camera": cam, "share_farthest_is_largest": shares,
                    "pass": bool(shares) and all(v >= FARTHEST_SHARE for v in shares.values())})
    ok = bool(per) and all(p["pass"] for p in per)
    why = "; ".join(f"{p['camera']}: lowest share {min(p['share_farthest_is_largest'].values()):.2f} "
                    f"({min(p['share_farthest_is_largest'], key=p['share_farthest_is_largest'].get)})" for p in per)
    return {"id": "farthest_corner", "paper": PAPER_QUOTES["farthest_corner"],
            "measure": f"the corner with the largest sigma_major is the one farthest from the camera foot in >= "
                       f"{FARTHEST_SHARE:.0%} of the frames, every camera and type",
            "per_camera": {p["camera"]: _verdict(p["pass"]) for p in per}, "details": per,
            "verdict": _verdict(ok), "why": why}


def evaluate_claims(result) -> list[dict]:
    """The statements (a)-(d) on a :class:`~footprint_uq.scenario.case_study.CaseStudyResult` (module doc)."""
    return [xy_sequence_claim(result), lane_width_claim(result), ranking_claim(result), farthest_corner_claim(result)]

