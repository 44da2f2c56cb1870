"""Layers you can name: the import graph of `harness/`, `implementations/` and `problems/` has no
cycle, and no module imports from a layer above its own.

The layers are the numbered list at the top of docs/LAYOUT.md (lowest first; a module belongs to
the layer of the longest name prefix listed). The graph counts every import: at module level,
inside functions, and the `from package import module` form as an import of that module; only
imports under `if TYPE_CHECKING:` are left out (they never run). An arrow that breaks the rules
today is allowed only if it is in `EXCEPTIONS` with its reason; an entry the code no longer needs
fails the test too, so the list only shrinks.

Deferred imports (inside a function) are allowed only where an optional library is imported on
first use: a library of `DEFERRABLE_LIBRARIES` (each shown optional: not installed by the
project's required dependencies), or a project module that imports one at module level (itself,
through its own module-level imports, or through its package). The entry points' start-up and one
import-time re-entrance keep a few more, each in `DEFERRED` with its reason; that list only shrinks
too.

Run as a script (`python tests/test_import_layers.py`) to print the measured graph: modules,
imports, imports inside functions, cycles and upward arrows with and without the exceptions.
"""

from __future__ import annotations

import ast
import functools
import importlib.metadata
import re
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("harness", "implementations", "problems")

# Arrows (importer, imported) the rules forbid but the code still has, each with its reason and
# the fix that removes it. A deferred (function-level) import is no reason by itself: it is
# allowed only where a heavy optional library is imported on first use, which is never a module
# of this project.
EXCEPTIONS: dict[tuple[str, str], str] = {}

# Libraries a function may import on first use, each with its reason: every one is optional (not
# installed by the [project] dependencies of pyproject.toml; `test_deferrable_libraries_are_optional`
# checks it), so a module-level import would break the harness where it is missing.
DEFERRABLE_LIBRARIES: dict[str, str] = {
    "jax": "the jax extra: problems as jax.numpy code and the library step contracts",
    "sympy": "the jax extra: heyoka expressions turned into jax.numpy through sympy",
    "numba": "the compiled loops: their kernels compile on first use (~0.3 s CPU just to import)",
    "llvmlite": "numba's code generator: native entry points of compiled problems",
    "sksundae": "the sundials extra: CVODE for stiff references and the cvode steppers",
    "rebound": "the rebound extra: REBOUND's N-body integrators",
    "distributed": "a Dask cluster, only when `--scheduler` names one",
    "psutil": "available memory and machine facts where installed (dask brings it)",
}

_BUILDER = ("a family module builds its steppers while it is imported (`Method.stepper()` asks the "
            "step loops, whose first call loads this builder), so the builder imports the families "
            "only when it builds: at module level it would import a half-imported family")
# Deferred imports of project modules that import no optional library, each with its reason.
DEFERRED: dict[tuple[str, str], str] = {
    ("harness.cli", "harness.cli.lookups"):
        "`harness list steppers|problems` and `reference` import the registry and the ground truth "
        "(heyoka, pandas: ~1 s CPU), which `harness --help` and a usage error (exit 2) never need",
    ("harness.cli", "harness.cli.commands"):
        "the other commands import the experiments, runner and report too (matplotlib, jinja2: "
        "~2 s CPU), which a lookup does not need",
    ("harness.pytest_plugin", "harness.api"):
        "pytest imports the plugin at the start of every test run of every project that has the "
        "harness installed; only a test that asks for the fixture needs the API (~2 s CPU)",
    **{("implementations.builder", f"implementations.{family}"): _BUILDER
       for family in ("runge_kutta", "implicit_rk", "splitting", "multistep", "verlet",
                      "second_order_multistep", "compiled")},
}


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


@functools.lru_cache(maxsize=1024)
def _parsed(path: Path) -> ast.Module:
    return ast.parse(path.read_text())


def _statements(node: ast.AST, deferred: bool = False):
    """Yield (import statement, inside a function) for every import under `node`; those under
    `if TYPE_CHECKING:` are left out (its `else:` is kept)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            yield from _statements(ast.Module(body=child.orelse, type_ignores=[]), deferred)
        elif isinstance(child, ast.Import | ast.ImportFrom):
            yield child, deferred
        else:
            yield from _statements(child, deferred or isinstance(
                child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda))


def _targets(node: ast.Import | ast.ImportFrom, mod: str, is_pkg: bool, modules) -> list[str]:
    """The absolute names an import statement in module `mod` imports (`from package import
    module` names the module)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    src = node.module or ""
    if node.level:
        base = mod.split(".") if is_pkg else mod.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        src = ".".join(base + ([node.module] if node.module else []))
    return [f"{src}.{a.name}" if f"{src}.{a.name}" in modules else src for a in node.names]


