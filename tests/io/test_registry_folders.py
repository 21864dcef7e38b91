"""A folder given as a log: the only folder format is a ROS 2 bag, so anything else is named
for what it holds (pipeline/io/registry.py)."""

from __future__ import annotations

import pytest

from pipeline.io import registry
from pipeline.io.base import IngestError


def test_a_folder_without_metadata_yaml_says_what_it_holds_and_an_empty_one_says_so(tmp_path):
    only = tmp_path / "only"
    only.mkdir()
    for n in ("husky.mcap", "a.txt", "b.txt", "c.txt"):
        (only / n).write_bytes(b"x")
    with pytest.raises(IngestError) as exc:
        registry.detect(only)
    assert exc.value.reason == ("a folder without metadata.yaml, so not a ROS 2 bag (it holds a.txt, b.txt, "
                                "c.txt and 1 more); give a log file itself, or the bag's folder")
    (tmp_path / "empty").mkdir()
    with pytest.raises(IngestError, match="an empty folder, not a log"):
        registry.detect(tmp_path / "empty")


def test_a_folder_that_cannot_be_listed_says_why(tmp_path, monkeypatch):
    # as root (CI) chmod 0 does not stop a listing: the refusal itself, as the OS gives it
    d = tmp_path / "locked"
    d.mkdir()
    real = type(d).iterdir

    def refuse(self):
        if self == d:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(type(d), "iterdir", refuse)
    with pytest.raises(IngestError) as exc:
        registry.detect(d)
    assert exc.value.reason == "cannot list the folder: Permission denied"
