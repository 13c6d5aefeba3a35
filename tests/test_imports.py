"""No import cycles: the import graph of the project's packages, read from
their source with ``ast`` (imports at module level and inside functions,
relative imports resolved; ``if TYPE_CHECKING:`` blocks, which never run,
left out), has no cycle. Imports by a computed name (``importlib``: the FMU
catalog, the engine's plugins and factories, the lazy names of
``quadrotor_paper.stability`` and ``fnn_controller``) are not seen.

An edge ``a -> b`` means running ``a`` may import ``b``: ``import x.y``
imports ``x`` and ``x.y``; ``from x import y`` imports ``x`` and, when ``y``
is a submodule, ``x.y``. The packages that contain a module are already
being imported when it runs, so an import of a submodule does not count as
an import of them; a name taken from an ancestor package's ``__init__``
does.
"""
from __future__ import annotations

import ast
import dis
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from tests.source_trees import tree

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fmu_models", "fnn_controller", "cosim", "quadrotor_paper")


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


class _Imports(ast.NodeVisitor):
    """The modules a module names in its import statements, anywhere in it."""

    def __init__(self, module: str, is_package: bool):
        self.package = module if is_package else module.rpartition(".")[0]
        self.found: list[tuple[str, str | None]] = []  # (module, name imported from it or None)

    def visit_If(self, node: ast.If) -> None:
        test = node.test
        if (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
                (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"):
            for child in node.orelse:
                self.visit(child)
        else:
            self.generic_visit(node)

    def visit_Import(self, node: ast.Import) -> None:
        self.found += [(alias.name, None) for alias in node.names]

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        base = _absolute(node.module or "", node.level, self.package)
        self.found += [(base, alias.name) for alias in node.names]


def _absolute(base: str, level: int, package: str) -> str:
    """The module ``from {'.' * level}{base} import ...`` names, run in ``package``."""
    if not level:
        return base
    parts = package.split(".")
    anchor = ".".join(parts[:len(parts) - (level - 1)])
    return f"{anchor}.{base}" if base else anchor


def _known(name: str, modules) -> str | None:
    """``name`` or its longest prefix that is one of ``modules``."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        visitor = _Imports(module, path.name == "__init__.py")
        visitor.visit(tree(path))  # parsed once per process (tests/source_trees.py)
        edges = set()
        for base, name in visitor.found:
            submodule = f"{base}.{name}" if name else None
            # a submodule, else the module the names come from (an ancestor's __init__ too)
            target = submodule if submodule in modules else _known(base, modules)
            if target is None:
                continue  # not one of ours
            edges.add(target)
            parts = target.split(".")
            for parent in (".".join(parts[:i]) for i in range(1, len(parts))):  # they run first
                if not (module == parent or module.startswith(parent + ".")):
                    edges.add(parent)
        edges.discard(module)
        graph[module] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_the_graph_sees_imports_inside_functions_and_relative_ones(graph):
    assert "fnn_controller.position_parameters" in graph["fnn_controller.variants.registry"]  # relative, ..
    assert "fnn_controller.variants.pd" in graph["fnn_controller.variants"]  # relative, from a package's __init__
    assert "fnn_controller.variants" in graph["fnn_controller.position"]  # the package around registry
    assert "fnn_controller.parametric" in graph["quadrotor_paper.controller_component"]  # inside a method


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle_through_the_package(graph, package):
    through = [c for c in cycles(graph) if any(m == package or m.startswith(package + ".") for m in c)]
    assert through == []


def test_a_cycle_hidden_in_a_function_is_found(graph):
    """The cycle this test was written against: the variant registry checked
    a variant's fields against PositionParams, imported inside
    register_variant from the module whose laws looked variants up by name."""
    graph = {**graph, "fnn_controller.variants.registry": graph["fnn_controller.variants.registry"]
             | {"fnn_controller.position"}}
    assert any({"fnn_controller.position", "fnn_controller.variants.registry"} <= set(c) for c in cycles(graph))


def test_the_engine_imports_nothing_of_the_application(graph):
    """Every module of ``cosim/``, every import statement in it (top level
    and inside functions): the engine names no application package."""
    engine = [m for m in graph if m == "cosim" or m.startswith("cosim.")]
    assert len(engine) == len(list((ROOT / "cosim").rglob("*.py")))
    outside = {m: sorted(t for t in graph[m] if t.split(".")[0] != "cosim") for m in engine}
    assert {m: t for m, t in outside.items() if t} == {}


def test_importing_every_engine_module_loads_no_application_package():
    """The same at run time, where an import by a computed name would show
    (without reading a registry, which loads the cosim.plugins entry points)."""
    engine = sorted(m for m in _modules() if m.startswith("cosim."))
    code = (f"import sys; import {', '.join(engine)}; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('quadrotor_paper', 'fnn_controller', 'fmu_models')))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"



def _imports_when_loaded(module: str, path: Path) -> list[tuple[str, str | None]]:
    """The imports that run when the module is imported, not those in its functions: read from its
    compiled code (module level and class bodies), as :class:`_Imports` reads a tree: ``(module, name
    imported from it or None)``. Compiling is C alone, parsing builds every node of the tree in
    Python: for the suite's ~100 test modules about 0.3 s of CPU instead of 2 s (their trees are read
    by no other test). An ``if TYPE_CHECKING:`` block is left out, as :class:`_Imports` leaves it: its
    jump when false is taken."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: list[tuple[str, str | None]] = []
    todo = [compile(path.read_bytes(), str(path), "exec", dont_inherit=True)]
    while todo:
        code = todo.pop()
        consts = []  # the arguments of IMPORT_NAME: level, then the names of ``from ... import``
        skip_to, last = -1, None
        for op in dis.get_instructions(code):
            if op.offset < skip_to:
                continue
            if last == "TYPE_CHECKING" and op.opname.startswith("POP_JUMP") and op.opname.endswith("IF_FALSE"):
                skip_to = op.argval  # the offset after the block (its else, if any)
            last = op.argval
            if op.opname == "IMPORT_NAME":
                level, names = consts[-2:]
                base = _absolute(op.argval, level, package)
                found += [(base, name) for name in names] if names else [(base, None)]
            consts.append(op.argval if op.opname == "LOAD_CONST" else None)
        # a class body runs when its module is loaded; a function's (CO_NEWLOCALS) when called
        todo += [c for c in code.co_consts if inspect.iscode(c) and not c.co_flags & inspect.CO_NEWLOCALS]
    return found


def test_collecting_the_suite_imports_no_python_control():
    """python-control (with scipy.signal and matplotlib.pyplot, which it imports: 2-3 s of CPU) is
    imported where a linear system is made, as cosim.linearize.linearization does: no test module, nor what it
    imports when loaded (the project's modules, the tests' helpers, ``quadrotor_paper.stability``'s
    lazy names resolved to their modules), imports it, so collecting the suite does not, and a worker
    that runs no stability test never does. Read from the sources (imports by a computed name other
    than the stability package's are not seen), compiled, not parsed (:func:`_imports_when_loaded`)."""
    from quadrotor_paper.stability import _MODULE_OF as lazy

    modules = _modules()
    for path in sorted((ROOT / "tests").rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        modules[".".join(parts)] = path
        modules.setdefault(parts[-1], path)  # pytest's rootdir-relative imports: ``from toy_models import ...``
    tests = [m for m, p in modules.items() if m.startswith("tests.") and p.name.startswith(("test_", "conftest"))]
    loaded, third_party, todo = set(), {}, list(tests)
    while todo:
        module = todo.pop()
        if module in loaded:
            continue
        loaded.add(module)
        for base, name in _imports_when_loaded(module, modules[module]):
            if base == "quadrotor_paper.stability" and name in lazy:
                base, name = f"quadrotor_paper.stability.{lazy[name]}", None
            target = f"{base}.{name}" if name and f"{base}.{name}" in modules else _known(base, modules)
            if target is None:
                third_party.setdefault(base.split(".")[0], module)
            else:
                parts = target.split(".")
                todo += [".".join(parts[:i]) for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in modules]
    assert "quadrotor_paper.stability.loops" in loaded and "tests.paper.test_stability_linear" in loaded
    assert "control" not in third_party, f"{third_party['control']} imports python-control when loaded"


# The engine's layers, lowest first (docs/cosim.md, "Layout"): a module imports only from its own
# package or a lower layer; packages of one layer do not import each other. The foundation is the
# modules at the top of cosim/ (errors, files, cache, native, executor, component, ...).
ENGINE_LAYERS = (("cosim",), ("cosim.fmi",), ("cosim.loop",), ("cosim.scenario",),
                 ("cosim.study", "cosim.ssp", "cosim.linearize"), ("cosim.calibration",))


def _engine_package(module: str) -> str:
    """``cosim.loop.master`` -> ``cosim.loop``; a foundation module -> ``cosim``."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and (ROOT / "cosim" / parts[1]).is_dir() else "cosim"


def _layer(package: str) -> int:
    return next(i for i, layer in enumerate(ENGINE_LAYERS) if package in layer)


def test_every_engine_package_has_a_layer():
    folders = {f"cosim.{p.name}" for p in (ROOT / "cosim").iterdir() if (p / "__init__.py").exists()}
    assert folders == {p for layer in ENGINE_LAYERS for p in layer} - {"cosim"}


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """``a -> b`` edges of the engine where ``b``'s package is not below ``a``'s."""
    found = []
    for module, targets in graph.items():
        if not module.startswith("cosim"):
            continue
        here = _engine_package(module)
        for target in targets:
            there = _engine_package(target)
            if there != here and not _layer(there) < _layer(here):
                found.append(f"{module} -> {target}")
    return sorted(found)


def test_the_engine_imports_only_downward(graph):
    assert upward_imports(graph) == []


def test_an_upward_import_is_found(graph):
    """The rule catches what it is for: the loop reading a scenario, the FMU layer using the loop's
    kernel (the FMU's C structures were moved from the kernel into cosim.fmi.c_calls for this)."""
    graph = {**graph, "cosim.loop.master": graph["cosim.loop.master"] | {"cosim.scenario.definition"},
             "cosim.fmi.fmu": graph["cosim.fmi.fmu"] | {"cosim.loop.kernel"},
             "cosim.study.run": graph["cosim.study.run"] | {"cosim.ssp.archive"}}
    assert upward_imports(graph) == ["cosim.fmi.fmu -> cosim.loop.kernel", "cosim.loop.master -> cosim.scenario.definition",
                                     "cosim.study.run -> cosim.ssp.archive"]


@pytest.mark.parametrize("package", [p for layer in ENGINE_LAYERS[1:] for p in layer])
def test_each_engine_package_names_its_surface(package):
    """Its ``__init__`` says what it owns and may import, and every name of its surface is there."""
    import importlib

    module = importlib.import_module(package)
    assert "May import" in (module.__doc__ or "") or "may import" in (module.__doc__ or "")
    assert module.__all__
    for name in module.__all__:
        assert getattr(module, name) is not None, f"{package}.{name}"
