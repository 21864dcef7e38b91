"""Demos per maneuver in the box frame (pipeline.align.demos)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_align import synthetic_segments, synthetic_state

from pipeline.align.demos import (DEMO_COLUMNS, altitude_profile_rms, fit_to_reference, flight_demos,
                                  rigid_fit, to_frame, transfer_segments)
from pipeline.frames.rotations import quat_to_dcm
from pipeline.models.features import heading_rotation


def test_a_flight_in_a_rotated_box_flies_along_box_x_in_the_box_frame():
    psi = np.radians(37.0)
    st = synthetic_state(500, heading_rad=psi)
    fd = flight_demos(st, synthetic_segments([(0, 8, "a"), (8, 16, "b")]), flight_id="f",
                      heading_rad=psi, sample_hz=5.0)
    assert fd.frame == "box" and [d.label for d in fd.demos] == ["a", "b"]
    x = fd.demos[0].x
    assert x.shape[1] == len(DEMO_COLUMNS) == 13
    # box x = 20 m/s * t, box y = 5 sin(0.2 t): the rotation undoes the heading exactly
    ts = fd.demos[0].t_ns * 1e-9
    np.testing.assert_allclose(x[:, 0], 20.0 * ts, atol=0.05)
    np.testing.assert_allclose(x[:, 1], 5.0 * np.sin(0.2 * ts), atol=1e-9)
    # yaw = the box heading: the body x axis is the box x axis
    np.testing.assert_allclose(quat_to_dcm(x[:, 9:13])[:, :, 0], np.tile([1.0, 0, 0], (len(x), 1)), atol=1e-12)


def test_demos_take_every_kth_grid_row_at_the_demo_rate():
    st = synthetic_state(500)
    fd = flight_demos(st, synthetic_segments([(0, 10, "a")]), flight_id="f", sample_hz=5.0)
    assert fd.diagnostics["stride"] == 5
    assert np.all(np.diff(fd.demos[0].t_ns) == 200_000_000) and len(fd.demos[0].t_ns) == 50


def test_the_frame_rotation_rotates_vectors_and_the_quaternion_alike(rng):
    x = rng.standard_normal((20, 13))
    x[:, 9:13] /= np.linalg.norm(x[:, 9:13], axis=1, keepdims=True)
    psi = 1.1
    y = to_frame(x, psi, [1.0, 2.0, 3.0])
    r = heading_rotation(psi)
    np.testing.assert_allclose(y[:, 3:6], x[:, 3:6] @ r.T, atol=1e-12)
    np.testing.assert_allclose(y[:, 0:3], x[:, 0:3] @ r.T + [1.0, 2.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(quat_to_dcm(y[:, 9:13]), r @ quat_to_dcm(x[:, 9:13]), atol=1e-12)
    assert np.all(np.sum(y[1:, 9:13] * y[:-1, 9:13], axis=1) >= 0)  # sign-continuous


def test_a_demo_with_gap_rows_inside_its_segment_is_dropped_with_the_reason():
    st = synthetic_state(500)
    st.loc[60:62, "gap"] = True  # inside the second segment (t 2.4 s)
    fd = flight_demos(st, synthetic_segments([(0, 2, "a"), (2, 4, "b"), (4, 6, "b")]), flight_id="f")
    assert [d.name for d in fd.demos] == ["f:a#1", "f:b#2"]
    assert len(fd.dropped) == 1 and fd.dropped[0].name == "f:b#1"
    assert fd.dropped[0].reason == "3 gap rows inside the segment"


def test_excluded_labels_and_non_finite_segments_give_no_demo():
    st = synthetic_state(500)
    st.loc[160:170, "pos_n_m"] = np.nan
    fd = flight_demos(st, synthetic_segments([(0, 2, "tkOf"), (2, 4, "a"), (6, 8, "b")]), flight_id="f",
                      exclude=("tkOf",))
    assert [d.label for d in fd.demos] == ["a"]
    assert fd.dropped[0].label == "b" and "non-finite pos_n_m" in fd.dropped[0].reason


def test_a_segment_that_ends_before_it_starts_is_dropped_saying_so():
    st = synthetic_state(500)
    seg = synthetic_segments([(0, 2, "a"), (2, 4, "b")])
    seg.loc[1, ["t_start_ns", "t_end_ns"]] = seg.loc[1, ["t_end_ns", "t_start_ns"]].to_numpy()
    fd = flight_demos(st, seg, flight_id="f")
    assert [d.name for d in fd.demos] == ["f:a#1"]
    assert fd.dropped[0].reason.startswith("the segment is empty (t_end_ns <= t_start_ns")


def test_the_rigid_fit_recovers_a_known_heading_and_translation(rng):
    t = np.linspace(0, 60, 301)
    ref = np.column_stack([100 * np.sin(0.1 * t), 30 * t - 0.2 * t ** 2, -50 - 20 * np.sin(0.3 * t)])
    psi, tr = np.radians(-70.0), np.array([40.0, -25.0, 3.0])
    # the flight is the reference in another frame: x = R^T (ref - t), and flown 10 % slower at the start
    warp = np.interp(np.linspace(0, 1, 331) ** 1.1, np.linspace(0, 1, 301), np.arange(301))
    src_ref = np.column_stack([np.interp(warp, np.arange(301), ref[:, k]) for k in range(3)])
    src = (src_ref - tr) @ heading_rotation(psi)
    fit = rigid_fit(src + 0.05 * rng.standard_normal(src.shape), ref, headings=12, iterations=30)
    assert abs(np.degrees(fit.heading_rad - psi)) < 0.5
    np.testing.assert_allclose(fit.translation_m, tr, atol=1.5)
    assert fit.rms_m < 2.0


def test_segments_are_carried_through_the_dtw_path():
    ref_t = np.arange(10, dtype=np.int64) * 10
    t = np.arange(20, dtype=np.int64) * 5 + 1000
    path = np.column_stack([np.arange(20), np.arange(20) // 2])  # flight sample 2i, 2i+1 <-> ref i
    seg = synthetic_segments([(0, 5e-8, "a"), (5e-8, 9e-8, "b")])
    out = transfer_segments(ref_t, seg, t, path)
    # ref boundary 50 ns = ref sample 5 -> flight samples 10, 11 (mean 10.5 -> 10) -> t 1050
    assert list(out["label"]) == ["a", "b"]
    assert list(out["t_start_ns"]) == [1000, 1050] and out["t_end_ns"].iloc[0] == 1050


def test_a_boxless_flight_fitted_to_its_reference_gets_the_reference_maneuvers():
    psi_ref = np.radians(20.0)
    ref = synthetic_state(900, heading_rad=psi_ref)
    seg = synthetic_segments([(0, 12, "a"), (12, 24, "b"), (24, 36, "c")])
    other = synthetic_state(900, heading_rad=np.radians(80.0), seed=1)
    fit, carried = fit_to_reference(other, ref, seg, ref_heading_rad=psi_ref, sample_hz=5.0, fit_hz=1.0,
                                    headings=12, iterations=30)
    # the other flight's box axis is at 80 deg in its own NED: its box heading is 80 deg
    assert abs(np.degrees(fit.heading_rad) - 80.0) < 1.0
    assert list(carried["label"]) == ["a", "b", "c"]
    np.testing.assert_allclose(carried["t_start_ns"].to_numpy() * 1e-9, [0, 12, 24], atol=0.5)
    fd = flight_demos(other, carried, flight_id="o", fit=fit)
    assert fd.frame == "rigid" and len(fd.demos) == 3
    np.testing.assert_allclose(fd.demos[1].x[:, 1], 5.0 * np.sin(0.2 * fd.demos[1].t_ns * 1e-9), atol=0.5)


def _climb_and_schedule(heights, seconds_each=20, hz=1.0):
    """Ground roll, then a level-by-level vertical schedule, at ``hz`` (NED, D = -height)."""
    n = int(seconds_each * hz)
    h = np.concatenate([np.zeros(n)] + [np.full(n, float(v)) for v in heights] + [np.zeros(n)])
    t = np.arange(len(h)) / hz
    return np.column_stack([30 * np.cos(0.05 * t), 30 * np.sin(0.05 * t), -h])


def test_the_altitude_profile_check_ignores_rotation_translation_and_timing_but_not_the_schedule(rng):
    ref = _climb_and_schedule([100, 250, 80, 300, 150])
    # the same schedule flown slower, in another NED frame (rotated about down, shifted)
    same = _climb_and_schedule([100, 250, 80, 300, 150], seconds_each=26)
    same = same @ heading_rotation(np.radians(140.0)).T + np.array([500.0, -300.0, 0.0])
    other = _climb_and_schedule([250, 100, 300, 80, 150])
    assert altitude_profile_rms(same + 0.1 * rng.standard_normal(same.shape), ref) < 1.0
    assert altitude_profile_rms(other, ref) > 40.0
    # the ground roll is left out: a longer taxi before take-off changes nothing
    taxi = np.vstack([np.zeros((60, 3)), ref])
    assert altitude_profile_rms(taxi, ref) == pytest.approx(0.0, abs=1e-9)
    assert np.isnan(altitude_profile_rms(np.zeros((50, 3)), ref))


def test_the_fit_to_a_reference_reports_the_altitude_profile_check():
    psi_ref = np.radians(20.0)
    ref = synthetic_state(900, heading_rad=psi_ref)
    seg = synthetic_segments([(0, 12, "a"), (12, 24, "b"), (24, 36, "c")])
    other = synthetic_state(900, heading_rad=np.radians(80.0), seed=1)
    ts = np.arange(900) / 5.0
    for st in (ref, other):  # take off, climb to 150 m and land again
        st["pos_d_m"] = -150.0 * np.sin(np.pi * ts / ts[-1]) ** 2
    fit, _ = fit_to_reference(other, ref, seg, ref_heading_rad=psi_ref, sample_hz=5.0, fit_hz=1.0,
                              headings=12, iterations=30)
    p = lambda st: st.loc[::5, ["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy()
    assert np.isfinite(fit.altitude_rms_m)
    assert fit.altitude_rms_m == pytest.approx(altitude_profile_rms(p(other), p(ref)))
    fd = flight_demos(other, seg, flight_id="o", fit=fit)
    assert fd.diagnostics["fit_altitude_rms_m"] == pytest.approx(fit.altitude_rms_m)


@pytest.mark.parametrize("shape", ["K2", "2K", "pair"])
def test_paths_come_as_k_by_2_from_every_usual_shape(shape):
    from pipeline.align.demos import path_array

    p = np.array([[0, 0], [1, 0], [2, 1], [3, 2]])
    given = {"K2": p, "2K": p.T, "pair": (p[:, 0], p[:, 1])}[shape]
    np.testing.assert_array_equal(path_array(given), p)


def test_the_box_frame_is_centred_on_the_pilot_not_on_the_ned_origin():
    # FlightCoach's box is centred on the pilot (FlightAnalysis Box.from_fcjson_parmameters);
    # its N/E/D are about originLat/Lng/Alt, tens of metres away
    psi = np.radians(-33.7)
    pilot = np.array([35.5, -26.4, -2.8])
    st = synthetic_state(500, heading_rad=psi)
    for c, a in enumerate(("pos_n_m", "pos_e_m", "pos_d_m")):
        st[a] = st[a] + pilot[c]
    fd = flight_demos(st, synthetic_segments([(0, 8, "a")]), flight_id="f", heading_rad=psi, sample_hz=5.0,
                      box_origin_ned_m=pilot)
    x, ts = fd.demos[0].x, fd.demos[0].t_ns * 1e-9
    np.testing.assert_allclose(x[:, 0], 20.0 * ts, atol=0.05)
    np.testing.assert_allclose(x[:, 1], 5.0 * np.sin(0.2 * ts), atol=1e-9)
    np.testing.assert_allclose(x[:, 2], st["pos_d_m"].to_numpy()[::5][:len(x)] - pilot[2], atol=1e-9)
    assert fd.diagnostics["box_origin_ned_m"] == pytest.approx(list(pilot))
    # velocities are not shifted
    np.testing.assert_allclose(x[:, 3], 20.0, atol=0.5)


def test_the_pilot_position_of_a_flightcoach_log_is_its_box_origin_in_ned():
    from pipeline.preprocess.state import box_pilot_ned_m

    # P23 #036's parameters: FlightCoach's own moveNorth/moveEast shift (-E, -N of the pilot)
    # says the same within its rounding
    params = {"pilotLat": "51.6416694", "pilotLng": "-2.525727", "pilotAlt": 2.81, "originLat": 51.6413505,
              "originLng": -2.5253452, "originAlt": 0.04, "moveEast": -35.45999327314384,
              "moveNorth": 26.346327680554936}
    n, e, d = box_pilot_ned_m({"params": params})
    assert n == pytest.approx(-params["moveEast"], abs=0.05) and e == pytest.approx(-params["moveNorth"], abs=0.1)
    assert d == pytest.approx(-(2.81 - 0.04), abs=0.01)
    assert box_pilot_ned_m({"params": {"rotation": 0.1}}) is None and box_pilot_ned_m(None) is None


def test_a_box_less_flight_is_fitted_onto_the_reference_in_its_pilot_centred_box_frame():
    psi = np.radians(25.0)
    pilot = np.array([30.0, -20.0, 0.0])
    ref = synthetic_state(1500, heading_rad=psi, seed=1)
    for c, a in enumerate(("pos_n_m", "pos_e_m")):
        ref[a] = ref[a] + pilot[c]
    other = synthetic_state(1500, heading_rad=0.0, seed=2)  # the same schedule in its own NED
    seg = synthetic_segments([(0, 20, "a"), (20, 40, "b")])
    fit, carried = fit_to_reference(other, ref, seg, ref_heading_rad=psi, sample_hz=2.0, fit_hz=1.0,
                                    headings=12, iterations=10, ref_origin_ned_m=pilot)
    assert fit.rms_m < 1.0
    np.testing.assert_allclose(fit.translation_m, 0.0, atol=0.5)  # both already start at the box origin


def test_the_rigid_fit_of_a_log_with_extra_flying_before_the_schedule_fits_the_schedule_only():
    import pandas as pd

    def figure(st):  # a figure-of-eight with a climb: DTW pins it down, unlike a straight line
        ts = st["t_ns"].to_numpy() * 1e-9
        st["pos_n_m"], st["pos_e_m"] = 150.0 * np.sin(0.1 * ts), 100.0 * np.sin(0.2 * ts)
        st["pos_d_m"] = -100.0 - 20.0 * np.sin(0.3 * ts)
        return st

    ref = figure(synthetic_state(1500, seed=1))  # 60 s: take-off, two maneuvers, landing
    seg = synthetic_segments([(0, 4, "tkoff"), (4, 30, "a"), (30, 56, "b"), (56, 60, "lnd")])
    shift = np.array([40.0, -25.0, 5.0])
    sched = figure(synthetic_state(1500, seed=2))
    for c, a in enumerate(("pos_n_m", "pos_e_m", "pos_d_m")):
        sched[a] = sched[a] - shift[c]
    # 15 s of circling 200 m away before the schedule (the CSV logs' climb-out and circuits)
    loiter = synthetic_state(375, seed=3)
    w = np.arange(375) * 0.04 * 0.3
    loiter["pos_n_m"], loiter["pos_e_m"] = -150.0 + 40.0 * np.cos(w), 120.0 + 40.0 * np.sin(w)
    sched["t_ns"] = sched["t_ns"] + loiter["t_ns"].iloc[-1] + 40_000_000
    other = pd.concat([loiter, sched], ignore_index=True)
    kw = dict(ref_heading_rad=0.0, sample_hz=2.0, fit_hz=1.0, headings=12, iterations=20)
    whole, _ = fit_to_reference(other, ref, seg, **kw)
    fit, carried = fit_to_reference(other, ref, seg, **kw, schedule_exclude=("tkoff", "lnd"))
    # the loiter pulls the whole-flight fit (61 m RMS, translation 36 m off); the schedule's is
    # left with the one-pass uncertainty of the carried span (6 m, 2 m)
    assert whole.rms_m > 30.0 and np.linalg.norm(whole.translation_m - shift) > 20.0
    assert fit.rms_m < 10.0 and abs(fit.heading_rad) < 0.02
    np.testing.assert_allclose(fit.translation_m, shift, atol=3.0)
    assert list(carried["label"]) == ["a", "b"]
    start_a = int(carried.loc[carried["label"] == "a", "t_start_ns"].iloc[0])
    assert abs(start_a - (int(sched["t_ns"].iloc[0]) + 4_000_000_000)) <= 500_000_000
