"""The package's layers import downwards only (docs/architecture.md, "Layers").

Parses every module of ``pmpm`` and ``decomposition`` (ast, nothing is imported) and checks that
1. no import goes to a higher layer,
2. the import graph has no circle (imports inside functions count as edges too, so none can
   hide a circle),
3. no function imports a pmpm or decomposition module, except in the entry points (the command
   lines ``pmpm`` and ``pmpm bench``, the Python API, the package's lazy attributes and the kernel warm-up), which defer
   them so that ``pmpm --help`` and scene checks do not pay for numba (their edges are checked
   by 1 and 2 like any other).

Shown to fail: an import of pmpm.physics.loads put back into pmpm/core/solver.py fails
``test_no_import_goes_upwards`` (core -> physics); a function-level ``from pmpm.api import run``
in pmpm/runner.py fails ``test_no_function_level_imports`` and, with api importing run, the circle
test.
"""
import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
PACKAGES = ("pmpm", "decomposition")

#: layer of each module, by the longest matching prefix (lower imports nothing from higher)
LAYERS = [
    ("pmpm.errors", 0), ("pmpm.files", 0), ("pmpm.registry", 0), ("pmpm.jitcache", 0), ("pmpm.log", 0), ("pmpm.mpidefaults", 0),
    ("decomposition", 1),
    ("pmpm.core", 2),
    ("pmpm.physics", 3),
    ("pmpm.scene", 4),
    ("pmpm.io", 5), ("pmpm.results", 5),
    ("pmpm.build", 6), ("pmpm.stop", 6), ("pmpm.runner", 6),
    ("pmpm.api", 7), ("pmpm.benchmarks", 7), ("pmpm.warmup", 7),
    ("pmpm.cli", 8), ("pmpm.__main__", 8), ("pmpm", 8),
]
#: modules whose functions may import pmpm modules (lazily, for start-up time: module doc)
ENTRY_POINTS = {"pmpm", "pmpm.cli", "pmpm.api", "pmpm.warmup", "pmpm.__main__", "pmpm.benchmarks.cli"}


def layer(module):
    best = max((p for p, _ in LAYERS if module == p or module.startswith(p + ".")), key=len)
    return dict(LAYERS)[best]


def _module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(module, is_package, node):
    """The absolute module names an import node names (the module itself for ``from x import y``
    and ``x.y`` too when y is a submodule)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = node.module or ""
    if node.level:
        parts = module.split(".")
        if not is_package:
            parts = parts[:-1]
        parts = parts[:len(parts) - node.level + 1]
        base = ".".join(parts + ([base] if base else []))
    return [base] + [f"{base}.{a.name}" for a in node.names]


def _imports():
    """{module: [(target, line, inside_function)]} over the packages' modules."""
    modules = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            modules[_module_name(path)] = path
    out = {}
    for module, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        found = []

        def visit(node, in_function):
            for child in ast.iter_child_nodes(node):
                inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    for target in _resolve(module, path.name == "__init__.py", child):
                        if target in modules and target != module and not module.startswith(target + "."):  # parent: implicit
                            found.append((target, child.lineno, in_function))
                visit(child, inner)
        visit(tree, False)
        out[module] = found
    return out


IMPORTS = _imports()


def test_the_packages_are_found():
    assert "pmpm.core.solver" in IMPORTS and "decomposition" in IMPORTS and len(IMPORTS) > 50


def test_no_import_goes_upwards():
    bad = [f"{m}:{line} imports {t} (layer {layer(t)} above {layer(m)})"
           for m, found in IMPORTS.items() for t, line, _ in found if layer(t) > layer(m)]
    assert bad == []


def test_no_function_level_imports():
    bad = [f"{m}:{line} imports {t} inside a function" for m, found in IMPORTS.items()
           for t, line, inside in found if inside and m not in ENTRY_POINTS]
    assert bad == []


def find_circle(graph):
    """A list of modules forming a circle in ``graph`` ({module: set of modules}), or None."""
    state = {}
    stack = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if t not in state:
                circle = visit(t)
                if circle:
                    return circle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            circle = visit(m)
            if circle:
                return circle
    return None


def test_no_import_circle():
    graph = {m: {t for t, _, _ in found} for m, found in IMPORTS.items()}
    assert find_circle(graph) is None, " -> ".join(find_circle(graph))


@pytest.mark.parametrize("graph, circle", [({"a": {"b"}, "b": {"c"}, "c": {"a"}}, True),
                                           ({"a": {"b"}, "b": {"c"}, "c": set()}, False)])
def test_the_circle_finder_finds_circles(graph, circle):
    assert (find_circle(graph) is not None) == circle


def test_solver_imports_nothing_from_physics_scene_or_results():
    targets = {t for t, _, _ in IMPORTS["pmpm.core.solver"]}
    assert not [t for t in targets if t.split(".")[:2] in (["pmpm", "physics"], ["pmpm", "scene"], ["pmpm", "results"])]
