"""Shared test helpers: seeded random cameras, pixels that see the ground, finite differences.

The factories are plain functions exposed through fixtures (``random_params``,
``ground_pixels``, ``random_opencv_camera``, ``random_pantilt_camera``,
``central_diff``, ``rel_err``) so that test files need no import from this file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from footprint_uq import params as P
from footprint_uq.cameras.distortion import distort
from footprint_uq.cameras.pinhole import normalised_to_pixel
from footprint_uq.cameras.rotation import R_W_C

# Hypothesis profiles: "explore" (the default: new random examples each run, failures kept in
# .hypothesis/ and replayed) and "ci" (.ci/run: a fixed seed, so that a run on a clean clone is
# reproducible; a failure prints the example and its reproduce blob).
settings.register_profile("explore", print_blob=True)
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "explore"))

IMAGE_SIZE_PX = (1920, 1080)

# A command line whose kernels are not in numba's cache would run on the reference path while they compile in a
# detached process (products.warmup.KernelGate); the suite compiles them in the test instead (deterministic,
# no process left behind).  tests/test_warmup.py sets the other modes itself.
os.environ.setdefault("FOOTPRINT_UQ_COMPILE", "foreground")


@pytest.fixture(autouse=True)
def _no_compile_handler_left():
    """A command line's compile handler (footprint_uq._notices) does not outlive its test."""
    yield
    from footprint_uq import _notices

    _notices.set_compile_handler(None)

# Real data (Rope3D, TUMTraf, ETSI ASN.1, OpenCV boards; each folder has a SOURCE.txt and its licence): the copies
# in tests/data (tests/data/real/README.md), so that a fresh clone runs every real-data test, else
# ../shared/data beside the repository; FOOTPRINT_UQ_SHARED_DATA overrides both.
TEST_DATA = Path(__file__).resolve().parent / "data"
REAL_DATA = {"rope3d-demo": TEST_DATA / "rope3d-demo", "etsi-its-asn1": TEST_DATA / "real" / "etsi-its-asn1",
             "tumtraf-calib": TEST_DATA / "real" / "tumtraf-calib",
             "opencv-chessboard-left": TEST_DATA / "real" / "opencv-chessboard-left",
             "opencv-chessboard-right": TEST_DATA / "opencv-chessboard-right"}
SHARED_DATA = Path(os.environ.get("FOOTPRINT_UQ_SHARED_DATA",
                                  Path(__file__).resolve().parents[2] / "shared" / "data"))


def real_data_folder(name: str) -> Path | None:
    """The folder of the real data set ``name`` (see :data:`REAL_DATA`), or None where it is nowhere."""
    candidates = [SHARED_DATA / name] if "FOOTPRINT_UQ_SHARED_DATA" in os.environ else []
    candidates += [REAL_DATA[name]] if name in REAL_DATA else []
    candidates += [SHARED_DATA / name]
    return next((c for c in candidates if c.is_dir()), None)


@pytest.fixture(scope="session")
def shared_data():
    """``shared_data("rope3d-demo")`` -> the folder's path, or the test is skipped with a message."""
    def get(name: str) -> Path:
        folder = real_data_folder(name)
        if folder is None:
            pytest.skip(f"real data folder {name} is neither in tests/data nor in {SHARED_DATA}")
        return folder
    return get


def make_random_params(rng, *, distortion: str = "strong", skew: bool = True, roll: bool = True,
                       ground: bool = True, tilt_deg=(8.0, 40.0)) -> np.ndarray:
    """A random but plausible roadside camera as a (22,) parameter vector.

    ``distortion``: ``"none"``, ``"mild"`` (k1, k2, p1, p2, k3) or ``"strong"``
    (all eight coefficients, rational model included, |k1| up to 0.35).
    """
    p = np.zeros(P.N_PARAMS)
    fx = rng.uniform(900.0, 2000.0)
    p[P.FX] = fx
    p[P.FY] = fx * rng.uniform(0.97, 1.03)
    p[P.CX] = (IMAGE_SIZE_PX[0] - 1) / 2 + rng.uniform(-30, 30)
    p[P.CY] = (IMAGE_SIZE_PX[1] - 1) / 2 + rng.uniform(-30, 30)
    if skew:
        p[P.SKEW] = rng.uniform(-5.0, 5.0)
    if distortion == "strong":
        p[P.DIST_SLICE] = [rng.uniform(-0.35, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(-5e-3, 5e-3),
                           rng.uniform(-5e-3, 5e-3), rng.uniform(-0.02, 0.02), rng.uniform(-0.1, 0.1),
                           rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02)]
    elif distortion == "mild":
        p[[P.K1, P.K2, P.P1, P.P2, P.K3]] = [rng.uniform(-0.1, 0.05), rng.uniform(-0.02, 0.02),
                                             rng.uniform(-1e-3, 1e-3), rng.uniform(-1e-3, 1e-3),
                                             rng.uniform(-0.005, 0.005)]
    elif distortion != "none":
        raise ValueError(distortion)
    p[P.XM], p[P.YM], p[P.HM] = rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(4.0, 20.0)
    p[P.PAN] = np.deg2rad(rng.uniform(-180, 180))
    p[P.TILT] = np.deg2rad(rng.uniform(*tilt_deg))
    if roll:
        p[P.ROLL] = np.deg2rad(rng.uniform(-10, 10))
    if ground:
        p[P.GDZ], p[P.GSX], p[P.GSY] = rng.uniform(-0.5, 0.5), rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03)
    return p


