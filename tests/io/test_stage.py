"""Declared stage paths: Snakemake's namedlists and plain dicts read the same."""

from __future__ import annotations

from snakemake.iocontainers import InputFiles

from pipeline.io.stage import declared, declared_list


def test_declared_paths_read_dicts_and_snakemake_namedlists_alike():
    nl = InputFiles(["a.parquet", "b.parquet"])
    nl._set_name("sets", 0, 2)
    for paths in (nl, {"sets": ["a.parquet", "b.parquet"]}):
        assert declared_list(paths, "sets") == ["a.parquet", "b.parquet"]
        assert declared(paths, "states") is None and declared_list(paths, "states") == []
