"""WGS-84 geodesy: geodetic (lat, lon, h) <-> ECEF <-> local NED, exact, plus seed 004's flat Earth.

Every conversion between GPS fixes and the pipeline's local NED frame goes through this module
(readers, the simulator, preprocessing). Two methods are offered:

``method="wgs84"`` (default, exact)
    geodetic -> ECEF (closed form) -> rotation into the NED axes at the origin; the inverse runs
    NED -> ECEF -> geodetic with Bowring's iteration on the reduced latitude, iterated to a fixed
    point everywhere including the poles and the polar axis. The result is exact up to floating
    point at any range: against an 80-bit forward computation the inverse is within 2.5 nm in
    height and 1.6 nm in latitude (the spacing of float64 latitudes in degrees is itself 1.6 nm
    near ±90°). Points across the antimeridian are continuous because no longitude difference
    is ever formed.

``method="flat"`` (seed 004, thesis eq. 5.1)
    .. math::

        n = r(\\varphi - \\varphi'), \\quad e = r\\cos\\varphi\\,(\\lambda - \\lambda'), \\quad
        d = -(h - h')

    with ``r`` the mean Earth radius (the thesis leaves its value open; we use the IUGG mean
    radius ``R1 = (2a + b)/3``) and ``φ`` the latitude of the *point*, not of the origin. Its
    error against the exact conversion is derived in :func:`flat_earth_error_model` and
    measured by :func:`flat_earth_error` (``tests/frames/test_geodesy.py`` holds both).

Angles are in degrees at the public interface (``_deg`` columns of the canonical schema), heights
are ellipsoidal (WGS-84) in metres. All functions broadcast over NumPy arrays. This module depends
on NumPy only (pymap3d is the test oracle, never imported here).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]
Method = Literal["wgs84", "flat"]

#: WGS-84 semi-major axis (m) and flattening (NIMA TR8350.2).
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
#: semi-minor axis (m), first and second eccentricity squared
WGS84_B = WGS84_A * (1.0 - WGS84_F)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)
#: IUGG mean Earth radius R1 = (2a + b) / 3 (m), the default ``r`` of the flat-Earth formula
R_MEAN = (2.0 * WGS84_A + WGS84_B) / 3.0

_MAX_BOWRING_ITER = 8


def _f64(*xs: ArrayLike) -> tuple[F64, ...]:
    return tuple(np.asarray(x, dtype=np.float64) for x in xs)


def radii_of_curvature(lat_deg: ArrayLike) -> tuple[F64, F64]:
    """Meridian and prime-vertical radii of curvature of the WGS-84 ellipsoid.

    .. math::

        N(\\varphi) = \\frac{a}{\\sqrt{1 - e^2\\sin^2\\varphi}}, \\qquad
        M(\\varphi) = \\frac{a(1 - e^2)}{(1 - e^2\\sin^2\\varphi)^{3/2}}

    Parameters
    ----------
    lat_deg : array-like
        Geodetic latitude (deg).

    Returns
    -------
    m_m, n_m : ndarray
        Meridian radius ``M`` and prime-vertical radius ``N`` (m).
    """
    s = np.sin(np.radians(np.asarray(lat_deg, dtype=np.float64)))
    w2 = 1.0 - WGS84_E2 * s * s
    n = WGS84_A / np.sqrt(w2)
    return n * (1.0 - WGS84_E2) / w2, n


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike,
                     h_m: ArrayLike) -> tuple[F64, F64, F64]:
    """WGS-84 geodetic coordinates to Earth-centred, Earth-fixed (ECEF) Cartesian coordinates.

    .. math::

        x = (N + h)\\cos\\varphi\\cos\\lambda, \\quad y = (N + h)\\cos\\varphi\\sin\\lambda, \\quad
        z = (N(1 - e^2) + h)\\sin\\varphi

    Parameters
    ----------
    lat_deg, lon_deg : array-like
        Geodetic latitude and longitude (deg); broadcast together with ``h_m``.
    h_m : array-like
        Ellipsoidal height (m).

    Returns
    -------
    x_m, y_m, z_m : ndarray
        ECEF coordinates (m).
    """
    lat, lon, h = _f64(lat_deg, lon_deg, h_m)
    phi, lam = np.radians(lat), np.radians(lon)
    sphi, cphi = np.sin(phi), np.cos(phi)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * sphi * sphi)
    return ((n + h) * cphi * np.cos(lam), (n + h) * cphi * np.sin(lam),
            (n * (1.0 - WGS84_E2) + h) * sphi)


def ecef_to_geodetic(x_m: ArrayLike, y_m: ArrayLike, z_m: ArrayLike) -> tuple[F64, F64, F64]:
    """ECEF coordinates to WGS-84 geodetic latitude, longitude (deg) and ellipsoidal height (m).

    Bowring's (1976) iteration on the reduced latitude ``β``, started from ``tan β₀ = z / ((1−f)p)``:

    .. math::

        \\tan\\varphi = \\frac{z + e'^2 b \\sin^3\\beta}{p - e^2 a \\cos^3\\beta}, \\qquad
        \\tan\\beta = (1 - f)\\tan\\varphi, \\qquad p = \\sqrt{x^2 + y^2}

    written with ``atan2`` so that the polar axis (``p = 0``) gives ``φ = ±90°`` exactly. One step
    is already accurate to ~2e-15 rad for terrestrial heights; the loop stops at the fixed point
    (2-3 steps; at most 8), which is exact to rounding for any point outside the ellipsoid's
    evolute (tested from −10 km to +10 000 km height). The height uses the form that is well
    conditioned at every latitude:

    .. math:: h = p\\cos\\varphi + z\\sin\\varphi - a\\sqrt{1 - e^2\\sin^2\\varphi}

    Parameters
    ----------
    x_m, y_m, z_m : array-like
        ECEF coordinates (m), broadcast together.

    Returns
    -------
    lat_deg, lon_deg, h_m : ndarray
        Geodetic latitude in [−90, 90], longitude in (−180, 180] (0 on the polar axis), height (m).
    """
    x, y, z = _f64(x_m, y_m, z_m)
    x, y, z = np.broadcast_arrays(x, y, z)
    p = np.hypot(x, y)
    beta = np.arctan2(z, (1.0 - WGS84_F) * p)
    phi = np.zeros_like(beta)
    for _ in range(_MAX_BOWRING_ITER):
        sb, cb = np.sin(beta), np.cos(beta)
        phi_new = np.arctan2(z + WGS84_EP2 * WGS84_B * sb**3, p - WGS84_E2 * WGS84_A * cb**3)
        beta = np.arctan2((1.0 - WGS84_F) * np.sin(phi_new), np.cos(phi_new))
        done = np.all(np.abs(phi_new - phi) <= 1e-15)
        phi = phi_new
        if done:
            break
    sphi, cphi = np.sin(phi), np.cos(phi)
    h = p * cphi + z * sphi - WGS84_A * np.sqrt(1.0 - WGS84_E2 * sphi * sphi)
    lon = np.degrees(np.arctan2(y, x))
    return np.degrees(phi), np.where(lon == -180.0, 180.0, lon), h


def _ned_axes(lat0_deg: ArrayLike, lon0_deg: ArrayLike) -> F64:
    """Rows are the north, east, down unit vectors at the origin, in ECEF: ``R_ned_ecef``."""
    phi, lam = (np.radians(a) for a in _f64(lat0_deg, lon0_deg))
    sp, cp, sl, cl = np.sin(phi), np.cos(phi), np.sin(lam), np.cos(lam)
    z = np.zeros_like(sp + sl)
    return np.stack([
        np.stack([-sp * cl, -sp * sl, cp + z], -1),
        np.stack([-sl + z, cl + z, z], -1),
        np.stack([-cp * cl, -cp * sl, -sp + z], -1),
    ], -2)


def ecef_to_ned(x_m: ArrayLike, y_m: ArrayLike, z_m: ArrayLike,
                lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike) -> tuple[F64, F64, F64]:
    """ECEF point(s) to local NED about a geodetic origin.

    .. math::

        \\begin{bmatrix} n \\\\ e \\\\ d \\end{bmatrix} =
        \\begin{bmatrix}
        -\\sin\\varphi_0\\cos\\lambda_0 & -\\sin\\varphi_0\\sin\\lambda_0 & \\cos\\varphi_0 \\\\
        -\\sin\\lambda_0 & \\cos\\lambda_0 & 0 \\\\
        -\\cos\\varphi_0\\cos\\lambda_0 & -\\cos\\varphi_0\\sin\\lambda_0 & -\\sin\\varphi_0
        \\end{bmatrix} (\\mathbf{x} - \\mathbf{x}_0)

    Parameters
    ----------
    x_m, y_m, z_m : array-like
        ECEF coordinates (m).
    lat0_deg, lon0_deg, h0_m : array-like
        NED origin (deg, deg, m ellipsoidal).

    Returns
    -------
    n_m, e_m, d_m : ndarray
    """
    x0, y0, z0 = geodetic_to_ecef(lat0_deg, lon0_deg, h0_m)
    dx = (np.stack(np.broadcast_arrays(*_f64(x_m, y_m, z_m)), -1)
          - np.stack(np.broadcast_arrays(x0, y0, z0), -1))
    ned = np.einsum("...ij,...j->...i", _ned_axes(lat0_deg, lon0_deg), dx)
    return ned[..., 0], ned[..., 1], ned[..., 2]


def ned_to_ecef(n_m: ArrayLike, e_m: ArrayLike, d_m: ArrayLike,
                lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike) -> tuple[F64, F64, F64]:
    """Local NED about a geodetic origin to ECEF (the transpose of :func:`ecef_to_ned`).

    Parameters
    ----------
    n_m, e_m, d_m : array-like
        Local NED coordinates (m).
    lat0_deg, lon0_deg, h0_m : array-like
        NED origin (deg, deg, m ellipsoidal).

    Returns
    -------
    x_m, y_m, z_m : ndarray
        ECEF coordinates (m).
    """
    x0, y0, z0 = geodetic_to_ecef(lat0_deg, lon0_deg, h0_m)
    ned = np.stack(np.broadcast_arrays(*_f64(n_m, e_m, d_m)), -1)
    dx = np.einsum("...ji,...j->...i", _ned_axes(lat0_deg, lon0_deg), ned)
    return dx[..., 0] + x0, dx[..., 1] + y0, dx[..., 2] + z0


def _check_method(method: str) -> None:
    if method not in ("wgs84", "flat"):
        raise ValueError(f"method must be 'wgs84' or 'flat', got {method!r}")


def geodetic_to_ned(lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike,
                    lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike,
                    *, method: Method = "wgs84", radius_m: float = R_MEAN) -> tuple[F64, F64, F64]:
    """WGS-84 geodetic point(s) to local NED (m) about the origin ``(lat0, lon0, h0)``.

    ``method="wgs84"`` is exact (geodetic -> ECEF -> NED, see :func:`ecef_to_ned`);
    ``method="flat"`` is seed 004's eq. 5.1 (see :func:`flat_earth_to_ned`). Both are continuous
    across the antimeridian.

    Parameters
    ----------
    lat_deg, lon_deg, h_m : array-like
        Point(s): geodetic latitude, longitude (deg), ellipsoidal height (m).
    lat0_deg, lon0_deg, h0_m : array-like
        NED origin, same units; broadcast against the points.
    method : {"wgs84", "flat"}
        Exact conversion, or the flat-Earth approximation.
    radius_m : float
        Earth radius ``r`` of the flat-Earth formula (ignored for ``"wgs84"``).

    Returns
    -------
    n_m, e_m, d_m : ndarray
        North, east, down (m).
    """
    _check_method(method)
    if method == "flat":
        return flat_earth_to_ned(lat_deg, lon_deg, h_m, lat0_deg, lon0_deg, h0_m, radius_m=radius_m)
    return ecef_to_ned(*geodetic_to_ecef(lat_deg, lon_deg, h_m), lat0_deg, lon0_deg, h0_m)


def ned_to_geodetic(n_m: ArrayLike, e_m: ArrayLike, d_m: ArrayLike,
                    lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike,
                    *, method: Method = "wgs84", radius_m: float = R_MEAN) -> tuple[F64, F64, F64]:
    """Local NED (m) about ``(lat0, lon0, h0)`` to WGS-84 geodetic; inverse of :func:`geodetic_to_ned`.

    Parameters
    ----------
    n_m, e_m, d_m : array-like
        North, east, down (m).
    lat0_deg, lon0_deg, h0_m : array-like
        NED origin (deg, deg, m ellipsoidal).
    method : {"wgs84", "flat"}
        Exact conversion (NED -> ECEF -> geodetic, :func:`ecef_to_geodetic`), or the exact
        inverse of the flat-Earth formula (:func:`ned_to_flat_earth`).
    radius_m : float
        Earth radius ``r`` of the flat-Earth formula (ignored for ``"wgs84"``).

    Returns
    -------
    lat_deg, lon_deg, h_m : ndarray
        Latitude, longitude in (−180, 180] (deg), ellipsoidal height (m).
    """
    _check_method(method)
    if method == "flat":
        return ned_to_flat_earth(n_m, e_m, d_m, lat0_deg, lon0_deg, h0_m, radius_m=radius_m)
    return ecef_to_geodetic(*ned_to_ecef(n_m, e_m, d_m, lat0_deg, lon0_deg, h0_m))


def wrap_deg(angle_deg: ArrayLike) -> F64:
    """Wrap angle(s) to (−180, 180] degrees."""
    a = np.asarray(angle_deg, dtype=np.float64)
    w = np.mod(a + 180.0, 360.0) - 180.0
    return np.where(w == -180.0, 180.0, w)


def flat_earth_to_ned(lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike,
                      lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike,
                      *, radius_m: float = R_MEAN) -> tuple[F64, F64, F64]:
    """Seed 004's flat-Earth geodetic -> NED (thesis eq. 5.1).

    .. math::

        n = r(\\varphi - \\varphi'), \\quad e = r\\cos\\varphi\\,(\\lambda - \\lambda'), \\quad
        d = -(h - h')

    The longitude difference is wrapped to (−π, π] so tracks crossing the antimeridian stay
    continuous. The error against the exact conversion is derived in
    :func:`flat_earth_error_model`.

    Parameters
    ----------
    lat_deg, lon_deg, h_m : array-like
        Point(s) (deg, deg, m).
    lat0_deg, lon0_deg, h0_m : array-like
        Origin ``(φ', λ', h')`` (deg, deg, m).
    radius_m : float
        ``r``, default the IUGG mean radius :data:`R_MEAN`.

    Returns
    -------
    n_m, e_m, d_m : ndarray
    """
    lat, lon, h, lat0, lon0, h0 = _f64(lat_deg, lon_deg, h_m, lat0_deg, lon0_deg, h0_m)
    n = radius_m * np.radians(lat - lat0)
    e = radius_m * np.cos(np.radians(lat)) * np.radians(wrap_deg(lon - lon0))
    return n, e, -(h - h0)


def ned_to_flat_earth(n_m: ArrayLike, e_m: ArrayLike, d_m: ArrayLike,
                      lat0_deg: ArrayLike, lon0_deg: ArrayLike, h0_m: ArrayLike,
                      *, radius_m: float = R_MEAN) -> tuple[F64, F64, F64]:
    """Exact inverse of :func:`flat_earth_to_ned`.

    .. math::

        \\varphi = \\varphi' + n / r, \\quad \\lambda = \\lambda' + \\frac{e}{r\\cos\\varphi}, \\quad
        h = h' - d

    Parameters
    ----------
    n_m, e_m, d_m : array-like
        Flat-Earth NED (m).
    lat0_deg, lon0_deg, h0_m : array-like
        Origin (deg, deg, m).
    radius_m : float
        ``r``, default :data:`R_MEAN`.

    Returns
    -------
    lat_deg, lon_deg, h_m : ndarray
        Longitude wrapped to (−180, 180].
    """
    n, e, d, lat0, lon0, h0 = _f64(n_m, e_m, d_m, lat0_deg, lon0_deg, h0_m)
    lat = lat0 + np.degrees(n / radius_m)
    lon = wrap_deg(lon0 + np.degrees(e / (radius_m * np.cos(np.radians(lat)))))
    return lat, lon, h0 - d



def _level_point(range_m: ArrayLike, bearing_deg: ArrayLike, lat0_deg: ArrayLike, lon0_deg: ArrayLike,
                 h0_m: ArrayLike) -> tuple[F64, F64, F64]:
    """The point at exact horizontal NED range/bearing from the origin and at the origin's height.

    The tangent-plane point ``(s cos α, s sin α, 0)`` is dropped along its own normal to
    ``h = h0``; its exact horizontal NED then differs from ``(s cos α, s sin α)`` only at third
    order (``~ s³/R²``), and every comparison below uses the point's exact NED anyway.
    """
    s, a = _f64(range_m, bearing_deg)
    lat, lon, _ = ned_to_geodetic(s * np.cos(np.radians(a)), s * np.sin(np.radians(a)), 0.0,
                                  lat0_deg, lon0_deg, h0_m)
    return lat, lon, np.broadcast_to(np.asarray(h0_m, dtype=np.float64), lat.shape)


def flat_earth_error(range_m: ArrayLike, bearing_deg: ArrayLike, lat0_deg: ArrayLike,
                     lon0_deg: ArrayLike = 0.0, h0_m: ArrayLike = 0.0,
                     *, radius_m: float = R_MEAN) -> tuple[F64, F64, F64, F64, F64]:
    """Measured error of the flat-Earth formula against the exact WGS-84 conversion.

    The test point lies at horizontal range ``s`` and bearing ``α`` from the origin and at the
    origin's ellipsoidal height (level flight), so the flat formula's ``d`` is 0 and its whole
    vertical error is the curvature drop.

    Parameters
    ----------
    range_m : array-like
        Horizontal range ``s`` (m).
    bearing_deg : array-like
        Bearing ``α`` clockwise from north (deg).
    lat0_deg, lon0_deg, h0_m : array-like
        Origin; broadcast with range and bearing.
    radius_m : float
        ``r`` of the flat formula.

    Returns
    -------
    err_n_m, err_e_m, err_d_m : ndarray
        Flat minus exact NED (m).
    n_m, e_m : ndarray
        The point's exact north and east (m), ``≈ (s cos α, s sin α)``, for use with
        :func:`flat_earth_error_model`.
    """
    lat, lon, h = _level_point(range_m, bearing_deg, lat0_deg, lon0_deg, h0_m)
    n, e, d = geodetic_to_ned(lat, lon, h, lat0_deg, lon0_deg, h0_m)
    nf, ef, df = flat_earth_to_ned(lat, lon, h, lat0_deg, lon0_deg, h0_m, radius_m=radius_m)
    return nf - n, ef - e, df - d, n, e


def flat_earth_error_model(n_m: ArrayLike, e_m: ArrayLike, lat0_deg: ArrayLike,
                           h0_m: ArrayLike = 0.0, dh_m: ArrayLike = 0.0,
                           *, radius_m: float = R_MEAN) -> tuple[F64, F64, F64]:
    """Analytic second-order (small-angle) error of the flat-Earth formula, flat minus exact.

    **Derivation.** Write the point as ``(φ0 + u, λ0 + v, h0 + w)`` and Taylor-expand its exact
    ECEF position ``P(φ, λ, h)`` about the origin, projecting onto the origin's NED axes. With
    ``M, N`` the meridian and prime-vertical radii at ``φ0`` (:func:`radii_of_curvature`),
    ``M_h = M + h0``, ``N_h = N + h0``, ``M' = dM/dφ = 3Me²sinφ0cosφ0/(1 − e²sin²φ0)`` and the
    partial derivatives ``P_φ = M_h n̂``, ``P_λ = N_h cosφ ê``, ``P_h = −d̂``,
    ``P_φφ = M' n̂ + M_h d̂``, ``P_λλ·(n̂, ê, d̂) = (N_h sinφ cosφ, 0, N_h cos²φ)``,
    ``P_φλ = −M_h sinφ ê``, ``P_φh = n̂``, ``P_λh = cosφ ê``, the exact NED is

    .. math::

        n &= M_h u + \\underbrace{\\tfrac12 M' u^2 + \\tfrac12 N_h \\sin\\varphi_0\\cos\\varphi_0\\, v^2
             + u w}_{Q_n} + O(3) \\\\
        e &= N_h \\cos\\varphi_0\\, v \\underbrace{- M_h \\sin\\varphi_0\\, u v
             + \\cos\\varphi_0\\, v w}_{Q_e} + O(3) \\\\
        d &= -w + \\tfrac12\\big(M_h u^2 + N_h \\cos^2\\varphi_0\\, v^2\\big) + O(3)

    while seed 004's formula gives ``n_f = r u``, ``e_f = r cos(φ0 + u) v =
    r cosφ0 v − r sinφ0 u v + O(3)``, ``d_f = −w``. Eliminating ``u, v`` with
    ``u = (n − Q_n)/M_h``, ``v = (e − Q_e)/(N_h cosφ0)``, with ``ρ_M = r/M_h``,
    ``ρ_N = r/N_h``:

    .. math::

        \\varepsilon_n &= n_f - n = (\\rho_M - 1)\\,n - \\rho_M\\Big(\\frac{M' n^2}{2M_h^2}
            + \\frac{\\tan\\varphi_0\\, e^2}{2N_h} + \\frac{n\\,w}{M_h}\\Big) \\\\
        \\varepsilon_e &= e_f - e = (\\rho_N - 1)\\,e + (\\rho_N - \\rho_M)\\frac{\\tan\\varphi_0\\, n e}{N_h}
            - \\rho_N \\frac{e\\,w}{N_h} \\\\
        \\varepsilon_d &= d_f - d = -\\Big(\\frac{n^2}{2M_h} + \\frac{e^2}{2N_h}\\Big)

    Reading the terms off:

    * **First order, scale.** One radius ``r`` cannot equal both ``M`` and ``N``; with the mean
      radius the relative scale error is ``r/M − 1`` north and ``r/N − 1`` east, between
      −1.1e-3 (equator, east) and +6.3e-3 (pole, north), i.e. metres at 1 km. This dominates
      horizontally up to ~10 km and is the price of the thesis's single ``r``.
    * **Second order, convergence of meridians.** A path due east along the parallel curves
      north of the tangent-plane east axis by ``s² tanφ0 / (2N)`` (783 m at 100 km, 45°).
      Using the point's own ``cos φ`` in ``e_f`` (as the thesis does) cancels the second-order
      east term up to the tiny ``ρ_N − ρ_M``.
    * **Vertical, curvature drop.** A level point sits ``s²/(2R_α)`` below the tangent plane
      (``1/R_α = cos²α/M + sin²α/N``, Euler's formula); the flat formula reports ``d = 0``.

    The neglected terms are third order, ``O(s³/R²)`` times factors ``O(1 + tan²φ0)``
    (e.g. the sphere's ``−R Δφ³/6``), so the model is faithful while ``s ≪ R cos φ0``. Measured
    over all bearings at latitudes 0-75°, the horizontal residual relative to the error is
    < 2e-5 at 1 km, < 1.4e-3 at 10 km and 0.7-2.6 % at 100 km (the test allows
    ``0.5 (s/R)(1 + tan²φ0)``); the vertical residual is < 1.2e-4 relative.

    Parameters
    ----------
    n_m, e_m : array-like
        The point's exact local north and east (m).
    lat0_deg : array-like
        Origin latitude (deg).
    h0_m : array-like
        Origin ellipsoidal height (m).
    dh_m : array-like
        Point height above the origin ``w = h − h0`` (m).
    radius_m : float
        ``r`` of the flat formula.

    Returns
    -------
    err_n_m, err_e_m, err_d_m : ndarray
        Predicted flat-minus-exact NED error (m).
    """
    n, e, lat0, h0, w = _f64(n_m, e_m, lat0_deg, h0_m, dh_m)
    m, nn = radii_of_curvature(lat0)
    mh, nh = m + h0, nn + h0
    phi = np.radians(lat0)
    sp, cp = np.sin(phi), np.cos(phi)
    dm = 3.0 * m * WGS84_E2 * sp * cp / (1.0 - WGS84_E2 * sp * sp)
    rho_m, rho_n = radius_m / mh, radius_m / nh
    tan0 = sp / cp
    q_n = dm * n * n / (2.0 * mh * mh) + tan0 * e * e / (2.0 * nh) + n * w / mh
    err_n = (rho_m - 1.0) * n - rho_m * q_n
    err_e = (rho_n - 1.0) * e + (rho_n - rho_m) * tan0 * n * e / nh - rho_n * e * w / nh
    err_d = -(n * n / (2.0 * mh) + e * e / (2.0 * nh))
    return err_n, err_e, err_d


def flat_earth_error_bound(range_m: ArrayLike, lat0_deg: ArrayLike, h0_m: ArrayLike = 0.0,
                           *, radius_m: float = R_MEAN) -> tuple[F64, F64]:
    """Worst case over bearing of the small-angle error model (level flight, ``w = 0``).

    Bounding each term of :func:`flat_earth_error_model` with ``|n|, |e| ≤ s`` and
    ``|n e| ≤ s²/2``:

    .. math::

        |\\varepsilon_n| &\\le |\\rho_M - 1|\\,s + \\rho_M\\Big(\\frac{|M'|}{2M_h^2}
            + \\frac{|\\tan\\varphi_0|}{2N_h}\\Big) s^2 \\\\
        |\\varepsilon_e| &\\le |\\rho_N - 1|\\,s + |\\rho_N - \\rho_M|\\frac{|\\tan\\varphi_0|}{2N_h} s^2 \\\\
        \\varepsilon_h &\\le \\sqrt{\\max|\\varepsilon_n|^2 + \\max|\\varepsilon_e|^2}, \\qquad
        |\\varepsilon_d| \\le \\frac{s^2}{2 M_h}

    The vertical bound is attained (bearing north, ``M ≤ N``). The horizontal one adds maxima
    reached at different bearings, so it exceeds the true worst case: measured over 72 bearings
    at latitudes 0-75° and 1-100 km, worst case / bound lies in 0.68-0.99 (0.94-0.98 at 45.5°);
    ``tests/frames/test_geodesy.py`` asserts [bound/1.6, bound] up to the third-order remainder.

    Parameters
    ----------
    range_m : array-like
        Horizontal range ``s`` (m).
    lat0_deg, h0_m : array-like
        Origin latitude (deg) and height (m).
    radius_m : float
        ``r`` of the flat formula.

    Returns
    -------
    horiz_m, vert_m : ndarray
        Upper bounds of the horizontal and vertical error (m).
    """
    s, lat0, h0 = _f64(range_m, lat0_deg, h0_m)
    m, nn = radii_of_curvature(lat0)
    mh, nh = m + h0, nn + h0
    phi = np.radians(lat0)
    sp, cp = np.sin(phi), np.cos(phi)
    dm = 3.0 * m * WGS84_E2 * sp * cp / (1.0 - WGS84_E2 * sp * sp)
    rho_m, rho_n = radius_m / mh, radius_m / nh
    tan0 = np.abs(sp / cp)
    en = np.abs(rho_m - 1.0) * s + rho_m * (np.abs(dm) / (2.0 * mh * mh) + tan0 / (2.0 * nh)) * s**2
    ee = np.abs(rho_n - 1.0) * s + np.abs(rho_n - rho_m) * tan0 / (2.0 * nh) * s * s
    return np.hypot(en, ee), s * s / (2.0 * mh)
