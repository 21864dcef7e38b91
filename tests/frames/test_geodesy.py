"""Geodesy: WGS-84 closed forms, pymap3d as oracle, antimeridian/pole cases, and the flat-Earth
error against its analytic small-angle model and bound (seed 004, thesis eq. 5.1).

Hypothesis properties over the globe live in ``tests/properties/test_frames_properties.py``.
"""

from __future__ import annotations

import numpy as np
import pymap3d as pm
import pytest
from numpy.testing import assert_allclose

from pipeline.frames import geodesy as geo


def test_wgs84_constants_match_published_values():
    # NIMA TR8350.2 Table 3.3
    assert geo.WGS84_B == pytest.approx(6356752.3142, abs=1e-4)
    assert geo.WGS84_E2 == pytest.approx(6.69437999014e-3, rel=1e-11)
    assert geo.R_MEAN == pytest.approx(6371008.7714, abs=1e-4)  # IUGG R1
    m, n = geo.radii_of_curvature([0.0, 90.0])
    assert_allclose(m, [geo.WGS84_A * (1 - geo.WGS84_E2), geo.WGS84_A ** 2 / geo.WGS84_B], rtol=1e-15)
    assert_allclose(n, [geo.WGS84_A, geo.WGS84_A ** 2 / geo.WGS84_B], rtol=1e-15)


def test_ecef_closed_form_points():
    x, y, z = geo.geodetic_to_ecef([0.0, 0.0, 90.0, -90.0], [0.0, 90.0, 0.0, 33.0], [0.0, 10.0, 0.0, 5.0])
    assert_allclose(x, [geo.WGS84_A, 0.0, 0.0, 0.0], atol=1e-9)
    assert_allclose(y, [0.0, geo.WGS84_A + 10.0, 0.0, 0.0], atol=1e-9)
    assert_allclose(z, [0.0, 0.0, geo.WGS84_B, -geo.WGS84_B - 5.0], atol=1e-9)


def test_polar_axis_inverse_is_exact():
    # p = 0: latitude exactly ±90°, height exactly |z| - b
    lat, _, h = geo.ecef_to_geodetic(0.0, 0.0, [geo.WGS84_B + 123.0, -(geo.WGS84_B - 50.0)])
    assert_allclose(lat, [90.0, -90.0], rtol=0, atol=0)
    assert_allclose(h, [123.0, -50.0], atol=1e-9)


def test_ecef_against_pymap3d(rng):
    lat = rng.uniform(-90, 90, 2000)
    lon = rng.uniform(-180, 180, 2000)
    h = rng.uniform(-500, 30000, 2000)
    ours = geo.geodetic_to_ecef(lat, lon, h)
    assert_allclose(np.stack(ours), np.stack(pm.geodetic2ecef(lat, lon, h)), rtol=0, atol=1e-8)
    lat2, lon2, h2 = geo.ecef_to_geodetic(*ours)
    # the inverse is exact to a few ULP of |x| ~ 6.4e6 m (1 ULP = 0.93 nm)
    back = np.stack(geo.geodetic_to_ecef(lat2, lon2, h2))
    assert np.max(np.abs(back - np.stack(ours))) < 1e-8
    assert np.max(np.abs(h2 - h)) < 1e-8


def test_points_along_the_local_axes():
    lat0, lon0, h0 = 45.5, -73.6, 30.0
    n, e, d = geo.geodetic_to_ned(lat0, lon0, h0 + 100.0, lat0, lon0, h0)
    assert_allclose([n, e, d], [0.0, 0.0, -100.0], atol=1e-9)
    # 1e-5 deg north of the origin: north by M*dφ, the same height sits below the tangent plane
    m, _ = geo.radii_of_curvature(lat0)
    n, e, d = geo.geodetic_to_ned(lat0 + 1e-5, lon0, h0, lat0, lon0, h0)
    assert n == pytest.approx((m + h0) * np.radians(1e-5), rel=1e-6)
    assert abs(e) < 1e-9 and d > 0


