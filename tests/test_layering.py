"""The layering of the source tree (README, "Layout"), checked by parsing every module's
imports (module-level and the ones inside functions alike):

- the generic core (systems/contact, systems/c3, systems/learning) imports only itself;
- systems/ never imports diagrams/, scenarios/ or tools/;
- models/ imports only models/ and the core's systems/contact;
- scenarios/ imports only scenarios/;
- diagrams/ never imports tools/;
- inside tools/diagnosis: the engine imports only the engine and the backends, the
  backends only the backends, a task (tasks/<task>) the engine, the backends and itself,
  and only the harness and tools/bench (it times diagnoses of harness data)
  import the harness;
- no import circles anywhere (tests/ excluded: tests may import anything).

The checker runs on the real tree and on synthetic trees that break one rule each, so
it is shown to fail where it should.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "adaptive_c3"
TOP = ("systems", "diagrams", "models", "scenarios", "tools")
CORE = ("systems.contact", "systems.c3", "systems.learning")
DIAG = "tools.diagnosis"
ENGINE, BACKENDS, TASKS, HARNESS = (f"{DIAG}.{w}" for w in ("engine", "backends", "tasks", "harness"))


def _module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph(root: Path) -> dict[str, set[str]]:
    """module (dotted, without the `adaptive_c3.` prefix) -> the project modules it imports."""
    files = {_module_name(root, p): p for top in TOP if (root / top).is_dir()
             for p in sorted((root / top).rglob("*.py"))}
    graph = {}
    for mod, path in files.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                # `from pkg import sub` imports the module pkg.sub when it exists
                names = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}"[len(PACKAGE) + 1:]
                         in files else node.module for a in node.names]
            for name in names:
                if name.startswith(PACKAGE + "."):
                    target = name[len(PACKAGE) + 1:]
                    while target and target not in files:   # `import a.b.c` names a.b.c
                        target = target.rpartition(".")[0]
                    if target and target != mod:
                        deps.add(target)
        graph[mod] = deps
    return graph


def _in(mod: str, *areas: str) -> bool:
    return any(mod == a or mod.startswith(a + ".") for a in areas)


def layering_violations(graph: dict[str, set[str]]) -> list[str]:
    """One line per import that breaks a rule of the module docstring."""
    bad = []
    for mod, deps in sorted(graph.items()):
        for dep in sorted(deps):
            if _in(mod, *CORE) and not _in(dep, *CORE):
                bad.append(f"{mod} -> {dep}: the generic core imports only itself")
            elif _in(mod, "systems") and _in(dep, "diagrams", "scenarios", "tools"):
                bad.append(f"{mod} -> {dep}: systems/ never imports {dep.split('.')[0]}/")
            elif _in(mod, "models") and not _in(dep, "models", "systems.contact"):
                bad.append(f"{mod} -> {dep}: models/ imports only models/ and systems/contact")
            elif _in(mod, "scenarios") and not _in(dep, "scenarios"):
                bad.append(f"{mod} -> {dep}: scenarios/ imports only scenarios/")
            elif _in(mod, "diagrams") and _in(dep, "tools"):
                bad.append(f"{mod} -> {dep}: diagrams/ never imports tools/")
            elif _in(dep, HARNESS) and not _in(mod, HARNESS, "tools.bench"):
                bad.append(f"{mod} -> {dep}: only the harness and the bench import the diagnosis harness")
            elif _in(mod, ENGINE) and _in(dep, DIAG) and not _in(dep, ENGINE, BACKENDS):
                bad.append(f"{mod} -> {dep}: the diagnosis engine imports only the engine and the backends")
            elif _in(mod, BACKENDS) and _in(dep, DIAG) and not _in(dep, BACKENDS):
                bad.append(f"{mod} -> {dep}: the diagnosis backends import only the backends")
            elif (_in(mod, TASKS) and _in(dep, DIAG)
                  and not _in(dep, ENGINE, BACKENDS, ".".join(mod.split(".")[:4]))):
                bad.append(f"{mod} -> {dep}: a diagnosis task imports the engine, the backends and itself")
    return bad


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


# ------------------------------------------------------------------ the real tree
def test_project_keeps_its_layering():
    graph = import_graph(ROOT)
    assert len(graph) > 50          # the walk found the project, not an empty folder
    assert layering_violations(graph) == []


def test_project_has_no_import_circles():
    assert import_cycles(import_graph(ROOT)) == []


def test_every_package_is_installed():
    """A sub-package missing from pyproject's list imports from the checkout but not
    from an installed wheel; catch it here instead of on a user's machine."""
    tomllib = pytest.importorskip("tomllib")
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())
                 ["tool"]["setuptools"]["packages"])
    found = {PACKAGE + "." + _module_name(ROOT, p.parent.joinpath("__init__.py"))
             for top in TOP + ("tests",) for p in (ROOT / top).rglob("__init__.py")}
    assert found - listed == set()


