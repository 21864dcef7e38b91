"""The command line says what it did: --format choices, real commands only, ingest warnings,
the vehicle profile preprocess used (issue 13, item 8)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import pipeline.io.ingest as ingest_mod
import pipeline.io.registry as registry
from pipeline.cli import COMMANDS, build_parser, main
from pipeline.io.manifest import reader_names
from pipeline.simulate.demo import write_demo_flight

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("logs") / "demo.bin"
    write_demo_flight(p, seed=3)
    return p


@pytest.mark.parametrize("command", ["ingest", "info"])
def test_format_lists_the_reader_names_in_help_and_rejects_others(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
    assert "force a reader instead of detecting: " + ", ".join(reader_names()) in out
    with pytest.raises(SystemExit) as exc:
        main([command, "x.bin", "--format", "binlog", *(["-o", "o"] if command == "ingest" else [])])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'binlog'" in err and "'dataflash'" in err and "'ulog'" in err


def test_help_lists_only_commands_that_exist(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    listed = [line.split()[0] for line in out.split("COMMAND\n", 2)[-1].split("options:")[0].splitlines()
              if line.startswith("    ") and not line.startswith("     ")]
    assert listed == list(COMMANDS)
    assert all((ROOT / "pipeline" / "cli" / f"{c}.py").exists() for c in listed)
    description = build_parser().description
    for word in ("learn", "estimate", "report"):  # stages the workflow runs, not commands
        assert f" {word}," not in description and f" {word}." not in description


def test_ingest_prints_the_warnings_that_info_prints(demo_log, tmp_path, capsys, monkeypatch):
    real = registry.read_log

    def with_warnings(*a, **k):
        log = real(*a, **k)
        log.meta.setdefault("diagnostics", {}).setdefault("warnings", []).extend(
            ["GPS glitch at 3.2 s", "baro stuck for 1.0 s"])
        return log

    monkeypatch.setattr(registry, "read_log", with_warnings)
    monkeypatch.setattr(ingest_mod, "read_log", with_warnings)
    assert main(["info", str(demo_log)]) == 0
    info_warnings = [l.split("warning: ", 1)[1] for l in capsys.readouterr().out.splitlines() if "warning: " in l]
    assert info_warnings == ["GPS glitch at 3.2 s", "baro stuck for 1.0 s"]
    assert main(["ingest", str(demo_log), "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert [l.split("warning: ", 1)[1] for l in err.splitlines() if "warning: " in l] == info_warnings
    assert f"uavpipe ingest: {demo_log}: warning: GPS glitch at 3.2 s" in err
    meta = json.loads((tmp_path / "out" / "demo" / "meta.json").read_text())
    assert meta["diagnostics"]["warnings"] == info_warnings


@pytest.fixture(scope="module")
def ingested(demo_log, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ingest")
    assert main(["ingest", str(demo_log), "-o", str(out)]) == 0
    return out / "demo"


@pytest.mark.parametrize("vehicle, profile", [("husky", "husky"), ("generic", "default"), (None, "default")])
def test_preprocess_says_which_vehicle_profile_it_used(ingested, tmp_path, capsys, vehicle, profile):
    args = ["preprocess", str(ingested), "-o", str(tmp_path / "pp"), *(["--vehicle", vehicle] if vehicle else [])]
    assert main(args) == 0
    assert f"vehicle profile {profile}" in capsys.readouterr().out


def test_preprocess_refuses_an_unknown_vehicle_in_one_line(ingested, tmp_path, capsys):
    assert main(["preprocess", str(ingested), "-o", str(tmp_path / "pp"), "--vehicle", "sim-qaud"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown vehicle 'sim-qaud'" in err and "generic" in err
    assert not (tmp_path / "pp").exists()


def test_preprocess_estimate_and_classify_say_one_line_per_input_not_the_library_line_too(
        ingested, model_dir, tmp_path, capsys):
    # the entry points' own summary went to stderr beside the command's line (twice per flight)
    from pipeline.io.stage import say

    assert main(["preprocess", str(ingested), "-o", str(tmp_path / "pp")]) == 0
    out, err = capsys.readouterr()
    assert out.count("\n") == 1 and err == ""
    st = tmp_path / "pp" / "demo" / "state.parquet"
    # the demo log has no radar: the flight fails, said once (the entry point's line, not restated)
    assert main(["estimate", str(ingested), "--state", str(st), "-o", str(tmp_path / "e")]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "demo: placeholder estimates (no radar stream" in err
    assert main(["classify", str(model_dir), str(st), "-o", str(tmp_path / "c.parquet")]) == 0
    out, err = capsys.readouterr()
    assert out.count("\n") == 1 and err == ""
    say("uavpipe x", "outside a command the summary is said", restated=True)  # the workflow's log
    assert capsys.readouterr().err == "uavpipe x: outside a command the summary is said\n"
