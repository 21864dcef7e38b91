"""Controls: raw pulse widths -> normalised sticks and, where configured, physical deflections.

Sticks (per-vehicle channel map, ``preprocess.vehicles.<v>.controls``): a bidirectional stick
``ail``, ``ele``, ``rud`` is mapped piecewise-linearly about its trim,

.. math:: s = \\begin{cases} (u - u_{trim})/(u_{max} - u_{trim}) & u \\ge u_{trim} \\\\
                              (u - u_{trim})/(u_{trim} - u_{min}) & u < u_{trim} \\end{cases}

clipped to [−1, 1] (negated when ``reverse``), and the throttle as
:math:`(u - u_{min})/(u_{max} - u_{min})` clipped to [0, 1]. Positive sticks are the raw
increasing-pulse sense unless ``reverse`` is set; vehicle entries document their convention.

Physical controls (seed 004 §6 step 8, bench polynomials in the pulse width :math:`u` in µs,
clamped to the fitted range first): ``delta_a_rad``, ``delta_e_rad``, ``delta_r_rad`` and
``thrust_N``, with coefficients in increasing powers of :math:`u`. The thrust fit (5.12) is
used with the corrected sign, :math:`F = -6.2628\\cdot10^{-6}u^2 + 0.0287u - 22.6335` and
:math:`F \\ge 0` (the printed ``+`` gives 34.5 N at 1500 µs against a 10 N motor).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..io.base import last_params

STICKS = ("ail", "ele", "rud", "thr")
PHYSICAL = ("delta_a_rad", "delta_e_rad", "delta_r_rad", "thrust_N")

#: ArduPilot defaults (RCMAP: 1 roll, 2 pitch, 3 throttle, 4 yaw; 1100-1900 µs)
DEFAULT_CONTROLS: dict[str, dict] = {
    "ail": {"channel": "rc_1_us", "min_us": 1100, "trim_us": 1500, "max_us": 1900},
    "ele": {"channel": "rc_2_us", "min_us": 1100, "trim_us": 1500, "max_us": 1900},
    "thr": {"channel": "rc_3_us", "min_us": 1100, "max_us": 1900},
    "rud": {"channel": "rc_4_us", "min_us": 1100, "trim_us": 1500, "max_us": 1900},
}


#: stick -> the function each autopilot maps it by: (ArduPilot RCMAP_*, PX4 RC_MAP_*)
_MAP_PARAMS = {"ail": ("RCMAP_ROLL", "RC_MAP_ROLL"), "ele": ("RCMAP_PITCH", "RC_MAP_PITCH"),
               "thr": ("RCMAP_THROTTLE", "RC_MAP_THROTTLE"), "rud": ("RCMAP_YAW", "RC_MAP_YAW")}


def controls_from_params(params: pd.DataFrame | Mapping[str, float] | None,
                         controls: Mapping[str, Mapping] | None = None) -> tuple[dict, list[str]]:
    """The stick map and radio calibration the autopilot itself used, from the log's parameters.

    Each stick's channel is the autopilot's map of its function (ArduPilot ``RCMAP_ROLL``,
    ``_PITCH``, ``_THROTTLE``, ``_YAW``; PX4 ``RC_MAP_*``; an ArduPilot log with calibration but
    no ``RCMAP_*`` uses its defaults 1, 2, 3, 4), and its ``min_us``/``trim_us``/``max_us`` and
    ``reverse`` the channel's calibration ``RCn_MIN``/``RCn_TRIM``/``RCn_MAX`` and ``RCn_REVERSED``
    (1 = reversed) or ``RCn_REV`` (−1 = reversed). So :func:`normalise_stick` maps the pulse as
    the autopilot did: on px4-ekf-failure (calibrated 982–2006 µs) the fixed 1100–1900 µs scale
    read the sticks 10–26 % too large and put the elevator at ±1 on 19 % of samples; on
    px4-motor-failure (``RC_MAP_THROTTLE`` 1, ``ROLL`` 2, ``PITCH`` 3) ``ail`` was the throttle.

    Parameters
    ----------
    params : DataFrame or mapping
        The ``params`` stream (or ``{name: value}``).
    controls : mapping, optional
        The configured sticks (default :data:`DEFAULT_CONTROLS`): what the log does not give is
        kept from them.

    Returns
    -------
    (dict, list of str)
        The sticks' specs (a function the autopilot leaves unmapped, map 0, is ``None``) and
        notes saying what came from the log (empty when it has none of these parameters).
    """
    pv = dict(params) if isinstance(params, Mapping) else last_params(params)
    pv = {k: v for k, v in pv.items() if np.isfinite(v)}
    base = {k: (dict(v) if v else None) for k, v in (DEFAULT_CONTROLS if controls is None else controls).items()}
    px4 = any(k.startswith("RC_MAP_") for k in pv)
    has_map = px4 or any(k.startswith("RCMAP_") for k in pv)
    has_cal = any(f"RC{i}_MIN" in pv for i in range(1, 5))
    if not (has_map or has_cal):
        return base, []
    out, said = dict(base), []
    for stick, names in _MAP_PARAMS.items():
        name = names[1] if px4 else names[0]
        if has_map:
            ch = int(pv.get(name, 0))
            if ch <= 0:
                out[stick] = None
                said.append(f"{stick} unmapped ({name} 0)")
                continue
        else:  # ArduPilot calibration without RCMAP (older firmware): its fixed map, DEFAULT_CONTROLS's
            ch = int(DEFAULT_CONTROLS[stick]["channel"].split("_")[1])
        spec = {k: v for k, v in (base.get(stick) or {}).items() if k not in ("channel", "reverse")}
        spec["channel"] = f"rc_{ch}_us"
        lo, hi, trim = pv.get(f"RC{ch}_MIN"), pv.get(f"RC{ch}_MAX"), pv.get(f"RC{ch}_TRIM")
        if lo is not None and hi is not None and lo < hi:
            spec["min_us"], spec["max_us"] = lo, hi
            if stick != "thr":
                # a trim at an end (a throttle-style channel mapped to a stick) has no centre: the middle
                spec["trim_us"] = trim if trim is not None and lo < trim < hi else 0.5 * (lo + hi)
        rev = pv.get(f"RC{ch}_REVERSED")
        reverse = (rev == 1) if rev is not None else (pv.get(f"RC{ch}_REV") == -1)
        if reverse:
            spec["reverse"] = True
        out[stick] = spec
        cal = f" {spec['min_us']:.0f}/{spec['trim_us']:.0f}/{spec['max_us']:.0f}" if "trim_us" in spec \
            else f" {spec.get('min_us', 1100):.0f}-{spec.get('max_us', 1900):.0f}"
        said.append(f"{stick} rc_{ch}{cal} µs{' reversed' if reverse else ''}")
    what = ("PX4 RC_MAP_*" if px4 else "ArduPilot RCMAP_*" if has_map else "ArduPilot default map") + \
        (", RCn_MIN/TRIM/MAX" if has_cal else "")
    return out, [f"sticks from the log's parameters ({what}): " + ", ".join(said)]


def check_stick(name: str, spec: Mapping) -> None:
    """Raise ValueError (``controls.<name>: ...``) for a stick spec without a channel or with
    pulse widths out of order (min < trim < max; throttle: min < max)."""
    if "channel" not in spec:
        raise ValueError(f"controls.{name}: missing 'channel' (e.g. rc_1_us)")
    lo, hi = float(spec.get("min_us", 1100)), float(spec.get("max_us", 1900))
    if not lo < hi:
        raise ValueError(f"controls.{name}: min_us {lo} must be below max_us {hi}")
    if name != "thr":
        trim = float(spec.get("trim_us", 0.5 * (lo + hi)))
        if not lo < trim < hi:
            raise ValueError(f"controls.{name}: trim_us {trim} must lie in ({lo}, {hi})")


def normalise_stick(u: NDArray, spec: Mapping, *, unipolar: bool = False) -> NDArray[np.float64]:
    """Pulse width (µs) -> stick in [−1, 1] (bipolar) or [0, 1] (``unipolar``, throttle)."""
    u = np.asarray(u, dtype=np.float64)
    lo, hi = float(spec.get("min_us", 1100)), float(spec.get("max_us", 1900))
    # 0 µs is "no pulse" (channel not connected / failsafe), not full-low stick
    u = np.where(u > 0, u, np.nan)
    if unipolar:
        s = np.clip((u - lo) / (hi - lo), 0.0, 1.0)
        return 1.0 - s if spec.get("reverse") else s
    trim = float(spec.get("trim_us", 0.5 * (lo + hi)))
    s = np.where(u >= trim, (u - trim) / (hi - trim), (u - trim) / (trim - lo))
    s = np.clip(s, -1.0, 1.0)
    return -s if spec.get("reverse") else s


def physical_control(u: NDArray, spec: Mapping) -> NDArray[np.float64]:
    """Bench polynomial ``sum_i poly[i] * u^i`` of the clamped pulse width, then clamped output.

    ``spec``: ``channel``, ``poly`` (increasing powers), optional ``clamp_us: [lo, hi]`` and
    ``min``/``max`` on the result.
    """
    u = np.asarray(u, dtype=np.float64)
    u = np.where(u > 0, u, np.nan)
    if "clamp_us" in spec:
        lo, hi = spec["clamp_us"]
        u = np.clip(u, float(lo), float(hi))
    y = np.polynomial.polynomial.polyval(u, np.asarray(spec["poly"], dtype=np.float64))
    if "min" in spec or "max" in spec:
        y = np.clip(y, spec.get("min", -np.inf), spec.get("max", np.inf))
    return y


def controls_from_pwm(ctrl: pd.DataFrame, controls: Mapping[str, Mapping] | None = None,
                      physical: Mapping[str, Mapping] | None = None) -> pd.DataFrame:
    """Normalised sticks (and physical controls) from gridded ``rc_*_us``/``servo_*_us`` columns.

    Parameters
    ----------
    ctrl : DataFrame
        Pulse-width columns (already on the state grid).
    controls : mapping, optional
        ``{ail|ele|rud|thr: {channel, min_us, trim_us, max_us, reverse}}``; default ArduPilot AETR.
    physical : mapping, optional
        ``{delta_a_rad|delta_e_rad|delta_r_rad|thrust_N: {channel, poly, clamp_us, min, max}}``.

    Returns
    -------
    DataFrame with ``ail, ele, rud, thr`` and the configured physical columns (NaN where the
    channel is absent or never logged).
    """
    controls = DEFAULT_CONTROLS if controls is None else controls
    n = len(ctrl)
    out = {}
    for name in STICKS:
        spec = controls.get(name)
        if not spec or spec.get("channel") not in ctrl.columns:
            out[name] = np.full(n, np.nan)
            continue
        check_stick(name, spec)
        out[name] = normalise_stick(ctrl[spec["channel"]].to_numpy(dtype=np.float64, na_value=np.nan),
                                    spec, unipolar=(name == "thr"))
    for name, spec in (physical or {}).items():
        if name not in PHYSICAL:
            raise ValueError(f"physical control {name!r} unknown; known: {PHYSICAL}")
        if spec.get("channel") not in ctrl.columns:
            out[name] = np.full(n, np.nan)
            continue
        out[name] = physical_control(ctrl[spec["channel"]].to_numpy(dtype=np.float64, na_value=np.nan), spec)
    return pd.DataFrame(out, index=ctrl.index)
