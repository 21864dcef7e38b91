"""Hypothesis properties of ``pipeline.frames``: rotation round trips to 1e-12 and WGS-84
geodesy over the whole globe (poles and the antimeridian included), with pymap3d as oracle.

Derandomised so a run is reproducible; the example counts are modest to keep the file < ~15 s.
"""

from __future__ import annotations

import numpy as np
import pymap3d as pm
from hypothesis import given, settings, strategies as st

from pipeline.frames import geodesy as geo
from pipeline.frames import rotations as rot

SETTINGS = settings(max_examples=200, deadline=None, derandomize=True)

finite = dict(allow_nan=False, allow_infinity=False)
quats = (st.tuples(*[st.floats(-1.0, 1.0, **finite)] * 4)
         .map(np.array)
         .filter(lambda q: np.linalg.norm(q) > 1e-3)
         .map(lambda q: q / np.linalg.norm(q)))
angles = st.floats(-np.pi, np.pi, **finite)
pitches = st.floats(-np.radians(89.9), np.radians(89.9), **finite)
vectors = st.tuples(*[st.floats(-1e3, 1e3, **finite)] * 3).map(np.array)

# the globe, with extra weight on the poles and the antimeridian
lats = st.one_of(st.floats(-90.0, 90.0, **finite), st.floats(89.0, 90.0), st.floats(-90.0, -89.0),
                 st.sampled_from([-90.0, 90.0, 0.0]))
lons = st.one_of(st.floats(-180.0, 180.0, **finite), st.floats(179.0, 180.0), st.floats(-180.0, -179.0),
                 st.sampled_from([-180.0, 180.0, 0.0]))
heights = st.floats(-500.0, 10_000.0, **finite)
bearings = st.floats(0.0, 360.0, **finite)


def _angle_diff(a, b):
    """a − b wrapped to (−π, π]."""
    return np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))


# --- rotations -------------------------------------------------------------------------------

@SETTINGS
@given(quats)
def test_quat_dcm_quat_round_trip(q):
    r = rot.quat_to_dcm(q)
    assert np.max(np.abs(r @ r.T - np.eye(3))) < 1e-14
    assert abs(np.linalg.det(r) - 1.0) < 1e-14
    back = rot.dcm_to_quat(r)
    assert back[0] >= 0.0
    assert np.max(np.abs(back - np.sign(back @ q) * q)) < 1e-12  # equal up to sign


@SETTINGS
@given(angles, pitches, angles)
def test_euler_quat_euler_round_trip(roll, pitch, yaw):
    r2, p2, y2 = rot.quat_to_euler(rot.euler_to_quat(roll, pitch, yaw))
    assert abs(p2 - pitch) < 1e-12
    assert abs(_angle_diff(r2, roll)) < 1e-12
    assert abs(_angle_diff(y2, yaw)) < 1e-12
    r3, p3, y3 = rot.dcm_to_euler(rot.euler_to_dcm(roll, pitch, yaw))
    assert abs(p3 - pitch) < 1e-12
    assert abs(_angle_diff(r3, roll)) < 1e-12
    assert abs(_angle_diff(y3, yaw)) < 1e-12


@SETTINGS
@given(quats)
def test_quat_euler_quat_round_trip(q):
    # every attitude, gimbal lock included: q -> Euler -> q is the same rotation
    back = rot.euler_to_quat(*rot.quat_to_euler(q))
    assert abs(abs(back @ q) - 1.0) < 1e-12


@SETTINGS
@given(quats, quats, vectors)
def test_composition_and_inverse(p, q, v):
    pq = rot.quat_multiply(p, q)
    assert np.allclose(rot.quat_to_dcm(pq), rot.quat_to_dcm(p) @ rot.quat_to_dcm(q), atol=1e-14, rtol=0)
    assert np.allclose(rot.quat_rotate(pq, v), rot.quat_rotate(p, rot.quat_rotate(q, v)), atol=1e-11, rtol=0)
    assert np.allclose(rot.quat_rotate_inverse(q, rot.quat_rotate(q, v)), v, atol=1e-11, rtol=0)
    assert np.allclose(rot.quat_multiply(q, rot.quat_conj(q)), [1, 0, 0, 0], atol=1e-15, rtol=0)


