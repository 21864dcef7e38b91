"""Shipped column maps for the CSV/Parquet importer (:mod:`pipeline.io.tabular`), one YAML each."""
