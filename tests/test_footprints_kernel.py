"""The fused numba FrameProcessor against the numpy reference path (1e-9 relative)."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, PanTiltCamera, status
from footprint_uq.cameras.base import Camera
from footprint_uq.products.footprints import (
    FrameProcessor,
    footprints_from_boxes2d,
    footprints_from_boxes3d,
    footprints_from_corners,
)
from footprint_uq.uncertainty.budget import psd_factor

BUDGET = ErrorBudget.preset("basler1")
FULL_BUDGET = BUDGET.replace(roll_deg=0.02, ground_height_m=0.05, ground_slope_deg=0.5, pan_deg=0.03,
                             tilt_deg=0.03)
FIELDS = ("corners_px", "corners_xy_world_m", "corners_cov_m2", "joint_cov_m2", "corner_reason", "corner_usable",
          "largest_index", "largest_semi_major_m", "largest_xy_world_m", "largest_cov_m2", "centre_xy_world_m",
          "centre_cov_m2", "centre_valid", "centre_reason", "centre_bad_corner", "area_m2", "v2x_codes")


def assert_same(ref, fast, rtol=1e-9):
    for f in FIELDS:
        a, b = getattr(ref, f), getattr(fast, f)
        assert a.shape == b.shape, f
        if a.dtype.kind == "f":
            assert np.array_equal(np.isnan(a), np.isnan(b)), f
            m = ~np.isnan(a)
            # relative to each object's scale of that field (entries that cancel to ~0 are judged on it)
            ax = tuple(range(1, a.ndim))
            absa = np.nan_to_num(np.abs(a))
            scale = absa.max(axis=ax, keepdims=True) if a.ndim > 1 else absa
            scale = np.broadcast_to(scale, a.shape)
            err = np.abs(a[m] - b[m]) / np.maximum(scale[m], 1e-300)
            assert err.max(initial=0.0) <= rtol, (f, err.max())
        else:
            assert np.array_equal(a, b), f


def make_boxes(camera, rng, n):
    uv = np.column_stack([rng.uniform(-200, 2100, n), rng.uniform(300, 1200, n)])
    bp = camera.backproject(uv)
    xy = np.where(bp.valid[:, None], bp.xy_world_m, rng.uniform(-30, 30, (n, 2)))
    return np.column_stack([xy, rng.uniform(0.5, 1.0, n), rng.uniform(3.5, 5.0, n), rng.uniform(1.6, 2.0, n),
                            rng.uniform(1.3, 1.8, n), rng.uniform(-np.pi, np.pi, n)])


def general_camera(rng, random_params):
    """A base Camera on an arbitrary parameter vector: skew, strong distortion, tilted ground."""
    c = Camera()
    c.params = random_params(rng, distortion="strong", skew=True, roll=True, ground=True, tilt_deg=(15, 35))
    c.image_size_px = (1920, 1080)
    c.ground_z_m = 0.0
    return c


@pytest.fixture(params=["pantilt", "opencv", "general"])
def camera(request, random_opencv_camera, random_params):
    rng = np.random.default_rng(5)
    if request.param == "pantilt":
        return PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0, roll_deg=2.0, position_m=(3.0, 4.0))
    if request.param == "opencv":
        return random_opencv_camera(rng, distortion="mild", skew=True, ground_z_m=1.5)
    return general_camera(rng, random_params)


@pytest.mark.parametrize("budget", [BUDGET, FULL_BUDGET], ids=["basler1", "full"])
def test_boxes3d_agree(camera, budget, rng):
    boxes = make_boxes(camera, rng, 60)
    boxes[3, 0] = np.nan  # one broken row stays a broken row
    for heading in (0.0, 23.0):
        for outside in (False, True):
            ref = footprints_from_boxes3d(camera, budget, boxes, allow_outside_image=outside,
                                          heading_offset_deg=heading)
            fast = FrameProcessor(camera, budget, allow_outside_image=outside,
                                  heading_offset_deg=heading).boxes3d(boxes)
            assert_same(ref, fast)
    assert (ref.corner_reason == status.OUTSIDE_IMAGE).any() and ref.centre_valid.any()
    assert (ref.corner_reason[3] == status.NOT_FINITE).all()


def test_boxes3d_blocks_layouts_and_behind_camera(rng):
    # 300 boxes: several projection blocks and kernel chunks; C-, F-ordered and strided input alike
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    boxes = make_boxes(cam, rng, 300)
    boxes[5, :2] = [-20.0 * np.sin(np.deg2rad(30.0)), -20.0 * np.cos(np.deg2rad(30.0))]  # 20 m behind it
    boxes[6, 6] = np.inf
    ref = footprints_from_boxes3d(cam, BUDGET, boxes)
    assert (ref.corner_reason[5] == status.BEHIND_CAMERA).all()
    assert (ref.corner_reason[6] == status.NOT_FINITE).all()
    proc = FrameProcessor(cam, BUDGET)
    wide = np.zeros((300, 14))
    wide[:, ::2] = boxes
    for b in (boxes, np.asfortranarray(boxes), wide[:, ::2]):
        assert_same(ref, proc.boxes3d(b))


def test_boxes3d_units_and_raised_bottom(camera, rng):
    boxes = make_boxes(camera, rng, 20)
    bd = boxes.copy()
    bd[:, 6] = np.rad2deg(bd[:, 6])
    proc = FrameProcessor(camera, BUDGET)
    assert_same(footprints_from_boxes3d(camera, BUDGET, bd, yaw_unit="deg"), proc.boxes3d(bd, yaw_unit="deg"))
    assert_same(footprints_from_boxes3d(camera, BUDGET, boxes, bottom_on_ground=False),
                proc.boxes3d(boxes, bottom_on_ground=False))


def test_corners_with_invalid_corners_and_detector_cov(camera, rng):
    n, K = 40, 4
    uv = rng.uniform([-100, 0], [2000, 1200], (n, K, 2))
    uv[0, 1] = np.nan
    uv[1, :, 1] = -200.0  # far above the image (above the horizon or outside)
    proc = FrameProcessor(camera, BUDGET)
    A = rng.normal(size=(n, K, 2, 2))
    per_corner = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(2)
    B = rng.normal(size=(n, 2 * K, 2 * K))
    full = B @ np.swapaxes(B, -1, -2) / K
    for det in (None, per_corner[:, 0], per_corner, full):
        ref = footprints_from_corners(camera, BUDGET, uv, pixel_cov_px2=det)
        assert_same(ref, proc.corners(uv, pixel_cov_px2=det))
    assert {status.NOT_FINITE, status.OUTSIDE_IMAGE} <= set(np.unique(ref.corner_reason).tolist())


@pytest.mark.parametrize("K", [1, 2, 3, 5, 7, 64, 65])
def test_other_polygon_sizes(K, rng):
    # 50 objects: several kernel chunks (64 // K objects each) and a shorter last one
    cam = PanTiltCamera(1200.0, (1280, 720), 6.0, -40.0, 20.0)
    ang = np.sort(rng.uniform(0, 2 * np.pi, (50, K)), axis=1)
    uv = np.stack([640 + 100 * np.cos(ang), 500 + 80 * np.sin(ang)], -1)
    uv[7, K // 2] = np.nan  # one object without a centre
    ref = footprints_from_corners(cam, BUDGET, uv)
    assert_same(ref, FrameProcessor(cam, BUDGET).corners(uv))
    assert not ref.centre_valid[7] and ref.centre_valid.sum() >= 45


def test_more_corners_than_the_kernel_layout_takes(rng):
    # the fused kernel holds at most MAX_CORNERS corners per object; beyond, the processor uses the
    # numpy reference (same results, no error)
    from footprint_uq.fast.footprint_kernels import MAX_CORNERS

    cam = PanTiltCamera(1200.0, (1280, 720), 6.0, -40.0, 20.0)
    K = MAX_CORNERS + 1
    ang = np.sort(rng.uniform(0, 2 * np.pi, (3, K)), axis=1)
    uv = np.stack([640 + 100 * np.cos(ang), 500 + 80 * np.sin(ang)], -1)
    assert_same(footprints_from_corners(cam, BUDGET, uv), FrameProcessor(cam, BUDGET).corners(uv))


@pytest.mark.parametrize("contact", ["bottom-centre", "bottom-corners"])
def test_boxes2d_agree(contact, rng):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    u0 = rng.uniform(0, 1700, 25)
    v0 = rng.uniform(300, 900, 25)
    boxes = np.column_stack([u0, v0, u0 + rng.uniform(20, 200, 25), v0 + rng.uniform(20, 170, 25)])
    sig = rng.uniform(0.5, 4.0, (25, 4))
    proc = FrameProcessor(cam, BUDGET)
    assert_same(footprints_from_boxes2d(cam, BUDGET, boxes, contact=contact),
                proc.boxes2d(boxes, contact=contact))
    assert_same(footprints_from_boxes2d(cam, BUDGET, boxes, contact=contact, box_cov_px2=sig),
                proc.boxes2d(boxes, contact=contact, box_cov_px2=sig))


def test_without_joint_covariance(rng):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    boxes = make_boxes(cam, rng, 10)
    a = FrameProcessor(cam, BUDGET).boxes3d(boxes)
    b = FrameProcessor(cam, BUDGET, joint_cov=False).boxes3d(boxes)
    assert b.joint_cov_m2 is None
    assert np.array_equal(a.centre_cov_m2, b.centre_cov_m2, equal_nan=True)


def test_empty_frame(rng):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    est = FrameProcessor(cam, BUDGET).boxes3d(np.zeros((0, 7)))
    assert len(est) == 0 and est.centre_cov_m2.shape == (0, 2, 2)


def test_psd_factor_reproduces_covariance(rng):
    for S in (BUDGET.param_covariance(), FULL_BUDGET.param_covariance()):
        L = psd_factor(S).dense()
        # each entry to the precision of its own variances (px^2 and rad^2 differ by 1e10)
        d = np.sqrt(np.diag(S))
        assert np.all(np.abs(L @ L.T - S) <= 1e-14 * np.outer(d, d))
    # fx and fy move together: one column, not two
    f = psd_factor(BUDGET.param_covariance())
    assert f.rank == np.count_nonzero(np.diag(BUDGET.param_covariance())) - 1
    assert np.array_equal(f.cols, np.sort(f.cols))  # sorted by column
    A = rng.normal(size=(22, 5))
    assert psd_factor(A @ A.T).rank == 5
    # the budget's own factor is this one
    np.testing.assert_array_equal(BUDGET.param_factor().vals, psd_factor(BUDGET.param_covariance()).vals)


def test_bad_input():
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    proc = FrameProcessor(cam, BUDGET)
    with pytest.raises(InputError, match=r"^boxes_world\[1\]"):
        proc.boxes3d(np.array([[0, 20, 0, 4.0, 2, 1.5, 0], [0, 20, 0, 4.0, -2, 1.5, 0]]))
    with pytest.raises(InputError, match="^boxes_world"):
        proc.boxes3d(np.zeros((3, 6)))
    with pytest.raises(InputError, match="^corners_px"):
        proc.corners(np.zeros((3, 2)))
    with pytest.raises(InputError, match="^pixel_cov_px2"):
        proc.corners(np.full((2, 4, 2), 900.0), pixel_cov_px2=np.eye(2))
    with pytest.raises(InputError, match="^yaw_unit"):
        proc.boxes3d(np.zeros((1, 7)), yaw_unit="turns")


def test_kernel_v2x_fields_match_numpy_at_boundaries(rng):
    from footprint_uq.fast import footprint_kernels as fk
    from footprint_uq.products.footprints import V2X_FIELDS
    from footprint_uq.products.v2x import cpm_fields, j2735_fields

    s = np.array([0.0, 0.01 / 1.96, 0.05 / 1.96, 40.94 / 1.96, 40.95 / 1.96, 0.05, 12.65, 12.69, 12.70, 300.0])
    covs = [np.diag([a * a, b * b]) for a in s for b in s[::3]]
    A = rng.normal(size=(200, 2, 2)) * rng.uniform(0.01, 5, (200, 1, 1))
    covs += list(A @ np.swapaxes(A, -1, -2))
    covs += [np.full((2, 2), np.nan), np.zeros((2, 2)), np.array([[1.0, 1.0], [1.0, 1.0]])]
    C = np.array(covs)
    for heading in (0.0, 17.0, -90.0):
        want = {**cpm_fields(C, heading), **j2735_fields(C, heading)}
        h = np.deg2rad(heading)
        ch, sh = (1.0, 0.0) if heading == 0.0 else (np.cos(h), np.sin(h))
        c00, c01, c11 = (np.ascontiguousarray(C[:, a, b]) for a, b in ((0, 0), (0, 1), (1, 1)))
        got = fk.v2x_codes(c00, c01, c11, ch, sh)  # in blocks of 64, as in the kernel
        for j, name in enumerate(V2X_FIELDS):
            assert np.array_equal(got[j], want[name]), (heading, name)


def test_processor_is_thread_safe(rng):
    from concurrent.futures import ThreadPoolExecutor

    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    proc = FrameProcessor(cam, BUDGET)
    frames = [make_boxes(cam, rng, 50) for _ in range(8)]
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(proc.boxes3d, frames))
    for boxes, est in zip(frames, results, strict=True):
        assert_same(footprints_from_boxes3d(cam, BUDGET, boxes), est)


@pytest.mark.parametrize("budget", [ErrorBudget(), ErrorBudget(imaging_px=(0.5, 0.5))], ids=["zero", "pixel-only"])
def test_degenerate_budgets(budget, rng):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    boxes = make_boxes(cam, rng, 20)
    ref = footprints_from_boxes3d(cam, budget, boxes)
    assert_same(ref, FrameProcessor(cam, budget).boxes3d(boxes))
    ok = ref.centre_valid
    if not np.any(budget.pixel_covariance()):
        assert np.all(ref.centre_cov_m2[ok] == 0.0)
        assert np.all(ref.v2x["cpm_x_confidence"][ok] == 1) and np.all(ref.v2x["cpm_xy_correlation"][ok] == 101)
        assert np.all(ref.v2x["j2735_position_confidence"][ok] == 15)


def test_reference_empty_frame():
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    est = footprints_from_boxes3d(cam, BUDGET, np.zeros((0, 7)))
    assert len(est) == 0 and est.joint_cov_m2.shape == (0, 8, 8) and est.v2x_codes.shape == (0, 7)


def test_empty_reusable_shapes_and_memory():
    from footprint_uq.products.frame_processor import _POOL_MIN_BYTES, empty_reusable

    for shape, dtype in (((3, 2), np.float64), ((_POOL_MIN_BYTES // 8 + 5, 2, 2), np.float64), ((1 << 21,), np.int8),
                         ((0, 4, 2), np.float64)):
        a = empty_reusable(shape, dtype)
        assert a.shape == shape and a.dtype == dtype and a.flags.writeable and a.flags.c_contiguous
        a[...] = 1
        assert a.sum() == a.size


def test_thread_buffer_reused_per_thread_and_per_shape():
    import threading

    from footprint_uq.fast.buffers import thread_buffer

    a = thread_buffer("t", (5,))
    assert thread_buffer("t", (5,)) is a  # reused
    assert thread_buffer("t", (6,)).shape == (6,)  # another shape: a new buffer
    assert thread_buffer("t", (6,), np.int8).dtype == np.int8  # another dtype too
    other = []
    t = threading.Thread(target=lambda: other.append(thread_buffer("t", (6,), np.int8)))
    t.start()
    t.join()
    assert not np.shares_memory(other[0], thread_buffer("t", (6,), np.int8))  # one per thread


@pytest.mark.parametrize("N", [0, 1, 100, 40_000])
@pytest.mark.parametrize("K", [1, 2, 4, 8])
@pytest.mark.parametrize("joint", [False, True])
def test_outputs_max_bytes_bounds_alloc_outputs(N, K, joint):
    """outputs_max_bytes (FrameProcessor's once-per-frame allocation choice) is at least the largest array
    alloc_outputs makes (and the (N, K, 2) pixels): it is written from the same shapes and must not go stale."""
    from footprint_uq.fast import footprint_kernels as fk

    arrays = fk.alloc_outputs(N, K, joint=joint, corners=True) + (np.empty((N, K, 2)),)
    largest = max(a.nbytes for a in arrays)
    bound = fk.outputs_max_bytes(N, K, joint=joint)
    assert largest <= bound <= 2 * largest or N == 0


@pytest.mark.parametrize("budget", [BUDGET, FULL_BUDGET], ids=["basler1", "full"])
def test_centre_shared_jacobian_splits_the_covariance(camera, budget, rng):
    """The centre's whitened parameter Jacobian B (the tracker's shared calibration error): the kernel equals the
    reference, B B^T is the camera-level part (the whole covariance without pixel noise), the frame part is PSD,
    and B is dC/dp L by seeded central differences of the back-projection."""
    boxes = make_boxes(camera, rng, 40)
    boxes[3, 0] = np.nan
    ref = footprints_from_boxes3d(camera, budget, boxes)
    plain = FrameProcessor(camera, budget).boxes3d(boxes)
    assert plain.centre_shared_m is None and plain.centre_cov_frame_m2 is None
    fast = FrameProcessor(camera, budget, shared_jacobian=True).boxes3d(boxes)
    L = budget.param_factor().dense()
    assert fast.centre_shared_m.shape == ref.centre_shared_m.shape == (40, 2, L.shape[1])
    ok = ref.centre_valid
    assert np.array_equal(ok, fast.centre_valid) and ok.sum() > 10 and np.isnan(fast.centre_shared_m[~ok]).all()
    scale = np.abs(ref.centre_shared_m[ok]).max(axis=(1, 2), keepdims=True)
    assert np.abs(fast.centre_shared_m[ok] - ref.centre_shared_m[ok]).max() <= 1e-9 * scale.max()
    frame = fast.centre_cov_frame_m2[ok]
    assert np.linalg.eigvalsh(frame).min() >= -1e-12 * np.abs(fast.centre_cov_m2[ok]).max()
    quiet = budget.replace(imaging_px=(0.0, 0.0), resolution_px=(0.0, 0.0))
    q = FrameProcessor(camera, quiet, shared_jacobian=True).boxes3d(boxes)
    np.testing.assert_allclose(q.centre_cov_shared_m2[ok], q.centre_cov_m2[ok], rtol=1e-9,
                               atol=1e-12 * np.abs(q.centre_cov_m2[ok]).max())
    # central differences of the centre along each factor column (parameters moved by L[:, c] * h)
    uv = ref.corners_px[ok][:5]
    i = np.flatnonzero(ok)[:5]
    for c in range(L.shape[1]):
        h = 1e-4
        xy = []
        for s in (h, -h):
            cam = Camera()
            cam.params, cam.image_size_px, cam.ground_z_m = camera.params + s * L[:, c], (1920, 1080), camera.ground_z_m
            xy.append(footprints_from_corners(cam, quiet, uv, linearity=False).centre_xy_world_m)
        num = (xy[0] - xy[1]) / (2 * h)
        np.testing.assert_allclose(ref.centre_shared_m[i, :, c], num, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("n, r", [(0, 1), (3, 13)])
def test_point_outputs_are_alloc_outputs_layout(n, r):
    """fk.point_outputs (allocated in compiled code for point_shared_jacobian) is alloc_outputs(n, 1,
    corners=False, shared_rank=r) array for array: shapes and dtypes (the twin must not drift)."""
    from footprint_uq.fast import footprint_kernels as fk

    got, ref = fk.point_outputs(n, r), fk.alloc_outputs(n, 1, corners=False, shared_rank=r)
    assert [(a.shape, a.dtype) for a in got] == [(a.shape, a.dtype) for a in ref]


@pytest.mark.parametrize("budget", [BUDGET, FULL_BUDGET], ids=["basler1", "full"])
def test_point_jacobian_into_is_point_shared_jacobian(camera, budget, rng):
    """fk.point_jacobian_into (the tracker's B at its predicted positions: only the stages that form B) gives
    fk.point_shared_jacobian's B (the whole one-point footprint) to the bit, NaN rows included: pixels inside and
    outside the image, above the horizon, beyond the lens's fold, NaN; three chunks of the kernel (150 points)."""
    from footprint_uq.fast import footprint_kernels as fk

    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, v2x_policy="linear",
                          shared_jacobian=True, allow_outside_image=True)
    n = 150
    uv = np.column_stack([rng.uniform(-900.0, 2800.0, n), rng.uniform(-300.0, 1600.0, n)])
    uv[7] = np.nan
    uv[8, 1] = np.inf
    uv[70:76, 1] = -4000.0  # far above the horizon (every camera of the fixture looks down 15-37 deg)
    ref = proc.point_shared_jacobian(uv)
    kernel, args = proc.point_jacobian_kernel()
    got = np.full((n, 2, ref.shape[2]), -1.0)
    kernel(uv, *args, got, np.empty(fk.SCRATCH_SHAPE))
    np.testing.assert_array_equal(got, ref)
    ok = ~np.isnan(ref).any(axis=(1, 2))
    assert ok.sum() > 100 and not ok[[7, 8, 70, 75]].any()  # (both kinds of rows)
