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


# --- experiments and tests (issue 26) -------------------------------------------------------------
# An experiment is a script in experiments/; ``common.py`` and the ``_*.py`` modules are the
# harness the scripts share. Tests mirror the package; ``helpers.py`` and ``conftest.py`` hold
# what tests share. Neither experiments nor tests take a private name (``_x``) out of a module
# (a private *module* may be imported, as inside the package), and no experiment imports another
# experiment, no test another test module.

REPO = ROOT.parent
EXPERIMENTS = REPO / "experiments"
TESTS = REPO / "tests"
HARNESS = {"common"} | {p.stem for p in EXPERIMENTS.glob("_*.py")}
SCRIPTS = {p.stem for p in EXPERIMENTS.glob("*.py")} - HARNESS

# A private module's own tests may reach into it (test file -> the modules it may open).
OWN_TESTS = {"test_tables.py": {"anisosample._table_build"}}

# What is still to be moved (issue 26): each entry must disappear when its use is fixed; a new
# use fails the test. Experiments: none left (w_fig10 runs w_fig9 in its own process,
# common.run_script; h_fig2_defect lost its --before mode, which loaded archived code).
KNOWN_EXPERIMENT_IMPORTS: dict[str, set[str]] = {}
# Tests: none left (each private helper a test used got a public name or is tested through the
# public API); a new use fails the test.
KNOWN_TEST_USES: dict[str, set[str]] = {}


def _imported(path: Path, known: set[str]):
    """(what was imported, module it names or None, alias, line) for every import in ``path``;
    ``known`` lists the dotted module names that ``from X import Y`` can name as modules."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, None, a.asname or a.name.split(".")[0], node.lineno
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                if sub in known:
                    yield sub, None, a.asname or a.name, node.lineno
                else:
                    yield node.module, a.name, a.asname or a.name, node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level:  # tests' ".helpers", ".test_x"
            for a in node.names:
                mod = node.module or a.name
                yield "." * node.level + mod, None if node.module is None else a.name, \
                    a.asname or a.name, node.lineno


def _dotted(node) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _private_names_taken(path: Path, known: set[str]) -> set[str]:
    """``from M import _x`` and ``M._x`` (``M`` bound to a module of ``known``, through any
    alias or attribute chain) where ``M._x`` is not itself a module."""
    found, aliases = set(), {}
    for target, name, alias, _ in _imported(path, known):
        if name is None:
            if target in known or target.split(".")[0] in {t.split(".")[0] for t in known}:
                # "import anisosample.render as R" binds R; "import anisosample.render" binds
                # the top package anisosample
                aliases[alias] = target if alias != target.split(".")[0] else target.split(".")[0]
        elif _is_private(name) and target in known and f"{target}.{name}" not in known:
            found.add(f"from {target} import {name}")
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Attribute) and _is_private(node.attr):
            base = _dotted(node.value)
            if base is None or base.split(".")[0] not in aliases:
                continue
            head, *rest = base.split(".")
            module = ".".join([aliases[head], *rest])
            if module in known and f"{module}.{node.attr}" not in known:
                found.add(f"{module}.{node.attr}")
    return found


def _experiment_findings(folder: Path = EXPERIMENTS) -> dict[str, set[str]]:
    known = set(MODULES) | HARNESS | SCRIPTS | {PKG}
    out = {}
    for path in sorted(folder.glob("*.py")):
        found = _private_names_taken(path, known)
        for target, name, _, _ in _imported(path, known):
            top = target.removeprefix("experiments.")
            if top in SCRIPTS and top != path.stem and name is None:
                found.add(f"import {top}")
            elif top in SCRIPTS and top != path.stem:
                found.add(f"from {top} import {name}")
        if found:
            out[path.stem] = found
    return out


def test_no_experiment_imports_another_or_a_private_name():
    assert _experiment_findings() == KNOWN_EXPERIMENT_IMPORTS


def test_the_experiment_check_finds_both_rules(tmp_path):
    text = ("import w_fig6\nfrom w_fig6_baselines import Memo\nimport _w_render as W\n"
            "from anisosample import directions\nfrom anisosample.render.xml import _lookat\n"
            "import anisosample as asp\ndirections._Params()\nasp.directions._params()\n"
            "W._private()\nW.block_estimate()\n")
    (tmp_path / "w_fig9.py").write_text(text)  # a real script's name, a fake script's text
    assert _experiment_findings(tmp_path) == {"w_fig9": {
        "import w_fig6", "from w_fig6_baselines import Memo",
        "from anisosample.render.xml import _lookat", "anisosample.directions._Params",
        "anisosample.directions._params", "_w_render._private"}}


def _test_findings(folder: Path = TESTS) -> dict[str, set[str]]:
    """Per test file (path relative to ``folder``): test modules it imports, private names it
    takes out of anisosample's modules."""
    known = set(MODULES) | {PKG}
    out = {}
    for path in sorted(folder.rglob("*.py")):
        rel = path.relative_to(folder).as_posix()
        found = {f for f in _private_names_taken(path, known)
                 if f.split(" import ")[0].removeprefix("from ") not in OWN_TESTS.get(rel, ())
                 and f.rsplit(".", 1)[0] not in OWN_TESTS.get(rel, ())}
        for target, name, _, _ in _imported(path, known):
            last = target.rsplit(".", 1)[-1]
            if last.startswith("test_") or (name or "").startswith("test_"):
                found.add(f"imports {target}" + (f".{name}" if name else ""))
        if found:
            out[rel] = found
    return out


