"""The import graph of src/depthnormals, read with ``ast``: no cycle, layers import one way only,
and no function takes more than 16 parameters.

LAYERS is the one place where the layer order is declared (docs/architecture.md draws it).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = "depthnormals"

#: Lowest first. A module belongs to the layer of its longest matching prefix; it may import
#: modules of its own layer or of a lower one, never of a higher one.
LAYERS: tuple[tuple[str, ...], ...] = (
    # base: validation, threads, camera, file formats, analytic scenes, rendering, metrics,
    # digests of code and data
    ("depthnormals._validate", "depthnormals._parallel", "depthnormals.camera", "depthnormals._png",
     "depthnormals.io", "depthnormals.metrics", "depthnormals.analytic", "depthnormals.render",
     "depthnormals._progress", "depthnormals._fingerprint", "depthnormals._numba_cache"),
    ("depthnormals.kernels",),  # shared compiled row kernels and their constants
    ("depthnormals.estimators",),  # one public function per estimator
    ("depthnormals.ddm",),  # the discontinuity discrimination module, fused 3F2N+
    ("depthnormals.registry", "depthnormals.batch"),  # names -> estimators, the dispatcher, batches
    # front ends and the public API
    ("depthnormals", "depthnormals.__main__", "depthnormals.cli", "depthnormals.commands",
     "depthnormals.datasets", "depthnormals.evaluate", "depthnormals.synth",
     "depthnormals.torch", "depthnormals.viz", "depthnormals.jobs", "depthnormals.cluster",
     "depthnormals.compat"),
)
#: Layers below this one may not import by name at run time (``importlib``).
FIRST_FRONT_END = len(LAYERS) - 1
MAX_PARAMETERS = 16
#: Over the limit (none left).
KNOWN_OVER: set[str] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted((SRC / PKG).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Modules of the package that ``name`` imports (anywhere in the file, lazily or not)."""
    is_pkg = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[: len(base) - node.level + (1 if is_pkg else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for alias in node.names:  # ``from pkg import submodule`` names the submodule
                sub = f"{mod}.{alias.name}"
                found.add(sub if sub in known else mod)
    return {m for m in found if m in known}


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {m: _imports(m, p, known) - {m} for m, p in mods.items()}


def layer_of(module: str) -> int:
    best, level = -1, -1
    for i, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, level = len(p), i
    assert level >= 0, f"{module} is in no layer: add it to LAYERS in tests/test_architecture.py"
    return level


def test_every_module_has_a_layer():
    for m in _graph():
        layer_of(m)


def upward(graph: dict[str, set[str]]) -> list[str]:
    """The imports of ``graph`` that go against the layer order."""
    return sorted(f"{a} ({layer_of(a)}) imports {b} ({layer_of(b)})"
                  for a, deps in graph.items() for b in deps if layer_of(b) > layer_of(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Import cycles of ``graph`` (one per back edge of a depth-first search)."""
    state: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                found.append([*stack[stack.index(d):], d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    return found


def test_no_import_goes_up_a_layer():
    bad = upward(_graph())
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_no_import_cycle():
    found = cycles(_graph())
    assert not found, "import cycles:\n" + "\n".join(" -> ".join(c) for c in found)


def test_core_layers_import_by_name_only():
    """Below the front ends nothing is imported through ``importlib``: the graph is static."""
    bad = [m for m, p in _modules().items()
           if layer_of(m) < FIRST_FRONT_END and "importlib" in p.read_text()]
    assert not bad, f"importlib in core modules: {bad}"


def test_no_function_takes_more_than_16_parameters():
    bad = []
    for m, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                a = node.args
                n = (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                     + (a.vararg is not None) + (a.kwarg is not None))
                if n > MAX_PARAMETERS and f"{m}.{getattr(node, 'name', '')}" not in KNOWN_OVER:
                    bad.append(f"{m}.{getattr(node, 'name', 'lambda')}: {n}")
    assert not bad, f"functions with more than {MAX_PARAMETERS} parameters:\n" + "\n".join(bad)


def test_the_checks_can_fail():
    """The checks reject what they should (a test that cannot fail is a defect): the circle
    this layout replaced (estimators -> registry -> ddm -> estimators) is caught by both."""
    old = {"depthnormals.estimators.threefn": {"depthnormals.registry"},
           "depthnormals.registry": {"depthnormals.ddm._module"},
           "depthnormals.ddm._module": {"depthnormals.estimators.threefn"}}
    assert len(cycles(old)) == 1
    assert upward(old) == ["depthnormals.estimators.threefn (2) imports depthnormals.registry (4)"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
