"""The dependency direction of the design card, read from every module's import statements.

pipeline -> workers -> recap, and everyone -> schemas; ``reports`` reads run folders through
``schemas`` only (never ``workers`` or ``pipeline``; it may use the pure ``recap``); ``recap`` is pure (no Ray, no I/O libraries, none of our
other packages); ``schemas`` imports none of our other packages. Imports inside functions count:
a lazy import is still a dependency.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
OURS = ("recap", "workers", "pipeline", "schemas", "reports")

#: package -> our packages it may import (besides itself)
ALLOWED = {
    "schemas": set(),
    "recap": {"schemas"},
    "workers": {"recap", "schemas"},
    "reports": {"recap", "schemas"},
    "pipeline": {"workers", "recap", "schemas", "reports"},
}
#: third-party modules recap/ must not touch: the method stays free of Ray and of file formats
RECAP_FORBIDDEN = {"ray", "litellm", "pyarrow", "duckdb", "requests", "httpx"}


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module)
    return found


def package_imports(package: str) -> dict[str, set[str]]:
    return {str(p.relative_to(REPO)): imported_modules(p) for p in sorted((REPO / package).rglob("*.py"))}


@pytest.mark.parametrize("package", OURS)
def test_each_package_imports_only_what_the_layering_allows(package):
    wrong = {
        f"{path}: {module}"
        for path, modules in package_imports(package).items()
        for module in modules
        if (top := module.split(".")[0]) in OURS and top != package and top not in ALLOWED[package]
    }
    assert wrong == set()


def test_the_method_is_free_of_ray_and_io_libraries():
    wrong = {
        f"{path}: {module}"
        for path, modules in package_imports("recap").items()
        for module in modules
        if module.split(".")[0] in RECAP_FORBIDDEN
    }
    assert wrong == set()


def test_the_check_sees_a_violation(tmp_path):
    """The reader is not blind: a lazy import inside a function is found."""
    bad = tmp_path / "m.py"
    bad.write_text("def f():\n    from workers.gateway import core\n    import ray.util\n")
    assert imported_modules(bad) == {"workers.gateway", "ray.util"}


def test_bench_imports_nothing_from_tests():
    """bench/ measures the product: it imports nothing of tests/ (nor runs ``-m tests.``)."""
    wrong = {
        f"{p.relative_to(REPO)}: {module}"
        for p in sorted((REPO / "bench").rglob("*.py"))
        for module in imported_modules(p)
        if module.split(".")[0] == "tests"
    }
    wrong |= {str(p.relative_to(REPO)) for p in (REPO / "bench").rglob("*.py") if '"tests.' in p.read_text()}
    assert wrong == set()


#: test folders that are not a package's mirror: shared doubles, the real-model check, the
#: whole-pipeline chaos lab, and folders of golden files
NOT_MIRRORS = {"tests/doubles", "tests/realmodel", "tests/pipeline/chaos"}


def test_test_folders_mirror_the_packages():
    """``tests/workers/envs/fever`` holds the tests of ``workers/envs/fever``: every folder of test
    modules names a folder of the code (so a module's tests are found without grep)."""
    folders = {p.parent for p in (REPO / "tests").rglob("test_*.py")}
    wrong = sorted(
        str(rel)
        for d in folders
        if d != REPO / "tests"
        and not (REPO / (rel := d.relative_to(REPO)).relative_to("tests")).is_dir()
        and str(rel) not in NOT_MIRRORS
    )
    assert wrong == []
