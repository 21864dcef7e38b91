"""``uavpipe config``: the validated, defaulted configuration the workflow and every command see."""

from __future__ import annotations

import yaml

from pipeline.cli import main
from pipeline.config import defaults, load_config


def test_config_prints_the_validated_file_with_every_default(capsys):
    assert main(["config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out) == load_config()


def test_config_defaults_and_one_section(capsys):
    assert main(["config", "--defaults"]) == 0
    assert yaml.safe_load(capsys.readouterr().out) == defaults()
    assert main(["config", "--section", "preprocess"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["rate_hz"] == load_config()["preprocess"]["rate_hz"]


def test_a_bad_file_is_one_line_naming_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("preprocess: {rate_hx: 3}\n")
    assert main(["config", "--config", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "preprocess.rate_hx: unknown key" in err[0]


def test_a_dotted_section_prints_the_users_value_not_the_default(tmp_path, capsys):
    from pipeline.config import section

    f = tmp_path / "radar.yaml"
    f.write_text("simulate:\n  sensors:\n    radar:\n      rate_hz: 10\n")
    assert main(["config", "--config", str(f), "--section", "simulate.sensors"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["radar"]["rate_hz"] == 10.0
    assert section(load_config(f), "simulate.sensors.radar")["rate_hz"] == 10.0
    assert main(["config", "--config", str(f), "--section", "simulate.sensors.radar.rate_hz"]) == 0
    assert capsys.readouterr().out == "simulate.sensors.radar.rate_hz: 10.0\n"


def test_an_unknown_key_in_a_dotted_section_is_one_line_naming_the_keys_there(capsys):
    assert main(["config", "--section", "preprocess.rate_hx"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no key 'rate_hx' in preprocess (keys: rate_hz," in err[0]


def test_without_config_a_command_reads_the_current_folders_dataset_config(tmp_path, monkeypatch, capsys):
    (tmp_path / "datasets").mkdir()
    (tmp_path / "datasets" / "config.yaml").write_text("seed: 5\n")
    monkeypatch.chdir(tmp_path)
    assert main(["config", "--section", "seed"]) == 0
    assert capsys.readouterr().out == "seed: 5\n"
    monkeypatch.chdir(tmp_path / "datasets")     # no datasets/config.yaml here: the project's
    assert main(["config", "--section", "seed"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["seed"] != 5
