"""The import graph follows the documented layer order (docs/architecture.md): a module
imports only modules of its own layer or of layers below, the stages import nothing of each
other, and no two modules import each other, directly or round a circle."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Layers from the bottom up: a module may import its own layer's and lower layers' modules.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("potflat.errors", "potflat.types", "potflat._jit", "potflat._lazy", "potflat._heap",
     "potflat._interrupts"),
    ("potflat.mesh",),
    ("potflat.io",),
    ("potflat.raster",),
    ("potflat.importance",),
    ("potflat.rollout", "potflat.relax", "potflat.bake"),
    ("potflat.files",),
    ("potflat.view",),
    ("potflat_cli",),
)
#: The stage packages: none imports another.
STAGES = ("potflat.rollout", "potflat.relax", "potflat.bake")


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[0] == "cli":
        parts[0] = "potflat_cli"
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    files = [*(ROOT / "potflat").rglob("*.py"), *(ROOT / "cli").rglob("*.py")]
    return {_module_name(p): p for p in files if "__pycache__" not in p.parts}


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """potflat modules ``name`` imports, anywhere in the file (function bodies included), as
    the longest known module name each import names."""
    out = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for target in targets:
            while target and target not in MODULES:
                target = target.rpartition(".")[0]
            if target and target != name and target.startswith(("potflat", "potflat_cli")):
                out.add(target)
    return out


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _layer(name: str) -> int | None:
    for i, prefixes in enumerate(LAYERS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return i
    return None


def test_every_module_has_a_layer():
    facade = {"potflat"}  # the public API re-exports every layer's names lazily
    assert [m for m in MODULES if m not in facade and _layer(m) is None] == []


@pytest.mark.parametrize("name", sorted(m for m in MODULES if m != "potflat"))
def test_no_upward_import(name):
    upward = sorted(t for t in GRAPH[name] if t != "potflat" and _layer(t) > _layer(name))
    assert not upward, f"{name} imports {upward} from a higher layer"


def test_no_stage_imports_another_stage():
    def stage(name: str) -> str | None:
        return next((s for s in STAGES if name == s or name.startswith(s + ".")), None)

    crossing = sorted((m, t) for m, targets in GRAPH.items() for t in targets
                      if stage(m) and stage(t) and stage(m) != stage(t))
    assert not crossing


def test_no_import_cycle():
    seen, on_path, cycles = set(), [], []

    def visit(node: str) -> None:
        if node in on_path:
            cycles.append(on_path[on_path.index(node):] + [node])
            return
        if node in seen:
            return
        seen.add(node)
        on_path.append(node)
        for target in sorted(GRAPH.get(node, ())):
            if target != "potflat" and not (node.startswith(target + ".") or target.startswith(node + ".")):
                visit(target)
        on_path.pop()

    for name in sorted(GRAPH):
        visit(name)
    assert not cycles, cycles[:3]


def test_the_checks_see_an_upward_import_and_a_cycle(monkeypatch):
    """The graph reads imports inside functions too, and the checks fail on what they guard."""
    assert "potflat.raster.render" in GRAPH["potflat.importance"]
    monkeypatch.setitem(GRAPH, "potflat.mesh.distortion", GRAPH["potflat.mesh.distortion"] | {"potflat.files.pipeline"})
    with pytest.raises(AssertionError):
        test_no_upward_import("potflat.mesh.distortion")
    monkeypatch.setitem(GRAPH, "potflat.mesh.boundary", GRAPH["potflat.mesh.boundary"] | {"potflat.mesh.distortion"})
    monkeypatch.setitem(GRAPH, "potflat.mesh.distortion", {"potflat.mesh.boundary"})
    with pytest.raises(AssertionError):
        test_no_import_cycle()