def make_ground_pixels(rng, params, n: int, *, min_depression_deg: float = 3.0,
                       box=(0.6, 0.4)) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pixels whose rays descend at least ``min_depression_deg`` below the horizontal.

    Undistorted normalised coordinates are drawn in ``|x| < box[0], |y| < box[1]``
    (well inside the lens model's invertible region for the factory's
    distortions) and distorted into pixels.  Returns ``(uv_px (n, 2), xy_n (n, 2))``.
    """
    R = R_W_C(params[P.PAN], params[P.TILT], params[P.ROLL])
    out = np.zeros((0, 2))
    sin_min = np.sin(np.deg2rad(min_depression_deg))
    for _ in range(100):
        xn = rng.uniform([-box[0], -box[1]], [box[0], box[1]], (4 * n, 2))
        ray = (R @ np.concatenate([xn, np.ones((4 * n, 1))], -1)[..., None])[..., 0]
        ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
        out = np.concatenate([out, xn[ray[:, 2] < -sin_min]])
        if len(out) >= n:
            break
    assert len(out) >= n, "camera sees too little ground"
    xn = out[:n]
    uv = normalised_to_pixel(distort(xn, params[P.DIST_SLICE]), *params[:5])
    return uv, xn


def make_central_diff(f, x0, steps):
    """Central differences of ``f`` (array -> array (..., m)) w.r.t. each entry of ``x0`` (n,).

    Returns ``(..., m, n)``.
    """
    x0 = np.asarray(x0, dtype=np.float64)
    cols = []
    for j in range(x0.shape[-1]):
        e = np.zeros_like(x0)
        e[..., j] = steps[j]
        cols.append((f(x0 + e) - f(x0 - e)) / (2.0 * steps[j]))
    return np.stack(cols, -1)


def make_rel_err(fd, an, *, per_column: bool = False):
    """Worst-case relative error ``max |fd - an| / max |an|``.

    With ``per_column`` (Jacobians ``(..., m, n)``) the error of each of the n
    columns is relative to the largest entry of that column over all points, so
    a column that is legitimately tiny at some points is not judged on round-off;
    returns an ``(n,)`` array then.
    """
    fd, an = np.asarray(fd, dtype=np.float64), np.asarray(an, dtype=np.float64)
    if not per_column:
        return float(np.max(np.abs(fd - an)) / np.max(np.abs(an)))
    ax = tuple(range(an.ndim - 1))
    return np.max(np.abs(fd - an), axis=ax) / np.max(np.abs(an), axis=ax)


@pytest.fixture
def rng():
    return np.random.default_rng(20240611)


@pytest.fixture
def random_params():
    return make_random_params


@pytest.fixture
def ground_pixels():
    return make_ground_pixels


@pytest.fixture
def central_diff():
    return make_central_diff


@pytest.fixture
def rel_err():
    return make_rel_err


@pytest.fixture
def random_opencv_camera():
    """Factory ``(rng, distortion="strong", ground_z_m=0.0) -> OpenCVCamera`` (no skew in K by default)."""
    from footprint_uq import OpenCVCamera

    def make(rng, distortion="strong", ground_z_m=0.0, skew=False):
        p = make_random_params(rng, distortion=distortion, skew=skew, ground=False)
        R_wc = R_W_C(p[P.PAN], p[P.TILT], p[P.ROLL])
        C = np.array([p[P.XM], p[P.YM], p[P.HM] + ground_z_m])
        K = np.array([[p[P.FX], p[P.SKEW], p[P.CX]], [0.0, p[P.FY], p[P.CY]], [0.0, 0.0, 1.0]])
        R = R_wc.T
        return OpenCVCamera(K, p[P.DIST_SLICE], R, -R @ C, IMAGE_SIZE_PX, ground_z_m=ground_z_m)

    return make


@pytest.fixture
def random_pantilt_camera():
    """Factory ``(rng, ground_z_m=0.0) -> PanTiltCamera``."""
    from footprint_uq import PanTiltCamera

    def make(rng, ground_z_m=0.0):
        return PanTiltCamera(rng.uniform(900, 2000), IMAGE_SIZE_PX, rng.uniform(4, 20), rng.uniform(-180, 180),
                             rng.uniform(8, 40), rng.uniform(-10, 10), tuple(rng.uniform(-50, 50, 2)),
                             tuple(np.array(IMAGE_SIZE_PX) / 2 + rng.uniform(-30, 30, 2)), ground_z_m)

    return make


# `make test-quick` runs `pytest -m "not slow"`: the suite less the tests below (each ~10 s or more on a
# quiet 2-core machine, or whole modules of end-to-end jobs) and those marked @pytest.mark.slow in their
# file. `make test` runs everything. Entries are file names or "file::test" prefixes.
SLOW_TESTS = (
    "test_bench.py",                      # bench/run.py --quick end to end (~1-2 min)
    "test_fuzz.py",                       # a 60-s atheris fuzz of the readers
    "test_reliability.py",                # jobs SIGKILLed while writing, ENOSPC, Dask workers killed
    "test_service_mqtt.py",               # a real Mosquitto broker, restarts and SIGTERM drains
    "test_lens_domain.py::test_every_answer_is_a_principal_root",
    "test_lens_domain.py::test_pincushion_and_no_distortion",
    "test_calibration_extrinsics.py::test_rendered_images_and_pcd_pairs_through_the_cli",
    "test_calibration_extrinsics.py::test_lidar_campaigns_bootstrap_covers_the_error",
    "test_calibration_gcp.py::test_covariance_matches_monte_carlo",  # 300 solves, each checking its weakness
    "test_calibration_gcp.py::test_coverage_200_campaigns",
    "test_calibration_gcp.py::test_sigma_at_the_limit_never_writes_a_budget_locate_refuses",
    "test_calibration_gcp.py::test_kill_after_every_rename_leaves_the_old_set_or_the_new_set",
    "test_output_sets.py::test_kill_after_every_rename_leaves_the_old_set_or_the_new_set",  # 5 commands, ~2-3 min
    "test_report_browser.py",             # headless chromium over every HTML page the project writes
    "test_plan_browser.py",
    "test_validation_browser.py",
    "test_service_faults.py",             # the service's hostile cases through a real Mosquitto
    "test_cp_serve_mqtt.py",              # serve --cp-service through a real Mosquitto, both official decoders
    "test_cpm_official.py::test_every_payload_decodes_with_the_official_modules_to_the_records_numbers",
    "test_centre_linearity.py",           # the footprint centre's Monte Carlo sweep
    "test_examples.py",                   # every example script end to end
    "test_cli.py::test_demo_writes_report",
    "test_warmup.py::test_cold_cache_first_run_compiles_in_the_background",  # a full compile of the objects kernels
)


#: `@pytest.mark.long`: sweeps or compiles of several minutes (twins of faster tests); skipped -- and listed with
#: this reason at the end of the run -- unless FOOTPRINT_UQ_LONG_TESTS=1
RUN_LONG = os.environ.get("FOOTPRINT_UQ_LONG_TESTS") == "1"


def pytest_collection_modifyitems(config, items):
    skip_long = pytest.mark.skip(reason="long (minutes): run with FOOTPRINT_UQ_LONG_TESTS=1 make test")
    for item in items:
        nodeid = item.nodeid.removeprefix("tests/")
        if any(nodeid == s or nodeid.startswith(s + "::") or nodeid.startswith(s + "[") for s in SLOW_TESTS):
            item.add_marker(pytest.mark.slow)
        if "long" in item.keywords:
            item.add_marker(pytest.mark.slow)
            if not RUN_LONG:
                item.add_marker(skip_long)
