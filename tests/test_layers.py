"""Layers point down only: core <- physics <- integrators <- engines <- studies <- steplab's
commands; and no module imports itself back through others (no import cycle).

Read from the source with ``ast`` (every import, also those inside functions), so an
upward import or a cycle fails here even where no test happens to execute it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: each layer's folder and installed name, lowest first; the commands (cli, io, paper,
#: bench, animate, peers) sit above them all. The foundations (steplab/core: registries,
#: records, timing) import nothing else of steplab; the engine adapters (steplab/engines)
#: build on the model and the integrators' trajectories, and the studies measure them
LAYERS = (("steplab/core", "steplab.core"), ("physics", "steplab.physics"), ("integrators", "steplab.integrators"),
          ("steplab/engines", "steplab.engines"), ("studies", "steplab.studies"))
#: every folder of steplab's modules and its installed name, for the cycle check
PACKAGES = (*LAYERS, ("steplab", "steplab"))


def layer_of(module: str) -> int:
    """The rank of a ``steplab.*`` module: 0 core, 1 physics, 2 integrators, 3 engines, 4 studies, 5 the commands."""
    for rank, (_, package) in enumerate(LAYERS):
        if module == package or module.startswith(package + "."):
            return rank
    return len(LAYERS)


def imported_modules(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, absolute name) of every steplab import in ``path``, a module of ``package``: the
    module, or for ``from m import name`` the module and the name (``steplab.io.write_atomic``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = package.split(".")
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: one dot is the package that holds the module, each more its parent
                base = ".".join(here[:len(here) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module
            # `from steplab import cli` imports the module steplab.cli; `from m import f`, m.f
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names]
    return [(line, name) for line, name in found if name == "steplab" or name.startswith("steplab.")]


def sources():
    for rank, (folder, package) in enumerate(LAYERS):
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).parent.parts
            yield pytest.param(rank, path, ".".join([package, *parts]), id=str(path.relative_to(ROOT)))


@pytest.mark.parametrize(("rank", "path", "package"), list(sources()))
def test_no_module_imports_a_layer_above_its_own(rank, path, package):
    upward = [f"{path.relative_to(ROOT)}:{line} imports {name}"
              for line, name in imported_modules(path, package) if layer_of(name) > rank]
    assert not upward, upward


def test_the_check_sees_an_upward_import(tmp_path):
    """The walk finds absolute, relative, aliased and function-local imports (else it proves nothing)."""
    module = tmp_path / "runner.py"
    module.write_text("from steplab.io import write_atomic\nfrom .. import integrators\n"
                      "def f():\n    from steplab import paper\n    import steplab.bench as b\n")
    names = [name for _, name in imported_modules(module, "steplab.studies")]
    assert names == ["steplab.io.write_atomic", "steplab.integrators", "steplab.paper", "steplab.bench"]
    assert [layer_of(n) for n in names] == [5, 2, 5, 5]


# --- no import cycles ---------------------------------------------------------------------



def modules() -> dict[str, Path]:
    """Every steplab module by its installed name (a package by its own name, not ``.__init__``)."""
    found = {}
    for folder, package in PACKAGES:
        for path in (ROOT / folder).rglob("*.py"):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            found[".".join([package, *parts]).removesuffix(".__init__")] = path
    return found


def import_graph(found: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the steplab modules it imports (``from package import module`` names the module)."""
    graph = {}
    for name, path in found.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for _, imported in imported_modules(path, package):
            while imported and imported not in found:  # `from m import f`: the module m
                imported = imported.rpartition(".")[0]
            targets.add(imported)
        graph[name] = targets - {name, ""}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The import cycles: each set of two or more modules that all reach one another."""
    def reach(start: str) -> set[str]:
        seen, todo = set(), list(graph[start])
        while todo:
            module = todo.pop()
            if module not in seen:
                seen.add(module)
                todo += graph.get(module, ())
        return seen

    reaches = {module: reach(module) for module in graph}
    found = []
    for module in sorted(graph):
        component = {other for other in reaches[module] if module in reaches.get(other, ())}
        if len(component) > 1 and component not in found:
            found.append(component)
    return found


def test_no_import_cycle_among_steplab_modules():
    found = cycles(import_graph(modules()))
    assert not found, [sorted(c) for c in found]


def test_the_cycle_check_sees_a_cycle(tmp_path):
    """Three modules in a ring (one link an import inside a function, one a relative import), and
    a fourth outside it: the check finds the ring alone."""
    code = {"a": "from . import b\n", "b": "def f():\n    from .c import g\n",
            "c": "import steplab.x.a\nfrom steplab.x import d\n", "d": "import numpy\n"}
    found = {}
    for name, text in code.items():
        (tmp_path / f"{name}.py").write_text(text)
        found[f"steplab.x.{name}"] = tmp_path / f"{name}.py"
    assert cycles(import_graph(found)) == [{"steplab.x.a", "steplab.x.b", "steplab.x.c"}]
