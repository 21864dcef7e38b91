"""DataFlash writer: round trips through our decoder AND pymavlink, the one message catalogue.

(The demo flight written with it is tested in tests/simulate/test_demo.py.)"""

from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from helpers import pymavlink_by_type
from pipeline.io import dataflash as df
from pipeline.io.dataflash import catalogue as cat
from pipeline.io.dataflash.writer import DataFlashWriter
from pipeline.simulate.demo import write_demo_flight


ALL_CHARS = "bBhHiIfdnNZcCeELMqQ"


def test_every_format_char_roundtrips_through_both_readers(tmp_path):
    p = tmp_path / "all.bin"
    labels = [f"F{c}" if c.islower() else f"U{c}" for c in ALL_CHARS]
    n = 7
    vals = {
        "Fb": np.arange(-3, 4, dtype=np.int8), "UB": np.arange(250, 257) % 256,
        "Fh": np.array([-32768, -1, 0, 1, 2, 3, 32767]), "UH": np.arange(n) * 9000,
        "Fi": np.arange(n) * -300_000_001 // 1, "UI": np.arange(n, dtype=np.uint64) * 600_000_001,
        "Ff": np.linspace(-1, 1, n).astype(np.float32), "Fd": np.linspace(-1e10, 1e10, n) / 3,
        "Fn": ["ab", "", "xyzw", "a", "b", "c", "d"], "UN": [f"NAME_{i}" for i in range(n)],
        "UZ": ["hello world, this is a longer text message " + str(i) for i in range(n)],
        "Fc": np.arange(n) * 1.23 - 4, "UC": np.arange(n) * 100.25, "Fe": np.arange(n) * -1e5 + 0.07,
        "UE": np.arange(n) * 1e6 + 0.01, "UL": np.linspace(-89.9999999, 179.9999999, n),
        "UM": np.arange(n, dtype=np.int8), "Fq": -(2 ** np.arange(50, 57, dtype=np.int64)),
        "UQ": np.arange(n, dtype=np.uint64) * np.uint64(2 ** 61),
    }
    fmt = "".join(ALL_CHARS)
    assert len(fmt) > 16  # split across two messages (16 fields at most per FMT)
    with DataFlashWriter(p) as w:
        w.define("ALL1", 10, fmt[:10], labels[:10])
        w.define("ALL2", 11, fmt[10:], labels[10:])
        w.write_many("ALL1", {k: vals[k] for k in labels[:10]})
        w.write_many("ALL2", {k: vals[k] for k in labels[10:]})
    res = df.decode(p)
    pm = pymavlink_by_type(p)
    assert res.diagnostics["record_counts"] == {k: len(v) for k, v in pm.items()} == {
        "FMT": 3, "ALL1": n, "ALL2": n}
    for name in ("ALL1", "ALL2"):
        for col in res.formats[name].columns:
            theirs = [getattr(x, col) for x in pm[name]]
            ours = res.tables[name][col]
            assert ours.tolist() == theirs, col
    # physical values come back (scaled formats to their resolution)
    t = res.tables
    np.testing.assert_allclose(t["ALL2"]["UL"], vals["UL"], atol=0.6e-7)
    np.testing.assert_allclose(t["ALL2"]["Fc"], vals["Fc"], atol=0.005)
    assert t["ALL1"]["UN"].tolist() == vals["UN"] and t["ALL1"]["Fn"].tolist() == vals["Fn"]
    assert t["ALL2"]["UQ"].tolist() == vals["UQ"].tolist()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_formats_round_trip_through_our_decoder_and_pymavlink_agrees_column_by_column(data, tmp_path):
    """Random formats and values: write_many -> decode gives the values back; pymavlink agrees."""
    fmt = data.draw(st.text(alphabet="bBhHiIfdNcCLMQ", min_size=1, max_size=8), label="fmt")
    n = data.draw(st.integers(1, 20), label="n")
    labels = [f"V{i}" for i in range(len(fmt))]
    cols = {}
    for c, lab in zip(fmt, labels):
        if c == "N":
            cols[lab] = data.draw(st.lists(st.text(alphabet="abcXYZ_09", max_size=16), min_size=n, max_size=n))
        elif c in "fd":
            cols[lab] = np.array(data.draw(st.lists(st.floats(-1e6, 1e6, width=32), min_size=n, max_size=n)))
        else:
            kind = np.dtype(df.FORMAT_CHARS[c][0])
            info = np.iinfo(kind)
            raw = data.draw(st.lists(st.integers(int(info.min), int(info.max)), min_size=n, max_size=n))
            raw = np.array(raw, dtype=kind)
            div = df.FORMAT_CHARS[c][1]
            cols[lab] = raw / div if div else raw
    p = tmp_path / "rnd.bin"  # one file per example (overwritten: tmp_path is shared by the examples)
    with DataFlashWriter(p) as w:
        w.define("RND", 42, fmt, labels)
        w.write_many("RND", cols)
    res = df.decode(p)
    assert res.diagnostics["record_counts"]["RND"] == n and res.diagnostics["bytes_skipped"] == 0
    pm = pymavlink_by_type(p)
    assert {k: len(v) for k, v in pm.items()} == {"FMT": 2, "RND": n}
    for c, lab in zip(fmt, labels):
        got = res.tables["RND"][lab]
        if c == "N":
            assert got.tolist() == cols[lab]
        else:
            assert np.array_equal(got, np.asarray(cols[lab]).astype(got.dtype)), (c, lab)
        assert got.tolist() == [getattr(m, lab) for m in pm["RND"]], (c, lab)


