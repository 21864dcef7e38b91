"""The flight manifest check (pipeline/io/manifest.py): one line naming file, line and flight id."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.config import ConfigError, load_config
from pipeline.io.manifest import check_manifest, reader_names

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
    with pytest.raises(ConfigError, match=r"nope\.tsv: cannot read the manifest"):
        check_manifest(tmp_path / "nope.tsv", CONFIG)
