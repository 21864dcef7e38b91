"""The numba kernels of ``pipeline/`` keep the habits that hold their cold compile down (README,
Layout): every kernel is cached, and none assigns a whole row of an array it made with two or
more dimensions (``Pp[k] = P``: numba then compiles its shape-mismatch message into the kernel,
3.2 s for that one line of the GPS smoother; 8.9 → 3.0 s for the kernel once written out).

An AST walk: a kernel is a function decorated with ``njit``/``numba.njit``/``jit`` or passed to
``lazy_njit``; its arrays of known rank are the names it binds to ``np.zeros``/``np.empty``/
``np.ones``/``np.full`` with a shape tuple of two or more entries (or ``np.eye``); a row
assignment is ``name[i] = …`` with one index that is not a slice."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "pipeline"
MAKERS = {"zeros", "empty", "ones", "full"}


def _decorator_name(d: ast.expr) -> str:
    f = d.func if isinstance(d, ast.Call) else d
    return f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")


def _kernels(tree: ast.Module) -> list[tuple[ast.FunctionDef, ast.expr | None]]:
    """(function, its njit decorator or None for a ``lazy_njit`` one)."""
    lazy = {n.value.args[0].id for n in ast.walk(tree)
            if isinstance(n, ast.Assign) and isinstance(n.value, ast.Call)
            and getattr(n.value.func, "id", "") == "lazy_njit" and n.value.args
            and isinstance(n.value.args[0], ast.Name)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            deco = [d for d in node.decorator_list if _decorator_name(d) in ("njit", "jit")]
            if deco:
                out.append((node, deco[0]))
            elif node.name in lazy:
                out.append((node, None))
    return out


def _ranked_arrays(fn: ast.FunctionDef) -> set[str]:
    names = set()
    for n in ast.walk(fn):
        if not (isinstance(n, ast.Assign) and isinstance(n.value, ast.Call)):
            continue
        f = n.value.func
        attr = f.attr if isinstance(f, ast.Attribute) else ""
        shape = n.value.args[0] if n.value.args else None
        ranked = (attr in MAKERS and isinstance(shape, ast.Tuple) and len(shape.elts) >= 2) or attr == "eye"
        if ranked:
            names.update(t.id for t in n.targets if isinstance(t, ast.Name))
    return names


def _row_assignments(fn: ast.FunctionDef) -> list[str]:
    ranked = _ranked_arrays(fn)
    found = []
    for n in ast.walk(fn):
        targets = n.targets if isinstance(n, ast.Assign) else [n.target] if isinstance(n, ast.AugAssign) else []
        for t in targets:
            for s in (t.elts if isinstance(t, ast.Tuple) else [t]):
                if (isinstance(s, ast.Subscript) and isinstance(s.value, ast.Name) and s.value.id in ranked
                        and not isinstance(s.slice, (ast.Tuple, ast.Slice))):
                    found.append(f"line {s.lineno}: {ast.unparse(s)} = ...")
    return found


FILES = sorted(p for p in PKG.rglob("*.py") if "njit" in p.read_text(encoding="utf-8"))


def test_the_walk_finds_the_kernels_it_is_meant_to_check():
    names = {fn.name for p in FILES for fn, _ in _kernels(ast.parse(p.read_text(encoding="utf-8")))}
    assert {"_rts_axis", "_mpc_euler_kernel", "_k_stats", "_combine_kernel", "_dtw_path_kernel"} <= names


def test_the_check_flags_the_row_assignment_the_smoother_had():
    fn = ast.parse("def k(n):\n    Pp = np.zeros((n, 4, 4))\n    P = np.eye(4)\n    Pp[1] = P\n"
                   "    Pp[1, 2, 3] = 0.0\n    x = np.zeros(n)\n    x[0] = 1.0\n").body[0]
    assert _row_assignments(fn) == ["line 4: Pp[1] = ..."]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_kernel_is_cached_and_assigns_no_whole_rows(path):
    problems = []
    for fn, deco in _kernels(ast.parse(path.read_text(encoding="utf-8"))):
        if deco is not None and not any(k.arg == "cache" and getattr(k.value, "value", None) is True
                                        for k in getattr(deco, "keywords", [])):
            problems.append(f"{fn.name}: not cache=True (it would compile again in every process)")
        problems += [f"{fn.name} {r}" for r in _row_assignments(fn)]
    assert not problems, "; ".join(problems)
