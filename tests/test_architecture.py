"""The repository's layering rules (DESIGN.md), checked on the source's import statements.

Why static: the rules are about which process may hold which library (torch and bpy never share one; the add-on
must load in a Blender without torch), and an import that only runs on some code path would slip past any test
that merely imports the modules.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLENDER_MODULES = {"bpy", "bmesh", "mathutils", "gpu", "bpy_extras"}
# bpy workers: each runs in its own subprocess of the project python, never in a torch process
BPY_WORKERS = {"gg_core/physics/blender_cloth.py", "gg_core/synth/blender_scene.py", "gg_core/synth/materials.py",
               "gg_core/synth/render.py"}
ENTRY_LAYERS = {"stages", "commands", "cli", "__main__"}   # gg_core's top: what no domain module may import
MAX_COLUMNS = 120


def _sources(*folders: str) -> list[Path]:
    return sorted(p for f in folders for p in (ROOT / f).rglob("*.py") if "__pycache__" not in p.parts)


def _runtime_imports(path: Path) -> list[tuple[int, str, int]]:
    """(line, module, relative level) of every import outside `if TYPE_CHECKING:` blocks (those never run); a
    `from M import a, b` gives M.a and M.b, since a and b may be modules themselves (`from .. import stages`)."""
    found: list[tuple[int, str, int]] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for n in child.orelse:
                    visit(n)
                continue
            if isinstance(child, ast.Import):
                found.extend((child.lineno, a.name, 0) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = f"{child.module}." if child.module else ""
                found.extend((child.lineno, base + a.name, child.level) for a in child.names)
            visit(child)

    visit(ast.parse(path.read_text(), str(path)))
    return found


def _top(module: str) -> str:
    return module.split(".")[0]


def _gg_core_layer(path: Path, module: str, level: int) -> str | None:
    """The gg_core subpackage (or top module) an import statement in gg_core's `path` refers to, None if outside."""
    if level == 0:
        parts = module.split(".")
        return parts[1] if parts[0] == "gg_core" and len(parts) > 1 else None
    package = path.relative_to(ROOT / "gg_core").parent.parts
    if level - 1 > len(package):
        return None
    base = package[:len(package) - (level - 1)]
    target = [*base, *module.split(".")]
    return target[0]


@pytest.mark.parametrize("folder", ["blender_addon", "operators"])
def test_the_addon_never_imports_torch(folder: str) -> None:
    hits = [f"{p.relative_to(ROOT)}:{line} imports {m}" for p in _sources(folder)
            for line, m, level in _runtime_imports(p) if level == 0 and _top(m) == "torch"]
    assert not hits, hits


def _local_files(path: Path, module: str, level: int) -> list[Path]:
    """The repository's source files an import statement in `path` runs: the module (or the package's
    __init__.py) and every package __init__.py on the way to it; empty for third-party modules."""
    if level == 0 and _top(module) not in {"gg_core", "blender_addon", "operators"}:
        return []
    package = path.parent.relative_to(ROOT).parts
    parts = [*(package[:len(package) - (level - 1)] if level else ()), *module.split(".")]
    files = [ROOT.joinpath(*parts[:i], "__init__.py") for i in range(1, len(parts) + 1)]
    files += [ROOT.joinpath(*parts[:i]).with_suffix(".py") for i in range(1, len(parts) + 1)]
    return [f for f in files if f.is_file()]


def _optional_import_lines(path: Path) -> set[int]:
    """Lines of the imports inside a `try:` that catches ImportError: code that runs on without the module."""
    lines: set[int] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Try) and any(h.type is not None and "ImportError" in ast.unparse(h.type)
                                             for h in node.handlers):
            lines |= {n.lineno for stmt in node.body for n in ast.walk(stmt)
                      if isinstance(n, ast.Import | ast.ImportFrom)}
    return lines


@pytest.mark.parametrize("folder", ["blender_addon", "operators"])
def test_the_addon_reaches_no_torch_through_gg_core(folder: str) -> None:
    """Why: an add-on module importing a gg_core module that imports torch fails in a Blender without it, though
    the add-on's own import statements name no torch."""
    seen, todo, hits = set(), _sources(folder), []
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        optional = _optional_import_lines(p)
        for line, m, level in _runtime_imports(p):
            if level == 0 and _top(m) == "torch" and line not in optional:
                hits.append(f"{p.relative_to(ROOT)}:{line} imports torch")
            todo += _local_files(p, m, level)
    assert not hits, hits
    assert ROOT / "gg_core" / "storage.py" in seen          # the walk follows the add-on into gg_core


def test_gg_core_imports_blender_only_in_its_bpy_workers() -> None:
    hits = [f"{p.relative_to(ROOT)}:{line} imports {m}" for p in _sources("gg_core")
            for line, m, level in _runtime_imports(p)
            if level == 0 and _top(m) in BLENDER_MODULES and str(p.relative_to(ROOT)) not in BPY_WORKERS]
    assert not hits, hits


def test_domain_modules_never_import_the_entry_layers() -> None:
    hits = []
    for p in _sources("gg_core"):
        own = p.relative_to(ROOT / "gg_core").parts[0].removesuffix(".py")
        if own in ENTRY_LAYERS:
            continue
        hits += [f"{p.relative_to(ROOT)}:{line} imports {'.' * level}{m}" for line, m, level in _runtime_imports(p)
                 if _gg_core_layer(p, m, level) in ENTRY_LAYERS]
    assert not hits, hits


def test_layer_resolution_of_relative_imports() -> None:
    """The checker itself: a relative import two levels up from a diagnosis module reaches gg_core's stages."""
    path = ROOT / "gg_core" / "diagnosis" / "pipeline.py"
    assert _gg_core_layer(path, "stages.diagnose", 2) == "stages"
    assert _gg_core_layer(path, "residuals", 1) == "diagnosis"
    assert _gg_core_layer(path, "stages", 2) == "stages"                    # from .. import stages
    assert _gg_core_layer(path, "gg_core.cli", 0) == "cli"
    assert _gg_core_layer(path, "numpy", 0) is None


def test_python_lines_fit_the_column_limit() -> None:
    long = [f"{p.relative_to(ROOT)}:{i} has {len(line)} columns" for p in _sources("gg_core", "blender_addon",
                                                                                     "operators", "tests", "tools")
            for i, line in enumerate(p.read_text().splitlines(), 1) if len(line) > MAX_COLUMNS]
    assert not long, long
