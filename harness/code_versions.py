"""A module's code version: the source of a project module and of every project module it
imports, read from the source (never by importing anything new), with the thresholds it reads.

What a remembered value (`harness.derived`) and a cell's cache key (`harness.keys`) depend on.
Imports are parsed once per version of a module's text and kept on disk (`harness.memo`) under
the compiled-code directory (`harness.cache.code_dir()`, `keys/`): like compiled code they
follow from the source text alone, so a run with a cache directory of its own (a test's empty
cache) still finds them.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib
import importlib.util
import json
import os
import stat
import sys
from typing import Any

from harness.cache import code_dir
from harness.memo import kept
from harness.provenance import PROJECT_ROOT

__all__ = ["experiment_modules", "measuring_modules", "module_version", "project_files", "tolerance_values",
           "JUDGING_MODULES", "PRESENTING_PARTS", "LISTING_MODULES", "MEASURING_MODULES",
           "PROJECT_PACKAGES", "TOLERANCES"]

PROJECT_PACKAGES = ("harness", "problems", "implementations")
# Modules every cell steps through via objects (a stepper's carry, a problem's dynamics and
# coefficient objects), which an experiment's imports need not name.
MEASURING_MODULES = ("harness.problem", "harness.stepper", "harness.coefficients",
                     "harness.multistep_coefficients", "harness.coefficient_input")
# Modules that only judge measurements (verdict rules, the gate), or only list or look up other
# code (the registry: its entries are keyed by `code_version`; the experiment list): never part of
# a cell's key, and not followed in the import graph.
JUDGING_MODULES = (
    "harness.gate",
    "harness.rules",
    "harness.facts",
    "harness.populations",
    "harness.report",
    "harness.kit",
    "harness.registry",
    "harness.experiments",
    "harness.runner",
    "harness.keys",
    "harness.code_versions",
    "harness.store",
    "harness.cli",
    "harness.progress",
)
TOLERANCES = "harness.tolerances"
# The modules of an experiment's folder (`harness/experiments/<name>/`) that only judge or present
# its results: never part of a cell's key.
PRESENTING_PARTS = ("judge", "section", "figures", "timing_section")


@functools.cache
def _excluded(name: str) -> bool:
    """A judging-only or listing module (a package in JUDGING_MODULES excludes its submodules,
    except `harness.experiments`, whose experiment modules are measuring code)."""
    if name == "harness.experiments":
        return True
    parts = name.split(".")
    if parts[:2] == ["harness", "experiments"] and len(parts) >= 4 and parts[-1] in PRESENTING_PARTS:
        return True
    return any(name == m or name.startswith(m + ".") for m in JUDGING_MODULES
               if m != "harness.experiments")


def _is_project(name: str) -> bool:
    return name.split(".")[0] in PROJECT_PACKAGES


def _module_path(name: str) -> str | None:
    path = _located(name)
    return path if path and os.path.isfile(path) else None


def _located(name: str) -> str | None:
    """The file module `name` is loaded, or would be loaded, from (not checked to exist)."""
    path = getattr(sys.modules.get(name), "__file__", None)
    if path is None:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            spec = None
        path = spec.origin if spec is not None else None
    return path


def _source(name: str) -> str | None:
    """The module's source text (None when it has no source file)."""
    path = _located(name)
    try:
        st = os.stat(path) if path else None
    except OSError:
        st = None
    if st is None or not stat.S_ISREG(st.st_mode):
        return None
    return _read(path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=512)
def _read(path: str, mtime_ns: int, size: int) -> str:
    with open(path, "rb") as fh:
        return fh.read().decode("utf-8", errors="replace")


@functools.lru_cache(maxsize=512)
def _parse(text: str) -> ast.Module | None:
    try:
        return ast.parse(text)
    except SyntaxError:
        return None


def _is_package(name: str) -> bool:
    path = _module_path(name)
    return bool(path) and os.path.basename(path) == "__init__.py"


def _imports(name: str, nodes: list[ast.AST]) -> tuple[set[str], set[str]]:
    """(project modules imported in `nodes`, tolerances names read there) for module `name`."""
    modules: set[str] = set()
    tol_names: set[str] = set()
    tol_aliases: set[str] = set()
    attributes: set[tuple[str, str]] = set()
    package = name if _is_package(name) else name.rpartition(".")[0]
    for root in nodes:
        for node in ast.walk(root):
            if isinstance(node, ast.Attribute):
                if isinstance(node.value, ast.Name):
                    attributes.add((node.value.id, node.attr))
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if _is_project(a.name):
                        modules.add(a.name)
                        if a.name == TOLERANCES:
                            tol_aliases.add(a.asname or a.name)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    parent = ".".join(parts[: len(parts) - node.level + 1])
                    base = f"{parent}.{base}" if base else parent
                if not _is_project(base):
                    continue
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    if importlib.util.find_spec(base) and _module_path(sub):
                        modules.add(sub)  # `from harness import tolerances as tol`
                        if sub == TOLERANCES:
                            tol_aliases.add(a.asname or a.name)
                    else:
                        modules.add(base)
                        if base == TOLERANCES:
                            tol_names.add(a.name)
    tol_names |= {attr for base, attr in attributes if base in tol_aliases}
    return modules, tol_names


