"""The package's module graph (issue 16): no import cycle, and no module uses another's private
names.

Read from the source (``ast``), so that imports inside functions count too: a lazy import that
closes a loop is still a cycle. A private *module* (``_validate``, ``warps._base``) may be
imported; a private *name* (``_check``) of another module may not, neither imported nor reached
as ``module._name``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import anisosample

ROOT = Path(anisosample.__file__).resolve().parent
PKG = "anisosample"


def _module_name(path: Path) -> str:
    parts = (PKG, *path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in ROOT.rglob("*.py")}


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _imports(module: str):
    """(target module, imported name or None, alias) for every import of ``module``."""
    path = MODULES[module]
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith(PKG):
                    yield a.name, None, a.asname or a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                target = _resolve(module, is_package, node.level, node.module)
            elif node.module and node.module.startswith(PKG):
                target = node.module
            else:
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in MODULES:  # "from . import tables": the module tables
                    yield sub, None, a.asname or a.name
                else:
                    yield target, a.name, a.asname or a.name


def _graph() -> dict[str, set[str]]:
    graph = {m: set() for m in MODULES}
    for m in MODULES:
        for target, _, _ in _imports(m):
            if target in MODULES and target != m:
                # A package's own __init__ importing its children is how packages are built;
                # a child importing its parent package is the edge that can close a loop.
                if m != PKG and target.startswith(m + "."):
                    continue
                graph[m].add(target)
    return graph


def _cycles(graph):
    """Every strongly connected component with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_is_read():
    graph = _graph()
    assert "anisosample.tables" in graph["anisosample.selection"]
    assert "anisosample._validate" in graph["anisosample.selection"]


def test_no_import_cycle_inside_the_package():
    graph = {m: {t for t in ts if t != PKG} for m, ts in _graph().items() if m != PKG}
    assert _cycles(graph) == []


def test_the_cycle_check_finds_a_lazy_back_edge():
    graph = {m: set(ts) for m, ts in _graph().items() if m != PKG}
    for ts in graph.values():
        ts.discard(PKG)
    graph["anisosample.tables"].add("anisosample.selection")  # what tables.aligned_sampler did
    assert ["anisosample.selection", "anisosample.tables"] in _cycles(graph)


def _private_uses(module: str) -> list[str]:
    found = []
    aliases = {}
    for target, name, alias in _imports(module):
        if name is not None and name.startswith("_") and not name.startswith("__"):
            if f"{target}.{name}" not in MODULES:
                found.append(f"from {target} import {name}")
        if name is None and target in MODULES:
            aliases[alias] = target
    tree = ast.parse(MODULES[module].read_text())
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith("_")
                and not node.attr.startswith("__")
                and f"{aliases[node.value.id]}.{node.attr}" not in MODULES):
            found.append(f"{node.value.id}.{node.attr} (line {node.lineno})")
    return found


def test_no_module_uses_another_modules_private_names():
    uses = {m: u for m in MODULES if (u := _private_uses(m))}
    assert uses == {}


def test_the_private_name_check_finds_both_forms(tmp_path, monkeypatch):
    fake = tmp_path / "fake.py"
    fake.write_text("from . import vmf\nfrom .fit import x\nfrom .vmf import _y\nvmf._check(1)\n")
    monkeypatch.setitem(MODULES, "anisosample.fake", fake)
    assert _private_uses("anisosample.fake") == [
        "from anisosample.vmf import _y", "vmf._check (line 4)"]
