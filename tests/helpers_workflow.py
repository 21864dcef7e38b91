"""Scratch copies of the workflow for the tests that run Snakemake (tests/workflow/)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = str(Path(sys.executable).parent / "snakemake")
#: the manifest's header row (datasets/flights.tsv)
HEADER = "flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\n"


def copy_workflow(dst: Path, rows: list[str], extra_config: str = "", tiny: bool = True,
                  extra_tiny: str = "") -> Path:
    """Copy the Snakefile, rules/, reports/ and profiles/ to ``dst`` with a manifest of ``rows``.

    ``datasets/config.yaml`` is the shipped one plus ``extra_config``; with ``tiny`` the tiny
    sizes of tests/workflow/config.yaml (plus ``extra_tiny``) go to ``datasets/tiny.yaml``, which
    the tests merge over the default config.
    """
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "rules", "reports", "profiles"):
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, dst / name)
    (dst / "datasets").mkdir()
    cfg = (ROOT / "datasets" / "config.yaml").read_text()
    (dst / "datasets" / "config.yaml").write_text(cfg + extra_config)
    (dst / "datasets" / "flights.tsv").write_text(HEADER + "".join(r + "\n" for r in rows))
    tiny_cfg = (ROOT / "tests" / "workflow" / "config.yaml").read_text() + extra_tiny
    (dst / "datasets" / ("tiny.yaml" if tiny else "unused.yaml")).write_text(tiny_cfg)
    return dst
