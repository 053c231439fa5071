"""V2X confidence fields: ETSI CPM and SAE J2735, at their boundaries."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import InputError
from footprint_uq.products.v2x import (
    K95_2D,
    cpm_coordinate_confidence,
    cpm_correlation,
    cpm_fields,
    j2735_axis_accuracy,
    j2735_fields,
    j2735_orientation,
    j2735_position_confidence,
    rotate_to_true_north,
)


def diag(sx, sy, rho=0.0):
    return np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])


# -- ETSI CPM CoordinateConfidence (0.01 m at 95 %, 1..4096) -----------------------------------------
@pytest.mark.parametrize("sigma_m, code", [
    (0.0, 1),                      # zero: the smallest value, "<= 0.01 m"
    (0.01 / 1.96, 1),              # exactly 0.01 m at 95 %
    (0.0100001 / 1.96, 2),         # just above a step goes up
    (0.05 / 1.96, 5),              # exactly on a step stays (no binary-rounding bump)
    (1.0, 196),                    # 1.96 m
    (40.94 / 1.96, 4094),          # the largest in-range value
    (40.9401 / 1.96, 4095),        # out of range
    (1e6, 4095),
    (np.inf, 4095),
    (np.nan, 4096),                # unavailable
])
def test_cpm_coordinate_confidence_boundaries(sigma_m, code):
    assert cpm_coordinate_confidence(sigma_m) == code


def test_cpm_coordinate_confidence_is_never_optimistic(rng):
    s = rng.uniform(0, 20, 10000)
    c = cpm_coordinate_confidence(s)
    assert np.all(c * 0.01 >= 1.96 * s - 1e-12)  # the stated confidence covers the 95 % value
    inside = c > 1  # and it is the smallest step that does
    assert np.all((c[inside] - 1) * 0.01 < 1.96 * s[inside] + 1e-9)


@pytest.mark.parametrize("cov, code", [
    (diag(1.0, 2.0, 0.0), 0),
    (diag(1.0, 2.0, 0.5), 50),
    (diag(1.0, 2.0, -0.734), -73),
    (diag(1.0, 2.0, 0.735), 74),   # rounding to nearest
    (diag(1.0, 2.0, 1.0), 100),
    (diag(1.0, 2.0, -1.0), -100),
    (diag(0.0, 2.0, 0.0), 101),    # undefined for a zero variance
    (np.full((2, 2), np.nan), 101),
])
def test_cpm_correlation_boundaries(cov, code):
    assert cpm_correlation(cov) == code


def test_cpm_fields_shapes_and_heading():
    covs = np.stack([diag(0.1, 0.5), diag(2.0, 1.0, 0.3), np.full((2, 2), np.nan)])
    f = cpm_fields(covs)
    assert set(f) == {"cpm_x_confidence", "cpm_y_confidence", "cpm_xy_correlation"}
    assert all(v.shape == (3,) and v.dtype == np.int32 for v in f.values())
    assert f["cpm_x_confidence"].tolist() == [20, 392, 4096]
    assert f["cpm_y_confidence"].tolist() == [98, 196, 4096]
    assert f["cpm_xy_correlation"].tolist() == [0, 30, 101]
    # world +y points east (heading offset 90): world y becomes east (x), world x becomes south
    g = cpm_fields(diag(0.1, 0.5), heading_offset_deg=90.0)
    assert g["cpm_x_confidence"] == 98 and g["cpm_y_confidence"] == 20
    assert cpm_fields(diag(0.1, 0.5, 0.4), heading_offset_deg=90.0)["cpm_xy_correlation"] == -40
    # broadcasting over leading dims
    assert cpm_fields(np.broadcast_to(diag(1, 1), (2, 3, 2, 2)))["cpm_x_confidence"].shape == (2, 3)


# -- SAE J2735 ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("sigma_m, code", [
    (0.0, 0),
    (0.05, 1),
    (0.0500001, 2),
    (0.5, 10),
    (12.65, 253),
    (12.69, 254),   # ceil reaches 254 = ">= 12.70 m" (conservative)
    (12.70, 254),
    (100.0, 254),
    (np.inf, 254),
    (np.nan, 255),
])
def test_j2735_axis_accuracy_boundaries(sigma_m, code):
    assert j2735_axis_accuracy(sigma_m) == code


UNIT = 360.0 / 65535.0


@pytest.mark.parametrize("bearing_deg, code", [
    (0.0, 0),
    (UNIT, 1),
    (90.0, 16384),     # 16383.75 rounds to nearest
    (179.999, 32767),
    (180.0, 0),        # an axis: 180 deg is 0 deg
    (270.0, 16384),
    (-90.0, 16384),
    (np.nan, 65535),   # unavailable
])
def test_j2735_orientation_boundaries(bearing_deg, code):
    assert j2735_orientation(bearing_deg) == code


@pytest.mark.parametrize("radius_m, code", [
    (0.0, 15),        # a1cm
    (0.01, 15),       # exactly 1 cm
    (0.0100001, 14),  # just above: a2cm
    (0.3, 10),        # a50cm (10) is the smallest level >= 0.3 m
    (1.0, 9),
    (499.9, 1),
    (500.0, 1),
    (500.1, 0),       # no level can state it: unavailable
    (np.inf, 0),
    (np.nan, 0),
])
def test_j2735_position_confidence_rule(radius_m, code):
    assert j2735_position_confidence(radius_m) == code


def test_j2735_fields_pinned():
    # semi-major 1 m along north (world y, heading 0), semi-minor 0.2 m
    f = j2735_fields(diag(0.2, 1.0))
    assert f["j2735_semi_major"] == 20 and f["j2735_semi_minor"] == 4
    assert f["j2735_orientation"] == 0
    # 95 % radius 2.4477 m -> the smallest level >= it is a5m (7)
    assert K95_2D == pytest.approx(2.4477, abs=1e-4)
    assert f["j2735_position_confidence"] == 7
    # major axis along world x (east) -> bearing 90 deg; with a heading offset of 30 deg -> 120 deg
    assert j2735_fields(diag(1.0, 0.2))["j2735_orientation"] == round(90 / UNIT)
    assert j2735_fields(diag(1.0, 0.2), heading_offset_deg=30.0)["j2735_orientation"] == round(120 / UNIT)
    # 45 deg ellipse (major axis north-east)
    c = np.array([[1.0, 0.9], [0.9, 1.0]])
    assert j2735_fields(c)["j2735_orientation"] == round(45 / UNIT)
    # NaN: everything unavailable
    g = j2735_fields(np.full((2, 2), np.nan))
    assert (g["j2735_semi_major"], g["j2735_semi_minor"], g["j2735_orientation"],
            g["j2735_position_confidence"]) == (255, 255, 65535, 0)
    # zero covariance
    z = j2735_fields(np.zeros((2, 2)))
    assert z["j2735_semi_major"] == 0 and z["j2735_position_confidence"] == 15


def test_rotation_preserves_the_ellipse(rng):
    A = rng.normal(size=(50, 2, 2))
    C = A @ np.swapaxes(A, -1, -2)
    R = rotate_to_true_north(C, 37.0)
    assert np.allclose(np.linalg.eigvalsh(R), np.linalg.eigvalsh(C))
    assert np.allclose(rotate_to_true_north(C, 0.0), C)


def test_bad_input():
    with pytest.raises(InputError, match="^cov_m2"):
        cpm_fields(np.zeros((3, 2)))
    with pytest.raises(InputError, match="variance"):
        cpm_fields(np.array([[-1.0, 0.0], [0.0, 1.0]]))
    with pytest.raises(InputError, match="^sigma_m"):
        cpm_coordinate_confidence(-0.1)
    with pytest.raises(InputError, match="^heading_offset_deg"):
        j2735_fields(np.eye(2), heading_offset_deg=np.nan)


def test_circular_covariance_orientation_is_deterministic():
    c = np.eye(2) * 0.3
    for h in (0.0, 17.0, 45.0, -120.0):
        assert j2735_fields(c, heading_offset_deg=h)["j2735_orientation"] == 0
    assert j2735_fields(np.zeros((2, 2)))["j2735_orientation"] == 0


def test_covariance_not_psd_or_asymmetric_is_refused():
    from footprint_uq.errors import InputError
    from footprint_uq.products.v2x import cpm_fields, j2735_fields

    for bad in ([[1.0, 2.0], [2.0, 1.0]], [[1.0, 0.5], [0.0, 1.0]], [[1.0, np.nan], [np.nan, 1.0]]):
        for f in (cpm_fields, j2735_fields):
            with pytest.raises(InputError, match="positive semi-definite"):
                f(np.array([np.eye(2), bad]))
    # rounding of a computed covariance is accepted; NaN (unavailable) is not an error
    c = np.array([[1.0, 1.0 - 1e-15], [1.0 - 1e-15, 1.0 - 2e-15]])
    cpm_fields(c)
    assert j2735_fields(np.full((2, 2), np.nan))["j2735_semi_major"] == 255


def test_one_infinite_variance_keeps_the_finite_axis():
    """diag(inf, 1): the semi-minor axis is 1 m (code 20), not 'unavailable'; the major axis is east."""
    from footprint_uq.products.v2x import J2735_AXIS_MAX, j2735_fields

    f = j2735_fields(np.diag([np.inf, 1.0]))
    assert f["j2735_semi_major"] == J2735_AXIS_MAX and f["j2735_semi_minor"] == 20
    assert f["j2735_orientation"] == round(90.0 / (360.0 / 65535.0))
    g = j2735_fields(np.diag([1.0, np.inf]))
    assert g["j2735_semi_minor"] == 20 and g["j2735_orientation"] == 0
