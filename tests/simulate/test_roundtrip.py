"""Simulated flights written as .bin / .tlog / ROS 1 bag / ROS 2 MCAP bag: read back by our ingest
and by the independent libraries (pymavlink, rosbags, mcap); sensor streams recovered within a
per-field quantisation table; same seed -> same bytes."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from pipeline.io.registry import read_log
from pipeline.io.sidecar import find_sidecar, sidecar_path
from pipeline.simulate.scenarios import SimSettings, run_scenario, scenario_for
from pipeline.simulate.sensors import SensorSettings
from pipeline.simulate.writers import write_flight

T0_UTC_NS = 1767268800 * 10 ** 9
CFG = {"rate_hz": 100, "sensors": {"imu": {"rate_hz": 100}, "gps": {"dropout_count": 1, "dropout_s": 2.0}}}

#: (format, stream, column) -> absolute tolerance of the stored encoding (see writers.py)
QUANT: dict[str, dict[str, dict[str, float]]] = {
    "bin": {
        "imu": {"gyr_x_radps": 1e-6, "gyr_y_radps": 1e-6, "gyr_z_radps": 1e-6,
                "acc_x_mps2": 1e-5, "acc_y_mps2": 1e-5, "acc_z_mps2": 1e-5},
        "gps": {"lat_deg": 6e-8, "lon_deg": 6e-8, "alt_msl_m": 0.0051, "alt_wgs84_m": 0.0051,
                "vel_n_mps": 1e-4, "vel_e_mps": 1e-4, "vel_d_mps": 1e-5},
        "baro": {"alt_rel_m": 1e-4, "press_Pa": 0.01, "temp_degC": 0.0051},
        "attitude": {"q_w": 1e-4, "q_x": 1e-4, "q_y": 1e-4, "q_z": 1e-4},
        "rangefinder": {"dist_m": 0.0051},
        "control": {"rc_1_us": 0, "rc_2_us": 0, "rc_3_us": 0, "rc_4_us": 0,
                    "servo_1_us": 0, "servo_2_us": 0, "servo_3_us": 0, "servo_4_us": 0},
        "radar": {"range_m": 2e-4, "dcos_u": 1e-7, "dcos_v": 1e-7, "range_rate_mps": 1e-5},
    },
    "tlog": {
        "imu": {"gyr_x_radps": 5.1e-4, "gyr_y_radps": 5.1e-4, "gyr_z_radps": 5.1e-4,
                "acc_x_mps2": 0.0050, "acc_y_mps2": 0.0050, "acc_z_mps2": 0.0050},
        "gps": {"lat_deg": 6e-8, "lon_deg": 6e-8, "alt_msl_m": 5.1e-4, "alt_wgs84_m": 5.1e-4,
                "vel_n_mps": 0.01, "vel_e_mps": 0.01},
        "baro": {"press_Pa": 0.01, "temp_degC": 0.0051},
        "attitude": {"q_w": 1e-6, "q_x": 1e-6, "q_y": 1e-6, "q_z": 1e-6},
        "rangefinder": {"dist_m": 0.0051},
        "control": {"rc_1_us": 0, "rc_2_us": 0, "rc_3_us": 0, "rc_4_us": 0,
                    "servo_1_us": 0, "servo_2_us": 0, "servo_3_us": 0, "servo_4_us": 0},
    },
    "bag": {
        "imu": {c: 1e-12 for c in ("gyr_x_radps", "gyr_y_radps", "gyr_z_radps",
                                   "acc_x_mps2", "acc_y_mps2", "acc_z_mps2")},
        "gps": {"lat_deg": 1e-12, "lon_deg": 1e-12, "alt_wgs84_m": 1e-9},
        "baro": {"press_Pa": 1e-9},
        "attitude": {"q_w": 1e-12, "q_x": 1e-12, "q_y": 1e-12, "q_z": 1e-12},
        "rangefinder": {"dist_m": 1e-6},  # sensor_msgs/Range.range is float32
        "radar": {"range_m": 1e-9, "dcos_u": 1e-15, "dcos_v": 1e-15, "range_rate_mps": 1e-12},
    },
}
QUANT["mcap"] = QUANT["bag"]
FORMATS = ("bin", "tlog", "bag", "mcap")


def _flight(out: Path, seed: int):
    st = SimSettings.from_config(CFG)
    se = SensorSettings.from_config(CFG)
    sc = scenario_for("maneuver", st, "M3")
    rng = np.random.default_rng(seed)
    tr = run_scenario(sc, st, 1, rng)
    return write_flight(out, "flight", tr, se, st.vehicle, st.rate_hz, rng, t0_utc_ns=T0_UTC_NS)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    base = tmp_path_factory.mktemp("simlogs")
    a = _flight(base / "a", 5)
    b = _flight(base / "b", 5)
    c = _flight(base / "c", 6)
    return a, b, c


def _digest(p: Path) -> str:
    h = hashlib.sha256()
    files = sorted(x for x in p.rglob("*") if x.is_file()) if p.is_dir() else [p]
    for f in files:
        h.update(f.name.encode() + f.read_bytes())
    return h.hexdigest()


@pytest.mark.parametrize("fmt", FORMATS)
def test_same_seed_same_bytes(written, fmt):
    (pa, _), (pb, _), (pc, _) = written
    assert _digest(pa[fmt]) == _digest(pb[fmt])
    assert _digest(sidecar_path(pa[fmt])) == _digest(sidecar_path(pb[fmt]))
    assert _digest(pa[fmt]) != _digest(pc[fmt])
    assert _digest(sidecar_path(pa[fmt])) != _digest(sidecar_path(pc[fmt]))


@pytest.mark.parametrize("fmt", FORMATS)
def test_ingest_recovers_streams(written, fmt):
    (paths, sim), _, _ = written
    log = read_log(paths[fmt])
    assert log.meta["status"] == "ok", log.meta["diagnostics"]
    assert not log.meta["diagnostics"]["bytes_skipped"]
    for stream, cols in QUANT[fmt].items():
        got = log[stream]
        ref = sim[stream]
        if stream == "control":  # one row per source message: compare each message's columns
            got = got.groupby("t_ns", as_index=False).first()
        m = ref.merge(got, on="t_ns", suffixes=("_ref", "_got"))
        assert len(m) == len(ref), (fmt, stream, len(m), len(ref))
        assert len(m) > 0, (fmt, stream)
        if stream == "rangefinder":
            np.testing.assert_array_equal(m["valid_got"].to_numpy(bool), m["valid_ref"].to_numpy(bool))
            # M3 flies at 40-70 m, above the rangefinder's 6 m max_m: every reading is out of range
            # by design and out-of-range readings differ by design (clipped / +inf / 601 cm), so
            # only the validity is compared (should the flight ever get valid readings, this
            # assert fails: then compare their dist_m against QUANT)
            assert not m["valid_ref"].to_numpy(bool).any(), (fmt, "rangefinder now has valid readings")
            continue
        for col, tol in cols.items():
            a, b = m[f"{col}_got"].to_numpy(float), m[f"{col}_ref"].to_numpy(float)
            if col.startswith("q_"):  # q and -q are the same rotation
                sgn = np.sign(np.sum(m[[f"q_{c}_got" for c in "wxyz"]].to_numpy() *
                                     m[[f"q_{c}_ref" for c in "wxyz"]].to_numpy(), axis=1))
                a = a * sgn
            err = np.max(np.abs(a - b))  # no initial: an empty comparison raises
            assert err <= tol + 1e-12, (fmt, stream, col, err)
    # the truth side-car came along by name, on the same time base
    assert find_sidecar(paths[fmt]) == sidecar_path(paths[fmt])
    tr = log["truth"]
    assert len(tr) == 2801 and set(tr["label"].astype(str)) == {"M3"}  # 3 s transition + 25 s at 100 Hz
    assert list(log["labels"]["label"]) == ["M3"]
    assert log.meta.get("labels_path") == str(sidecar_path(paths[fmt]))
    assert not any("shifted" in w for w in log.meta["diagnostics"]["warnings"])


def test_the_bin_and_the_tlog_give_the_same_ned_origin_so_their_states_share_the_truths_frame(written):
    # the DataFlash log has its ORGN; the tlog now carries GPS_GLOBAL_ORIGIN as ArduPilot sends
    # it (before, the tlog reader fell back to the first fix and its NED sat ~560 m off truth)
    (paths, _), _, _ = written
    se = SensorSettings.from_config(CFG)
    ob, ot = (read_log(paths[f]).meta["ned_origin"] for f in ("bin", "tlog"))
    assert ot["source"] == "GPS_GLOBAL_ORIGIN" and ob["source"] == "ORGN"
    assert ot["lat_deg"] == pytest.approx(se.origin[0], abs=1e-7) == pytest.approx(ob["lat_deg"], abs=1e-7)
    assert ot["lon_deg"] == pytest.approx(ob["lon_deg"], abs=1e-7)
    assert ot["alt_msl_m"] == pytest.approx(ob["alt_msl_m"], abs=1e-3)
    assert ot["alt_msl_m"] == pytest.approx(se.origin[2] - se.geoid_undulation_m, abs=1e-3)


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_a_ros_flight_takes_its_side_cars_origin_so_its_state_shares_the_truths_frame(written, fmt):
    # a ROS bag carries no navigation origin: its reader's first fix sat ~560 m from the truth's
    # origin; the side-car records that origin (and the radar site) and ingest adopts it
    (paths, _), _, _ = written
    se = SensorSettings.from_config(CFG)
    meta = read_log(paths[fmt]).meta
    o = meta["ned_origin"]
    assert o["source"] == "truth side-car"
    assert (o["lat_deg"], o["lon_deg"], o["alt_wgs84_m"]) == pytest.approx(se.origin, abs=1e-9)
    assert o["alt_msl_m"] == pytest.approx(se.origin[2] - se.geoid_undulation_m, abs=1e-9)
    assert meta["radar"]["site_ned_m"] == list(se.radar.site_ned_m)
    assert any("NED origin from the truth side-car" in w for w in meta["diagnostics"]["warnings"])


def test_gps_dropout_gap(written):
    (paths, sim), _, _ = written
    t = sim["gps"]["t_ns"].to_numpy() * 1e-9
    gaps = np.diff(t)
    big = gaps[gaps > 0.15]
    assert len(big) == 1 and big[0] == pytest.approx(2.0 + 0.1, abs=0.101)


def test_bin_radar_params_and_pymavlink(written):
    from pymavlink import mavutil

    (paths, sim), _, _ = written
    log = read_log(paths["bin"])
    assert log.meta["radar"]["site_ned_m"] == [0.0, 0.0, 0.0] and log.meta["radar"]["tau_rd_s"] == 0.0
    m = mavutil.mavlink_connection(str(paths["bin"]))
    counts: dict[str, int] = {}
    while (msg := m.recv_match()) is not None:
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    m.close()
    assert counts["RADR"] == len(sim["radar"]) and counts["IMU"] == len(sim["imu"])
    assert counts["GPS"] == len(sim["gps"]) and counts["BARO"] == len(sim["baro"])


def test_bin_declares_exactly_the_catalogue_ardupilot4_layout(written):
    from pymavlink import mavutil

    from pipeline.io.dataflash import catalogue as cat

    (paths, _), _, _ = written
    m = mavutil.mavlink_connection(str(paths["bin"]))
    fmts = {}
    while (msg := m.recv_match(type="FMT")) is not None:
        fmts[msg.Name] = (msg.Type, msg.Format, msg.Columns)
    m.close()
    want = {d.name: (d.type_id, d.fmt, d.labels) for d in (*cat.layout("ardupilot4"), cat.UNIT, cat.MULT, cat.FMTU)}
    assert fmts == {"FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"), **want}


def test_tlog_pymavlink(written):
    from pymavlink import mavutil

    (paths, sim), _, _ = written
    m = mavutil.mavlink_connection(str(paths["tlog"]))
    counts: dict[str, int] = {}
    while (msg := m.recv_match()) is not None:
        assert msg.get_type() != "BAD_DATA"
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    m.close()
    assert counts["SCALED_IMU"] == len(sim["imu"]) and counts["GPS_RAW_INT"] == len(sim["gps"])
    assert counts["ATTITUDE"] == len(sim["attitude"])


@pytest.mark.parametrize("fmt", ["bag", "mcap"])
def test_rosbags_reads_with_stored_radar_definition(written, fmt):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    (paths, sim), _, _ = written
    # an empty-ish store: the Radar type must come from the bag's own stored definition
    with AnyReader([paths[fmt]], default_typestore=get_typestore(Stores.LATEST)) as r:
        conns = [c for c in r.connections if c.topic == "/radar"]
        assert conns and conns[0].msgtype == "uavpipe_msgs/msg/Radar"
        rng = [r.deserialize(raw, c.msgtype).range for c, _, raw in r.messages(connections=conns)]
        n = {c.topic: c.msgcount for c in r.connections}
    np.testing.assert_allclose(rng, sim["radar"]["range_m"].to_numpy(), rtol=0, atol=1e-9)
    assert n["/imu"] == len(sim["imu"]) and n["/gps/fix"] == len(sim["gps"])


def test_mcap_library_reads(written):
    from mcap.reader import make_reader

    (paths, sim), _, _ = written
    files = list(paths["mcap"].glob("*.mcap"))
    assert len(files) == 1
    with open(files[0], "rb") as fh:
        reader = make_reader(fh)
        summ = reader.get_summary()
        schemas = {s.name: s for s in summ.schemas.values()}
        assert "uavpipe_msgs/msg/Radar" in schemas
        assert b"float64 range_rate" in schemas["uavpipe_msgs/msg/Radar"].data
        n = sum(1 for _ in reader.iter_messages(topics=["/radar"]))
    assert n == len(sim["radar"])


@pytest.fixture(scope="module")
def cal_written(tmp_path_factory):
    st = SimSettings.from_config(CFG)
    se = SensorSettings.from_config(CFG)
    sc = scenario_for("calibration", st)
    rng = np.random.default_rng(8)
    tr = run_scenario(sc, st, 1, rng, vel0_zero=True, vertical_disturbance=False)
    return write_flight(tmp_path_factory.mktemp("simcal"), "cal", tr, se, st.vehicle, st.rate_hz, rng,
                        t0_utc_ns=T0_UTC_NS)


@pytest.mark.slow  # a second simulated flight (~3 s); the M3 flight's round trips stay in the fast lane
@pytest.mark.parametrize("fmt", FORMATS)
def test_calibration_flight_rangefinder_roundtrip(cal_written, fmt):
    paths, sim = cal_written
    log = read_log(paths[fmt], config={"ros": {"topics": {"/rangefinder": {"stream": "rangefinder",
                                                                          "orientation": 25}}}})
    ref, got = sim["rangefinder"], log["rangefinder"]
    m = ref.merge(got, on="t_ns", suffixes=("_ref", "_got"))
    assert len(m) == len(ref)
    valid = m["valid_ref"].to_numpy(bool)
    assert valid.sum() > 100 and (~valid).sum() > 100  # hovers in range, climb-out beyond 6 m
    np.testing.assert_array_equal(m["valid_got"].to_numpy(bool), valid)
    tol = QUANT[fmt]["rangefinder"]["dist_m"]
    assert np.max(np.abs(m["dist_m_got"][valid] - m["dist_m_ref"][valid])) <= tol + 1e-12
    hover = [lab for lab in log["labels"]["label"] if lab == "hover"]
    assert len(hover) >= 2


@pytest.mark.slow  # a second simulated flight in four formats (~1 s)
def test_a_longer_range_rangefinder_keeps_its_configured_limits_in_every_format(tmp_path):
    # the tlog and ROS writers wrote fixed 0.17-6 m limits, and the readers judge validity by
    # the limits in the file: with max_m 200 every reading of the M3 flight (40-70 m up) came
    # back invalid in .tlog, .bag and MCAP while the .bin kept them
    cfg = {**CFG, "sensors": {**CFG["sensors"], "rangefinder": {"max_m": 200.0, "min_m": 0.3}}}
    st, se = SimSettings.from_config(cfg), SensorSettings.from_config(cfg)
    rng = np.random.default_rng(5)
    tr = run_scenario(scenario_for("maneuver", st, "M3"), st, 1, rng)
    paths, sim = write_flight(tmp_path, "far", tr, se, st.vehicle, st.rate_hz, rng, t0_utc_ns=T0_UTC_NS,
                              formats=("bin", "tlog", "bag", "mcap"))
    want = sim["rangefinder"]["valid"].to_numpy(dtype=bool)
    assert want.mean() > 0.9                      # the flight is inside the longer range
    for fmt, p in paths.items():
        rf = read_log(p)["rangefinder"]
        assert len(rf) == len(want), fmt
        np.testing.assert_array_equal(rf["valid"].to_numpy(dtype=bool), want, err_msg=fmt)
        ok = want
        np.testing.assert_allclose(rf["dist_m"].to_numpy()[ok], sim["rangefinder"]["dist_m"].to_numpy()[ok],
                                   atol=QUANT[fmt]["rangefinder"]["dist_m"], err_msg=fmt)
