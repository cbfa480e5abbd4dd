"""The shape rules of issue 11, held by the suite: no function over
:data:`MAX_FUNCTION_LINES` lines (docstring included) in the package."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("app", "core", "devices")
MAX_FUNCTION_LINES = 120


def _long_functions() -> list[str]:
    found = []
    for folder in PACKAGE_DIRS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        rel = path.relative_to(ROOT)
                        found.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_no_function_over_120_lines():
    assert _long_functions() == []
