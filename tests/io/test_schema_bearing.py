"""The issue-16 bearing stream and the bearing-only estimate tables, declared in schema.py."""

from __future__ import annotations

import numpy as np

from pipeline.io import schema
from pipeline.io.base import FlightLog


def test_the_bearing_stream_has_the_common_columns_then_azimuth_and_sigma():
    assert "bearing" in schema.STREAM_NAMES and "bearing" in schema.SENSOR_STREAMS
    assert schema.STREAMS_1_2 == ("bearing",)
    assert schema.column_names("bearing") == ["t_ns", "instance", "src", "t_boot_ns", "az_rad", "sigma_rad"]
    assert "source" not in schema.column_names("bearing")          # the source is the common src


def test_a_bearing_stream_conforms_with_its_observer_as_instance():
    log = FlightLog.from_streams({}, {"bearing": {"t_ns": np.array([0, 50_000_000]), "instance": np.uint8(2),
                                                  "src": "vision", "az_rad": np.array([0.1, 0.2]),
                                                  "sigma_rad": np.radians([0.2, 0.2])}})
    b = log["bearing"]
    assert list(b["instance"]) == [2, 2] and list(b["src"]) == ["vision", "vision"]


def test_the_estimate_table_holds_the_cppv_state_its_upper_covariance_and_the_mode_probabilities():
    names = schema.column_names("bearing_estimate")
    assert names[:6] == ["t_ns", "x_rel_n_m", "x_rel_e_m", "x_speed_mps", "x_course_rad", "x_omega_radps"]
    assert sum(n.startswith("P_") for n in names) == 15
    assert {"nis", "mode_p_cv", "mode_p_ct"} <= set(names)
    assert schema.column_names("bearing_weights")[:3] == ["t_ns", "filter", "weight"]
