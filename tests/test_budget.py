"""Error budgets: the paper's Tables 2-3, validation, covariance overrides, files, the ground-slope model."""

from __future__ import annotations

import json
from decimal import Decimal

import numpy as np
import pytest

from footprint_uq import ConfigError, ErrorBudget, PanTiltCamera, load_budget, propagate
from footprint_uq import params as P
from footprint_uq.cameras.ground import sigma_ground_z
from footprint_uq.uncertainty import presets

# Hand-copied from the paper (shared/seed, Tables 2 and 3), as printed.
# Table 2: sigma fx, fy, f, c, r (px), k1, k2, p1, p2, k3.
TABLE2_PRINTED = {
    "basler1": ("0.1992", "0.1923", "0.2768", "0.1713", "0.1314", "5E-4", "0.0019", "3E-5", "5E-5", "0.0002"),
    "basler2": ("0.1479", "0.1470", "0.2085", "0.1486", "0.1465", "0.0004", "0.0011", "2E-5", "3E-5", "0.0009"),
    "bw-cube1": ("0.3057", "0.3180", "0.4411", "0.3031", "0.2437", "0.0004", "0.0005", "7E-5", "8E-5", "0.0005"),
    "bw-cube2": ("0.670", "0.680", "0.9546", "0.3075", "0.3656", "0.0001", "0.0001", "1E-5", "3E-5", "0.0003"),
    "bw-bullet1": ("0.4225", "0.4255", "0.5996", "0.4115", "0.3405", "0.001", "0.0014", "6E-5", "1E-5", "0.0009"),
    "bw-bullet2": ("0.332", "0.325", "0.4645", "0.416", "0.299", "0.0001", "4E-5", "5E-5", "7E-5", "0.0001"),
}
# Table 3: sigma X, Y, h (m), sigma alpha, sigma theta (printed in 10^-3 deg).
TABLE3_PRINTED = {
    "basler1": ("0.1061", "0.0861", "0.1936", "0.1524", "0.1480"),
    "bw-cube1": ("0.4912", "0.1910", "0.8484", "0.8032", "0.7049"),
    "bw-bullet2": ("0.0658", "0.0588", "0.1546", "0.3123", "0.2239"),
}


def _half_ulp(text: str) -> float:
    """Half a unit in the last printed digit: '0.2768' -> 0.00005, '0.670' -> 0.0005."""
    return 0.5 * 10.0 ** Decimal(text).as_tuple().exponent


def test_table2_exactly_as_printed():
    assert set(presets.PAPER_TABLE2) == set(TABLE2_PRINTED)
    for name, row in TABLE2_PRINTED.items():
        assert presets.PAPER_TABLE2[name] == tuple(float(v) for v in row), name


def test_table3_exactly_as_printed_with_the_milli_degree_unit():
    for name, row in TABLE3_PRINTED.items():
        assert presets.PAPER_TABLE3[name] == tuple(float(v) for v in row), name
        b = ErrorBudget.preset(name)
        X, Y, h, a, t = (float(v) for v in row)
        # the paper's X is north, Y east: world (east, north) = (Y, X)
        assert b.position_m == (Y, X) and b.height_m == h
        # "0.1524" in a column headed (10^-3 deg) is 0.0001524 deg
        assert b.pan_deg == pytest.approx(a * 1e-3, rel=1e-15)
        assert b.tilt_deg == pytest.approx(t * 1e-3, rel=1e-15)
        S = b.param_covariance()
        assert np.sqrt(S[P.PAN, P.PAN]) == pytest.approx(np.deg2rad(a * 1e-3), rel=1e-14)
        assert np.sqrt(S[P.TILT, P.TILT]) == pytest.approx(np.deg2rad(t * 1e-3), rel=1e-14)
    # pinned: Basler1 pan 0.1524e-3 deg = 0.1524e-3 * pi / 180 rad = 2.6599e-6 rad
    S = ErrorBudget.preset("basler1").param_covariance()
    assert np.sqrt(S[P.PAN, P.PAN]) == pytest.approx(2.65988e-6, rel=1e-5)


