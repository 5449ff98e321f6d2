"""The package's layout: stage subpackages, short modules, no import circle, no import-time magic."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import vasc_pipeline

PACKAGE = Path(vasc_pipeline.__file__).parent
MAX_LINES = 500
MAX_TOP_LEVEL = 12
MAX_FUNCTION_LINES = 80
# The numba decorators of vasc_pipeline._jit: a kernel is one loop over flat arrays, and splitting
# it would cost calls in the hot path, so kernels are exempt from MAX_FUNCTION_LINES.
JIT_DECORATORS = {"jit", "jit_inline", "jit_norc", "jit_norc_inline"}


def modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its ``__init__``)."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its file (lazy imports too)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            submodules = {f"{target}.{a.name}" for a in node.names} & known
            found.update(submodules or {target})
    # a package's own __init__ runs before its submodules: an import of it from inside is no edge
    return {m for m in found if m in known and m != name and not name.startswith(m + ".")}


def test_no_module_is_longer_than_500_lines():
    long = {n: len(p.read_text().splitlines()) for n, p in modules().items()}
    assert {n: k for n, k in long.items() if k > MAX_LINES} == {}


def _is_numba_kernel(node: ast.FunctionDef) -> bool:
    for d in node.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", None)
        if name in JIT_DECORATORS:
            return True
    return False


def long_functions() -> dict[str, int]:
    """Every function and method (nested ones too) longer than MAX_FUNCTION_LINES, numba kernels aside."""
    out = {}
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_numba_kernel(node):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    out[f"{name}.{node.name}"] = length
    return out


def test_no_function_outside_the_numba_kernels_is_longer_than_80_lines():
    assert long_functions() == {}


def test_the_top_level_shows_the_stages():
    entries = [p.name for p in PACKAGE.iterdir() if p.name != "__pycache__"]
    assert len(entries) <= MAX_TOP_LEVEL, sorted(entries)
    for stage in ("config", "model", "kernel", "engine", "pipeline", "store", "reduce", "figures"):
        assert (PACKAGE / stage / "__init__.py").is_file(), stage


def test_no_import_circle():
    mods = modules()
    graph = {name: imported_modules(name, path, set(mods)) for name, path in mods.items()}
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node, path):
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                raise AssertionError("import circle: " + " -> ".join(path[path.index(nxt) :] + [nxt]))
            if nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])


def test_the_reduction_imports_neither_the_pipeline_nor_the_figures():
    """The arrows run down the data's path: the pipeline calls the reduction, then the figures."""
    mods = modules()
    for name, path in mods.items():
        if name.startswith("vasc_pipeline.reduce"):
            up = {m for m in imported_modules(name, path, set(mods)) if m.split(".")[1] in ("pipeline", "figures")}
            assert not up, (name, sorted(up))


def test_numba_kernels_live_in_the_kernel():
    """Outside ``kernel/`` only the generator (``model/rng.py``, which the model's own builders
    draw from in Python) is compiled."""
    for name, path in modules().items():
        if name.startswith("vasc_pipeline.kernel") or name in ("vasc_pipeline._jit", "vasc_pipeline.model.rng"):
            continue
        decorated = {
            getattr(d, "id", getattr(d, "attr", None))
            for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.FunctionDef)
            for d in node.decorator_list
        }
        assert not decorated & JIT_DECORATORS, name


def test_every_kernel_module_declares_its_names():
    for path in (PACKAGE / "kernel").glob("*.py"):
        if path.name != "__init__.py":
            tree = ast.parse(path.read_text())
            assert any(
                isinstance(n, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in n.targets)
                for n in tree.body
            ), path.name


@pytest.mark.parametrize("name", sorted(vasc_pipeline._SHORT_NAMES))
def test_short_names_are_their_stage_modules(name):
    module = getattr(vasc_pipeline, name)
    assert module is importlib.import_module(f"vasc_pipeline.{vasc_pipeline._SHORT_NAMES[name]}")
    assert module.__spec__.name == module.__name__ == f"vasc_pipeline.{vasc_pipeline._SHORT_NAMES[name]}"


def test_importing_the_package_changes_no_import_machinery_and_stars_nothing():
    import sys

    assert not [f for f in sys.meta_path if type(f).__module__.startswith("vasc_pipeline")]
    for name, path in modules().items():
        tree = ast.parse(path.read_text())
        stars = [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and any(a.name == "*" for a in n.names)]
        assert not stars, name
        if path.name == "__init__.py":  # every package says what it offers
            assert any(
                isinstance(n, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in n.targets)
                for n in tree.body
            ), name


def test_the_version_is_the_installed_metadata():
    from importlib.metadata import version

    assert vasc_pipeline.__version__ == version("vasc_pipeline")


def test_the_readme_api_imports():
    from vasc_pipeline import (  # noqa: F401
        cco,
        config,
        costs,
        engine,
        export,
        job,
        kernel,
        morphometry,
        physics,
        reference,
        store,
        summary,
        sweep,
        tissue,
        tree,
    )

    for fn in (
        engine.run,
        engine.build_problem,
        engine.initial_state,
        engine.state_from_tree,
        engine.run_block,
        engine.anneal_blocks,
        engine.finish,
        engine.state_arrays,
        engine.restore_state,
        config.compose,
        morphometry.morphometry,
        morphometry.compare_with_kassab,
        reference.kassab_dataset,
        export.export_run,
    ):
        assert callable(fn)


def top_level_definitions(path: Path) -> set[str]:
    """The public names a module defines itself (functions, classes, assignments)."""
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(x.id for t in node.targets for x in ast.walk(t) if isinstance(x, ast.Name))
    return {n for n in names if not n.startswith("_")}


@pytest.mark.parametrize(
    "package, modules",
    [
        ("config", ["schema", "compose"]),
        ("engine", ["problem", "run"]),
        ("store", ["run_store"]),
        ("reduce", ["stage"]),
        ("kernel", ["state", "schedule", "exclusion", "supply", "pressure", "cells", "moves", "loop"]),
    ],
)
def test_a_former_module_s_names_are_on_its_package(package, modules):
    """config.py, engine.py, store.py, reduce.py and kernel.py became packages: every public name
    those modules defined is still an attribute of the package."""
    pkg = importlib.import_module(f"vasc_pipeline.{package}")
    for module in modules:
        missing = top_level_definitions(PACKAGE / package / f"{module}.py") - set(dir(pkg))
        assert not missing, (module, sorted(missing))
