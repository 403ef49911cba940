"""Layers point down only: physics <- integrators <- engines <- studies <- steplab's commands.

Read from the source with ``ast`` (every import, also those inside functions), so an
upward import fails here even where no test happens to execute it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: each layer's folder and installed name, lowest first; the commands (cli, io, paper,
#: bench, animate, peers) sit above them all. The engine adapters (steplab/engines) build on
#: the model and the integrators' trajectories, and the studies measure them
LAYERS = (("physics", "steplab.physics"), ("integrators", "steplab.integrators"),
          ("steplab/engines", "steplab.engines"), ("studies", "steplab.studies"))


def layer_of(module: str) -> int:
    """The rank of a ``steplab.*`` module: 0 physics, 1 integrators, 2 engines, 3 studies, 4 the commands."""
    for rank, (_, package) in enumerate(LAYERS):
        if module == package or module.startswith(package + "."):
            return rank
    return len(LAYERS)


def imported_modules(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, absolute module name) of every steplab import in ``path``, a module of ``package``."""
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
            # `from steplab import cli` imports the module steplab.cli
            found += [(node.lineno, f"{base}.{alias.name}" if base == "steplab" else base) for alias in node.names]
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
    assert names == ["steplab.io", "steplab.integrators", "steplab.paper", "steplab.bench"]
    assert [layer_of(n) for n in names] == [4, 1, 4, 4]
