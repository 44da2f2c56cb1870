"""Layers you can name: the import graph of `harness/`, `implementations/` and `problems/` has no
cycle, and no module imports from a layer above its own.

The layers are the numbered list at the top of docs/LAYOUT.md (lowest first; a module belongs to
the layer of the longest name prefix listed). The graph counts every import: at module level,
inside functions, and the `from package import module` form as an import of that module; only
imports under `if TYPE_CHECKING:` are left out (they never run). An arrow that breaks the rules
today is allowed only if it is in `EXCEPTIONS` with its reason; an entry the code no longer needs
fails the test too, so the list only shrinks.

Run as a script (`python tests/test_import_layers.py`) to print the measured graph: modules,
imports, imports inside functions, cycles and upward arrows with and without the exceptions.
"""

from __future__ import annotations

import ast
import functools
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("harness", "implementations", "problems")

# Arrows (importer, imported) the rules forbid but the code still has, each with its reason and
# the fix that removes it. A deferred (function-level) import is no reason by itself: it is
# allowed only where a heavy optional library is imported on first use, which is never a module
# of this project.
EXCEPTIONS: dict[tuple[str, str], str] = {}


# -- the layers, read from docs/LAYOUT.md --------------------------------------------------------------
def layers() -> list[tuple[str, tuple[str, ...]]]:
    """The numbered layers at the top of docs/LAYOUT.md.

    Returns
    -------
    list of (layer name, module prefixes), lowest layer first.
    """
    note = (ROOT / "docs" / "LAYOUT.md").read_text()
    block = note.split("## Layers", 1)[1].split("```", 2)[1]
    out = []
    for line in block.splitlines():
        m = re.match(r"\s*(\d+)\.\s+([\w -]+?)\s{2,}(.+)$", line)
        if m:
            assert int(m.group(1)) == len(out) + 1, f"layers out of order at {line!r}"
            out.append((m.group(2).strip(), tuple(m.group(3).split())))
    return out


def layer_of(module: str, table: list[tuple[str, tuple[str, ...]]]) -> int | None:
    """The index of the layer whose longest prefix names `module` (None: not in any layer); a
    prefix written `=name` names that module alone."""
    best, best_len = None, -1
    for i, (_, prefixes) in enumerate(table):
        for p in prefixes:
            exact = p.startswith("=")
            p = p.lstrip("=")
            if (module == p or (not exact and module.startswith(p + "."))) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


# -- the import graph -------------------------------------------------------------------------------
def project_modules() -> dict[str, tuple[Path, bool]]:
    """Every module of PACKAGES: dotted name -> (path, is a package)."""
    out = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            if "__pycache__" in p.parts:
                continue
            parts = list(p.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_pkg else parts)] = (p, is_pkg)
    return out


def _resolve(name: str, modules) -> str | None:
    """The longest project module that `name` (a module or a name in one) lies in."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _visit(node: ast.AST, deferred: bool, mod: str, is_pkg: bool, modules, edges: list) -> None:
    """Append to `edges` the imports under `node` in module `mod` (see `import_edges`)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            for sub in child.orelse:
                _visit(sub, deferred, mod, is_pkg, modules, edges)
            continue
        inner = deferred or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
        if isinstance(child, ast.Import):
            targets = [a.name for a in child.names]
        elif isinstance(child, ast.ImportFrom):
            src = child.module or ""
            if child.level:
                base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                base = base[: len(base) - (child.level - 1)]
                src = ".".join(base + ([child.module] if child.module else []))
            targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in modules else src for a in child.names]
        else:
            _visit(child, inner, mod, is_pkg, modules, edges)
            continue
        for t in targets:
            r = _resolve(t, modules)
            if r and r != mod:
                edges.append((mod, r, deferred, child.lineno))


def import_edges(modules: dict[str, tuple[Path, bool]]) -> list[tuple[str, str, bool, int]]:
    """Every import of one project module by another.

    Returns
    -------
    list of (importer, imported, inside a function, line); `imported` is the longest project
    module the imported name resolves to. Imports under `if TYPE_CHECKING:` are left out.
    """
    edges: list[tuple[str, str, bool, int]] = []
    for mod, (path, is_pkg) in modules.items():
        _visit(ast.parse(path.read_text()), False, mod, is_pkg, modules, edges)
    return edges


