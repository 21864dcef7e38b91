"""Demonstrations per maneuver from preprocessed flights, in the aerobatic box frame.

A *demo* is one labelled segment of one flight: the rows of ``results/state/<flight>.parquet``
(uniform grid) with ``t_start_ns <= t_ns < t_end_ns`` of a row of
``results/segments/<flight>.parquet``, taken at ``sample_hz`` (every ``round(grid_hz /
sample_hz)``-th grid row) as a ``(N, 13)`` array of :data:`DEMO_COLUMNS`: NED position,
velocity, acceleration and the attitude quaternion (scalar first, sign-continuous along the demo,
:func:`~pipeline.frames.rotations.quat_continuity`), all in the **box frame**.

**Box frame.** A FlightCoach flight carries its box heading ``box_rotation_rad`` (ψ) and the
box origin, the pilot's position ``box_pilot_ned_m`` (:math:`o`, in the flight's NED frame), in
the ``state`` metadata (preprocessing copies them from the ingest meta's ``params``). Its NED
frame is about ``originLat/Lng/Alt``, which is *not* the box origin: FlightCoach's box is centred
on the pilot (FlightAnalysis ``Box.from_fcjson_parmameters``: from ``pilotLat/Lng`` towards
``centerLat/Lng``), 17-44 m away in the P23 flights, on opposite sides along the box axis, so
ignoring it displaced the two P23 flights' demos by ~60 m against each other. The box frame is
NED rotated about down by ψ about the pilot, :math:`x_{box} = R_z(\\psi)\\,(x_{NED} - o)` for
position (:math:`R_z(\\psi)\\,v` for velocity and acceleration;
:func:`~pipeline.models.features.heading_rotation`) and :math:`q_{box} = q_z(-\\psi) \\otimes q`
for the body→NED quaternion. Without ``box_pilot_ned_m`` (older state tables) the rotation is
about the NED origin.

**Box-less flights** (the kd0aij CSVs: NED about the first fix, no labels) get a rigid transform
onto the set's labelled reference flight (already in its box frame), :func:`rigid_fit`: the
whole schedule's track at ``csv_fit.sample_hz`` is matched to the reference's by DTW for each of
``csv_fit.headings`` initial headings (centroids aligned), the best is refined by
``csv_fit.iterations`` rounds of DTW + least squares (2-D rotation about down, 3-D translation,
Kabsch on the matched pairs). The flight's segments are then the reference's maneuver list
carried through a last DTW path at the demo rate (:func:`transfer_segments`).

**Bad input** never raises: a segment with ``gap`` rows or non-finite values inside it, or with
fewer than 2 samples, becomes a :class:`Dropped` record with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..frames.rotations import quat_continuity, quat_multiply, quat_normalize
from ..models.features import heading_rotation

F64 = NDArray[np.float64]

#: The 13 demo dimensions (``state`` table names), in order.
DEMO_COLUMNS: tuple[str, ...] = (
    "pos_n_m", "pos_e_m", "pos_d_m", "vel_n_mps", "vel_e_mps", "vel_d_mps",
    "acc_n_mps2", "acc_e_mps2", "acc_d_mps2", "q_w", "q_x", "q_y", "q_z",
)


@dataclass(frozen=True)
class Demo:
    """One demonstration: a labelled segment of one flight in the box frame.

    Attributes
    ----------
    name : str
        ``<flight_id>:<label>#<k>`` (``k`` counts the label's occurrences in the flight from 1).
    flight_id, label : str
    segment_id : int
    t_ns : ndarray (N,)
        The sample times (the flight's own clock).
    x : ndarray (N, 13)
        :data:`DEMO_COLUMNS` in the box frame.
    """

    name: str
    flight_id: str
    label: str
    segment_id: int
    t_ns: NDArray[np.int64]
    x: F64


@dataclass(frozen=True)
class Dropped:
    """A segment (or a whole flight, ``segment_id`` -1) left out, with the reason."""

    name: str
    flight_id: str
    label: str
    segment_id: int
    reason: str


@dataclass(frozen=True)
class RigidFit:
    """A rotation about down + translation taking a box-less flight onto its reference.

    :math:`x_{ref} = R_z(\\psi)\\,x + t` (:func:`~pipeline.models.features.heading_rotation`):
    ``heading_rad`` is ψ, the box heading of the flight's own NED frame.

    Attributes
    ----------
    heading_rad : float
    translation_m : ndarray (3,)
        NED translation in the reference frame (m).
    rms_m : float
        RMS 3-D distance of the DTW-matched pairs after the fit (m).
    n_pairs : int
        Matched pairs of the last round.
    altitude_rms_m : float
        RMS altitude difference of the two airborne tracks after DTW on altitude alone
        (:func:`altitude_profile_rms`; NaN until :func:`fit_to_reference` fills it). It does not
        depend on the fit, so it tells a flight that does not fly the reference's schedule from a
        fit that failed to find it.
    """

    heading_rad: float
    translation_m: F64
    rms_m: float
    n_pairs: int
    altitude_rms_m: float = float("nan")

    def apply(self, x: F64) -> F64:
        """The ``(N, 13)`` demo array ``x`` (flight NED) in the reference frame."""
        return to_frame(x, self.heading_rad, self.translation_m)


@dataclass(frozen=True)
class FlightDemos:
    """The demos of one flight and what was left out.

    ``frame`` is ``box`` (FlightCoach box heading), ``rigid`` (fitted to the reference) or
    ``ned`` (neither: kept in the flight's NED frame); ``heading_rad`` the rotation used.
    """

    flight_id: str
    demos: list[Demo]
    dropped: list[Dropped]
    frame: str
    heading_rad: float
    diagnostics: dict = field(default_factory=dict)


# --- frames -------------------------------------------------------------------------------------

def to_frame(x: F64, heading_rad: float, translation_m: Sequence[float] | None = None) -> F64:
    """Rotate ``(N, 13)`` demo rows about down by ``heading_rad`` (then translate the position).

    Position, velocity and acceleration triples become :math:`R_z(\\psi)\\,v`; the body→NED
    quaternion becomes :math:`q_z(-\\psi) \\otimes q` (body→frame), sign-continuous.
    """
    x = np.array(x, dtype=np.float64, copy=True)
    rot = heading_rotation(heading_rad)
    for k in range(3):
        x[:, 3 * k:3 * k + 3] = x[:, 3 * k:3 * k + 3] @ rot.T
    if translation_m is not None:
        x[:, 0:3] += np.asarray(translation_m, dtype=np.float64)
    half = -0.5 * float(heading_rad)
    qz = np.array([np.cos(half), 0.0, 0.0, np.sin(half)])
    x[:, 9:13] = quat_continuity(quat_multiply(qz, quat_normalize(x[:, 9:13])))
    return x


def state_array(state: pd.DataFrame) -> F64:
    """The :data:`DEMO_COLUMNS` of a ``state`` table as an ``(N, 13)`` float array."""
    return state.loc[:, list(DEMO_COLUMNS)].to_numpy(dtype=np.float64)


def grid_stride(t_ns: NDArray[np.int64], sample_hz: float) -> int:
    """Rows of the uniform state grid per demo sample: ``max(1, round(grid_hz / sample_hz))``."""
    if len(t_ns) < 2:
        return 1
    dt = float(np.median(np.diff(t_ns))) * 1e-9
    return max(1, int(round(1.0 / (dt * float(sample_hz))))) if dt > 0 else 1


# --- demos of one flight -------------------------------------------------------------------------

def box_translation(heading_rad: float, origin_ned_m: Sequence[float] | None) -> F64 | None:
    """The translation of :func:`to_frame` that puts the box origin ``origin_ned_m`` (NED, m) at
    zero after the rotation by ``heading_rad``: :math:`-R_z(\\psi)\\,o` (``None`` without one)."""
    if origin_ned_m is None:
        return None
    o = np.asarray(origin_ned_m, dtype=np.float64).reshape(3)
    return -(heading_rotation(heading_rad) @ o)


def flight_demos(state: pd.DataFrame, segments: pd.DataFrame, *, flight_id: str,
                 heading_rad: float | None = None, fit: RigidFit | None = None,
                 sample_hz: float = 3.0, exclude: Sequence[str] = (),
                 box_origin_ned_m: Sequence[float] | None = None) -> FlightDemos:
    """Cut one flight's labelled segments into box-frame demos.

    Parameters
    ----------
    state : DataFrame
        The flight's ``state`` table (uniform grid; :data:`DEMO_COLUMNS`, ``t_ns``, ``gap``).
    segments : DataFrame
        ``segment_id``, ``t_start_ns``, ``t_end_ns``, ``label``.
    flight_id : str
    heading_rad : float, optional
        The box heading (FlightCoach ``box_rotation_rad``); rotation about ``box_origin_ned_m``.
    fit : RigidFit, optional
        A rigid transform onto a reference flight (box-less flights); wins over ``heading_rad``.
    sample_hz : float
        Demo rate (nearest grid rows, see :func:`grid_stride`).
    exclude : sequence of str
        Labels never taken (take-off, landing).
    box_origin_ned_m : sequence of 3 float, optional
        The box origin (FlightCoach: the pilot, ``box_pilot_ned_m``) in the flight's NED frame;
        default the NED origin. Used with ``heading_rad`` only.

    Returns
    -------
    FlightDemos
    """
    t = state["t_ns"].to_numpy(np.int64)
    stride = grid_stride(t, sample_hz)
    x_all = state_array(state)
    gap = state["gap"].to_numpy(bool) if "gap" in state else np.zeros(len(state), bool)
    if fit is not None:
        frame, psi = "rigid", float(fit.heading_rad)
    elif heading_rad is not None and np.isfinite(heading_rad):
        frame, psi = "box", float(heading_rad)
    else:
        frame, psi = "ned", 0.0
    shift = box_translation(psi, box_origin_ned_m) if frame == "box" else None
    demos: list[Demo] = []
    dropped: list[Dropped] = []
    seen: dict[str, int] = {}
    for row in segments.sort_values("t_start_ns").itertuples():
        label = str(row.label)
        if label in exclude or not label:
            continue
        seen[label] = seen.get(label, 0) + 1
        name = f"{flight_id}:{label}#{seen[label]}"
        inside = (t >= int(row.t_start_ns)) & (t < int(row.t_end_ns))
        idx = np.flatnonzero(inside)
        reason = ""
        if int(row.t_end_ns) <= int(row.t_start_ns):
            reason = ("the segment is empty (t_end_ns <= t_start_ns; for segments carried from the reference: "
                      "the alignment puts the whole maneuver at one instant of this flight, which does not fly "
                      "it where the schedule does)")
        elif gap[idx].any():
            n_gap = int(gap[idx].sum())
            reason = f"{n_gap} gap row{'s' * (n_gap != 1)} inside the segment"   # the align page shows it
        idx = idx[::stride]
        if not reason and len(idx) < 2:
            reason = f"{len(idx)} sample{'s' * (len(idx) != 1)} in the segment at {sample_hz:g} Hz"
        if not reason and not np.isfinite(x_all[idx]).all():
            bad = sorted({DEMO_COLUMNS[j] for j in np.flatnonzero(~np.isfinite(x_all[idx]).all(axis=0))})
            reason = f"non-finite {', '.join(bad)} inside the segment"
        if reason:
            dropped.append(Dropped(name, flight_id, label, int(row.segment_id), reason))
            continue
        x = x_all[idx]
        x = fit.apply(x) if fit is not None else to_frame(x, psi, shift)
        demos.append(Demo(name, flight_id, label, int(row.segment_id), t[idx], x))
    diag = {"stride": stride, "n_demos": len(demos), "n_dropped": len(dropped), "frame": frame,
            "heading_rad": psi}
    if shift is not None:
        diag["box_origin_ned_m"] = [float(v) for v in box_origin_ned_m]
    if fit is not None:
        diag.update(translation_m=[float(v) for v in fit.translation_m], fit_rms_m=fit.rms_m,
                    fit_pairs=fit.n_pairs,
                    fit_altitude_rms_m=fit.altitude_rms_m if np.isfinite(fit.altitude_rms_m) else None)
    return FlightDemos(flight_id, demos, dropped, frame, psi, diag)


# --- the rigid fit of a box-less flight ----------------------------------------------------------

PathFn = Callable[[F64, F64], NDArray[np.int64]]


def warping_path(x: F64, y: F64) -> NDArray[np.int64]:
    """The DTW path ``(K, 2)`` (indices into x, y) of two multi-dimensional series.

    Symmetric2 steps, no window, squared-Euclidean local cost, by
    :func:`pipeline.align.dtw.dtw`.
    """
    from .dtw import dtw  # noqa: PLC0415 (kept lazy: numba compiles on first use)

    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    return path_array(dtw(x, y, step_pattern="symmetric2").path)


def path_array(path) -> NDArray[np.int64]:
    """A DTW path as a ``(K, 2)`` int array, from ``(K, 2)``, ``(2, K)``, a pair of index
    arrays or a list of pairs."""
    if isinstance(path, tuple) and len(path) == 2:
        return np.column_stack([np.asarray(path[0]), np.asarray(path[1])]).astype(np.int64)
    p = np.asarray(path, dtype=np.int64)
    if p.ndim == 2 and p.shape[1] != 2 and p.shape[0] == 2:
        p = p.T
    return p


def _kabsch_about_down(src: F64, dst: F64) -> tuple[float, F64]:
    """ψ and t minimising Σ|R_z(ψ) src + t − dst|² (R_z about down only)."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src[:, :2] - ms[:2], dst[:, :2] - md[:2]
    # x_frame = R x with R = [[c, s], [-s, c]]: maximise Σ b·(R a)
    num = np.sum(a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1])
    den = np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])
    psi = float(np.arctan2(num, den))
    t = md - ms @ heading_rotation(psi).T
    return psi, t