def test_sigma_f_is_the_rss_of_fx_and_fy_to_printed_precision():
    for name, row in TABLE2_PRINTED.items():
        fx, fy, f = (float(v) for v in row[:3])
        rss = np.hypot(fx, fy)
        # the printed f may be off by its own rounding plus what the rounding of fx and fy moves the RSS
        tol = _half_ulp(row[2]) + (fx * _half_ulp(row[0]) + fy * _half_ulp(row[1])) / rss
        assert abs(rss - f) <= tol, (name, rss, f, tol)
    assert _half_ulp("0.2768") == pytest.approx(5e-5) and _half_ulp("0.670") == pytest.approx(5e-4)


def test_preset_budget_values_and_param_covariance():
    b = ErrorBudget.preset("BW-Cube1")  # case-insensitive
    assert b.name == "bw-cube1"
    assert b.focal_px == 0.4411 and b.principal_point_px == (0.3031, 0.2437)
    assert b.distortion == (0.0004, 0.0005, 7e-5, 8e-5, 0.0005)
    assert b.imaging_px == (0.1, 0.1) and b.resolution_px == (0.01, 0.01)
    assert b.roll_deg == 0.0 and b.ground_height_m == 0.0 and b.ground_slope_deg == 0.0
    S = b.param_covariance()
    assert S.shape == (P.N_PARAMS, P.N_PARAMS)
    np.testing.assert_array_equal(S, S.T)
    assert np.linalg.eigvalsh(S).min() >= -1e-18
    # one focal error moves fx and fy together: a rank-one 2x2 block of sigma_f^2
    np.testing.assert_allclose(S[:2, :2], 0.4411**2 * np.ones((2, 2)), rtol=1e-15)
    assert S[P.CX, P.CX] == pytest.approx(0.3031**2) and S[P.K2, P.K2] == pytest.approx(0.0005**2)
    assert S[P.YM, P.YM] == pytest.approx(0.4912**2) and S[P.HM, P.HM] == pytest.approx(0.8484**2)
    assert S[P.XM, P.XM] == pytest.approx(0.1910**2)
    # pixel covariance: imaging and resolution add: 0.1^2 + 0.01^2 = 0.0101 px^2
    np.testing.assert_allclose(b.pixel_covariance(), 0.0101 * np.eye(2), rtol=1e-14)
    np.testing.assert_allclose(b.pixel_covariance(("imaging",)), 0.01 * np.eye(2), rtol=1e-14)
    assert set(b.shared_source_covariances()) == {"focal", "principal_point", "distortion", "position", "height",
                                                  "pan", "tilt"}


@pytest.mark.parametrize("d, field", [
    ({"focal_pix": 0.1}, "focal_pix"),
    ({"focal_px": -0.1}, "focal_px"),
    ({"height_m": float("nan")}, "height_m"),
    ({"pan_deg": float("inf")}, "pan_deg"),
    ({"tilt_deg": "small"}, "tilt_deg"),
    ({"roll_deg": True}, "roll_deg"),
    ({"position_m": [0.1, 0.2, 0.3]}, "position_m"),
    ({"imaging_px": [0.1, -0.1]}, "imaging_px"),
    ({"resolution_px": [0.1, float("nan")]}, "resolution_px"),
    ({"distortion": [1e-3, 1e-3]}, "distortion"),
    ({"ground_slope_deg": [1.0, 2.0]}, "ground_slope_deg"),
    ({"covariance": {"names": ["pan_deg", "tilt_deg"], "matrix": [[1.0, 2.0], [2.0, 1.0]]}}, "covariance.matrix"),
    ({"covariance": {"names": ["pan_deg"], "matrix": [[-1.0]]}}, "covariance.matrix"),
    ({"covariance": {"names": ["pan_deg", "tilt_deg"], "matrix": [[1.0, 0.5], [0.4, 1.0]]}}, "covariance.matrix"),
    ({"covariance": {"names": ["pan_deg", "tilt_deg"], "matrix": [[1.0, 0.0]]}}, "covariance.matrix"),
    ({"covariance": {"names": ["pan_deg"], "matrix": [[float("nan")]]}}, "covariance.matrix"),
    ({"covariance": {"names": ["yaw_deg"], "matrix": [[1.0]]}}, "covariance.names"),
    ({"covariance": {"names": ["pan_deg", "pan_rad"], "matrix": np.eye(2).tolist()}}, "covariance.names"),
    ({"covariance": {"names": ["x_m", "x_m"], "matrix": np.eye(2).tolist()}}, "covariance.names"),
    ({"covariance": [[1.0]]}, "covariance"),
])
def test_from_dict_validation_names_the_field(d, field):
    with pytest.raises(ConfigError) as ei:
        ErrorBudget.from_dict(d)
    assert ei.value.field.startswith(field), ei.value.field
    assert "\n" not in str(ei.value)
    with pytest.raises(ConfigError) as ei:
        ErrorBudget.from_dict(d, where="site.yaml")
    assert ei.value.field.startswith("site.yaml: " + field)