@functools.lru_cache(maxsize=1024)
def _module_imports(name: str, text: str | None) -> tuple[frozenset[str], frozenset[str]]:
    """`_imports` over a whole module's source, once per version of its text."""
    if text is None:
        return frozenset(), frozenset()
    found = _read_once("imports", name, text)
    return frozenset(found["modules"]), frozenset(found["names"])


@functools.lru_cache(maxsize=1024)
def _read_once(kind: str, name: str, text: str) -> dict[str, Any]:
    """What `kind` ('imports': the whole module's imports; 'measuring': the measuring part of an
    experiment's module and its imports) reads from module `name`'s source `text`, parsed once
    per version of the text and of the project's module list, then kept on disk under
    `code_dir()` (parsing is most of a cached run's key computation, in every process)."""
    listing = "\n".join(project_files())
    key = hashlib.sha256("\n".join([kind, name, listing, text]).encode()).hexdigest()[:32]
    return kept("keys", key, lambda: _parsed(kind, name, text), kind, root=code_dir)


def _parsed(kind: str, name: str, text: str) -> dict[str, Any]:
    tree = _parse(text)
    if tree is None:
        return {"counted": text, "modules": [], "names": []}
    nodes = _measuring_nodes(tree, {"summarize"}) if kind == "measuring" else [tree]
    modules, names = _imports(name, nodes)
    return {"counted": "\n".join(ast.unparse(n) for n in nodes) if kind == "measuring" else text,
            "modules": sorted(modules), "names": sorted(names)}


@functools.lru_cache(maxsize=1)
def project_files() -> tuple[str, ...]:
    """The project's module files, as paths relative to the project root, sorted (read once
    per process): what import names resolve against, and what a module version depends on.

    Returns
    -------
    tuple of str: the relative paths of the .py files of PROJECT_PACKAGES.
    """
    out = []
    for package in PROJECT_PACKAGES:
        for root, dirs, files in os.walk(PROJECT_ROOT / package):
            dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__pycache__")))
            out += sorted(os.path.relpath(os.path.join(root, f), PROJECT_ROOT) for f in files
                          if f.endswith(".py"))
    return tuple(out)


def _measuring_nodes(tree: ast.Module, judging_roots: set[str]) -> list[ast.AST]:
    """The top-level statements and methods of a module minus the functions reached only from
    `judging_roots` (method or function names, e.g. `summarize`)."""
    defs: dict[str, list[ast.AST]] = {}
    others: list[ast.AST] = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            defs.setdefault(node.name, []).append(node)
        elif isinstance(node, ast.ClassDef):
            head = ast.ClassDef(name=node.name, bases=node.bases, keywords=node.keywords,
                                body=[], decorator_list=node.decorator_list)
            others.append(head)
            for item in node.body:
                if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef):
                    defs.setdefault(item.name, []).append(item)
                else:
                    others.append(item)
        else:
            others.append(node)

    def referenced(nodes: list[ast.AST]) -> set[str]:
        out = set()
        for root in nodes:
            for n in ast.walk(root):
                if isinstance(n, ast.Name):
                    out.add(n.id)
                elif isinstance(n, ast.Attribute):
                    out.add(n.attr)
        return out

    def reach(start: set[str], seed_nodes: list[ast.AST]) -> set[str]:
        seen: set[str] = set()
        todo = (set(start) | referenced(seed_nodes)) & set(defs)
        while todo:
            name = todo.pop()
            seen.add(name)
            todo |= (referenced(defs[name]) & set(defs)) - seen
        return seen

    judging = reach(judging_roots & set(defs), [])
    # measuring: what top-level statements reach, and every def summarize does not reach (it may
    # be called from anywhere), with everything those reach
    measuring = reach(set(defs) - judging, others)
    keep = [d for name in sorted(measuring) for d in defs[name]]
    return others + keep


def experiment_modules(experiment) -> list[str]:
    """The modules of an experiment's classes, most derived first, without the contract's own.

    Parameters
    ----------
    experiment : an Experiment instance.

    Returns
    -------
    list of str: module names, without repeats.
    """
    return list(dict.fromkeys(
        c.__module__ for c in type(experiment).__mro__
        if c.__module__ not in ("abc", "builtins", "harness.experiments.base")))


