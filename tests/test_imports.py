"""Every module of the package imports on its own, in a fresh interpreter, and no module
imports itself back through others: the package's import graph, every import statement
counted (deferred ones inside functions too), has no cycle."""

import ast
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import persuasive

#: Every module but ``persuasive.__main__``, which runs the command line when imported.
MODULES = sorted(m.name for m in pkgutil.walk_packages(persuasive.__path__, "persuasive.")
                 if m.name != "persuasive.__main__")


#: Run in one fresh interpreter: it imports the third-party libraries every module needs (not
#: the package: numpy, numba, pandas, matplotlib, the extras...), then forks one child per
#: module, which imports it: each child starts with no module of the package loaded, as a
#: fresh interpreter would, without paying those imports again (70 s for the package with one
#: process per module).
_IMPORTER = """
import importlib, os, sys, traceback
import numpy, numba, pandas, pyarrow, scipy.optimize, click, tqdm
for lib in ("matplotlib.pyplot", "imageio", "distributed", "gymnasium", "highway_env",
            "starlette.applications", "uvicorn", "lanelet2"):
    try:  # the optional extras too, where installed
        importlib.import_module(lib)
    except ImportError:
        pass
for name in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        try:
            importlib.import_module(name)
        except BaseException as exc:
            print(name + "\t" + (traceback.format_exception_only(exc)[-1].strip()),
                  flush=True)
            os._exit(1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    if status != 0:
        print(name + "\tstatus " + str(status), flush=True)
"""


def test_every_module_imports_on_its_own(tmp_path):
    assert "persuasive.cli" in MODULES and "persuasive.cli.plots" in MODULES
    # the bytecode the children compile goes to a folder of the test's, where the next child
    # finds it (with PYTHONDONTWRITEBYTECODE every child compiled every source again)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(tmp_path / "pycache")
    env["MPLBACKEND"] = "Agg"
    half = len(MODULES) // 2  # two interpreters, one per core
    procs = [subprocess.Popen([sys.executable, "-c", _IMPORTER, *names], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for names in (MODULES[:half], MODULES[half:])]
    failures = {}
    for proc in procs:
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err[-2000:]
        for line in out.splitlines():
            name, _, why = line.partition("\t")
            failures.setdefault(name, why)
    assert failures == {}


def test_a_module_that_cannot_import_is_named():
    """The importer has teeth: a module that raises at import is reported with its error."""
    out = subprocess.run([sys.executable, "-c", _IMPORTER, "persuasive", "persuasive.nope"],
                         capture_output=True, text=True, timeout=120).stdout
    assert out.startswith("persuasive.nope\tModuleNotFoundError") and "persuasive\t" not in out


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