def test_define_validates(tmp_path):
    with DataFlashWriter(io.BytesIO()) as w:
        w.define("AAA", 5, "Qf", "TimeUS,X")
        with pytest.raises(ValueError, match="already used"):
            w.define("BBB", 5, "Qf", "TimeUS,X")
        with pytest.raises(ValueError, match="labels"):
            w.define("CCC", 6, "Qf", "TimeUS")
        with pytest.raises(ValueError, match="bad format"):
            w.define("DDD", 7, "Qx", "TimeUS,X")
        with pytest.raises(ValueError, match="1-4"):
            w.define("TOOLONG", 8, "Q", "TimeUS")
        with pytest.raises(KeyError, match="no field"):
            w.write("AAA", TimeUS=1, Y=2)
        with pytest.raises(ValueError, match="different lengths"):
            w.write_many("AAA", {"TimeUS": [1, 2], "X": [1.0, 2.0, 3.0]})


def test_write_merged_interleaves_by_time():
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("AA", 1, "Qh", "TimeUS,V")
        w.define("BB", 2, "Qf", "TimeUS,W")
        w.write_merged({"AA": {"TimeUS": [10, 30, 50], "V": [1, 3, 5]},
                        "BB": {"TimeUS": [20, 30, 40], "W": [2.0, 3.5, 4.0]}})
    res = df.decode(buf.getvalue())
    order = np.argsort(np.concatenate([res.offsets["AA"], res.offsets["BB"]]))
    t = np.concatenate([res.tables["AA"]["TimeUS"], res.tables["BB"]["TimeUS"]])[order]
    assert t.tolist() == [10, 20, 30, 30, 40, 50]
    assert res.offsets["AA"][1] < res.offsets["BB"][1]  # tie at 30: batch order kept


@pytest.mark.parametrize("layout", sorted(cat.MESSAGES))
def test_every_catalogue_layout_is_a_valid_set_of_definitions(layout, tmp_path):
    p = tmp_path / f"{layout}.bin"
    with DataFlashWriter(p) as w:  # define() validates names, ids, formats, labels, units
        w.define_layout(layout)
    msgs = cat.layout(layout)
    assert len({m.type_id for m in msgs}) == len(msgs) and len({m.name for m in msgs}) == len(msgs)
    fmts = {m.Name: (m.Type, m.Format, m.Columns) for m in pymavlink_by_type(p)["FMT"]}
    for m in msgs:
        assert fmts[m.name] == (m.type_id, m.fmt, m.labels)


def test_demo_flight_declares_exactly_the_catalogue_demo_layout(tmp_path):
    p = tmp_path / "d.bin"
    write_demo_flight(p, duration_s=2.0)
    fmts = {m.Name: (m.Type, m.Format, m.Columns) for m in pymavlink_by_type(p)["FMT"]}
    demo = {m.name: (m.type_id, m.fmt, m.labels) for m in cat.layout("demo")}
    unit_tables = {m.name: (m.type_id, m.fmt, m.labels) for m in (cat.UNIT, cat.MULT, cat.FMTU)}
    assert fmts == {"FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"), **demo, **unit_tables}