def measuring_modules(experiment) -> tuple[dict[str, str], set[str]]:
    """({module: the measuring source counted for it}, tolerances names the measuring code reads)
    for an experiment (see `harness.keys`).

    Parameters
    ----------
    experiment : a `harness.experiments.base.Experiment`; its classes' modules are read, the
        contract's own (`harness.experiments.base`) not.

    Returns
    -------
    tuple (dict, set): the source counted per module, and the thresholds read.
    """
    own = experiment_modules(experiment)
    counted: dict[str, str] = {}
    tol_names: set[str] = set()
    todo = [(m, True) for m in dict.fromkeys(own)]
    seen: set[str] = set()
    while todo:
        name, is_own = todo.pop()
        if name in seen or name == TOLERANCES:
            continue
        seen.add(name)
        text = _source(name)
        if text is None:
            counted[name] = f"<no source: {name}>"
            continue
        if is_own:
            found = _read_once("measuring", name, text)
            counted[name] = found["counted"]
            modules, names = set(found["modules"]), set(found["names"])
        else:
            counted[name] = text
            modules, names = _module_imports(name, text)
        tol_names |= names
        for m in sorted(modules):
            if m == TOLERANCES:
                continue
            if _is_project(m) and not _excluded(m) and m not in seen:
                todo.append((m, False))
    # a measuring module that is a package counts with the submodules it imports (its code split
    # into modules), followed within the package only
    todo = [m for m in MEASURING_MODULES if m not in counted]
    while todo:
        m = todo.pop()
        if m in counted:
            continue
        text = _source(m)
        counted[m] = text if text is not None else f"<no source: {m}>"
        modules, names = _module_imports(m, text)
        tol_names |= names
        root = next(r for r in MEASURING_MODULES if m == r or m.startswith(r + "."))
        todo += [s for s in sorted(modules) if s.startswith(root + ".") and s not in counted]
    return counted, tol_names


# Modules that only list, look up, run, store or show: what a summary is computed from never
# passes through them (followed by neither version).
LISTING_MODULES = ("harness.registry", "harness.runner", "harness.keys", "harness.code_versions",
                   "harness.store",
                   "harness.cli", "harness.progress", "harness.report")


def module_version(*names: str, judging: bool = False, extra: str = "") -> str:
    """sha256 of project modules' source and of every project module they import, directly or
    through others (imports inside functions count; judging-only modules are followed only with
    `judging`), with the values of the thresholds they read: what a value computed by those
    modules depends on. The walk over the import graph is remembered per process and redone when
    the source of a module it read is no longer the text it read (every cell asks this of its
    stepper's modules); the thresholds' values are read on every call.

    Parameters
    ----------
    names : the modules' dotted names; judging : bool, follow judging-only modules too;
    extra : str, text hashed along (a caller's own part of the key).

    Returns
    -------
    str: hex sha256 digest.
    """
    walk = _walks.get((names, judging))
    if walk is None or not all(_same(_source(m), text) for m, text in walk[0]):
        walk = _walks[(names, judging)] = _walk(names, judging)
    _, parts, tol_names = walk
    text = "\n".join(sorted([extra, *parts, tolerance_values(tol_names)]))
    return hashlib.sha256(text.encode()).hexdigest()


# (names, judging) -> the walk of `module_version`: ((module, source text read), ...), its parts
# (module name and source digest) and the thresholds read
_walks: dict[tuple[tuple[str, ...], bool], tuple[tuple[tuple[str, str | None], ...], tuple[str, ...],
                                                 frozenset[str]]] = {}


def _same(now: str | None, then: str | None) -> bool:
    return now is then or now == then  # the same object while the file is unchanged (`_read`)


def _walk(names: tuple[str, ...], judging: bool):
    """The modules `module_version` reads from `names` with the text of each, their parts and the
    thresholds they read."""
    def skipped(m: str) -> bool:
        if judging:
            return m == "harness.experiments" or any(m == x or m.startswith(x + ".") for x in LISTING_MODULES)
        return _excluded(m)

    read: list[tuple[str, str | None]] = []
    parts: list[str] = []
    tol_names: set[str] = set()
    todo, seen = list(names), set()
    while todo:
        m = todo.pop()
        if m in seen or m == TOLERANCES:
            continue
        seen.add(m)
        text = _source(m)
        read.append((m, text))
        parts.append(m + "\n" + hashlib.sha256((text or f"<no source: {m}>").encode()).hexdigest())
        modules, names_read = _module_imports(m, text)
        tol_names |= names_read
        todo += [i for i in sorted(modules) if _is_project(i) and not skipped(i) and i not in seen]
    return tuple(read), tuple(parts), frozenset(tol_names)


def tolerance_values(names: set[str]) -> str:
    """The values of the thresholds `names` of `harness.tolerances`, as JSON text.

    Parameters
    ----------
    names : set of str, names in `harness.tolerances` (a missing one shows as '<missing>').

    Returns
    -------
    str: JSON object name -> repr of the value, keys sorted.
    """
    tol = importlib.import_module(TOLERANCES)
    return json.dumps({n: repr(getattr(tol, n, "<missing>")) for n in sorted(names)})