@SETTINGS
@given(quats, vectors)
def test_ros_orientation_conversion_is_consistent(q_enu_flu, v_flu):
    q_ned_frd = rot.quat_enu_flu_to_ned_frd(q_enu_flu)
    # rotating the FRD-expressed body vector into NED == rotating in ROS frames, then ENU -> NED
    lhs = rot.quat_rotate(q_ned_frd, rot.flu_to_frd(v_flu))
    rhs = rot.enu_to_ned(rot.quat_rotate(q_enu_flu, v_flu))
    assert np.allclose(lhs, rhs, atol=1e-11, rtol=0)
    back = rot.quat_ned_frd_to_enu_flu(q_ned_frd)
    assert abs(abs(back @ q_enu_flu) - 1.0) < 1e-12
    assert np.allclose(rot.ned_to_enu(rot.enu_to_ned(v_flu)), v_flu, rtol=0, atol=0)
    assert np.allclose(rot.frd_to_flu(rot.flu_to_frd(v_flu)), v_flu, rtol=0, atol=0)


@SETTINGS
@given(angles, st.floats(-np.radians(89.0), np.radians(89.0)), angles)
def test_ros_rpy_maps_to_ned_rpy(roll, pitch, yaw):
    # REP 103 ZYX angles (r, p, y) in ENU/FLU are (r, -p, 90° - y) in NED/FRD
    q = rot.quat_enu_flu_to_ned_frd(rot.euler_to_quat(roll, pitch, yaw))
    r2, p2, y2 = rot.quat_to_euler(q)
    assert abs(_angle_diff(r2, roll)) < 1e-11
    assert abs(p2 + pitch) < 1e-12
    assert abs(_angle_diff(y2, np.pi / 2 - yaw)) < 1e-11


@SETTINGS
@given(quats, quats, st.floats(0.0, 1.0))
def test_slerp_constant_angular_rate_on_shortest_arc(q0, q1, t):
    qt = rot.quat_slerp(q0, q1, t)
    assert abs(np.linalg.norm(qt) - 1.0) < 1e-14
    # rotation angle from q0 is t times the (shortest) total angle
    total = 2.0 * np.arccos(min(1.0, abs(q0 @ q1)))
    part = 2.0 * np.arccos(min(1.0, abs(q0 @ qt)))
    assert total <= np.pi + 1e-12
    assert abs(part - t * total) < 1e-6  # arccos near 1 limits this check, not slerp
    rest = 2.0 * np.arccos(min(1.0, abs(qt @ q1)))
    assert abs(part + rest - total) < 1e-6  # on the great arc between the end points


# --- geodesy ---------------------------------------------------------------------------------

@SETTINGS
@given(lats, lons, st.floats(-10_000.0, 1e7, **finite))
def test_geodetic_ecef_round_trip(lat, lon, h):
    x, y, z = geo.geodetic_to_ecef(lat, lon, h)
    lat2, lon2, h2 = geo.ecef_to_geodetic(x, y, z)
    # exact to a few ULP of |x| (1 ULP at 6.4e6 m is 0.93 nm; at 1.6e7 m 1.9 nm)
    assert abs(h2 - h) < 1e-8
    assert abs(lat2 - lat) * 111e3 < 1e-8
    assert -180.0 < lon2 <= 180.0
    back = np.array(geo.geodetic_to_ecef(lat2, lon2, h2))
    assert np.max(np.abs(back - np.array([x, y, z]))) < 1e-8


