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