def test_geodetic_to_ned_against_pymap3d_grid():
    # a fixed grid incl. poles and the antimeridian; the hypothesis version roams freely
    lat0 = np.array([-90.0, -60.0, 0.0, 45.5, 89.999, 90.0])[:, None]
    lon0 = np.array([-180.0, -73.6, 0.0, 120.0, 179.9999, 180.0])[:, None]
    az = np.linspace(0, 360, 13)[None, :]
    for rng_m, tol in ((1e4, 1e-3), (1e5, 1e-2)):
        lat, lon, h = pm.aer2geodetic(az, 1.0, rng_m, lat0, lon0, 50.0)
        ours = np.stack(geo.geodetic_to_ned(lat, lon, h, lat0, lon0, 50.0))
        ref = np.stack(pm.geodetic2ned(lat, lon, h, lat0, lon0, 50.0))
        assert np.max(np.abs(ours - ref)) < tol
        assert np.max(np.abs(ours - ref)) < 1e-7  # in fact agreement is at nanometre level


def test_antimeridian_track_is_continuous():
    lon = np.linspace(179.99, 180.01, 201)
    lon = np.where(lon > 180.0, lon - 360.0, lon)  # as a GPS reports it
    for method in ("wgs84", "flat"):
        n, e, d = geo.geodetic_to_ned(10.0, lon, 0.0, 10.0, 179.99, 0.0, method=method)
        de = np.diff(e)
        assert np.all(de > 0)
        assert np.ptp(de) < 1e-6 * de.mean()
        lat2, lon2, _ = geo.ned_to_geodetic(n, e, d, 10.0, 179.99, 0.0, method=method)
        assert np.all((lon2 > -180.0) & (lon2 <= 180.0))
        assert np.max(np.abs(geo.wrap_deg(lon2 - lon))) < 1e-9


def test_bad_method_is_rejected():
    with pytest.raises(ValueError, match="method"):
        geo.geodetic_to_ned(0, 0, 0, 0, 0, 0, method="sphere")


def test_wrap_deg():
    assert_allclose(geo.wrap_deg([-540.0, -180.0, -179.0, 0.0, 180.0, 181.0, 540.0]),
                    [180.0, 180.0, -179.0, 0.0, 180.0, -179.0, 180.0])


# --- flat Earth (seed 004, thesis eq. 5.1) -----------------------------------------------------

def test_flat_earth_is_the_thesis_formula():
    lat, lon, h = 45.51, -73.58, 40.0
    lat0, lon0, h0 = 45.50, -73.60, 25.0
    n, e, d = geo.geodetic_to_ned(lat, lon, h, lat0, lon0, h0, method="flat", radius_m=6.371e6)
    assert n == pytest.approx(6.371e6 * np.radians(0.01), rel=1e-12)
    assert e == pytest.approx(6.371e6 * np.cos(np.radians(lat)) * np.radians(0.02), rel=1e-9)
    assert d == pytest.approx(-15.0, abs=1e-12)
    back = geo.ned_to_geodetic(n, e, d, lat0, lon0, h0, method="flat", radius_m=6.371e6)
    assert_allclose(back, (lat, lon, h), rtol=0, atol=1e-11)


@pytest.mark.parametrize("lat0", [0.0, 30.0, 45.5, 60.0, 75.0])
@pytest.mark.parametrize("range_m", [1e3, 1e4, 1e5])
def test_flat_earth_error_matches_small_angle_model(lat0, range_m):
    bearing = np.arange(0.0, 360.0, 5.0)
    en, ee, ed, n, e = geo.flat_earth_error(range_m, bearing, lat0, 17.0, 200.0)
    pn, pe, pd = geo.flat_earth_error_model(n, e, lat0, 200.0)
    # the neglected terms are third order: relative residual O(s/R)(1 + tan²φ0)
    s_over_r = range_m / geo.R_MEAN
    tol = 0.5 * s_over_r * (1.0 + np.tan(np.radians(lat0)) ** 2)
    scale = np.max(np.hypot(en, ee))
    assert np.max(np.hypot(en - pn, ee - pe)) <= tol * scale
    assert np.max(np.abs(ed - pd)) <= 0.01 * s_over_r * np.max(np.abs(ed))
    # worst case over bearing vs the analytic bound: below it (up to the third-order remainder)
    # and no more than a factor 1.6 below it (the bound combines maxima at different bearings)
    hb, vb = geo.flat_earth_error_bound(range_m, lat0, 200.0)
    h_meas, v_meas = np.max(np.hypot(en, ee)), np.max(np.abs(ed))
    assert hb / 1.6 <= h_meas <= hb * (1.0 + tol)
    # vertical: the bound is attained (bearing north); third-order terms are ~e²·s/R relative,
    # and the level test point's horizontal range falls short of s by ~s³/(2R²)
    vtol = 0.01 * s_over_r + 2.0 * s_over_r**2
    assert vb * (1.0 - vtol) <= v_meas <= vb * (1.0 + vtol)