def cycles(nodes: list[str], arrows: set[tuple[str, str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    adj: dict[str, list[str]] = {n: [] for n in nodes}
    for a, b in sorted(arrows):
        adj[a].append(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on_stack.add(v)
            if i < len(adj[v]):
                work.append((v, i + 1))
                w = adj[v][i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            for w in adj[v]:
                if w in on_stack:
                    low[v] = min(low[v], low[w])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


@functools.lru_cache(maxsize=1)
def _graph():
    modules = project_modules()
    edges = import_edges(modules)
    arrows = {(a, b) for a, b, _, _ in edges}
    return modules, edges, arrows


def upward(arrows: set[tuple[str, str]], table) -> list[tuple[str, str]]:
    """The arrows from a module to one in a higher layer."""
    return sorted((a, b) for a, b in arrows if layer_of(b, table) > layer_of(a, table))


# -- the tests --------------------------------------------------------------------------------------
def test_every_module_is_in_a_layer():
    table = layers()
    assert len(table) >= 5, "docs/LAYOUT.md: the layer list was not found"
    missing = [m for m in project_modules() if layer_of(m, table) is None]
    assert not missing, "modules in no layer of docs/LAYOUT.md: " + ", ".join(missing)


def test_no_import_points_to_a_higher_layer():
    table = layers()
    _, edges, arrows = _graph()
    where = {(a, b): line for a, b, _, line in edges}
    bad = [(a, b) for a, b in upward(arrows, table) if (a, b) not in EXCEPTIONS]
    assert not bad, "imports from a lower layer to a higher one:\n" + "\n".join(
        f"  {a} (layer {table[layer_of(a, table)][0]}, line {where[a, b]}) -> {b} "
        f"(layer {table[layer_of(b, table)][0]})" for a, b in bad)


def test_the_import_graph_has_no_cycle():
    modules, _, arrows = _graph()
    found = cycles(list(modules), arrows - set(EXCEPTIONS))
    assert not found, "import cycles:\n" + "\n".join("  " + " <-> ".join(c) for c in found)


def test_every_exception_is_still_needed():
    table = layers()
    modules, _, arrows = _graph()
    rest = arrows - set(EXCEPTIONS)
    stale = []
    for a, b in EXCEPTIONS:
        if (a, b) not in arrows:
            stale.append(f"{a} -> {b}: no such import any more")
        elif layer_of(b, table) <= layer_of(a, table) and not cycles(list(modules), rest | {(a, b)}):
            stale.append(f"{a} -> {b}: neither upward nor part of a cycle any more")
    assert not stale, "exceptions to remove from EXCEPTIONS:\n  " + "\n  ".join(stale)


def test_the_graph_sees_imports_inside_functions_and_package_members(tmp_path, monkeypatch):
    """The scan itself: a function-level import, a relative import and `from package import
    module` are arrows; an import under TYPE_CHECKING is not; a cycle is found."""
    pkg = tmp_path / "harness"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from harness import c\n\ndef f():\n    from harness.sub import b\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("from .. import a\n")
    (pkg / "c.py").write_text("import harness.sub.b\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "PACKAGES", ("harness",))
    modules = project_modules()
    arrows = {(a, b, d) for a, b, d, _ in import_edges(modules)}
    assert arrows == {("harness.a", "harness.sub.b", True), ("harness.sub.b", "harness.a", False),
                      ("harness.c", "harness.sub.b", False)}
    assert cycles(list(modules), {(a, b) for a, b, _ in arrows}) == [["harness.a", "harness.sub.b"]]


def main() -> None:
    """Print the measured graph (see the module docstring)."""
    table = layers()
    modules, edges, arrows = _graph()
    deferred = {(a, line) for a, _, d, line in edges if d}
    print(f"modules {len(modules)}, arrows {len(arrows)}, import statements inside functions "
          f"naming project modules {len(deferred)}")
    for label, graph in (("all arrows", arrows), ("without EXCEPTIONS", arrows - set(EXCEPTIONS))):
        found = cycles(list(modules), graph)
        print(f"{label}: {len(found)} cycles, sizes {sorted(map(len, found), reverse=True)}, "
              f"{len(upward(graph, table))} upward arrows")
        for c in found:
            print("   cycle:", " ".join(c))
    for a, b in upward(arrows, table):
        print(f"   upward: {a} -> {b}{'' if (a, b) in EXCEPTIONS else '   (NOT EXCEPTED)'}")


if __name__ == "__main__":
    main()
