"""Ground control points, from files to files (the ``footprint-uq calibrate gcp`` job).

:func:`run_gcp` reads the GCP table, solves the camera (:func:`footprint_uq.calibration.gcp.solve_gcp`)
and writes ``camera.yaml``, ``budget.yaml``, ``residuals.csv``, ``summary.json`` and the figures
``gcp.png`` / ``summary.html``.

The outputs are one unit: they are built in a hidden folder beside the output folder
(``.<name>.tmp-<hex>``), read back with the library's own camera and budget readers, and swapped
in together (:func:`footprint_uq.io.atomic.swap_in_folder`).  A run that fails or is killed at any
moment leaves the previous set or the new one, never a mix; every file carries the solve's id
(``solve_id`` in ``summary.json``, the budget's name ``gcp-<id>``, the first comment line of
``camera.yaml``).
"""

from __future__ import annotations

import csv
import io
import json
import warnings
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np
import yaml

from .._files import file_kind, require_regular
from ..errors import ConsistencyWarning, InputError
from ..io._common import sanitize
from ..io.atomic import TMP_MARK, atomic_write_text, recover_folder, swap_in_folder, temp_path
from ..io.camera_files import camera_to_dict, load_camera
from ..uncertainty.budget import ErrorBudget, load_budget
from ..viz.gcp import gcp_report_html, plot_gcp
from ..viz.maps import save_figure
from .gcp import INTRINSIC_IDX, LENS_K1_SIGMA, read_gcp_csv, solve_gcp

__all__ = ["run_gcp", "parse_image_size", "OUTPUT_NAMES", "MAX_IMAGE_PIXELS"]

#: the files of one solve (the last two only with figures)
OUTPUT_NAMES = ("camera.yaml", "budget.yaml", "residuals.csv", "summary.json", "gcp.png", "summary.html")
#: largest photo drawn behind the points (pixels; checked from the file header before decoding)
MAX_IMAGE_PIXELS = 60_000_000


def parse_image_size(text) -> tuple[int, int]:
    """``"1920x1080"`` (or a pair) -> ``(1920, 1080)``; InputError otherwise."""
    if isinstance(text, str):
        parts = text.lower().replace(" ", "").split("x")
    else:
        parts = list(text)
    try:
        w, h = (int(str(v)) for v in parts)
    except (TypeError, ValueError):
        raise InputError("--image-size", text, "WIDTHxHEIGHT in pixels, e.g. 1920x1080") from None
    if w <= 0 or h <= 0:
        raise InputError("--image-size", text, "a positive width and height")
    return w, h


def _yaml_text(data: dict, header: str) -> str:


    return f"# {header}\n" + yaml.safe_dump(sanitize(data), sort_keys=False, default_flow_style=None, width=100)


def _csv_text(rows: list[dict]) -> str:

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(float(v)) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def _image_header_size(path) -> tuple[int, int]:
    """(width, height) from a PNG or JPEG file's header, without decoding it; InputError otherwise."""
    if file_kind(path) not in (None, "regular file"):  # a FIFO, a device: refused, never waited on
        require_regular(path, "--image", "a PNG or JPEG file, read with seeking")
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
            if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
                return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
            if head[:2] == b"\xff\xd8":
                fh.seek(2)
                return _jpeg_size(fh)
    except OSError as e:
        raise InputError("--image", str(path), f"a readable image file ({e.strerror or e})") from None
    raise InputError("--image", str(path), "a PNG or JPEG file")


def _jpeg_size(fh) -> tuple[int, int]:
    """Walk a JPEG's marker segments to its start-of-frame (SOF0..SOF15 but DHT/JPG/DAC): (width, height)."""
    for _ in range(10_000):  # segments before the frame header (EXIF, ICC, ...): a few
        b = fh.read(1)
        if b != b"\xff":
            break
        while b == b"\xff":  # fill bytes
            b = fh.read(1)
        if not b:
            break
        marker = b[0]
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # stand-alone markers
            continue
        seg = fh.read(2)
        n = int.from_bytes(seg, "big") if len(seg) == 2 else 0
        if n < 2 or marker == 0xDA:  # truncated, or image data before any frame header
            break
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            body = fh.read(5)
            if len(body) == 5:
                return int.from_bytes(body[3:5], "big"), int.from_bytes(body[1:3], "big")
            break
        fh.seek(n - 2, 1)
    raise InputError("--image", getattr(fh, "name", "?"), "a JPEG file with a frame header")


def _read_image(path, image_size_px):

    w, h = _image_header_size(path)
    if (w, h) != tuple(image_size_px):
        raise InputError("--image size", f"{w}x{h}", f"the --image-size {image_size_px[0]}x{image_size_px[1]}")
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError("--image size", f"{w}x{h} ({w * h / 1e6:.0f} Mpx)",
                         f"at most {MAX_IMAGE_PIXELS / 1e6:g} Mpx to draw behind the points (leave out --image)")
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError("--image", str(path), "a readable image file")
    if (img.shape[1], img.shape[0]) != tuple(image_size_px):
        raise InputError("--image size", f"{img.shape[1]}x{img.shape[0]}",
                         f"the --image-size {image_size_px[0]}x{image_size_px[1]}")
    return img[..., ::-1]