def _transform_pos(p: F64, psi: float, t: F64) -> F64:
    return p @ heading_rotation(psi).T + t


def rigid_fit(track_ned: F64, reference: F64, *, headings: int = 24, iterations: int = 30,
              path_fn: PathFn | None = None) -> RigidFit:
    """Fit :math:`x_{ref} = R_z(\\psi)\\,x + t` of a whole flight to its reference by DTW.

    Parameters
    ----------
    track_ned : ndarray (N, 3)
        The box-less flight's positions (NED), at the fit rate.
    reference : ndarray (M, 3)
        The reference flight's positions in its box frame, at the same rate.
    headings : int
        Initial headings ``2πk/headings`` tried (centroids aligned); the best DTW distance wins.
    iterations : int
        Rounds of DTW path + least squares after it at most (it stops earlier once a round
        changes ψ by < 1e-6 rad and t by < 1 mm).
    path_fn : callable, optional
        ``(x, y) -> (K, 2)`` DTW path; default :func:`warping_path`.

    Returns
    -------
    RigidFit
    """
    path_fn = path_fn or warping_path
    src = np.asarray(track_ned, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    best = None
    for k in range(int(headings)):
        psi = 2.0 * np.pi * k / int(headings)
        t = ref.mean(axis=0) - src.mean(axis=0) @ heading_rotation(psi).T
        p = _transform_pos(src, psi, t)
        path = path_fn(p, ref)
        cost = float(np.mean(np.sum((p[path[:, 0]] - ref[path[:, 1]]) ** 2, axis=1)))
        if best is None or cost < best[0]:
            best = (cost, psi, t)
    _, psi, t = best
    path = np.zeros((0, 2), np.int64)
    for _ in range(int(iterations)):
        path = path_fn(_transform_pos(src, psi, t), ref)
        psi_new, t_new = _kabsch_about_down(src[path[:, 0]], ref[path[:, 1]])
        # like ICP this creeps along the track: stop once a round moves nothing noticeable
        done = abs(psi_new - psi) < 1e-6 and float(np.max(np.abs(t_new - t))) < 1e-3
        psi, t = psi_new, t_new
        if done:
            break
    p = _transform_pos(src, psi, t)
    rms = float(np.sqrt(np.mean(np.sum((p[path[:, 0]] - ref[path[:, 1]]) ** 2, axis=1)))) if len(path) else np.nan
    psi = float(np.arctan2(np.sin(psi), np.cos(psi)))
    return RigidFit(psi, np.asarray(t, dtype=np.float64), rms, int(len(path)))


#: height above the track's lowest sample (m) from which a track counts as airborne in
#: :func:`altitude_profile_rms` (taxiing and the ground roll are left out)
AIRBORNE_HEIGHT_M = 20.0


def altitude_profile_rms(track_ned: F64, reference: F64, *, path_fn: PathFn | None = None) -> float:
    """RMS altitude difference (m) of two tracks after DTW on altitude alone.

    Altitude ``−D`` is unchanged by the rotation about down and the horizontal translation of
    :func:`rigid_fit`, so this compares the two flights' vertical schedules before any fit: a
    flight of the same schedule matches closely (kd0aij-p21 against fc-p21-026: 15.5 m at 1 Hz),
    another schedule does not (the P23 flights against the P21 one: 27.4 and 29.7 m; F23: 35.9 m).
    kd0aij-141, listed as a P21 flight, gives 27.7 m: its vertical schedule is no closer to P21
    than a P23 flight's, which is why no rigid fit places it (pair RMS 113.5 m). Each track is cut to its
    airborne span (first to last sample more than :data:`AIRBORNE_HEIGHT_M` above its lowest
    sample, the ground); the vertical offset between the two frames is kept, as in the fit.

    Parameters
    ----------
    track_ned, reference : ndarray (N, 3), (M, 3)
        Positions (NED), at the same rate.
    path_fn : callable, optional
        ``(x, y) -> (K, 2)`` DTW path; default :func:`warping_path`.

    Returns
    -------
    float
        NaN when either track never gets airborne.
    """
    path_fn = path_fn or warping_path

    def airborne(p: F64) -> F64:
        h = np.max(p[:, 2]) - p[:, 2]
        up = np.flatnonzero(h > AIRBORNE_HEIGHT_M)
        return np.zeros((0, 2)) if not len(up) else np.c_[-p[up[0]:up[-1] + 1, 2], np.zeros(up[-1] + 1 - up[0])]

    a = airborne(np.asarray(track_ned, dtype=np.float64))
    b = airborne(np.asarray(reference, dtype=np.float64))
    if len(a) < 2 or len(b) < 2:
        return float("nan")
    path = path_fn(a, b)
    return float(np.sqrt(np.mean((a[path[:, 0], 0] - b[path[:, 1], 0]) ** 2)))


def transfer_segments(ref_t_ns: NDArray[np.int64], ref_segments: pd.DataFrame,
                      t_ns: NDArray[np.int64], path: NDArray[np.int64]) -> pd.DataFrame:
    """The reference's segments on another flight's clock through a DTW path.

    ``path`` pairs indices of the flight (``path[:, 0]`` into ``t_ns``) with indices of the
    reference (``path[:, 1]`` into ``ref_t_ns``). A reference boundary at time ``b`` maps to the
    mean flight index matched to the reference sample nearest ``b``.
    """
    path = np.asarray(path, dtype=np.int64)
    n_ref = len(ref_t_ns)
    sums = np.bincount(path[:, 1], weights=path[:, 0], minlength=n_ref)
    counts = np.bincount(path[:, 1], minlength=n_ref)
    j_of_i = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    # reference samples the path never visits (cannot happen for a full path) take neighbours
    ok = np.isfinite(j_of_i)
    j_of_i = np.interp(np.arange(n_ref), np.flatnonzero(ok), j_of_i[ok])

    def carry(b: int) -> int:
        i = int(np.clip(np.searchsorted(ref_t_ns, b), 0, n_ref - 1))
        return int(t_ns[int(np.clip(round(j_of_i[i]), 0, len(t_ns) - 1))])

    out = ref_segments.loc[:, ["segment_id", "t_start_ns", "t_end_ns", "label"]].copy()
    out["t_start_ns"] = [carry(int(b)) for b in ref_segments["t_start_ns"]]
    out["t_end_ns"] = [carry(int(b)) for b in ref_segments["t_end_ns"]]
    return out.reset_index(drop=True)


#: most heading change (deg) the schedule-only refit may make on the whole-flight fit; more means
#: the whole-flight fit did not find the schedule, and it is kept
SCHEDULE_FIT_MAX_TURN_DEG = 20.0


def fit_to_reference(state: pd.DataFrame, ref_state: pd.DataFrame, ref_segments: pd.DataFrame, *,
                     ref_heading_rad: float | None, sample_hz: float, fit_hz: float = 1.0,
                     headings: int = 24, iterations: int = 30,
                     path_fn: PathFn | None = None,
                     ref_origin_ned_m: Sequence[float] | None = None,
                     schedule_exclude: Sequence[str] | None = None) -> tuple[RigidFit, pd.DataFrame]:
    """Rigid fit of a box-less flight to a labelled reference, and its carried segments.

    The fit uses both tracks at ``fit_hz``; the segments come from one more DTW path of the
    fitted positions at ``sample_hz`` (:func:`transfer_segments`). The reference is taken in its
    box frame: rotated by ``ref_heading_rad`` about its box origin ``ref_origin_ned_m`` (default
    its NED origin), as :func:`flight_demos` puts its demos.

    ``schedule_exclude`` (labels, e.g. take-off and landing): fit the *schedule* only. The first
    fit of the whole flights gives the carried segments; both tracks are then cut to the span of
    their segments other than these labels (the CSV logs carry minutes of taxiing, climb-out and
    circuits the reference does not have, and they pull the translation: kd0aij-p21's maneuvers
    sat 45 m nearer and 22 m higher than the reference's on average), and the fit and the segment
    transfer are redone on the cut tracks, unless the refit turns the heading by more than
    :data:`SCHEDULE_FIT_MAX_TURN_DEG` (then the whole-flight fit did not find the schedule, its
    span is arbitrary, and it is kept: kd0aij-141, 112-114 m pair RMS either way, whose refit
    turned by 175°).
    """
    path_fn = path_fn or warping_path
    psi_ref = float(ref_heading_rad) if ref_heading_rad is not None else 0.0
    ref_shift = box_translation(psi_ref, ref_origin_ned_m) if ref_heading_rad is not None else None
    ref_shift = np.zeros(3) if ref_shift is None else ref_shift

    def positions(st: pd.DataFrame, hz: float) -> tuple[NDArray[np.int64], F64]:
        t = st["t_ns"].to_numpy(np.int64)
        p = st.loc[:, ["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy(np.float64)
        keep = np.isfinite(p).all(axis=1)
        t, p = t[keep], p[keep]
        s = grid_stride(t, hz)
        return t[::s], p[::s]

    t_src, src = positions(state, fit_hz)
    t_ref, ref = positions(ref_state, fit_hz)
    # the schedule check is taken on the whole flights in their own NED frames (nothing fitted)
    alt_rms = altitude_profile_rms(src, ref, path_fn=path_fn)
    ref = ref @ heading_rotation(psi_ref).T + ref_shift
    fit = rigid_fit(src, ref, headings=headings, iterations=iterations, path_fn=path_fn)
    fit = replace(fit, altitude_rms_m=alt_rms)
    t_src, src = positions(state, sample_hz)
    t_ref, ref = positions(ref_state, sample_hz)
    ref = ref @ heading_rotation(psi_ref).T + ref_shift
    path = path_fn(_transform_pos(src, fit.heading_rad, fit.translation_m), ref)
    carried = transfer_segments(t_ref, ref_segments, t_src, path)
    if schedule_exclude is None:
        return fit, carried
    skip = set(schedule_exclude)

    def span(seg: pd.DataFrame) -> tuple[int, int] | None:
        keep = seg[~seg["label"].astype(str).isin(skip)]
        return (int(keep["t_start_ns"].min()), int(keep["t_end_ns"].max())) if len(keep) else None

    s_ref, s_src = span(ref_segments), span(carried)
    if s_ref is None or s_src is None or s_src[1] <= s_src[0]:
        return fit, carried

    def cut(st: pd.DataFrame, sp: tuple[int, int]) -> pd.DataFrame:
        t = st["t_ns"].to_numpy(np.int64)
        return st.loc[(t >= sp[0]) & (t <= sp[1])]

    state_s, ref_s = cut(state, s_src), cut(ref_state, s_ref)
    t_src, src = positions(state_s, fit_hz)
    t_ref, ref = positions(ref_s, fit_hz)
    if len(src) < 3 or len(ref) < 3:
        return fit, carried
    ref = ref @ heading_rotation(psi_ref).T + ref_shift
    first = fit
    fit = replace(rigid_fit(src, ref, headings=headings, iterations=iterations, path_fn=path_fn),
                  altitude_rms_m=alt_rms)
    turn = abs(float(np.angle(np.exp(1j * (fit.heading_rad - first.heading_rad)))))
    if turn > np.radians(SCHEDULE_FIT_MAX_TURN_DEG):
        # the whole-flight fit was too poor to say where the schedule is (its span is then
        # arbitrary): keep it rather than a fit of an arbitrary piece
        return first, carried
    t_src, src = positions(state_s, sample_hz)
    t_ref, ref = positions(ref_s, sample_hz)
    ref = ref @ heading_rotation(psi_ref).T + ref_shift
    path = path_fn(_transform_pos(src, fit.heading_rad, fit.translation_m), ref)
    inside = ref_segments[~ref_segments["label"].astype(str).isin(skip)]
    return fit, transfer_segments(t_ref, inside, t_src, path)
