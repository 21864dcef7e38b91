"""The simulate modules import each other one way: no import circle, counting imports inside
functions too (a function-level import must not be what keeps a circle from failing)."""

from __future__ import annotations

import ast
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

SIM = Path(__file__).resolve().parents[2] / "pipeline" / "simulate"


def _sibling_imports(path: Path) -> set[str]:
    """Names of the ``pipeline.simulate`` modules that ``path`` imports, anywhere in it."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                out.add(node.module.split(".")[0])
            else:
                out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pipeline.simulate."):
            out.add(node.module.split(".")[2])
    return {m for m in out if (SIM / f"{m}.py").is_file()}


def test_simulate_modules_form_no_import_circle():
    graph = {p.stem: _sibling_imports(p) for p in SIM.glob("*.py") if p.stem != "__init__"}
    try:
        order = list(TopologicalSorter(graph).static_order())
    except CycleError as exc:
        raise AssertionError(f"import circle in pipeline/simulate: {exc.args[1]}") from None
    assert order.index("seeds") < order.index("writers") < order.index("datasets")


def test_writers_and_datasets_import_nothing_inside_functions():
    for name in ("writers", "datasets", "demo"):
        tree = ast.parse((SIM / f"{name}.py").read_text())
        nested = [n.lineno for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))]
        assert not nested, f"pipeline/simulate/{name}.py imports inside functions at lines {nested}"
