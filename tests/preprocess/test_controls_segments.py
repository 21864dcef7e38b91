"""Controls normalisation, seed-004 physical controls, mount rotation, segments."""

import numpy as np
import pandas as pd
import pytest

from pipeline.config import load_config
from pipeline.frames.rotations import euler_to_dcm
from pipeline.preprocess.controls import controls_from_pwm, normalise_stick
from pipeline.preprocess.mount import apply_mount, mount_dcm
from pipeline.preprocess.segment import build_segments
from pipeline.preprocess.state import PreprocessConfig


def test_stick_normalisation_piecewise_about_trim():
    spec = {"min_us": 1000, "trim_us": 1400, "max_us": 2000}
    np.testing.assert_allclose(normalise_stick([1000, 1200, 1400, 1700, 2000, 2500, 0], spec),
                               [-1, -0.5, 0, 0.5, 1, 1, np.nan])
    np.testing.assert_allclose(normalise_stick([1000, 1700], {**spec, "reverse": True}), [1, -0.5])
    np.testing.assert_allclose(normalise_stick([900, 1100, 1500, 1900, 2000], {"min_us": 1100, "max_us": 1900},
                                               unipolar=True), [0, 0, 0.5, 1, 1])


def test_seed004_physical_controls_from_config():
    cfg = PreprocessConfig.from_config(load_config(), vehicle="yak54")
    u = pd.DataFrame({"rc_1_us": [1150.0, 2100.0, 1552.0], "rc_2_us": [900.0, 2100.0, 1508.3],
                      "rc_3_us": [1500.0, 2100.0, 1012.0], "rc_4_us": [1000.0, 2000.0, 1516.8]})
    c = controls_from_pwm(u, cfg.controls, cfg.physical)
    # thesis §6.8: aileron +0.931 rad at 1150 µs, -0.790 at 2100, 0 near 1552
    np.testing.assert_allclose(c["delta_a_rad"], [0.931, -0.790, 0.0], atol=2e-3)
    # elevator -1.2387..+1.2051 rad over 900..2100 µs; rudder -1.344..+1.2564
    np.testing.assert_allclose(c["delta_e_rad"], [-1.2387, 1.2051, 0.0], atol=1e-3)
    np.testing.assert_allclose(c["delta_r_rad"], [-1.344, 1.2564, 0.0], atol=1e-3)
    # corrected thrust sign: 6.33 N at 1500, 10.02 N at 2100, ~0 at 1012 (and never negative)
    np.testing.assert_allclose(c["thrust_N"], [6.33, 10.02, 0.0], atol=0.02)
    assert controls_from_pwm(pd.DataFrame({"rc_3_us": [950.0]}), cfg.controls, cfg.physical)["thrust_N"][0] == 0.0
    assert c["thr"].between(0, 1).all() and c["ail"].between(-1, 1).all()


def test_mount_husky_gravity_and_yaw_axis():
    cfg = PreprocessConfig.from_config(load_config(), flight_id="husky-ros1")
    assert cfg.vehicle == "husky"
    # raw imu_link specific force at rest ≈ (0, +9.79, -0.01) FLU -> (0, -9.79, +0.01) as ingested (FRD)
    imu = pd.DataFrame({"acc_x_mps2": [0.0], "acc_y_mps2": [-9.79], "acc_z_mps2": [0.01],
                        "gyr_x_radps": [0.0], "gyr_y_radps": [0.0], "gyr_z_radps": [0.0]})
    out = apply_mount(imu, cfg.imu_mount)
    np.testing.assert_allclose(out[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy()[0],
                               [0.01, 0.0, -9.79], atol=1e-9)  # Rz(-90) Rx(90) (0, 9.79, -0.01) = (0.01, 0, 9.79) FLU
    # seed 004's vertical IMU: a 90° rotation about body x
    np.testing.assert_allclose(mount_dcm({"dcm": [[1, 0, 0], [0, 0, -1], [0, 1, 0]]}),
                               euler_to_dcm(np.pi / 2, 0, 0), atol=1e-12)
    with pytest.raises(ValueError):
        mount_dcm({"dcm": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]})


