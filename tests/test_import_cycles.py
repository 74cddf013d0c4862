"""No import cycles among our modules (recap/, workers/, pipeline/, schemas/, reports/).

Why: a cycle makes the import order matter (a module half-initialised when the other one
reads a name from it), hides which module owns a piece, and blocks splitting a package. The
layering test (tests/test_layers.py) checks the direction between packages; this one checks
the module graph inside them too.

The graph is read from the source with ``ast``, not by importing:

* every ``import`` statement counts, at module level and inside functions (a lazy import is
  still a dependency, it only moves the moment it runs), and inside ``if TYPE_CHECKING:``
  blocks too (an annotation-only import is still a dependency of the reader; the code is kept
  free of them rather than excused);
* ``import a.b.c`` is an edge to ``a.b.c``; ``from a.b import c`` is an edge to ``a.b.c``
  when that is a module of ours, else to ``a.b`` (the package ``__init__`` that provides the
  name, so re-exports in ``__init__`` files are part of the graph); relative imports are
  resolved against the importing module's package;
* importing ``a.b.c`` also runs ``a/__init__`` and ``a/b/__init__``, but that implicit edge
  from a submodule to its own parent packages is not counted: every submodule of a package
  that re-exports it would otherwise be "in a cycle" with it, which is how packages work.

Cycles are the strongly connected components with more than one module (Tarjan), and
modules that import themselves.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("recap", "workers", "pipeline", "schemas", "reports")


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def our_modules(root: Path, packages: Iterable[str]) -> dict[str, Path]:
    return {module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}


def imports_of(name: str, path: Path, modules: Mapping[str, Path]) -> set[str]:
    """The modules of ours that ``name`` (at ``path``) imports, anywhere in its body."""
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in modules else base)
    return {m for m in found if m in modules and m != name} | ({name} & found)


def import_graph(root: Path = REPO, packages: Iterable[str] = PACKAGES) -> dict[str, set[str]]:
    modules = our_modules(root, packages)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one node, plus self-loops (sorted)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0

    def visit(root: str) -> None:
        # iterative, so a deep chain of imports cannot hit the recursion limit
        nonlocal counter
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph.get(node, ()):
                        found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def test_our_modules_import_each_other_without_cycles():
    assert cycles(import_graph()) == []


def test_the_graph_sees_lazy_relative_and_reexport_imports(tmp_path):
    """The reader is not blind: a function-level import, a relative import, a TYPE_CHECKING
    import and a ``from pkg import name`` served by ``pkg/__init__`` all make edges."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from pkg.a import A\n")
    (pkg / "a.py").write_text("A = 1\ndef f():\n    from pkg.b import g\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .sub import c\ng = 1\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "c.py").write_text("from pkg import A\nfrom .. import a\nimport os\n")
    graph = import_graph(tmp_path, ["pkg"])
    assert graph == {
        "pkg": {"pkg.a"},
        "pkg.a": {"pkg.b"},
        "pkg.b": {"pkg.sub.c"},
        "pkg.sub": set(),
        "pkg.sub.c": {"pkg", "pkg.a"},
    }
    assert cycles(graph) == [["pkg", "pkg.a", "pkg.b", "pkg.sub.c"]]


def test_tarjan_finds_each_component_and_self_loops():
    graph = {"a": {"b"}, "b": {"a", "c"}, "c": {"d"}, "d": {"c"}, "e": {"e"}, "f": {"a"}}
    assert cycles(graph) == [["a", "b"], ["c", "d"], ["e"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