def _check_out(out: Path) -> None:
    """Refuse an output that is a file, or a folder holding anything but a previous solve's files."""
    if out.exists() and not out.is_dir():
        raise InputError("--out", str(out), "a folder (this is a file)")
    if out.is_dir():
        other = sorted(p.name for p in out.iterdir() if p.name not in OUTPUT_NAMES and TMP_MARK not in p.name)
        if other:
            raise InputError(f"--out {out}", f"a folder holding {other[0]!r}",
                             "a new folder or one holding only a previous `calibrate gcp` run's files")


def _checked_budget_text(sol) -> tuple[ErrorBudget, str]:
    """budget.yaml's text, parsed back by the budget reader (what every command reads) before it is written."""
    summ_id = sol.solve_id
    bud = sol.budget(name=f"gcp-{summ_id}")
    text = _yaml_text(bud.to_dict(), f"footprint-uq error budget: full covariance of the ground-control-point "
                                     f"solve {summ_id} (docs/calibration.md)")
    try:
        load_budget(yaml.safe_load(text))
    except InputError as e:
        raise InputError("ground control point solve", f"a covariance the budget files refuse ({e.value})",
                         "points that determine the camera at their stated sigmas (smaller sigma_px / sigma_m, "
                         "more or better spread points)") from None
    return bud, text


def _write_set(folder: Path, sol, img, notes, figures: bool) -> list[Path]:
    """Write one solve's files into ``folder`` (the staging folder) and read the camera and budget back."""
    _, budget_text = _checked_budget_text(sol)
    files = [
        atomic_write_text(folder / "camera.yaml", _yaml_text(camera_to_dict(sol.camera), "footprint-uq camera file "
                                                             f"from ground control points, solve {sol.solve_id}")),
        atomic_write_text(folder / "budget.yaml", budget_text),
        atomic_write_text(folder / "residuals.csv", _csv_text(sol.residual_rows())),
    ]
    summ = sol.summary()
    summ["warnings"] = notes
    files.append(atomic_write_text(folder / "summary.json", json.dumps(summ, indent=2, allow_nan=True) + "\n"))
    if figures:
        fig = plot_gcp(sol, image=img)
        try:
            files.append(save_figure(fig, folder / "gcp.png", dpi=120))
            shown = [f"NOT USABLE: {f}" for f in sol.flags] + list(notes)
            if sol.inflation > 1.0:
                shown.append(f"covariance inflated x{sol.inflation:.3g} (the cost rises slower than its quadratic "
                             "model, or lopsided)")
            files.append(atomic_write_text(folder / "summary.html", gcp_report_html(sol, fig, shown)))
        finally:
            plt.close(fig)
    load_camera(folder / "camera.yaml")  # every command reads these: refuse here, not there
    load_budget(folder / "budget.yaml")
    return files


def run_gcp(points, image_size_px, out_dir, *, intrinsics=None, intrinsics_budget=None, pixel_sigma_px: float = 1.0,
            survey_sigma_m: float = 0.05, origin_lat_deg=None, origin_lon_deg=None, origin_alt_m=None, image=None,
            figures: bool = True, solve_k1: bool = False, lens_k1_sigma: float = LENS_K1_SIGMA) -> dict:
    """The ``calibrate gcp`` command as a function: read, solve, write; returns ``{"solution", "files",
    "warnings"}``.

    Writes to ``out_dir`` as one unit (module doc): ``camera.yaml`` (the solved camera), ``budget.yaml``
    (the full parameter covariance of the solve), ``residuals.csv`` (per point and leave-one-out),
    ``summary.json``, ``gcp.png`` (points and residual arrows, ``image`` behind) and ``summary.html``.
    ``out_dir`` must be new, empty, or hold only a previous run's files (they are replaced).
    A solve that flags itself (``solution.flags``: another pose minimum, weak geometry, residual or lens
    tests) is still written, with its reasons in ``summary.json`` (``usable``, ``flags``) and the budget's
    description.
    """
    size = parse_image_size(image_size_px)
    if (origin_lat_deg is None) != (origin_lon_deg is None):
        raise InputError("--origin-lat/--origin-lon", (origin_lat_deg, origin_lon_deg), "both or neither")
    out = Path(out_dir)
    recover_folder(out)
    _check_out(out)
    gcps = read_gcp_csv(points, pixel_sigma_px=pixel_sigma_px, survey_sigma_m=survey_sigma_m,
                        origin_lat_deg=origin_lat_deg, origin_lon_deg=origin_lon_deg, origin_alt_m=origin_alt_m)
    cov_int = None
    if intrinsics_budget is not None:
        if intrinsics is None:
            raise InputError("--intrinsics-budget", str(intrinsics_budget), "--intrinsics too")
        cov_int = load_budget(intrinsics_budget).param_covariance()[np.ix_(INTRINSIC_IDX, INTRINSIC_IDX)]
    img = _read_image(image, size) if image is not None else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConsistencyWarning)
        sol = solve_gcp(gcps, size, intrinsics=intrinsics, intrinsics_cov=cov_int, solve_k1=solve_k1,
                        lens_k1_sigma=lens_k1_sigma)
    notes = [str(w.message) for w in caught if issubclass(w.category, ConsistencyWarning)]
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = temp_path(out)
    staging.mkdir()
    try:
        files = _write_set(staging, sol, img, notes, figures)
        swap_in_folder(staging, out)
    except BaseException:
        recover_folder(out)
        raise
    return {"solution": sol, "files": [out / f.name for f in files], "warnings": notes}
