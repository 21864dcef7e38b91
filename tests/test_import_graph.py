"""The allowed import graph of ``pipeline/`` (developers' guide, "Engineering rules").

frames -> io -> preprocess -> models -> estimate -> align -> report: each subpackage may import
the ones before it; ``simulate`` may import frames, io and estimate; ``studies`` may import all of
these; nothing imports ``studies`` or ``cli``; nothing imports Snakemake. ``pipeline/config.py``
(the one config schema) and the package root are importable from everywhere. Checked on the
source (AST), so a function-level import counts like a module-level one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "pipeline"
CHAIN = ("frames", "io", "preprocess", "models", "estimate", "align", "report")
SHARED = {"config", "__init__"}  # modules directly under pipeline/, importable from everywhere
ALLOWED = {name: set(CHAIN[:i]) for i, name in enumerate(CHAIN)}
ALLOWED["simulate"] = {"frames", "io", "estimate"}
ALLOWED["studies"] = set(CHAIN) | {"simulate"}
ALLOWED["cli"] = set(CHAIN) | {"simulate"}


def _subpackage(path: Path) -> str:
    rel = path.relative_to(PKG)
    if rel.as_posix() == "__main__.py":
        return "cli"  # `python -m pipeline` is the command line
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imports(path: Path, source: str | None = None) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in one module (its text, or ``source`` as if
    it were it)."""
    tree = ast.parse(path.read_text() if source is None else source, filename=str(path))
    rel = path.relative_to(PKG.parent).with_suffix("")
    pkg_parts = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg_parts[: len(pkg_parts) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
                if node.module is None:  # from . import x, y
                    out += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
                    continue
            else:
                mod = node.module or ""
            if mod == "pipeline":  # from pipeline import estimate (a subpackage, or __version__)
                out += [(node.lineno, f"pipeline.{a.name}") for a in node.names]
                continue
            out.append((node.lineno, mod))
    return out


MODULES = sorted(PKG.rglob("*.py"))
SUBPACKAGES = {p.name for p in PKG.iterdir() if p.is_dir() and (p / "__init__.py").exists()} | \
    {p.stem for p in PKG.glob("*.py")}


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.relative_to(PKG).as_posix())
def test_module_imports_only_what_the_graph_allows(path):
    bad = _bad_imports(path)
    assert not bad, f"{path.relative_to(PKG)}: " + "; ".join(bad)


def _bad_imports(path: Path, source: str | None = None) -> list[str]:
    me = _subpackage(path)
    bad = []
    for line, mod in _imports(path, source):
        top = mod.split(".")[0]
        if top == "snakemake":
            bad.append(f"line {line}: imports snakemake")
        if top != "pipeline":
            continue
        parts = mod.split(".")
        if len(parts) == 1:
            continue  # `import pipeline` / `from pipeline import __version__`
        target = parts[1]
        if target not in SUBPACKAGES or target in SHARED or target == me:  # root attributes: __version__
            continue
        if me in SHARED:
            bad.append(f"line {line}: pipeline/{me}.py imports {mod}")
        elif target not in ALLOWED.get(me, set()):
            bad.append(f"line {line}: {me} imports {mod}")
    return bad


def test_the_graph_test_sees_relative_imports():
    mods = dict((m, line) for line, m in _imports(PKG / "preprocess" / "state.py"))
    assert "pipeline.io.schema" in {m for m in mods} or "pipeline.io" in mods
    assert any(m.startswith("pipeline.frames") for m in mods)


def test_the_graph_test_sees_a_subpackage_imported_from_the_package_root():
    # `from pipeline import studies` names the subpackage only in the imported name
    src = "from pipeline import studies, __version__\n"
    probe = PKG / "io" / "probe.py"
    assert [m for _, m in _imports(probe, src)] == ["pipeline.studies", "pipeline.__version__"]
    assert _bad_imports(probe, src) == ["line 1: io imports pipeline.studies"]


@pytest.mark.parametrize("package,entry", [("io", "run_ingest"), ("simulate", "run_simulate_sets"),
                                           ("preprocess", "run_preprocess"), ("models", "run_train"),
                                           ("models", "run_classify"), ("report", "run_index")])
def test_every_stage_entry_point_is_importable_from_its_package(package, entry):
    import importlib

    fn = getattr(importlib.import_module(f"pipeline.{package}"), entry)
    assert callable(fn) and list(__import__("inspect").signature(fn).parameters)[:3] == ["inputs", "outputs",
                                                                                          "config"]

