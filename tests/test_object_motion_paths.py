"""object_motion's two ways in (tracking/motion.py): what the tracker hands (finite floats, C-contiguous float64
rows, float64 columns of n) passes a few attribute tests without a call; anything else is checked and converted.
Both give the same motion to the bit; a column of the wrong length is named whichever way it comes; ``age_s`` is
a copy of the tracks' unless the caller hands its own (CameraTracker.step_frame: the step's)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.tracking import object_motion
from footprint_uq.tracking.table import TrackOutput


def _bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def _tracks(rng, n: int) -> TrackOutput:
    """A tracker's output of n objects: some without a velocity (NaN), some at rest, the rest moving."""
    a = rng.normal(0.0, 0.6, (n, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2)
    v = rng.normal(0.0, 5.0, (n, 2))
    none = rng.random(n) < 0.2
    v[none], cov[none] = np.nan, np.nan
    v[rng.random(n) < 0.1] = 0.0
    return TrackOutput(np.arange(n, dtype=np.int64), np.zeros(n, bool), np.full(n, 3, np.int64),
                       rng.uniform(0.0, 4.0, n), rng.normal(0.0, 9.0, (n, 2)), cov.copy(), v, cov)


def _same(got, want, what):
    for name, g, w in zip(want._fields, got, want, strict=True):
        assert g.shape == w.shape and np.array_equal(_bits(g), _bits(w)), (what, name)


def _converted(tracks: TrackOutput) -> TrackOutput:
    """The same values in the forms the checks convert: strided / Fortran-ordered rows, a list of ids."""
    v = np.empty((len(tracks.track_id), 4))
    v[:, ::2] = tracks.v_mps  # (a strided view of the same values)
    return tracks._replace(track_id=tracks.track_id.tolist(), v_mps=v[:, ::2],
                           cov_v_m2ps2=np.asfortranarray(tracks.cov_v_m2ps2))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 70), seed=st.integers(0, 2**32 - 1),
       h=st.sampled_from([0.0, 12.5, -123.25, 359.875]), with_yaw=st.booleans(), with_sigma=st.booleans())
def test_fast_and_converted_inputs_give_the_same_bits(n, seed, h, with_yaw, with_sigma):
    rng = np.random.default_rng(seed)
    tracks = _tracks(rng, n)
    boxes = rng.normal(0.0, 2.0, (n, 7))
    sigma = rng.uniform(0.0, 0.2, n)
    want = object_motion(tracks, heading_offset_deg=h, yaw_rad=boxes[:, 6] if with_yaw else None,
                         sigma_yaw_rad=sigma if with_sigma else None)
    got = object_motion(_converted(tracks), heading_offset_deg=np.float64(h) if h else 0,
                        yaw_rad=boxes[:, 6:7].tolist() if with_yaw else None,
                        sigma_yaw_rad=sigma.reshape(n, 1).tolist() if with_sigma else None, heading_min_ratio=3)
    _same(got, want, "converted")
    own = object_motion(tracks, heading_offset_deg=h, yaw_rad=np.ascontiguousarray(boxes[:, 6]) if with_yaw else None,
                        sigma_yaw_rad=sigma if with_sigma else None, age_s=tracks.age_s)
    _same(own, want, "contiguous yaw, own ages")
    assert own.age_s is tracks.age_s and want.age_s is not tracks.age_s
    assert np.array_equal(_bits(want.age_s), _bits(tracks.age_s))


def test_columns_of_another_length_are_named_whichever_way_they_come():
    rng = np.random.default_rng(3)
    n = 9
    tracks = _tracks(rng, n)
    for name in ("yaw_rad", "sigma_yaw_rad", "age_s"):
        for wrong in (np.zeros(n - 1), np.zeros(n + 1), np.zeros((n, 2)), np.zeros(2 * n)[::2][:n - 1],
                      [0.0] * (n + 1), np.zeros(n + 1, np.float32)):
            with pytest.raises(InputError, match=name):
                object_motion(tracks, **{name: wrong})
    with pytest.raises(InputError, match="yaw_rad"):
        object_motion(tracks._replace(track_id=np.arange(n - 1)), yaw_rad=np.zeros(n))  # (n is the tracks')
    # a column of n as another dtype or a 2-D column is converted, not refused
    np.testing.assert_array_equal(object_motion(tracks, yaw_rad=np.zeros((n, 1), np.float32)).yaw_deg,
                                  object_motion(tracks, yaw_rad=np.zeros(n)).yaw_deg)


def test_velocity_rows_of_another_shape_are_named_not_read_past_their_end():
    """A malformed tracker output (velocities or their covariances not one per object) is refused by name: the
    compiled pass reads n rows of each."""
    tracks = _tracks(np.random.default_rng(4), 6)
    for field, wrong in (("v_mps", tracks.v_mps[:3]), ("v_mps", np.zeros((6, 3))), ("v_mps", np.zeros(12)),
                         ("cov_v_m2ps2", tracks.cov_v_m2ps2[:5]), ("cov_v_m2ps2", np.zeros((6, 4)))):
        with pytest.raises(InputError, match=field):
            object_motion(tracks._replace(**{field: wrong}))


def test_nan_and_bad_options_are_named_on_the_fast_path():
    tracks = _tracks(np.random.default_rng(5), 4)
    for bad in (float("nan"), float("inf"), -float("inf"), np.float64("nan"), None, "north"):
        with pytest.raises(InputError, match="heading_offset_deg"):
            object_motion(tracks, heading_offset_deg=bad)
        with pytest.raises(InputError, match="heading_min_ratio"):
            object_motion(tracks, heading_min_ratio=bad)
    for bad in (0.0, -1.0, 0, -3):
        with pytest.raises(InputError, match="heading_min_ratio"):
            object_motion(tracks, heading_min_ratio=bad)


