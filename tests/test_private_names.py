"""No module of ``pipeline/`` uses another module's private (``_x``) names (style.md: "no
module uses another module's private names"): an AST walk over every source file finds every
``from <pipeline module> import _name`` and every ``module._name`` on an imported pipeline
module."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "pipeline"

#: (importing module, imported module, name) still allowed: none
ALLOWED: set[tuple[str, str, str]] = set()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_module(name: str) -> bool:
    p = ROOT.joinpath(*name.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def _resolve(node: ast.ImportFrom, here: str, is_pkg: bool) -> str:
    if not node.level:
        return node.module or ""
    base = here.split(".") if is_pkg else here.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


def violations(path: Path, source: str | None = None) -> list[str]:
    """Cross-module private-name uses in ``path`` (its text, or ``source`` as if it were it)."""
    here = _module_name(path)
    tree = ast.parse(path.read_text() if source is None else source, filename=str(path))
    is_pkg = path.name == "__init__.py"
    modules: dict[str, str] = {}  # local name -> pipeline module it is bound to
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "pipeline":
                    modules[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom):
            src = _resolve(node, here, is_pkg)
            if src.split(".")[0] != "pipeline":
                continue
            for a in node.names:
                if _is_module(f"{src}.{a.name}"):
                    modules[a.asname or a.name] = f"{src}.{a.name}"
                elif _private(a.name) and src != here and (here, src, a.name) not in ALLOWED:
                    out.append(f"{path.relative_to(ROOT)}:{node.lineno}: from {src} import {a.name}")
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and _private(node.attr) and isinstance(node.value, ast.Name)
                and node.value.id in modules and modules[node.value.id] != here
                and (here, modules[node.value.id], node.attr) not in ALLOWED):
            out.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr} "
                       f"({modules[node.value.id]})")
    return out


def pipeline_imports(text: str) -> str:
    """The ``from pipeline... import`` / ``import pipeline...`` statements of a Snakemake file
    (parenthesised ones whole), as Python source."""
    return "\n".join(re.findall(r"^(?:from pipeline[\w.]* import \([^)]*\)|(?:from|import) pipeline[^\n]*)",
                                text, flags=re.M)) + "\n"


def test_the_snakemake_import_reader_sees_one_and_several_line_imports():
    text = "rule a:\n    input: x\nfrom pipeline.io.schema import (STATE,\n    _cast)\nimport pipeline.io\n"
    assert violations(ROOT / "rules" / "probe.py", pipeline_imports(text)) == [
        "rules/probe.py:1: from pipeline.io.schema import _cast"]


def test_no_module_imports_or_uses_another_modules_private_names():
    found = [v for p in sorted(PKG.rglob("*.py")) for v in violations(p)]
    assert not found, "private names used across modules:\n" + "\n".join(found)


def test_the_rule_adapters_and_benchmarks_use_only_public_pipeline_names():
    # they sit outside the package and call into it: the same rule holds for them
    files = [*sorted((ROOT / "rules").rglob("*.py")), *sorted((ROOT / "benchmarks").rglob("*.py"))]
    assert len(files) > 10
    found = [v for p in files for v in violations(p)]
    # the Snakemake files are not Python: their `from pipeline... import` lines, read as Python
    for smk in sorted([ROOT / "Snakefile", *(ROOT / "rules").glob("*.smk")]):
        found += [v.replace(str(smk.with_suffix(".py").relative_to(ROOT)), str(smk.relative_to(ROOT)))
                  for v in violations(smk.with_suffix(".py"), pipeline_imports(smk.read_text()))]
    assert not found, "private pipeline names used outside the package:\n" + "\n".join(found)


@pytest.mark.parametrize("src, bad", [
    ("from .plots import _layout\n", True),
    ("from ..io import schema\nschema._cast(1, 2)\n", True),
    ("from ..io.schema import cast\nfrom .. import __version__\n", False),
    ("def _own():\n    pass\n_own()\n", False),
])
def test_the_check_finds_private_imports_and_attribute_uses(src, bad):
    # the source is checked as if it were a module pipeline/report/probe.py
    assert bool(violations(PKG / "report" / "probe.py", src)) is bad
