"""Public functions say what they take and what they give, in the style of scipy's `_ivp`.

Swept over the modules in `SCOPE`: every public function and every public method of a public
class (name without a leading underscore; properties and dunder methods excepted, as attributes
and protocol hooks) has a docstring; one that takes arguments (besides `self`/`cls`) has a
`Parameters` section naming each of them, and one that returns a value (an annotation other than
None, or a `return <value>`) has a `Returns` (or, for a generator, `Yields`) section. A section is
its name underlined with dashes, as numpydoc writes it.

Run as a script (`python tests/test_docstrings.py`) to print what is missing and the docstring
share (docstring lines over code lines, and over all lines) of the scope and of the package.
"""

from __future__ import annotations

import ast
import functools
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Modules and packages whose public functions carry Parameters/Returns sections.
SCOPE = (
    "harness/theory", "harness/ground_truth", "harness/problem", "harness/stepper", "harness/store",
    "harness/runner", "harness/cli", "harness/coefficients.py", "harness/multistep_coefficients.py",
    "harness/scales.py", "harness/orbit.py", "harness/regimes.py", "harness/flow.py",
    "harness/derived.py", "harness/facts.py", "harness/api.py", "harness/pytest_plugin.py",
    "harness/tolerances.py", "problems",
    "harness/kit", "harness/report", "harness/experiments",
    "implementations", "harness/__init__.py", "harness/__main__.py", "harness/c_streams.py",
    "harness/cache.py", "harness/code_versions.py", "harness/coefficient_floors.py",
    "harness/coefficient_input.py", "harness/entry_points.py", "harness/errors.py",
    "harness/extended.py", "harness/gate.py", "harness/high_order.py",
    "harness/invariant_checks.py", "harness/jax_problem.py", "harness/keys.py", "harness/memo.py",
    "harness/method_checks.py", "harness/methods.py", "harness/names.py",
    "harness/not_converged.py", "harness/order_fit.py", "harness/perf_history.py",
    "harness/perturbation_law.py", "harness/populations.py", "harness/prediction.py",
    "harness/progress.py", "harness/provenance.py", "harness/registry.py", "harness/results.py",
    "harness/rules.py", "harness/sources.py", "harness/step_loops.py", "harness/timing.py",
    "harness/work_projection.py",
)
_PROPERTIES = {"property", "cached_property", "functools.cached_property", "setter", "deleter"}


def scope_files(scope=SCOPE) -> list[Path]:
    """The Python files of `scope`.

    Parameters
    ----------
    scope : paths relative to the project root, each a file or a directory (searched recursively).

    Returns
    -------
    list of Path
        The files, sorted; caches left out.
    """
    out: set[Path] = set()
    for entry in scope:
        path = ROOT / entry
        files = [path] if path.is_file() else path.rglob("*.py")
        out.update(p for p in files if "__pycache__" not in p.parts)
    return sorted(out)


def _section(doc: str, name: str) -> str | None:
    """The text of numpydoc section `name` in `doc` (up to the next section), or None."""
    m = re.search(rf"^\s*{name}\s*\n\s*-{{3,}}\s*\n(.*?)(?=^\s*\w[\w ]*\s*\n\s*-{{3,}}\s*$|\Z)", doc,
                  re.M | re.S)
    return None if m is None else m.group(1)


def _returns_value(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> tuple[bool, bool]:
    """(returns a value, is a generator): from the return annotation, else from the body."""
    generator = returns = False
    stack = list(fn.body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda | ast.ClassDef):
            continue
        if isinstance(node, ast.Yield | ast.YieldFrom):
            generator = True
        if isinstance(node, ast.Return) and node.value is not None and not (
                isinstance(node.value, ast.Constant) and node.value.value is None):
            returns = True
        stack.extend(ast.iter_child_nodes(node))
    if fn.returns is not None:
        text = ast.unparse(fn.returns)
        returns = text not in ("None", "NoReturn", "Never") and not generator
    return returns, generator


def _arguments(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    """The argument names a caller passes (`self`/`cls` of a method left out)."""
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    if method and names and names[0] in ("self", "cls"):
        names = names[1:]
    names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
    return names


@functools.cache
def public_functions(path: Path) -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef, bool]]:
    """The public functions of one module and the public methods of its public classes.

    Parameters
    ----------
    path : a Python source file.

    Returns
    -------
    list of (qualified name, function node, is a method)
        Properties, dunder methods and overload stubs are left out (parsed once per path).
    """
    out = []

    def skip(fn) -> bool:
        decorators = {ast.unparse(d).split("(")[0].rpartition(".")[2] for d in fn.decorator_list}
        return fn.name.startswith("_") or bool(decorators & (_PROPERTIES | {"overload"}))

    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not skip(node):
            out.append((node.name, node, False))
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for sub in node.body:
                if isinstance(sub, ast.FunctionDef | ast.AsyncFunctionDef) and not skip(sub):
                    out.append((f"{node.name}.{sub.name}", sub, True))
    return out


