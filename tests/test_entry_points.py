"""README's stage table: every entry point it names exists where it says, and each is also
importable from its stage's package (``pipeline.<stage>.run_<name>``, as the README promises)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_entry_points() -> list[tuple[str, str]]:
    """``(module, function)`` for each `run_*` in the entry-point column of the stage table; a
    bare ``run_x`` after ``a.b.run_y`` lives in ``a.b``."""
    text = README.read_text()
    table = text[text.index("| stage | entry point |"):].split("\n\n")[0]
    out = []
    for row in table.splitlines()[2:]:
        module = None
        for name in re.findall(r"`([a-z_.]*run_[a-z_]+)`", row.split("|")[2]):
            parts = name.removeprefix("pipeline.").split(".")
            if len(parts) > 1:
                module = "pipeline." + ".".join(parts[:-1])
            out.append((module, parts[-1]))
    return out


def test_every_entry_point_the_readme_names_exists_in_its_module_and_its_stage_package():
    found = readme_entry_points()
    assert len(found) >= 20 and all(m for m, _ in found)
    for module, fn in found:
        f = getattr(importlib.import_module(module), fn)
        stage = importlib.import_module(".".join(module.split(".")[:2]))
        assert callable(f) and getattr(stage, fn) is f, f"{module}.{fn} from {stage.__name__}"
