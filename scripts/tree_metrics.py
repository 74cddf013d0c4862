"""Prints the tree's size figures (issue 26): long modules, long functions, imports inside functions, `Any`.

Run: python scripts/tree_metrics.py [--list]. Counts the code packages only (not tests/ or bench/).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGES = ("recap", "workers", "pipeline", "schemas", "reports", "cli")
MODULE_LIMIT = 500
FUNCTION_LIMIT = 60


def _files(root: Path) -> list[Path]:
    return sorted(p for pkg in PACKAGES if (root / pkg).is_dir() for p in (root / pkg).rglob("*.py"))


def _nested_imports(tree: ast.AST) -> int:
    count = 0
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                if isinstance(inner, (ast.Import, ast.ImportFrom)):
                    count += 1
    return count


def _any_count(tree: ast.AST) -> int:
    return sum(
        1
        for node in ast.walk(tree)
        if (isinstance(node, ast.Name) and node.id == "Any") or (isinstance(node, ast.Attribute) and node.attr == "Any")
    ) - sum(1 for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) for alias in node.names if alias.name == "Any")


def main(argv: list[str]) -> int:
    """Walks the packages and prints the four figures (and, with --list, what is over the limits)."""
    root = Path(__file__).resolve().parent.parent
    long_modules: list[tuple[str, int]] = []
    long_functions: list[tuple[str, int]] = []
    nested = 0
    anys = 0
    lines = 0
    for path in _files(root):
        text = path.read_text()
        rel = str(path.relative_to(root))
        n = len(text.splitlines())
        lines += n
        if n > MODULE_LIMIT:
            long_modules.append((rel, n))
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > FUNCTION_LIMIT:
                    long_functions.append((f"{rel}::{node.name}", length))
        nested += _nested_imports(tree)
        anys += _any_count(tree)
    print(f"lines of code: {lines}")
    print(f"modules over {MODULE_LIMIT} lines: {len(long_modules)}")
    print(f"functions over {FUNCTION_LIMIT} lines: {len(long_functions)}")
    print(f"imports inside functions: {nested}")
    print(f"uses of Any: {anys}")
    if "--list" in argv:
        for rel, n in sorted(long_modules, key=lambda x: -x[1]):
            print(f"  module {rel}: {n}")
        for rel, n in sorted(long_functions, key=lambda x: -x[1]):
            print(f"  function {rel}: {n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
