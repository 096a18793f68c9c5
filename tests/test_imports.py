"""Every module of the package imports on its own, in a fresh interpreter, and no module
imports itself back through others: the package's import graph, every import statement
counted (deferred ones inside functions too), has no cycle."""

import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import persuasive

#: Every module but ``persuasive.__main__``, which runs the command line when imported.
MODULES = sorted(m.name for m in pkgutil.walk_packages(persuasive.__path__, "persuasive.")
                 if m.name != "persuasive.__main__")


def test_every_module_imports_on_its_own():
    assert "persuasive.cli" in MODULES and "persuasive.cli.plots" in MODULES
    procs = {}
    failures = {}
    for name in MODULES:  # a few at a time: each start pays the numpy/numba import
        procs[name] = subprocess.Popen([sys.executable, "-c", f"import {name}"],
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                       text=True)
        if len(procs) >= 4:
            _drain(procs, failures)
    while procs:
        _drain(procs, failures)
    assert failures == {}


def _drain(procs, failures):
    name = next(iter(procs))
    proc = procs.pop(name)
    _, err = proc.communicate(timeout=120)
    if proc.returncode != 0:
        failures[name] = err.strip().splitlines()[-1]


# -- no import cycles, counting every import -----------------------------------------------------

SRC = Path(persuasive.__file__).resolve().parent


def _modules(root: Path) -> dict[str, tuple[Path, bool]]:
    """Every module of the package under ``root``: dotted name -> (file, is a package)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        out[".".join(parts)] = (path, is_package)
    return out


def _is_type_checking(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement anywhere in ``tree`` (functions and classes included), except
    inside ``if TYPE_CHECKING:`` blocks (their ``else`` branches count)."""
    found = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        children = node.orelse if _is_type_checking(node) else ast.iter_child_nodes(node)
        for child in children:
            visit(child)

    visit(tree)
    return found


def import_graph(root: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (relative imports resolved; ``from X
    import name`` is an edge to the submodule ``X.name`` when there is one, else to ``X``)."""
    modules = _modules(root)
    graph: dict[str, set[str]] = {}
    for name, (path, is_package) in modules.items():
        package = name if is_package else name.rpartition(".")[0]
        edges = set()
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                edges.update(a.name for a in node.names if a.name in modules)
                continue
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                if sub in modules:
                    edges.add(sub)
                elif source in modules:
                    edges.add(source)
        edges.discard(name)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles of ``graph``: for every module on a cycle, a shortest cycle through
    it (each cycle listed once, starting at its first module in sorted order)."""
    found = set()
    for start in sorted(graph):
        previous: dict[str, str] = {}  # breadth-first from start, back to start
        frontier = [start]
        while frontier and start not in previous:
            following = []
            for v in frontier:
                for w in sorted(graph[v]):
                    if w not in previous:
                        previous[w] = v
                        following.append(w)
            frontier = following
        if start not in previous:
            continue
        path, v = [start], previous[start]
        while v != start:
            path.append(v)
            v = previous[v]
        cycle = path[:1] + path[:0:-1]
        first = cycle.index(min(cycle))
        found.add(tuple(cycle[first:] + cycle[:first]))
    return [list(c) + [c[0]] for c in sorted(found)]


def test_the_cycle_finder_sees_deferred_relative_and_package_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("__version__ = '1'\nfrom .a import f\n")
    (pkg / "a.py").write_text("def f():\n    from .sub import g\n    return g\n")
    (pkg / "sub" / "__init__.py").write_text("from .b import g\n")
    (pkg / "sub" / "b.py").write_text("from .. import __version__\n\ndef g():\n    pass\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from . import a\nelse:\n    import pkg.d\n")
    (pkg / "d.py").write_text("import pkg.c as c\n")
    graph = import_graph(pkg)
    assert graph["pkg.a"] == {"pkg.sub"}  # a deferred import counts
    assert graph["pkg.sub.b"] == {"pkg"}  # ``from .. import name`` is the package itself
    assert graph["pkg.c"] == {"pkg.d"}  # TYPE_CHECKING aside, its else branch counts
    found = {tuple(c) for c in cycles(graph)}
    assert found == {("pkg", "pkg.a", "pkg.sub", "pkg.sub.b", "pkg"),
                     ("pkg.c", "pkg.d", "pkg.c")}


def test_no_import_cycles_in_the_package():
    """The package reads bottom-up: no module imports, directly or through others, a module
    that imports it back, wherever the import statement stands (a deferred import inside a
    function hides a cycle, it does not untie it)."""
    graph = import_graph(SRC)
    assert "persuasive.cli" in graph and graph["persuasive"]
    found = cycles(graph)
    assert found == [], "import cycles:\n" + "\n".join(" -> ".join(c) for c in found)