def test_flat_earth_error_headline_numbers():
    # Montreal (the thesis's Stinger Dome), bearing east: first-order scale error r/N - 1,
    # then the s² tanφ/(2N) convergence term; vertical s²/(2N) drop
    lat0 = 45.5
    m, nn = geo.radii_of_curvature(lat0)
    en, ee, ed, _, _ = geo.flat_earth_error(np.array([1e3, 1e4, 1e5]), 90.0, lat0)
    # (third-order terms, ~s³/(6R²), are 1e-6 / 1e-4 / 3e-2 of the east error at 1 / 10 / 100 km)
    first_order = (geo.R_MEAN / nn - 1.0) * np.array([1e3, 1e4, 1e5])
    assert np.all(np.abs(ee / first_order - 1.0) < [1e-5, 1e-3, 4e-2])
    assert_allclose(en, -np.tan(np.radians(lat0)) * np.array([1e3, 1e4, 1e5]) ** 2 / (2 * nn), rtol=2e-2)
    assert_allclose(-ed, np.array([1e3, 1e4, 1e5]) ** 2 / (2 * nn), rtol=1e-3)
    # sanity of magnitudes quoted in the report: ~2.8 m at 1 km, ~0.8 km at 100 km
    assert 2.0 < np.hypot(en[0], ee[0]) < 4.0
    assert 700.0 < np.hypot(en[2], ee[2]) < 1000.0


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18, reason="needs 80-bit long double as oracle")
def test_ecef_to_geodetic_against_extended_precision(rng):
    # forward map in 80-bit arithmetic, rounded once to float64; our float64 inverse must recover
    # the point to a few nm (the rounding of the input alone is ~0.5 nm per coordinate)
    n = 20000
    lat = np.concatenate([[90.0, -90.0, 0.0], rng.uniform(89.999, 90.0, 100), rng.uniform(-90, 90, n)])
    lon = rng.uniform(-180, 180, lat.size)
    h = rng.uniform(-1e4, 1e5, lat.size)
    ld = np.longdouble
    phi, lam, hh = np.radians(lat.astype(ld)), np.radians(lon.astype(ld)), h.astype(ld)
    f = ld(1) / ld("298.257223563")
    e2 = f * (2 - f)
    nn = ld(geo.WGS84_A) / np.sqrt(1 - e2 * np.sin(phi) ** 2)
    xyz = [(nn + hh) * np.cos(phi) * np.cos(lam), (nn + hh) * np.cos(phi) * np.sin(lam),
           (nn * (1 - e2) + hh) * np.sin(phi)]
    lat2, _, h2 = geo.ecef_to_geodetic(*(c.astype(np.float64) for c in xyz))
    m, _ = geo.radii_of_curvature(lat)
    assert np.max(np.abs(h2 - h)) < 5e-9
    assert np.max(np.abs(np.radians(lat2 - lat) * m)) < 5e-9


def test_nan_input_propagates_without_warning():
    # a missing GPS fix stays missing (filterwarnings=error would turn a RuntimeWarning into a failure)
    assert np.all(np.isnan(geo.geodetic_to_ned(np.nan, 0.0, 0.0, 45.0, 0.0, 0.0)))
    lat, _, h = geo.ned_to_geodetic(np.nan, 0.0, 0.0, 45.0, 0.0, 0.0)
    assert np.isnan(lat) and np.isnan(h)