def test_direct_construction_is_validated():
    with pytest.raises(ConfigError, match="height_m"):
        ErrorBudget(height_m=-1.0)
    with pytest.raises(ConfigError, match="imaging_px"):
        ErrorBudget(imaging_px=(0.1, float("nan")))
    with pytest.raises(ConfigError, match="covariance"):
        ErrorBudget(covariance_names=("pan_rad",), covariance_matrix=np.eye(2))


def test_full_covariance_override_with_degree_aliases():
    cov_deg2 = [[0.04, 0.01], [0.01, 0.09]]  # deg^2: sigma pan 0.2 deg, sigma tilt 0.3 deg, correlation 1/6
    b = ErrorBudget.from_dict({"pan_deg": 5.0, "tilt_deg": 5.0, "height_m": 0.1,
                               "covariance": {"names": ["pan_deg", "tilt_deg"], "matrix": cov_deg2}})
    assert b.covariance_names == ("pan_rad", "tilt_rad")
    S = b.param_covariance()
    idx = [P.PAN, P.TILT]
    np.testing.assert_allclose(S[np.ix_(idx, idx)], np.array(cov_deg2) * (np.pi / 180) ** 2, rtol=1e-15)
    assert S[P.HM, P.HM] == pytest.approx(0.01)  # untouched
    # the matrix replaces the sigmas: the 5 deg never appears
    assert S[P.PAN, P.PAN] < 1e-4
    # radians are taken as they are; other parameters in the same matrix couple to them
    b = ErrorBudget.from_dict({"focal_px": 0.3, "covariance": {
        "names": ["fx_px", "height_m"], "matrix": [[0.25, 0.01], [0.01, 0.04]]}})
    S = b.param_covariance()
    assert S[P.FX, P.FX] == 0.25 and S[P.FX, P.HM] == 0.01 and S[P.HM, P.HM] == 0.04
    assert S[P.FX, P.FY] == 0.0 and S[P.FY, P.FY] == pytest.approx(0.09)
    # round trip through to_dict keeps the matrix (now in radians)
    b2 = ErrorBudget.from_dict(b.to_dict())
    np.testing.assert_array_equal(b2.param_covariance(), S)
    assert b2 == b and hash(b2) == hash(b)
    # equality sees the matrix (it once compared only the sigmas)
    b3 = ErrorBudget.from_dict({"focal_px": 0.3, "covariance": {
        "names": ["fx_px", "height_m"], "matrix": [[0.25, 0.0], [0.0, 0.04]]}})
    assert b3 != b


def test_scaled_and_replace():
    b = ErrorBudget.preset("basler2")
    s = b.scaled(2.0)
    np.testing.assert_allclose(s.param_covariance(), 4.0 * b.param_covariance(), rtol=1e-14)
    np.testing.assert_allclose(s.pixel_covariance(), 4.0 * b.pixel_covariance(), rtol=1e-14)
    r = b.replace(ground_height_m=0.05)
    assert r.ground_height_m == 0.05 and r.focal_px == b.focal_px
    with pytest.raises(ConfigError, match="ground_height_m"):
        b.replace(ground_height_m=-0.05)