def test_every_wing_says_what_it_may_import():
    for init in sorted(ROOT.glob("*/*/__init__.py")) + sorted(ROOT.glob("*/__init__.py")):
        if init.parent.name == "tests":
            continue
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and "import" in doc.lower(), f"{init.relative_to(ROOT)}: docstring must state its imports"


# ------------------------------------------------------------------ synthetic trees
def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        for parent in path.relative_to(tmp_path).parents:
            if str(parent) != ".":
                (tmp_path / parent / "__init__.py").touch()
        path.write_text(text)
    return tmp_path


CLEAN = {
    "systems/contact/lcs.py": "import numpy\n",
    "systems/c3/solver.py": "from adaptive_c3.systems.contact.lcs import Lcs\n",
    "systems/rolling/planner.py": ("from adaptive_c3.systems.c3 import solver\n"
                                   "from adaptive_c3.models.ball import R\n"),
    "models/ball.py": "from adaptive_c3.systems.contact import lcs\nR = 1\n",
    "scenarios/schema.py": "from adaptive_c3.scenarios import common\n",
    "scenarios/common.py": "X = 1\n",
    "diagrams/rolling.py": "import adaptive_c3.systems.rolling.planner\n",
    "tools/cli.py": ("def main():\n    from adaptive_c3.diagrams.rolling import build\n"),
    "tools/diagnosis/engine/fit.py": "from adaptive_c3.tools.diagnosis.backends import effects\n",
    "tools/diagnosis/backends/effects.py": "import numpy\n",
    "tools/diagnosis/tasks/ball/model.py": ("from adaptive_c3.tools.diagnosis.engine import fit\n"
                                            "from adaptive_c3.tools.diagnosis.tasks.ball import gait\n"),
    "tools/diagnosis/tasks/ball/gait.py": "X = 1\n",
    "tools/diagnosis/tasks/cube/model.py": "from adaptive_c3.tools.diagnosis.backends import effects\n",
    "tools/diagnosis/harness/draws.py": "from adaptive_c3.tools.diagnosis.tasks.ball import model\n",
    "tools/diagnosis/diagnose.py": "from adaptive_c3.tools.diagnosis.tasks.cube import model\n",
}


def test_checker_passes_a_clean_tree(tmp_path):
    graph = import_graph(_tree(tmp_path, CLEAN))
    assert graph["systems.rolling.planner"] == {"systems.c3.solver", "models.ball"}
    assert graph["diagrams.rolling"] == {"systems.rolling.planner"}
    assert layering_violations(graph) == []
    assert import_cycles(graph) == []


@pytest.mark.parametrize("rel, line, rule", [
    ("systems/c3/solver.py", "from adaptive_c3.models.ball import R\n", "generic core"),
    ("systems/contact/lcs.py", "def f():\n    import adaptive_c3.systems.rolling.planner\n",
     "generic core"),
    ("systems/rolling/planner.py", "from adaptive_c3.diagrams import rolling\n",
     "systems/ never imports diagrams/"),
    ("models/ball.py", "from adaptive_c3.systems.rolling.planner import P\n", "models/ imports only"),
    ("scenarios/common.py", "from adaptive_c3.models.ball import R\n", "scenarios/ imports only"),
    ("diagrams/rolling.py", "from adaptive_c3.tools.cli import main\n", "diagrams/ never imports tools/"),
    ("tools/diagnosis/diagnose.py", "from adaptive_c3.tools.diagnosis.harness import draws\n",
     "only the harness and the bench"),
    ("tools/diagnosis/engine/fit.py", "from adaptive_c3.tools.diagnosis.tasks.ball import gait\n",
     "engine imports only"),
    ("tools/diagnosis/backends/effects.py", "import adaptive_c3.tools.diagnosis.engine.fit\n",
     "backends import only"),
    ("tools/diagnosis/tasks/cube/model.py", "from adaptive_c3.tools.diagnosis.tasks.ball import gait\n",
     "task imports the engine"),
    ("tools/diagnosis/tasks/ball/gait.py", "from adaptive_c3.tools.diagnosis import diagnose\n",
     "task imports the engine"),
])
def test_checker_catches_one_forbidden_import(tmp_path, rel, line, rule):
    files = dict(CLEAN)
    files[rel] = files[rel] + line
    bad = layering_violations(import_graph(_tree(tmp_path, files)))
    assert len(bad) == 1 and rule in bad[0], bad


def test_checker_catches_a_circle_through_a_lazy_import(tmp_path):
    files = dict(CLEAN)
    files["scenarios/common.py"] = "def load():\n    from adaptive_c3.scenarios.schema import x\n"
    files["tools/a.py"] = "from adaptive_c3.tools import b\n"
    files["tools/b.py"] = "from adaptive_c3.tools.c import y\n"
    files["tools/c.py"] = "import adaptive_c3.tools.a\n"
    cycles = import_cycles(import_graph(_tree(tmp_path, files)))
    assert sorted(cycles) == [["scenarios.common", "scenarios.schema"],
                              ["tools.a", "tools.b", "tools.c"]]
