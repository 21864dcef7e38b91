"""The flight manifest check (pipeline/io/manifest.py): one line naming file, line and flight id."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.config import ConfigError, load_config
from pipeline.io.manifest import check_manifest, expand_path, log_available, reader_names

ROOT = Path(__file__).resolve().parents[2]
HEADER = "flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\n"
DEMO = "demo-quad\tresults/sim/demo/demo-quad.bin\tsim-quad\ttest\tnone\t\tdemo"
CONFIG = {"realdata_dir": "/nowhere", "preprocess": {"vehicles": {"default": {}, "sim-quad": {}, "husky": {}}}}


def _manifest(tmp_path: Path, *rows: str, comment: bool = True) -> Path:
    p = tmp_path / "flights.tsv"
    p.write_text(HEADER + ("# a comment line counts as a line\n" if comment else "")
                 + "".join(r + "\n" for r in rows))
    return p


def _error(tmp_path: Path, *rows: str) -> str:
    p = _manifest(tmp_path, *rows)
    with pytest.raises(ConfigError) as exc:
        check_manifest(p, CONFIG, base=tmp_path)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}:")
    return msg


def test_the_shipped_manifest_passes_with_the_shipped_config_and_every_row_is_returned():
    rows = check_manifest(ROOT / "datasets" / "flights.tsv", load_config(), base=ROOT)
    assert len(rows) == 26 and rows[0]["flight_id"] == "demo-quad" and rows[0]["format"] == ""


def test_an_unknown_vehicle_names_the_file_line_flight_and_the_known_vehicles(tmp_path):
    msg = _error(tmp_path, DEMO, "x1\tresults/sim/demo/x.bin\tsim-qaud\ttest\tnone\t\t")
    assert ":4: flight x1: unknown vehicle 'sim-qaud'" in msg
    assert "known: generic, default, husky, sim-quad" in msg


def test_generic_is_a_vehicle_without_an_entry(tmp_path):
    p = _manifest(tmp_path, DEMO.replace("sim-quad", "generic"))
    assert check_manifest(p, CONFIG, base=tmp_path)[0]["vehicle"] == "generic"


def test_a_labels_value_that_is_no_word_and_no_file_is_an_error(tmp_path):
    (tmp_path / "log.bin").write_bytes(b"x")
    msg = _error(tmp_path, DEMO, "lab1\tlog.bin\thusky\tnone\tmissing.parquet\t\t")
    assert ":4: flight lab1: labels 'missing.parquet' is neither 'embedded', 'none' nor an existing file" in msg


def test_labels_that_exist_or_are_written_by_the_workflow_pass(tmp_path):
    (tmp_path / "log.bin").write_bytes(b"x")
    (tmp_path / "truth.parquet").write_bytes(b"x")
    p = _manifest(tmp_path, DEMO, "a\tlog.bin\thusky\tnone\ttruth.parquet\t\t",
                  "b\tresults/sim/logs/s.bin\tsim-quad\ttest\tresults/sim/logs/s.bin.truth.parquet\t\t",
                  "c\tlog.bin\thusky\tnone\tembedded\t\t",
                  # the log is absent: the row is skipped with a notice, its labels are not checked
                  "d\t{realdata}/gone.bin\thusky\tnone\t{realdata}/gone.truth.parquet\t\t")
    assert [r["flight_id"] for r in check_manifest(p, CONFIG, base=tmp_path)] == ["demo-quad", "a", "b", "c", "d"]


def test_a_labels_folder_is_not_a_file(tmp_path):
    (tmp_path / "log.bin").write_bytes(b"x")
    (tmp_path / "adir").mkdir()
    msg = _error(tmp_path, "lab2\tlog.bin\thusky\tnone\tadir\t\t")
    assert ":3: flight lab2: labels 'adir'" in msg


def test_a_duplicate_id_names_both_lines(tmp_path):
    msg = _error(tmp_path, DEMO, "other\tresults/x.bin\tsim-quad\ttest\tnone\t\t", DEMO)
    assert ":5: flight demo-quad: duplicate flight_id (first on line 3)" in msg


def test_a_format_that_is_no_reader_lists_the_reader_names(tmp_path):
    msg = _error(tmp_path, DEMO.replace("\tnone\t\t", "\tnone\tbinlog\t"))
    assert ":3: flight demo-quad: unknown format 'binlog'" in msg
    assert f"readers: {', '.join(reader_names())}" in msg
    assert {"dataflash", "tlog", "ulog", "mcap", "rosbag1", "rosbag2", "flightcoach", "tabular"} <= set(reader_names())


def test_a_reader_name_as_format_passes(tmp_path):
    p = _manifest(tmp_path, DEMO.replace("\tnone\t\t", "\tnone\tdataflash\t"), comment=False)
    assert check_manifest(p, CONFIG, base=tmp_path)[0]["format"] == "dataflash"


def test_a_missing_column_or_manifest_is_one_line(tmp_path):
    p = tmp_path / "f.tsv"
    p.write_text("flight_id\tpath\n")
    with pytest.raises(ConfigError, match=r"f\.tsv:1: header lacks column\(s\) vehicle, role"):
        check_manifest(p, CONFIG)
    with pytest.raises(ConfigError, match=r"nope\.tsv: manifest file not found$"):
        check_manifest(tmp_path / "nope.tsv", CONFIG)
    # a column no stage reads (a typo, or a note) is refused, as an unknown config key is
    p.write_text("flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\tpilot\n")
    with pytest.raises(ConfigError, match=r"f\.tsv:1: header has unknown column\(s\) 'pilot' \(expected: "
                                          r"flight_id, .*; free text goes in notes\)$"):
        check_manifest(p, CONFIG)
    p.write_text("flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\tpath\n")
    with pytest.raises(ConfigError, match=r"f\.tsv:1: header has column\(s\) path twice"):
        check_manifest(p, CONFIG)


def test_a_leading_tilde_is_the_home_folder_and_realdata_expands_first(monkeypatch):
    monkeypatch.setenv("HOME", "/home/pilot")
    assert expand_path("~/logs/f 1.bin", None) == "/home/pilot/logs/f 1.bin"
    assert expand_path("{realdata}/a.bin", "~/data/") == "/home/pilot/data/a.bin"
    # only a leading tilde: one inside a name is a character of the name
    assert expand_path("logs/run~2.bin", None) == "logs/run~2.bin"


def test_a_log_under_the_home_folder_is_available_and_its_labels_are_checked(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / "my logs").mkdir()
    (tmp_path / "my logs" / "flight 1.bin").write_bytes(b"x")
    assert log_available(expand_path("~/my logs/flight 1.bin", None))
    assert not log_available(expand_path("~/my logs/flight 2.bin", None))
    # the log exists, so its labels must too: the check follows the tilde as well
    msg = _error(tmp_path, "home1\t~/my logs/flight 1.bin\thusky\tnone\t~/my logs/gone.parquet\t\t")
    assert ":3: flight home1: labels '~/my logs/gone.parquet' is neither" in msg


def test_a_simulated_log_this_config_does_not_write_names_the_file_line_and_flight(tmp_path):
    p = _manifest(tmp_path, DEMO, "s1\tresults/sim/logs/sim-M1-000.bin\tsim-quad\ttest\tnone\t\t",
                  "s3\tresults/sim/logs/sim-M3-000.bin\tsim-quad\ttest\tnone\t\t")
    planned = {"sim-M1-000.bin", "sim-M1-000-mcap"}
    with pytest.raises(ConfigError) as exc:
        check_manifest(p, CONFIG, base=tmp_path, simulated_logs=planned)
    assert str(exc.value) == (f"{p}:5: flight s3: results/sim/logs/sim-M3-000.bin is not written by the "
                              f"simulate stage with this config (simulate.datasets: sizes, log_formats)")
    # without simulated_logs nothing is checked; a directory log (MCAP) may carry a trailing slash
    assert len(check_manifest(p, CONFIG, base=tmp_path)) == 3
    p2 = _manifest(tmp_path, "m\tresults/sim/logs/sim-M1-000-mcap/\tsim-quad\ttest\tnone\t\t")
    assert len(check_manifest(p2, CONFIG, base=tmp_path, simulated_logs=planned)) == 1


def test_a_byte_order_mark_and_windows_line_ends_from_a_spreadsheet_are_read_as_plain_text(tmp_path):
    p = tmp_path / "flights.tsv"
    p.write_bytes(b"\xef\xbb\xbf" + (HEADER + DEMO + "\n").replace("\n", "\r\n").encode())
    rows = check_manifest(p, CONFIG, base=tmp_path)
    assert [(r["flight_id"], r["labels"], r["notes"]) for r in rows] == [("demo-quad", "none", "demo")]


def test_a_manifest_that_is_not_utf8_names_its_line(tmp_path):
    p = tmp_path / "flights.tsv"
    p.write_bytes((HEADER + DEMO + "\n").encode() + "caf\u00e9\tx.bin\thusky\tnone\tnone\t\t\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"flights\.tsv:3: not UTF-8 text \(byte 0xe9\); save the manifest as UTF-8$"):
        check_manifest(p, CONFIG, base=tmp_path)


@pytest.mark.parametrize("row, reason", [
    ("x_1\tresults/sim/demo/x.bin\tsim-quad\ttest\tnone\t\t", "flight_id 'x_1' must be letters, digits and '-'"),
    ("x1 \tresults/sim/demo/x.bin\tsim-quad\ttest\tnone\t\t", "flight_id 'x1 ' must be letters"),
    ("\tresults/sim/demo/x.bin\tsim-quad\ttest\tnone\t\t", "flight_id '' must be letters"),
    ("x1\tresults/sim/demo/x.bin\tsim-quad\tTrain\tnone\t\t", "flight x1: role 'Train' must be one of train, test, none"),
    ("x1\tresults/sim/demo/x.bin\tsim-quad", "flight x1: role '' must be one of"),
    ("x1\t\tsim-quad\ttest\tnone\t\t", "flight x1: empty path"),
    ("x1\tlogs/{date}/x.bin\tsim-quad\ttest\tnone\t\t", "flight x1: braces in a path are read as workflow wildcards"),
])
def test_what_the_row_schema_types_is_one_line_with_the_files_line_number(tmp_path, row, reason):
    # before: Snakemake's validator dumped a dozen lines naming a 0-based row (or, for a brace,
    # a WildcardError deep in the DAG); now the check names the file's 1-based line
    msg = _error(tmp_path, DEMO, row)
    assert ":4: " in msg and reason in msg, msg


def test_realdata_is_the_one_brace_a_path_may_hold(tmp_path):
    rows = check_manifest(_manifest(tmp_path, DEMO, "x1\t{realdata}/a.bin\tsim-quad\ttest\tnone\t\t"),
                          CONFIG, base=tmp_path)
    assert rows[1]["path"] == "{realdata}/a.bin"


def test_every_bad_row_is_one_line_of_the_error_and_a_short_row_says_a_tab_is_missing(tmp_path):
    p = _manifest(tmp_path, DEMO, "a1\tresults/sim/demo/x.bin\tsim-qaud\ttest\tnone\t\t",
                  DEMO, "b2\tresults/sim/demo/y.bin\ttest\tnone\t\t",          # the vehicle field left out
                  "c3\tresults/sim/demo/z.bin\tsim-quad\tsometimes\tnone\t\t")
    with pytest.raises(ConfigError) as exc:
        check_manifest(p, CONFIG, base=tmp_path)
    lines = str(exc.value).splitlines()
    assert [ln.split(": flight ")[0].rsplit(":", 1)[1] for ln in lines] == ["4", "5", "6", "7"]
    assert all(ln.startswith(f"{p}:") for ln in lines)
    assert "unknown vehicle 'sim-qaud'" in lines[0] and "duplicate flight_id (first on line 3)" in lines[1]
    assert "unknown vehicle 'test'" in lines[2]
    assert lines[2].endswith("(the row has 6 of the header's 7 fields: a missing tab shifts the columns after it)")
    assert "role 'sometimes'" in lines[3]


def test_a_comma_separated_manifest_is_told_it_must_use_tabs(tmp_path):
    p = tmp_path / "flights.tsv"
    p.write_text(HEADER.replace("\t", ",") + DEMO.replace("\t", ",") + "\n")
    with pytest.raises(ConfigError, match=r"header lacks column\(s\) .*the manifest is tab-separated\)$"):
        check_manifest(p, CONFIG, base=tmp_path)


def test_a_row_rejected_for_its_role_still_counts_for_a_later_duplicate(tmp_path):
    p = _manifest(tmp_path, "d1\tresults/sim/demo/x.bin\tsim-quad\tsometimes\tnone\t\t",
                  "d1\tresults/sim/demo/y.bin\tsim-quad\ttest\tnone\t\t")
    with pytest.raises(ConfigError) as exc:
        check_manifest(p, CONFIG, base=tmp_path)
    lines = str(exc.value).splitlines()
    assert "role 'sometimes'" in lines[0] and "duplicate flight_id (first on line 3)" in lines[1]