@SETTINGS
@given(lats, lons, heights, bearings, st.floats(0.0, 10_000.0), st.floats(-1_000.0, 1_000.0))
def test_lla_to_ned_agrees_with_pymap3d_10km(lat0, lon0, h0, bearing, rng_m, d_m):
    n, e = rng_m * np.cos(np.radians(bearing)), rng_m * np.sin(np.radians(bearing))
    lat, lon, h = pm.ned2geodetic(n, e, d_m, lat0, lon0, h0)
    ours = np.array(geo.geodetic_to_ned(lat, lon, h, lat0, lon0, h0))
    ref = np.array(pm.geodetic2ned(lat, lon, h, lat0, lon0, h0))
    assert np.max(np.abs(ours - ref)) < 1e-7  # both exact; measured worst ~4 nm


@SETTINGS
@given(lats, lons, heights, bearings, st.floats(10_000.0, 100_000.0), st.floats(-1_000.0, 1_000.0))
def test_lla_to_ned_agrees_with_pymap3d_100km(lat0, lon0, h0, bearing, rng_m, d_m):
    n, e = rng_m * np.cos(np.radians(bearing)), rng_m * np.sin(np.radians(bearing))
    lat, lon, h = pm.ned2geodetic(n, e, d_m, lat0, lon0, h0)
    ours = np.array(geo.geodetic_to_ned(lat, lon, h, lat0, lon0, h0))
    ref = np.array(pm.geodetic2ned(lat, lon, h, lat0, lon0, h0))
    assert np.max(np.abs(ours - ref)) < 1e-7  # both exact; measured worst ~4 nm


@SETTINGS
@given(lats, lons, heights, bearings, st.floats(0.0, 100_000.0), st.floats(-10_000.0, 1_000.0))
def test_ned_lla_ned_round_trip(lat0, lon0, h0, bearing, rng_m, d_m):
    ned = np.array([rng_m * np.cos(np.radians(bearing)), rng_m * np.sin(np.radians(bearing)), d_m])
    lat, lon, h = geo.ned_to_geodetic(*ned, lat0, lon0, h0)
    assert -90.0 <= lat <= 90.0 and -180.0 < lon <= 180.0
    back = np.array(geo.geodetic_to_ned(lat, lon, h, lat0, lon0, h0))
    assert np.max(np.abs(back - ned)) < 1e-7  # exact to a few ULP of the ECEF coordinates


@SETTINGS
@given(st.floats(-80.0, 80.0), lons, heights, bearings, st.floats(0.0, 100_000.0), st.floats(-1_000.0, 1_000.0))
def test_flat_earth_round_trip_and_continuity(lat0, lon0, h0, bearing, rng_m, d_m):
    ned = np.array([rng_m * np.cos(np.radians(bearing)), rng_m * np.sin(np.radians(bearing)), d_m])
    lat, lon, h = geo.ned_to_geodetic(*ned, lat0, lon0, h0, method="flat")
    assert -180.0 < lon <= 180.0
    back = np.array(geo.geodetic_to_ned(lat, lon, h, lat0, lon0, h0, method="flat"))
    assert np.max(np.abs(back - ned)) < 1e-6
    # the flat and exact conversions agree to the analytic bound (third-order slack)
    exact = np.array(geo.geodetic_to_ned(lat, lon, h0, lat0, lon0, h0))
    flat = np.array(geo.geodetic_to_ned(lat, lon, h0, lat0, lon0, h0, method="flat"))
    hb, vb = geo.flat_earth_error_bound(np.hypot(exact[0], exact[1]), lat0, h0)
    slack = 1.0 + 3.0 * rng_m / geo.R_MEAN * (1.0 + np.tan(np.radians(lat0)) ** 2)
    assert np.hypot(*(flat - exact)[:2]) <= hb * slack + 1e-8  # + float noise of ~1 ULP(6e6 m)
    assert abs(flat[2] - exact[2]) <= vb * slack + 1e-8