def _read_only(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a.flags.writeable = False
    return a


def test_converted_inputs_reach_the_kernel_as_the_tracker_hands_them():
    """Rows that are not C-contiguous, writable float64 are copied before the compiled pass: no new specialisation of
    motion_fields is compiled in a frame (the kernel's signatures: C rows, a yaw column strided or not)."""
    from footprint_uq.tracking.kernels import motion_fields

    rng = np.random.default_rng(8)
    n = 6
    tracks = _tracks(rng, n)
    boxes = rng.normal(0.0, 1.0, (n, 7))
    for yaw in (None, boxes[:, 6], np.ascontiguousarray(boxes[:, 6])):  # (the signatures the tracker's frames use)
        object_motion(tracks, yaw_rad=yaw, sigma_yaw_rad=np.full(n, 0.1))
    before = set(motion_fields.signatures)
    odd = (_converted(tracks), tracks._replace(v_mps=tracks.v_mps.astype(np.float32)),
           tracks._replace(cov_v_m2ps2=tracks.cov_v_m2ps2.astype(np.float32)),
           tracks._replace(v_mps=tracks.v_mps.tolist(), cov_v_m2ps2=tracks.cov_v_m2ps2.tolist()),
           tracks._replace(v_mps=_read_only(tracks.v_mps), cov_v_m2ps2=_read_only(tracks.cov_v_m2ps2)))
    for t in odd:
        for yaw in (None, boxes[:, 6]):
            object_motion(t, yaw_rad=yaw, sigma_yaw_rad=np.full(n, 0.1)[::-1])
    assert set(motion_fields.signatures) == before


def _fields_with_hypot(v, cov, h_deg, ratio):
    """motion_fields' speed, sigmas and heading-sigma gate written out with numpy's float64 scalars and ``hypot``
    (the kernel's form before 2026-11-29, wave 13, when its two norms became a guarded ``sqrt(x^2 + y^2)``)."""
    f = np.float64
    ch, sh = f(np.cos(np.radians(h_deg))), f(np.sin(np.radians(h_deg)))
    rows = []
    for (vx, vy), c in zip(v.tolist(), cov.tolist(), strict=True):
        vx, vy, c00, c01, c11 = f(vx), f(vy), f(c[0][0]), f(c[0][1]), f(c[1][1])
        ve, vn = ch * vx + sh * vy, -sh * vx + ch * vy
        a = ch * ch * c00 + 2.0 * ch * sh * c01 + sh * sh * c11
        b = -ch * sh * c00 + (ch * ch - sh * sh) * c01 + ch * sh * c11
        d = sh * sh * c00 - 2.0 * ch * sh * c01 + ch * ch * c11
        sp = np.hypot(ve, vn)
        if not sp > 0.0:
            rows.append((sp, np.nan, np.nan))
            continue
        s_sp = np.sqrt(ve * ve * a + 2.0 * ve * vn * b + vn * vn * d) / sp
        smax = np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b))
        s_h = np.degrees(np.sqrt(vn * vn * a - 2.0 * ve * vn * b + ve * ve * d) / (sp * sp))
        rows.append((sp, s_sp, s_h if sp >= ratio * smax else np.nan))
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


_COMPONENT = st.one_of(st.floats(-50.0, 50.0), st.sampled_from([0.0, -0.0, 1e-170, -3e-160, 1e-150, 2e150, -1e200,
                                                                   1e308, float("inf"), -float("inf"),
                                                                   float("nan")]))


@settings(max_examples=150, deadline=None)
@given(v=st.lists(st.tuples(_COMPONENT, _COMPONENT), min_size=1, max_size=12), seed=st.integers(0, 2**32 - 1),
       scale=st.sampled_from([1e-320, 1e-150, 1e-4, 1.0, 1e150, 1e300]), h=st.sampled_from([0.0, 30.0, -123.25]))
def test_the_speed_and_its_sigma_are_hypots_whatever_the_sizes(v, seed, scale, h):
    """The kernel's norms (a guarded sqrt of the squares' sum, hypot where that would overflow or underflow) give
    hypot's speed, sigmas and heading-sigma gate within a few ulps over the whole float range, and its answers --
    inf, NaN, 0, a tiny or huge finite speed -- exactly where the squares would leave the range."""
    from footprint_uq.tracking.kernels import motion_fields

    rng = np.random.default_rng(seed)
    v = np.array(v, dtype=np.float64)
    n = v.shape[0]
    a = rng.normal(0.0, 1.0, (n, 2, 2))
    cov = (a @ np.swapaxes(a, 1, 2)) * scale
    cov[rng.random(n) < 0.2, 0, 1] = 0.0  # (isotropic-ish: the eigen-norm's zero entries)
    cov[:, 1, 0] = cov[:, 0, 1]
    out, cov_out = np.empty((8, n)), np.empty((n, 2, 2))
    hr = np.radians(h)
    with np.errstate(all="ignore"):
        motion_fields(v, cov, np.cos(hr), np.sin(hr), 1.0, np.empty(0), np.empty(0), h, out, cov_out)
        want = _fields_with_hypot(v, cov, h, 1.0)
    got = np.column_stack([out[2], out[3], out[5]])
    for j, name in enumerate(("speed", "sigma_speed", "sigma_heading")):
        g, w = got[:, j], want[:, j]
        assert np.array_equal(np.isnan(g), np.isnan(w)), name
        ok = ~np.isnan(w)
        assert np.array_equal(np.isinf(g[ok]), np.isinf(w[ok])), name
        fin = ok & np.isfinite(w)
        np.testing.assert_allclose(g[fin], w[fin], rtol=1e-14, atol=0.0, err_msg=name)
    assert np.array_equal(out[2] == 0.0, want[:, 0] == 0.0)
