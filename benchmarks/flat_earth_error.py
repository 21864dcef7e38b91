"""Flat-Earth (seed 004, thesis eq. 5.1) error against the exact WGS-84 conversion.

For level points (at the origin's ellipsoidal height) at 1, 10 and 100 km range, the worst case
over 360 bearings of the horizontal, vertical and total error of ``n = r Δφ``,
``e = r cos φ Δλ``, ``d = −Δh`` (``r`` = IUGG mean radius) is measured against
``pipeline.frames.geodesy.geodetic_to_ned`` and compared with the analytic small-angle bound of
``flat_earth_error_bound`` (derivation in ``flat_earth_error_model``). The headline latitude is
45.5° N (the thesis's Stinger Dome, Montreal).

Usage: ``python benchmarks/flat_earth_error.py``; ends with ``RESULT <name> <value>`` lines.
"""

from __future__ import annotations

import numpy as np

from pipeline.frames import geodesy as geo

HEADLINE_LAT = 45.5
LATS = (0.0, HEADLINE_LAT, 60.0)
RANGES_KM = (1, 10, 100)


def worst_case(range_m: float, lat0: float) -> dict[str, float]:
    bearing = np.arange(0.0, 360.0, 1.0)
    en, ee, ed, n, e = geo.flat_earth_error(range_m, bearing, lat0, -73.6, 30.0)
    pn, pe, pd = geo.flat_earth_error_model(n, e, lat0, 30.0)
    hb, vb = geo.flat_earth_error_bound(range_m, lat0, 30.0)
    h = np.hypot(en, ee)
    return {
        "horiz": float(h.max()), "vert": float(np.abs(ed).max()),
        "total": float(np.sqrt(en**2 + ee**2 + ed**2).max()),
        "model_resid": float(np.hypot(en - pn, ee - pe).max() / h.max()),
        "bound_h": float(hb), "bound_v": float(vb),
    }


def main() -> None:
    print(f"{'lat':>6} {'range':>7} {'horiz_m':>10} {'vert_m':>10} {'total_m':>10} "
          f"{'bound_h_m':>10} {'meas/bnd':>8} {'bound_v_m':>10} {'model_rel_resid':>15}")
    rows = {}
    for lat0 in LATS:
        for r_km in RANGES_KM:
            w = worst_case(r_km * 1e3, lat0)
            rows[lat0, r_km] = w
            print(f"{lat0:6.1f} {r_km:5d}km {w['horiz']:10.4f} {w['vert']:10.4f} {w['total']:10.4f} "
                  f"{w['bound_h']:10.4f} {w['horiz'] / w['bound_h']:8.3f} {w['bound_v']:10.4f} "
                  f"{w['model_resid']:15.2e}")
    for r_km in RANGES_KM:
        w = rows[HEADLINE_LAT, r_km]
        print(f"RESULT flat_earth_err_{r_km}km_m {w['total']:.6g}")
    for r_km in RANGES_KM:
        w = rows[HEADLINE_LAT, r_km]
        print(f"RESULT flat_earth_err_h_{r_km}km_m {w['horiz']:.6g}")
        print(f"RESULT flat_earth_err_v_{r_km}km_m {w['vert']:.6g}")
        print(f"RESULT flat_earth_bound_h_{r_km}km_m {w['bound_h']:.6g}")
        print(f"RESULT flat_earth_bound_v_{r_km}km_m {w['bound_v']:.6g}")


if __name__ == "__main__":
    main()