def _visit(node: ast.AST, deferred: bool, mod: str, is_pkg: bool, modules, edges: list) -> None:
    """Append to `edges` the imports under `node` in module `mod` (see `import_edges`)."""
    for child, inner in _statements(node, deferred):
        for t in _targets(child, mod, is_pkg, modules):
            r = _resolve(t, modules)
            if r and r != mod:
                edges.append((mod, r, inner, child.lineno))


def import_edges(modules: dict[str, tuple[Path, bool]]) -> list[tuple[str, str, bool, int]]:
    """Every import of one project module by another.

    Returns
    -------
    list of (importer, imported, inside a function, line); `imported` is the longest project
    module the imported name resolves to. Imports under `if TYPE_CHECKING:` are left out.
    """
    edges: list[tuple[str, str, bool, int]] = []
    for mod, (path, is_pkg) in modules.items():
        _visit(_parsed(path), False, mod, is_pkg, modules, edges)
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


# -- deferred imports ---------------------------------------------------------------------------------
def _parents(module: str, modules) -> list[str]:
    parts = module.split(".")
    return [p for p in (".".join(parts[:i]) for i in range(1, len(parts))) if p in modules]


def optional_wrappers(modules: dict[str, tuple[Path, bool]]) -> set[str]:
    """The project modules whose import imports a library of DEFERRABLE_LIBRARIES: they import
    one at module level, or import such a module at module level, or lie in a package that does.

    Returns
    -------
    set of dotted module names.
    """
    libraries: dict[str, set[str]] = {}
    imports: dict[str, set[str]] = {}
    for mod, (path, is_pkg) in modules.items():
        top = [t for node, inner in _statements(_parsed(path)) if not inner
               for t in _targets(node, mod, is_pkg, modules)]
        libraries[mod] = {t.split(".")[0] for t in top if _resolve(t, modules) is None}
        imports[mod] = {r for t in top if (r := _resolve(t, modules)) and r != mod}
        imports[mod].update(_parents(mod, modules))
    found = {m for m, libs in libraries.items() if libs & set(DEFERRABLE_LIBRARIES)}
    while True:
        more = {m for m in modules if m not in found and imports[m] & found}
        if not more:
            return found
        found |= more


def deferred_imports(modules: dict[str, tuple[Path, bool]]) -> list[tuple[str, int, str, str | None]]:
    """Every import inside a function.

    Returns
    -------
    list of (module, line, imported name, the project module it resolves to or None).
    """
    out = []
    for mod, (path, is_pkg) in modules.items():
        for node, inner in _statements(_parsed(path)):
            if inner:
                out.extend((mod, node.lineno, t, _resolve(t, modules))
                           for t in _targets(node, mod, is_pkg, modules))
    return out


def deferred_import_faults(modules: dict[str, tuple[Path, bool]]) -> list[str]:
    """The deferred imports the rules do not allow, one line each (module docstring)."""
    wrappers = optional_wrappers(modules)
    faults = []
    for mod, line, name, target in deferred_imports(modules):
        if target is None and name.split(".")[0] not in DEFERRABLE_LIBRARIES:
            faults.append(f"{mod}, line {line}: `{name}` imported inside a function: not an "
                          "optional library of DEFERRABLE_LIBRARIES; import it at module level")
        elif target and target not in wrappers and (mod, target) not in DEFERRED:
            faults.append(f"{mod}, line {line}: `{target}` imported inside a function: it imports "
                          "no optional library at module level; import it at module level")
    return faults


def _required_distributions() -> set[str]:
    """The distributions the project's required dependencies install (their own requirements
    without extras, transitively), normalized names."""
    def norm(name: str) -> str:
        return re.sub(r"[-_.]+", "-", name).lower()

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = [re.match(r"[A-Za-z0-9_.-]+", d).group(0) for d in project["dependencies"]]
    seen: set[str] = set()
    while todo:
        name = norm(todo.pop())
        if name in seen:
            continue
        seen.add(name)
        try:
            requires = importlib.metadata.requires(name) or []
        except importlib.metadata.PackageNotFoundError:
            continue
        todo += [re.match(r"[A-Za-z0-9_.-]+", r).group(0) for r in requires
                 if "extra" not in r.partition(";")[2]]
    return seen


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