def test_load_budget_from_files_presets_and_mappings(tmp_path):
    d = {"name": "site A", "focal_px": 0.5, "principal_point_px": [0.3, 0.2], "pan_deg": 0.05,
         "ground_slope_deg": 0.5, "imaging_px": 0.2,
         "covariance": {"names": ["x_m", "y_m"], "matrix": [[0.01, 0.002], [0.002, 0.04]]}}
    yaml_path = tmp_path / "budget.yaml"
    yaml_path.write_text(
        "name: site A\nfocal_px: 0.5\nprincipal_point_px: [0.3, 0.2]\npan_deg: 0.05\nground_slope_deg: 0.5\n"
        "imaging_px: 0.2\ncovariance:\n  names: [x_m, y_m]\n  matrix: [[0.01, 0.002], [0.002, 0.04]]\n")
    json_path = tmp_path / "budget.json"
    json_path.write_text(json.dumps(d))
    ref = ErrorBudget.from_dict(d)
    assert ref.imaging_px == (0.2, 0.2)  # a scalar for a pair applies to both
    for spec in (yaml_path, str(yaml_path), json_path, d, ref):
        b = load_budget(spec)
        assert b == ref
        np.testing.assert_array_equal(b.param_covariance(), ref.param_covariance())
    assert load_budget("basler1") == ErrorBudget.preset("basler1")
    assert load_budget(" Basler1 ") == ErrorBudget.preset("basler1")
    with pytest.raises(ConfigError, match="preset"):
        load_budget("basler7")
    with pytest.raises(ConfigError, match="budget preset"):
        ErrorBudget.preset("basler7")
    bad = tmp_path / "bad.yaml"
    bad.write_text("focal_px: 0.5\nfocal_pixel: 0.3\n")
    with pytest.raises(ConfigError) as ei:
        load_budget(bad)
    assert ei.value.field == f"{bad}: focal_pixel"
    broken = tmp_path / "broken.json"
    broken.write_text("{focal_px: ")
    with pytest.raises(ConfigError) as ei:
        load_budget(broken)
    assert ei.value.field == str(broken)
    notamap = tmp_path / "list.yaml"
    notamap.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError):
        load_budget(notamap)


def test_ground_slope_model_reproduces_sigma_z_of_distance():
    """sigma_z(d)^2 = sigma_z0^2 + (d tan sigma_slope)^2 enters as sigma_z(d)^2 (dxy/dz)(dxy/dz)^T."""
    sigma_z0, slope_deg = 0.05, 0.8
    b = ErrorBudget.from_dict({"ground_height_m": sigma_z0, "ground_slope_deg": slope_deg})
    cam = PanTiltCamera(1400.0, (1920, 1080), 9.0, 60.0, 12.0, 2.0, (4.0, -7.0))
    uv = np.stack(np.meshgrid(np.linspace(50, 1870, 7), np.linspace(300, 1060, 5)), -1).reshape(-1, 2)
    est = propagate(cam, b, uv, breakdown=True)
    assert est.valid.all()
    bp = cam.backproject(uv, get_gradients=True)
    d = np.linalg.norm(est.xy_world_m - np.array(cam.position_m), axis=-1)
    assert d.min() < 30 and d.max() > 100  # near and far points
    j = bp.dxy_dp[..., P.GDZ]  # d xy / d (ground height at the point)
    expect = sigma_ground_z(d, sigma_z0, slope_deg)[:, None, None] ** 2 * (j[:, :, None] * j[:, None, :])
    ground = est.contributions["ground_height"] + est.contributions["ground_slope"]
    np.testing.assert_allclose(ground, expect, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(est.cov_m2, expect, rtol=1e-12, atol=1e-18)
    # hand check of sigma_z: 0.8 deg = 0.0139626 rad, tan = x + x^3/3 = 0.0139635 -> 1.39635 m at 100 m;
    # with 0.05 m: sqrt(0.05^2 + 1.39635^2) = 1.39725 m
    assert sigma_ground_z(100.0, 0.05, 0.8) == pytest.approx(1.39725, rel=1e-5)