def test_no_test_imports_another_test_or_a_private_name():
    assert _test_findings() == KNOWN_TEST_USES


def test_the_test_check_finds_both_rules(tmp_path):
    (tmp_path / "render").mkdir()
    (tmp_path / "render" / "test_x.py").write_text(
        "from .test_light_warps import plane\nfrom render.test_directions import _box\n"
        "from .helpers import SCENES\nfrom anisosample.render.xml import _lookat\n"
        "from anisosample import vmf, _table_build\nvmf._fit_reverse_kl_jit\n"
        "_table_build._finalize\nimport anisosample.render as R\nR.xml._rotation\n")
    assert _test_findings(tmp_path) == {"render/test_x.py": {
        "imports .test_light_warps.plane", "imports render.test_directions._box",
        "from anisosample.render.xml import _lookat", "anisosample.vmf._fit_reverse_kl_jit",
        "anisosample._table_build._finalize", "anisosample.render.xml._rotation"}}


def _own_parsers(folder: Path = EXPERIMENTS) -> dict[str, set[str]]:
    """Scripts that build an ``argparse.ArgumentParser`` or read ``sys.argv`` themselves instead
    of starting from ``common.parser`` (``common.py`` itself excepted)."""
    out = {}
    for path in sorted(folder.glob("*.py")):
        if path.stem == "common":
            continue
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            name = _dotted(node.func) if isinstance(node, ast.Call) else None
            if name is not None and name.split(".")[-1] == "ArgumentParser":
                found.add(f"{name} (line {node.lineno})")
            if isinstance(node, ast.Attribute) and _dotted(node) == "sys.argv":
                found.add(f"sys.argv (line {node.lineno})")
        if found:
            out[path.stem] = found
    return out


def test_every_experiment_parses_its_arguments_with_common_parser():
    assert _own_parsers() == {}


def test_the_parser_check_finds_both_forms(tmp_path):
    (tmp_path / "w_fig3.py").write_text(
        "import argparse\nimport sys\nap = argparse.ArgumentParser()\nN = int(sys.argv[1])\n")
    assert _own_parsers(tmp_path) == {"w_fig3": {"argparse.ArgumentParser (line 3)",
                                                  "sys.argv (line 4)"}}