def test_segments_from_labels_windows_modes():
    labels = pd.DataFrame({"t_start_ns": [5, 1], "t_end_ns": [9, 4], "label": ["b", "a"], "source": "x"})
    mode = pd.DataFrame({"t_ns": [0, 10, 20, 30], "mode": pd.array(["STAB", "STAB", "LOITER", "RTL"], dtype="string")})
    s = build_segments(labels, mode)
    assert s["label"].tolist() == ["a", "b"] and s["segment_id"].tolist() == [0, 1]
    s = build_segments(None, mode, t_end_ns=40)
    assert s["label"].tolist() == ["mode:STAB", "mode:LOITER", "mode:RTL"]
    assert s["t_start_ns"].tolist() == [0, 20, 30] and s["t_end_ns"].tolist() == [20, 30, 40]
    s = build_segments(None, mode, windows=[{"start_s": 1, "end_s": 2.5, "label": "hover"}])
    assert s.iloc[0].tolist() == [0, 1_000_000_000, 2_500_000_000, "hover"]
    assert len(build_segments(labels, mode, source="all")) == 5
    with pytest.raises(ValueError, match="end_s"):
        build_segments(None, None, windows=[{"start_s": 3, "end_s": 2}])
    assert len(build_segments(None, None)) == 0


def test_segments_from_simulation_truth_labels():
    truth = pd.DataFrame({"t_ns": np.arange(6) * 10, "label": pd.array(["hover", "hover", "m1", "m1", None, "m1"],
                                                                       dtype="string")})
    s = build_segments(None, None, truth=truth)
    assert s["label"].tolist() == ["hover", "m1"]
    assert s["t_start_ns"].tolist() == [0, 20] and s["t_end_ns"].tolist() == [20, 50]
    # an explicit labels stream wins under `auto`
    labels = pd.DataFrame({"t_start_ns": [0], "t_end_ns": [5], "label": ["x"], "source": "simulation_truth"})
    assert build_segments(labels, None, truth=truth)["label"].tolist() == ["x"]


def test_mode_segments_end_with_the_flight_and_none_lies_after_it():
    # the mode stream runs on past the state grid (7 s): segment B was 5-10 s and C 10-10 s
    mode = pd.DataFrame({"t_ns": [0, 5_000_000_000, 10_000_000_000], "mode": ["A", "B", "C"]})
    seg = build_segments(None, mode, t_end_ns=7_000_000_000)
    assert seg["label"].tolist() == ["mode:A", "mode:B"]
    assert seg["t_end_ns"].tolist() == [5_000_000_000, 7_000_000_000]
    # a flight longer than its last mode change: the last segment still runs to the end
    seg = build_segments(None, mode, t_end_ns=12_000_000_000)
    assert seg["t_end_ns"].tolist() == [5_000_000_000, 10_000_000_000, 12_000_000_000]


def test_a_labels_row_ending_before_it_starts_is_dropped_and_counted_in_the_notes():
    labels = pd.DataFrame({"t_start_ns": [0, 50, 20], "t_end_ns": [10, 40, 30], "label": ["a", "bad", "c"],
                           "source": "x"})
    notes: list[str] = []
    s = build_segments(labels, None, notes=notes)
    assert s["label"].tolist() == ["a", "c"] and s["segment_id"].tolist() == [0, 1]
    assert len(notes) == 1 and "1 of 3 rows dropped" in notes[0] and "'bad'" in notes[0]
    # every row invalid: `auto` falls through to the next source, still saying why
    notes.clear()
    mode = pd.DataFrame({"t_ns": [0, 10], "mode": pd.array(["STAB", "RTL"], dtype="string")})
    s = build_segments(labels.iloc[[1]], mode, t_end_ns=20, notes=notes)
    assert s["label"].tolist() == ["mode:STAB", "mode:RTL"] and "1 of 1 rows dropped" in notes[0]
    # with nowhere to count the drop, the row is an error naming it, not a silent loss
    with pytest.raises(ValueError, match=r"1 of 3 rows dropped.*row 1, label 'bad'"):
        build_segments(labels, None)
