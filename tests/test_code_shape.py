"""The shape rules of issues 11 and 26, held by the suite: no function over
:data:`MAX_FUNCTION_LINES` lines (docstring included) and no module over
:data:`MAX_MODULE_LINES` lines in the package, and a README of at most
:data:`MAX_README_LINES` lines."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("app", "core", "devices")
MAX_FUNCTION_LINES = 120
MAX_MODULE_LINES = 1000
MAX_README_LINES = 200


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


def test_no_module_over_1000_lines():
    long = [
        f"{path.relative_to(ROOT)} ({n} lines)"
        for folder in PACKAGE_DIRS
        for path in sorted((ROOT / folder).rglob("*.py"))
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    ]
    assert long == []


def test_readme_is_a_users_entry_of_at_most_200_lines():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert 20 < len(lines) <= MAX_README_LINES
