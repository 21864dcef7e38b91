"""CSV/Parquet importer: the kd0aij FlightData CSVs against pandas.read_csv, and config-given
column maps with unit conversion on small tables written at test time."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.spatial.transform import Rotation

import helpers_tabular
from helpers import realdata_file
from pipeline.frames.geodesy import geodetic_to_ned
from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.parquet import read_flightlog, write_flightlog
from pipeline.io.tabular import TabularReader, convert_unit, shipped_columnmaps

REAL = ["kd0aij_f3a_csv/P21.csv", "kd0aij_f3a_csv/141.csv"]


@pytest.fixture(scope="module", params=REAL, ids=["P21", "141"])
def real(request):
    p = realdata_file(request.param)
    return p, pd.read_csv(p), registry.read_log(p)


def test_detected_with_shipped_map(real):
    p, df, log = real
    assert log.meta["reader"] == "tabular"
    assert log.meta["source_format"] == "csv:kd0aij_flightdata"
    assert "kd0aij_flightdata" in log.meta["detected_by"]
    assert len(df.columns) == 57
    t = np.round(df["time_actual"].to_numpy() * 1e9).astype(np.int64)
    for s in ("gps", "local_position", "attitude", "imu", "baro"):
        np.testing.assert_array_equal(log[s]["t_ns"], t - t.min())
        np.testing.assert_array_equal(log[s]["t_boot_ns"].to_numpy(np.int64), t)
    assert log.meta["t0_boot_ns"] == t.min()


def test_values_equal_pandas(real):
    _, df, log = real
    g = log["gps"]
    np.testing.assert_array_equal(g["lat_deg"], df["global_position_latitude"])
    np.testing.assert_array_equal(g["lon_deg"], df["global_position_longitude"])
    np.testing.assert_array_equal(g["alt_msl_m"], df["altitude_gps"])
    np.testing.assert_array_equal(g["n_sats"], df["gps_sat_count_0"].astype(float))
    lp = log["local_position"]
    for a, c in zip("ned", "xyz"):
        np.testing.assert_array_equal(lp[f"pos_{a}_m"], df[f"position_{c}"])
        np.testing.assert_array_equal(lp[f"vel_{a}_mps"], df[f"velocity_{c}"])
    imu = log["imu"]
    for a in "xyz":
        np.testing.assert_array_equal(imu[f"acc_{a}_mps2"], df[f"acceleration_{a}"])
        assert imu[f"gyr_{a}_radps"].isna().all()  # axis_rate_* are not body rates: left out
    np.testing.assert_array_equal(log["baro"]["alt_rel_m"], df["altitude_baro"])
    q = log["attitude"][["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    sq = Rotation.from_euler("ZYX", df[["attitude_yaw", "attitude_pitch", "attitude_roll"]].to_numpy()).as_quat()
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", q, np.c_[sq[:, 3], sq[:, :3]])), 1.0, atol=1e-12)


def test_constant_columns_absent(real):
    p, df, log = real
    cmap = shipped_columnmaps()["kd0aij_flightdata"]
    const = [c for c in cmap.columns if df[c].nunique() <= 1]
    assert log.meta["columnmap"]["constant_columns"] == const
    ctl = log["control"]
    tx_logged = [i for i in range(8) if df[f"tx_controls_{i}"].nunique() > 1]
    if not tx_logged:  # P21: sticks not logged
        assert p.name == "P21.csv" and len(ctl) == 0
    else:  # 141: real stick inputs 875-2126 us
        assert p.name == "141.csv"
        for i in tx_logged:
            np.testing.assert_array_equal(ctl[f"rc_{i + 1}_us"], df[f"tx_controls_{i}"].astype(float))
        assert ctl["rc_1_us"].min() == 875 and ctl["rc_1_us"].max() == 2126
        assert ctl.filter(like="servo_").isna().all().all()
    assert len(log["mode"]) == 0  # mode_0 constant in both files
    assert not log.meta["columnmap"]["unmapped_columns"]


def test_frames_origin_and_sign(real):
    p, df, log = real
    o = log.meta["ned_origin"]
    assert (o["lat_deg"], o["lon_deg"]) == (df["global_position_latitude"][0], df["global_position_longitude"][0])
    # position_x/y are NED about the first fix: GPS converted about it agrees to metres
    n, e, _ = geodetic_to_ned(df["global_position_latitude"], df["global_position_longitude"], df["altitude_gps"],
                              o["lat_deg"], o["lon_deg"], o["alt_msl_m"])
    horiz = np.hypot(n - df["position_x"], e - df["position_y"])
    assert np.median(horiz) < 5.0
    assert np.hypot(df["position_x"], df["position_y"]).max() > 300  # ... on a 300+ m flight
    # body accelerometer in FRD: on the ground at the start, z reads about -g
    if p.name == "141.csv":
        assert np.mean(log["imu"]["acc_z_mps2"][:30]) == pytest.approx(-9.66, abs=0.2)


# --- config-given maps, Parquet, unit conversion ----------------------------------------------

def _map(**over):
    extra = {"mx": {"stream": "mag", "column": "mag_x_T", "unit": "mG"},
             "spare": {"stream": "airspeed", "column": "airspeed_mps", "unit": "kn", "optional": True}}
    return helpers_tabular.column_map("testmap", extra, constant_is_absent=True, **over)


def _table(rng, n=12):
    df = helpers_tabular.table(rng, n)
    df["mx"] = rng.normal(200, 5, n)
    df["ignored_col"] = np.zeros(n) + np.arange(n)
    return df


def test_parquet_with_config_map_and_units(tmp_path, rng):
    df = _table(rng)
    p = tmp_path / "flight.parquet"
    df.to_parquet(p)
    log = registry.read_log(p, config={"columnmaps": {"testmap": _map()}})
    assert log.meta["source_format"] == "parquet:testmap"
    np.testing.assert_array_equal(log["gps"]["t_ns"], np.arange(12) * 100_000_000)
    np.testing.assert_allclose(log["gps"]["lat_deg"], df["lat"] * 1e-7, rtol=1e-15)
    np.testing.assert_allclose(log["gps"]["alt_msl_m"], df["alt_ft"] * 0.3048, rtol=1e-15)
    np.testing.assert_allclose(log["baro"]["press_Pa"], df["p_mbar"] * 100, rtol=1e-15)
    np.testing.assert_allclose(log["baro"]["temp_degC"], df["tempK"] - 273.15, rtol=1e-12)
    np.testing.assert_allclose(log["mag"]["mag_x_T"], df["mx"] * 1e-7, rtol=1e-15)
    np.testing.assert_allclose(log["imu"]["gyr_x_radps"], np.radians(df["gx"]), rtol=1e-15)
    np.testing.assert_allclose(log["imu"]["acc_z_mps2"], df["az"] * 9.80665, rtol=1e-15)
    sq = Rotation.from_euler("ZYX", df[["yaw_deg", "pitch_deg", "roll_deg"]].to_numpy(), degrees=True).as_quat()
    q = log["attitude"][["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", q, np.c_[sq[:, 3], sq[:, :3]])), 1.0, atol=1e-12)
    assert list(log["mode"]["mode"]) == ["MANUAL", "FBWA", "MANUAL"]
    assert list(log["mode"]["t_ns"]) == [0, 400_000_000, 800_000_000]
    cm = log.meta["columnmap"]
    assert cm["absent_columns"] == ["spare"] and cm["unmapped_columns"] == ["ignored_col"]
    assert log.meta["ned_origin"]["lat_deg"] == pytest.approx(51.5)
    assert len(log["airspeed"]) == 0
    back = read_flightlog(write_flightlog(log, tmp_path / "store")[0].parent)
    for name, df in log.streams.items():
        pd.testing.assert_frame_equal(back[name], df)
    assert back.meta["columnmap"] == cm


def test_csv_with_map_file_and_bad_time_rows(tmp_path, rng):
    df = _table(rng)
    df.loc[3, "t_ms"] = np.nan
    p = tmp_path / "flight.csv"
    df.to_csv(p, index=False)
    mp = tmp_path / "testmap.yaml"
    mp.write_text(yaml.safe_dump(_map()))
    log = registry.read_log(p, config={"columnmaps": {"testmap": str(mp)}})
    assert log.meta["diagnostics"]["records_dropped"] == {"bad_time": 1}
    assert log.meta["status"] == "partial"
    assert len(log["gps"]) == 11


def test_epoch_unix_sets_utc(tmp_path, rng):
    df = _table(rng)
    df["t_ms"] = 1_700_000_000_000 + 100 * np.arange(len(df))
    p = tmp_path / "unix.parquet"
    df.to_parquet(p)
    m = _map(time={"column": "t_ms", "unit": "ms", "epoch": "unix"})
    log = registry.read_log(p, config={"columnmaps": {"testmap": m}})
    assert log.meta["t0_utc_ns"] == 1_700_000_000_000 * 1_000_000 and log.meta["utc_source"] == "file"
    assert log["gps"]["t_boot_ns"].isna().all()


@pytest.mark.parametrize("change, reason", [
    (lambda m: m["columns"]["lat"].update(unit="furlong"), r"column 'lat': unknown unit 'furlong'"),
    (lambda m: m["columns"]["alt_ft"].pop("unit"), r"column 'alt_ft' -> gps.alt_msl_m: no unit given"),
    (lambda m: m["columns"]["alt_ft"].update(unit="Pa"), r"unit 'Pa' \(pressure\) cannot convert to 'm'"),
    (lambda m: (m["columns"].update(nothere={"stream": "gps", "column": "hacc_m", "unit": "m"}),
                m.update(match={"columns": ["t_ms", "lat"]})),
     r"mapped column\(s\) missing from the file: \['nothere'\]"),
    (lambda m: m["columns"].update(lat={"stream": "gps", "column": "latitude", "unit": "deg"}),
     r"stream 'gps' has no column 'latitude'"),
    (lambda m: m.update(time={"column": "t_ms", "unit": "fortnight"}), "time column 't_ms': unknown time unit 'fortnight'"),
])
def test_bad_map_is_ingest_error(tmp_path, rng, change, reason):
    p = tmp_path / "flight.parquet"
    _table(rng).to_parquet(p)
    m = _map()
    change(m)
    with pytest.raises(IngestError, match=f"flight.parquet: column map 'testmap': {reason}"):
        registry.read_log(p, config={"columnmaps": {"testmap": m}})


def test_no_matching_map_and_forced_map(tmp_path, rng):
    p = tmp_path / "other.csv"
    _table(rng).to_csv(p, index=False)
    with pytest.raises(IngestError, match="other.csv: no column map matches this csv header"):
        registry.read_log(p)
    log = registry.read_log(p, config={"columnmaps": {"testmap": _map()}, "tabular": {"columnmap": "testmap"}})
    assert len(log["gps"]) == 12
    with pytest.raises(IngestError, match="column map 'nope' .* not found"):
        registry.read_log(p, config={"tabular": {"columnmap": "nope"}})


def test_kd0aij_missing_column_names_it(tmp_path):
    src = realdata_file(REAL[1])
    df = pd.read_csv(src, nrows=50).drop(columns=["velocity_z"])
    p = tmp_path / "cut.csv"
    df.to_csv(p, index=False)
    with pytest.raises(IngestError, match=r"cut.csv: column map 'kd0aij_flightdata': mapped column\(s\) "
                                          r"missing from the file: \['velocity_z'\]"):
        registry.read_log(p)


def test_sniff_rules(tmp_path):
    assert TabularReader.sniff(tmp_path / "a", b"PAR1\x15\x04")
    assert TabularReader.sniff(tmp_path / "a", b"time,alt\n0.1,2.0\n")
    assert TabularReader.sniff(tmp_path / "a", b"hello world, this is prose\nnot a table\n") is None
    assert TabularReader.sniff(tmp_path / "a", b'{"data": 1}') is None
    assert TabularReader.sniff(tmp_path / "a", b"ULog\x01\x12\x35\x01") is None


def test_convert_unit_round_trips():
    x = np.array([0.0, 1.5, -20.0])
    for a, b in (("deg", "rad"), ("K", "degC"), ("mbar", "Pa"), ("kn", "m/s"), ("mG", "T"), ("g", "m/s^2")):
        np.testing.assert_allclose(convert_unit(convert_unit(x, a, b), b, a), x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(convert_unit(np.array([0.0]), "K", "degC"), [-273.15])


#: unit -> (base unit of its dimension, value of 1 unit in that base unit), from the definitions
#: (international foot 0.3048 m, nautical mile 1852 m, standard gravity 9.80665 m/s^2, 1 G = 1e-4 T)
_CLOSED_FORM = {
    "m": ("m", 1.0), "cm": ("m", 0.01), "mm": ("m", 1e-3), "km": ("m", 1e3), "ft": ("m", 0.3048),
    "m/s": ("m/s", 1.0), "cm/s": ("m/s", 0.01), "mm/s": ("m/s", 1e-3), "km/h": ("m/s", 1000 / 3600),
    "kn": ("m/s", 1852 / 3600), "ft/s": ("m/s", 0.3048),
    "m/s^2": ("m/s^2", 1.0), "m/s2": ("m/s^2", 1.0), "g": ("m/s^2", 9.80665), "mg": ("m/s^2", 9.80665e-3),
    "rad": ("rad", 1.0), "deg": ("rad", np.pi / 180), "cdeg": ("rad", np.pi / 18000), "mrad": ("rad", 1e-3),
    "deg*1e7": ("rad", np.pi / 180e7),
    "rad/s": ("rad/s", 1.0), "deg/s": ("rad/s", np.pi / 180),
    "Pa": ("Pa", 1.0), "hPa": ("Pa", 100.0), "mbar": ("Pa", 100.0), "kPa": ("Pa", 1000.0),
    "degC": ("degC", 1.0), "cdegC": ("degC", 0.01),
    "T": ("T", 1.0), "uT": ("T", 1e-6), "nT": ("T", 1e-9), "G": ("T", 1e-4), "mG": ("T", 1e-7),
    "s": ("s", 1.0), "ms": ("s", 1e-3), "us": ("s", 1e-6), "ns": ("s", 1e-9),
    "1": ("1", 1.0),
}


def test_every_unit_in_the_table_has_a_closed_form_check():
    from pipeline.io.tabular import UNITS
    assert set(UNITS) - {"K"} == set(_CLOSED_FORM)


@pytest.mark.parametrize("src", sorted(_CLOSED_FORM))
def test_convert_unit_scales_each_unit_to_its_si_base_by_the_defined_factor(src):
    base, factor = _CLOSED_FORM[src]
    x = np.array([0.0, 1.0, -2.5, 1234.5])
    np.testing.assert_allclose(convert_unit(x, src, base), x * factor, rtol=1e-14, atol=0)
    np.testing.assert_allclose(convert_unit(x * factor, base, src), x, rtol=1e-14, atol=1e-300)


def test_convert_unit_with_offsets_and_between_non_base_units_matches_closed_forms():
    np.testing.assert_allclose(convert_unit(np.array([273.15, 300.0, 0.0]), "K", "degC"), [0.0, 26.85, -273.15],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(convert_unit(np.array([2500.0, -1000.0]), "cdegC", "K"), [298.15, 263.15],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(convert_unit(np.array([1.0]), "kn", "km/h"), [1.852], rtol=1e-14)
    np.testing.assert_allclose(convert_unit(np.array([1000.0]), "mG", "uT"), [100.0], rtol=1e-14)
