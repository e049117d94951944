"""The benchmarks' imports of sonibus resolve (``make bench`` is not run by the suite: a name
moved in the tree broke ``bench/stop_flood.py``'s import inside a function, found a day later)."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


def sonibus_imports(path: Path) -> list[tuple[int, str, str]]:
    """Every ``from sonibus.… import name`` of a script, at any depth: (line, module, name)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "sonibus":
            found += [(node.lineno, node.module, alias.name) for alias in node.names]
    return found


@pytest.mark.parametrize("script", sorted(BENCH.glob("*.py")), ids=lambda path: path.name)
def test_every_sonibus_name_a_benchmark_imports_exists(script: Path) -> None:
    missing = []
    for line, module, name in sonibus_imports(script):
        imported = importlib.import_module(module)
        if not hasattr(imported, name):
            try:
                importlib.import_module(f"{module}.{name}")  # (a submodule)
            except ModuleNotFoundError:
                missing.append(f"{script.name}:{line}: {module} has no {name}")
    assert not missing, "; ".join(missing)


def test_the_check_finds_a_moved_name(tmp_path: Path) -> None:
    script = tmp_path / "moved.py"
    script.write_text("def flood():\n    from sonibus.bus.messages import frame\n")
    assert sonibus_imports(script) == [(2, "sonibus.bus.messages", "frame")]
    assert not hasattr(importlib.import_module("sonibus.bus.messages"), "frame")
