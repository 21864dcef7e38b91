"""FlightCoach JSON reader: the four real files against the JSON itself and pymap3d."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from helpers import realdata_file
from pipeline.frames.rotations import euler_to_quat
from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.parquet import read_flightlog, write_flightlog
from pipeline.io.flightcoach import FlightCoachReader

REAL = [
    "flightcoach_f3a_json/manual_F3A_P23_22_02_18_00000036.json",
    "flightcoach_f3a_json/manual_F3A_P23_22_05_31_00000350.json",
    "flightcoach_f3a_json/manual_F3A_F23_22_02_18_00000035.json",
    "flightcoach_f3a_json/UK_England_Bristol_AMARC2002_F3A_P21_21_08_12_00000026.json",
]


@pytest.fixture(scope="module", params=REAL, ids=["P23_36", "P23_350", "F23_35", "P21_26"])
def real(request):
    p = realdata_file(request.param)
    obj = json.loads(p.read_text())
    return p, obj, pd.DataFrame(obj["data"]), registry.read_log(p)


def test_detected_and_timed(real):
    p, obj, data, log = real
    assert log.meta["reader"] == "flightcoach"
    assert log.meta["status"] == "ok"
    t_us = data["time"].to_numpy(np.int64)
    for s in ("local_position", "attitude", "gps"):
        np.testing.assert_array_equal(log[s]["t_ns"], (t_us - t_us[0]) * 1000)
        np.testing.assert_array_equal(log[s]["t_boot_ns"].to_numpy(np.int64), t_us * 1000)
    assert log.meta["t0_boot_ns"] == t_us[0] * 1000
    dt_ms = np.diff(t_us) / 1000
    assert 38.0 < dt_ms.min() and dt_ms.max() < 42.0  # ~25 Hz with 38.8-41.6 ms jitter (README)


def test_positions_and_velocities_exact(real):
    _, _, data, log = real
    lp = log["local_position"]
    for src, col in (("N", "pos_n_m"), ("E", "pos_e_m"), ("D", "pos_d_m"),
                     ("VN", "vel_n_mps"), ("VE", "vel_e_mps"), ("VD", "vel_d_mps")):
        np.testing.assert_array_equal(lp[col].to_numpy(), data[src].to_numpy(np.float64))


def test_attitude_from_radian_angles(real):
    _, _, data, log = real
    q = log["attitude"][["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    want = euler_to_quat(data["roll"], data["pitch"], data["yaw"])
    np.testing.assert_allclose(q, want, rtol=0, atol=1e-15)
    # independent oracle: SciPy's intrinsic ZYX rotation (scalar-last quaternion), up to sign
    sq = Rotation.from_euler("ZYX", np.c_[data["yaw"], data["pitch"], data["roll"]]).as_quat()
    dot = np.abs(np.einsum("ij,ij->i", q, np.c_[sq[:, 3], sq[:, :3]]))
    np.testing.assert_allclose(dot, 1.0, atol=1e-12)
    # r/p/yw are the same angles in degrees (rounded to 0.01 deg), not body rates
    for rad, deg in (("roll", "r"), ("pitch", "p"), ("yaw", "yw")):
        d = (np.degrees(data[rad]) - data[deg] + 180) % 360 - 180
        assert np.abs(d).max() <= 0.0051


def test_gps_from_origin_matches_pymap3d(real):
    _, obj, data, log = real
    par = obj["parameters"]
    lat0, lon0, h0 = par["originLat"], par["originLng"], par["originAlt"]
    g = log["gps"]
    lat, lon, h = pymap3d.ned2geodetic(data["N"], data["E"], data["D"], lat0, lon0, h0)
    m_per_deg = 111_320.0
    assert np.abs(g["lat_deg"] - lat).max() * m_per_deg < 1e-3
    assert np.abs(g["lon_deg"] - lon).max() * m_per_deg * np.cos(np.radians(lat0)) < 1e-3
    assert np.abs(g["alt_msl_m"] - h).max() < 1e-3
    # and back: pymap3d's inverse reproduces N, E, D to < 1 mm
    n, e, d = pymap3d.geodetic2ned(g["lat_deg"], g["lon_deg"], g["alt_msl_m"], lat0, lon0, h0)
    for got, want in ((n, "N"), (e, "E"), (d, "D")):
        assert np.abs(np.asarray(got) - data[want].to_numpy()).max() < 1e-3
    assert g["alt_wgs84_m"].isna().all()
    o = log.meta["ned_origin"]
    assert (o["lat_deg"], o["lon_deg"], o["alt_msl_m"], o["alt_wgs84_m"]) == (lat0, lon0, h0, None)


def test_labels_one_row_per_maneuver(real):
    p, obj, data, log = real
    lab = log["labels"]
    mans = obj["mans"]
    t_ns = (data["time"].to_numpy(np.int64) - int(data["time"].iloc[0])) * 1000
    assert len(lab) == len(mans)
    assert list(lab["label"]) == [m["name"] for m in mans]
    np.testing.assert_array_equal(lab["t_start_ns"], [t_ns[m["start"]] for m in mans])
    np.testing.assert_array_equal(lab["t_end_ns"], [t_ns[min(m["stop"], len(t_ns) - 1)] for m in mans])
    assert set(lab["source"]) == {"flightcoach_mans"}
    assert (lab["t_end_ns"] > lab["t_start_ns"]).all()
    assert lab["label"].iloc[0] in ("tkOf", "tkoff")
    if "_P23_" in p.name:  # the P23 schedule flies hB twice (README)
        assert (lab["label"] == "hB").sum() == 2


def test_meta_params_and_wind(real):
    p, obj, data, log = real
    par = obj["parameters"]
    assert log.meta["params"]["box_rotation_rad"] == par["rotation"]
    assert log.meta["params"]["schedule"] == par["schedule"]
    fc = log.meta["flightcoach"]
    assert ("wind" in fc) == ("wN" in data.columns)
    for df in log.streams.values():
        assert not any(c in df.columns for c in ("wN", "wE", "r", "p", "yw"))


# --- synthetic ------------------------------------------------------------------------------------

def _doc(n=10, **over):
    data = [{"time": 1_000_000 + 40_000 * i, "N": float(i), "E": -2.0 * i, "D": -10.0 - i,
             "VN": 1.0, "VE": -2.0, "VD": -1.0, "r": 10.0, "p": 5.0, "yw": 90.0} for i in range(n)]
    doc = {"version": "1.2", "parameters": {"rotation": 0.5, "originLat": 51.5, "originLng": -2.5,
                                            "originAlt": 5.0},
           "mans": [{"name": "tkoff", "start": 0, "stop": 4}, {"name": "loop", "start": 4, "stop": n}],
           "data": data}
    doc.update(over)
    return doc


def test_text_in_an_optional_field_is_a_missing_value_counted_per_column(tmp_path):
    doc = _doc()
    doc["data"][2]["VN"] = "n/a"
    doc["data"][5]["VN"] = "fast"
    doc["data"][3]["N"] = "x"          # a required field: the sample goes (bad_sample), no double count
    doc["data"][3]["VE"] = "y"
    p = tmp_path / "fc.json"
    p.write_text(json.dumps(doc))
    log = registry.read_log(p)
    assert log.meta["diagnostics"]["records_dropped"] == {"bad_sample": 1, "bad_value:VN": 2}
    vn = log["local_position"]["vel_n_mps"]
    assert vn.isna().sum() == 2 and len(vn) == 9


def test_synthetic_degrees_only_bad_sample_and_bad_maneuver(tmp_path):
    doc = _doc()
    doc["data"][3]["N"] = None
    doc["mans"].append({"name": "bogus", "start": 5, "stop": 99})
    p = tmp_path / "fc.json"
    p.write_text(json.dumps(doc))
    log = registry.read_log(p)
    d = log.meta["diagnostics"]
    assert d["records_dropped"] == {"bad_sample": 1, "bad_maneuver": 1}
    assert log.meta["status"] == "partial"
    assert len(log["local_position"]) == 9
    q = log["attitude"][["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    np.testing.assert_allclose(q, euler_to_quat(np.radians(10.0), np.radians(5.0), np.radians(90.0))[None].repeat(9, 0),
                               atol=1e-15)
    lab = log["labels"]
    assert list(lab["label"]) == ["tkoff", "loop"]
    # stop == len(data) is the exclusive end: clipped to the last sample
    assert list(lab["t_end_ns"]) == [160_000_000, 360_000_000]
    back = read_flightlog(write_flightlog(log, tmp_path / "store")[0].parent)
    for name, df in log.streams.items():
        pd.testing.assert_frame_equal(back[name], df)
    assert back.meta["params"]["box_rotation_rad"] == 0.5


def test_sniff(tmp_path):
    head = json.dumps(_doc()).encode()[:4096]
    assert FlightCoachReader.sniff(tmp_path / "x.json", head)
    assert FlightCoachReader.sniff(tmp_path / "x.json", b'{"data": [1, 2, 3]}') is None
    assert FlightCoachReader.sniff(tmp_path / "x.json", b'[{"mans": 1, "parameters": 2}]') is None


@pytest.mark.parametrize("text, reason", [
    ('{"parameters": {"originLat": 1}, "mans": [], "data": []}', "no 'data' samples"),
    ('{"parameters": {"originLat": 1}, "mans": [], "data": [{"time": 1, "N": 0}]}', r"lack field\(s\) \['E', 'D'\]"),
    ('{"parameters": {"originLat": 1}, "mans": [], "data": [{"time": 1, "N": 0, "E": 0, "D": "x"}]}',
     "no FlightCoach sample has finite"),
    ('{"parameters": {"originLat": 1}, "mans": 3, "data": [{"time": 1, "N": 0, "E": 0, "D": 0}]}',
     "'mans' must be a list"),
])
def test_structural_errors(tmp_path, text, reason):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(IngestError, match=f"bad.json: .*{reason}"):
        registry.read_log(p)


def test_a_binary_file_forced_through_the_reader_names_its_first_non_utf8_byte(tmp_path):
    # json.loads took these bytes for UTF-16 and said "truncated data at byte 13": not the reason
    p = tmp_path / "log.tlog"
    p.write_bytes(b"\x00\x05\xbf\x12" + bytes(range(256)) * 4 + b"\x01")   # odd length: UTF-16 "truncated"
    with pytest.raises(IngestError, match=r"log\.tlog: not UTF-8 text: byte 0xbf at offset 2 \(a binary file, "
                                          r"not FlightCoach JSON\?\)$"):
        FlightCoachReader().read(p)



def test_utf8_bytes_with_nul_near_the_start_are_said_to_be_no_json_not_no_utf8(tmp_path):
    p = tmp_path / "nul.json"
    p.write_bytes(b'{\x00"a": 1}')
    with pytest.raises(IngestError, match=r"nul\.json: invalid JSON: a NUL byte at offset 1 \(a binary file"):
        FlightCoachReader().read(p)