def test_deferred_imports_only_for_optional_libraries():
    faults = deferred_import_faults(project_modules())
    assert not faults, "deferred imports the rules do not allow:\n  " + "\n  ".join(faults)


def test_every_deferred_exception_is_still_needed():
    modules = project_modules()
    wrappers = optional_wrappers(modules)
    present = {(mod, target) for mod, _, _, target in deferred_imports(modules)}
    stale = [f"{a} -> {b}: " + ("no deferred import of it any more" if (a, b) not in present
                                 else "it imports an optional library: allowed without an entry")
             for a, b in DEFERRED if (a, b) not in present or b in wrappers]
    assert not stale, "entries to remove from DEFERRED:\n  " + "\n  ".join(stale)


def test_deferrable_libraries_are_optional():
    """No library of DEFERRABLE_LIBRARIES comes with the required dependencies (read from
    pyproject.toml and the installed distributions' own requirements)."""
    required = _required_distributions()
    assert {"heyoka", "numpy", "cloudpickle"} <= required  # the walk reaches requirements' requirements
    dists = importlib.metadata.packages_distributions()
    installed_required = [lib for lib in DEFERRABLE_LIBRARIES
                          if {re.sub(r"[-_.]+", "-", d).lower() for d in dists.get(lib, [lib])} & required]
    assert not installed_required, f"required, so not optional: {installed_required}"


def test_the_deferred_rule_sees_libraries_and_wrappers(tmp_path, monkeypatch):
    """The rule itself: inside a function, a required library, the standard library and a plain
    project module are faults; an optional library, a module that imports one at module level
    (or through a module or package that does) and an entry of DEFERRED are not."""
    pkg = tmp_path / "harness"
    (pkg / "opt").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "opt" / "__init__.py").write_text("import jax\n")
    (pkg / "opt" / "member.py").write_text("X = 1\n")
    (pkg / "wrap.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import numba\n"
                                 "else:\n    import sksundae\n")
    (pkg / "via.py").write_text("from harness import wrap\n")
    (pkg / "plain.py").write_text("import numpy as np\n")
    (pkg / "cli.py").write_text("def dispatch():\n    from harness import plain\n")
    (pkg / "user.py").write_text(
        "def f():\n    import pandas as pd\n    import json\n    from harness import plain\n"
        "    import jax.numpy as jnp\n    from harness import wrap, via\n"
        "    from harness.opt import member\n    from .opt import member\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "PACKAGES", ("harness",))
    monkeypatch.setattr(sys.modules[__name__], "DEFERRED", {("harness.cli", "harness.plain"): "start-up"})
    modules = project_modules()
    assert optional_wrappers(modules) == {"harness.opt", "harness.opt.member", "harness.wrap", "harness.via"}
    faults = deferred_import_faults(modules)
    assert [f.split(":")[0] for f in faults] == ["harness.user, line 2", "harness.user, line 3",
                                                 "harness.user, line 4"]
    assert "`pandas`" in faults[0] and "`json`" in faults[1] and "`harness.plain`" in faults[2]


def _loaded_by(module: str, libraries: tuple[str, ...]) -> list[str]:
    code = f"import sys, {module}; print(' '.join(m for m in {libraries!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return out.stdout.split()


def test_what_the_deferred_entries_buy():
    """The start-up DEFERRED's entries keep: parsing the command line and loading the pytest
    plugin import no heavy library; a lookup imports neither the report's drawing nor its
    templates."""
    heavy = ("heyoka", "numpy", "pandas", "scipy", "matplotlib", "jinja2")
    assert _loaded_by("harness.cli", heavy) == []
    assert _loaded_by("harness.pytest_plugin", heavy) == []
    assert _loaded_by("harness.cli.lookups", ("matplotlib", "jinja2")) == []


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
    deferred = deferred_imports(modules)
    print(f"deferred imports: {len(deferred)} names, {sum(t is not None for *_, t in deferred)} of "
          f"project modules ({len(optional_wrappers(modules))} modules import an optional library), "
          f"{len(DEFERRED)} entries in DEFERRED; not allowed: {len(deferred_import_faults(modules))}")
    for fault in deferred_import_faults(modules):
        print("   " + fault)


if __name__ == "__main__":
    main()