def problems_of(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    """What the docstring of `fn` lacks under the rule of this module.

    Parameters
    ----------
    fn : a function's syntax tree; method : whether it is a method (its `self`/`cls` is not
        documented).

    Returns
    -------
    list of str
        One phrase per defect; empty when the docstring follows the rule.
    """
    doc = ast.get_docstring(fn)
    if not doc:
        return ["no docstring"]
    found = []
    args = _arguments(fn, method)
    if args:
        params = _section(doc, "Parameters")
        if params is None:
            found.append("no Parameters section")
        else:
            missing = [a for a in args if not re.search(rf"(?<![\w]){re.escape(a)}(?![\w])", params)]
            if missing:
                found.append("Parameters does not name " + ", ".join(missing))
    returns, generator = _returns_value(fn)
    if returns and _section(doc, "Returns") is None:
        found.append("no Returns section")
    if generator and _section(doc, "Yields") is None and _section(doc, "Returns") is None:
        found.append("no Yields section")
    return found


def _cases():
    for path in scope_files():
        rel = path.relative_to(ROOT).as_posix()
        for qual, _fn, method in public_functions(path):
            yield pytest.param(path, qual, method, id=f"{rel}::{qual}")


@pytest.mark.parametrize(("path", "qualname", "method"), list(_cases()))
def test_public_function_has_parameters_and_returns(path, qualname, method):
    fn = next(f for q, f, _ in public_functions(path) if q == qualname)
    found = problems_of(fn, method)
    assert not found, f"{path.relative_to(ROOT)}:{fn.lineno} {qualname}: " + "; ".join(found)


def test_every_scope_entry_exists():
    """A renamed or moved module must not drop out of the sweep unnoticed."""
    missing = [entry for entry in SCOPE if not (ROOT / entry).exists()]
    assert not missing, f"SCOPE names paths that do not exist: {missing}"


def test_the_rule_catches_what_it_names():
    """The checker itself, on functions with known defects (it must be able to fail)."""
    src = '''
def none(a): return a
def no_params(a):
    """Docs.

    Returns
    -------
    int
    """
    return a
def half(a, b):
    """Docs.

    Parameters
    ----------
    a : first.

    Returns
    -------
    int
    """
    return a
def no_returns(a) -> int:
    """Docs.

    Parameters
    ----------
    a : the number.
    """
def good(a, *, b=1):
    """Docs.

    Parameters
    ----------
    a, b : numbers.

    Returns
    -------
    int
    """
    return a + b
def gen(a):
    """Docs.

    Parameters
    ----------
    a : count.
    """
    yield a
def nothing():
    """Prints."""
    print(1)
'''
    fns = {f.name: f for f in ast.parse(src).body}
    assert problems_of(fns["none"], False) == ["no docstring"]
    assert problems_of(fns["no_params"], False) == ["no Parameters section"]
    assert problems_of(fns["half"], False) == ["Parameters does not name b"]
    assert problems_of(fns["no_returns"], False) == ["no Returns section"]
    assert problems_of(fns["good"], False) == []
    assert problems_of(fns["gen"], False) == ["no Yields section"]
    assert problems_of(fns["nothing"], False) == []


def docstring_share(files: list[Path]) -> tuple[int, int, int]:
    """Docstring lines, code lines (not blank, comment or docstring) and all lines of `files`.

    Parameters
    ----------
    files : Python source files.

    Returns
    -------
    tuple of int
        (docstring lines, code lines, all lines), summed over the files.
    """
    doc = code = total = 0
    for path in files:
        src = path.read_text()
        lines: set[int] = set()
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) \
                    and node.body:
                first = node.body[0]
                if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                        and isinstance(first.value.value, str):
                    lines.update(range(first.lineno, first.end_lineno + 1))
        text = src.splitlines()
        total += len(text)
        for i, line in enumerate(text, 1):
            if i in lines:
                doc += 1
            elif line.strip() and not line.strip().startswith("#"):
                code += 1
    return doc, code, total


def main() -> None:
    """Print the defects in scope and the docstring share (see the module docstring)."""
    count = 0
    for path in scope_files():
        for qual, fn, method in public_functions(path):
            found = problems_of(fn, method)
            if found:
                count += 1
                print(f"{path.relative_to(ROOT)}:{fn.lineno} {qual}: {'; '.join(found)}")
    print(f"{count} public functions lack a section")
    package = [p for p in (ROOT / "harness").rglob("*.py") if "__pycache__" not in p.parts]
    for label, files in (("scope", scope_files()), ("harness/", package)):
        doc, code, total = docstring_share(files)
        print(f"{label}: {len(files)} files, {doc} docstring lines, {code} code lines: "
              f"{doc / code:.1%} of the code, {doc / total:.1%} of all {total} lines")


if __name__ == "__main__":
    sys.exit(main())
