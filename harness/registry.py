"""The registry of steppers and problems: entry points (built-ins included) and users' plugin files.

- Every entry, the built-ins too, comes through the entry-point groups `harness.steppers` and
  `harness.problems`: this project's distribution declares `implementations:builtin_steppers` and
  `problems:builtin_problems` there (pyproject.toml), so the registry names neither catalogue
  package. An entry point names a Stepper/Problem instance, a class, or a callable returning one
  or a list of them, loaded on the first lookup: this project's own first (origin 'builtin'; one
  that fails raises, never a silently smaller registry), then others' by distribution and name.
- `load_plugin(path)` imports a user's own file (`--plugin FILE.py`) and registers every
  module-level Stepper or Problem it defines (or those listed in `STEPPERS` / `PROBLEMS`).
A third party's file or entry point that fails to import is reported by name (`PluginError`);
the rest of the registry still loads.

Plugin files are first imported in a guarded child process (`probe_plugin`), because a file can
hurt the process that imports it in ways no `try` catches: `os._exit` or a fatal signal ends it
at once, a non-daemon thread keeps it alive forever, an endless loop hangs it. The probe runs the
import with a time limit (`PLUGIN_PROBE_TIMEOUT_S`) and reports such a file by name as a
`PluginError`; only a file that imports cleanly there is imported here (once per process and
content; worker processes of a run skip the probe, the submitting process made it). While a
plugin imports, `print()` goes to stderr, so `--json` output on stdout stays valid.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import importlib.util
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Generic, TypeVar

from harness.entry_points import group_entry_points, missing_builtins
from harness.errors import InputError, PluginError, UnknownNameError
from harness.methods import Method, method_from_record
from harness.problem import Problem
from harness.stepper import Stepper

__all__ = ["Registry", "steppers", "problems", "get_stepper", "get_problem", "load_plugin",
           "plugin_errors", "expand", "group_entry_points"]

T = TypeVar("T")

# Seconds a plugin file may take to import in the probe (it imports the harness, numpy, heyoka
# first: ~1-3 s on a loaded machine).
PLUGIN_PROBE_TIMEOUT_S = 120.0
_PROBE = r"""
import contextlib, importlib.util, os, sys, threading
path, result = sys.argv[1], sys.argv[2]
sys.path.insert(0, os.path.dirname(os.path.abspath(path)))
outcome = "ok"
try:
    with contextlib.redirect_stdout(sys.stderr):
        spec = importlib.util.spec_from_file_location("harness_plugin_probe", path)
        module = importlib.util.module_from_spec(spec)
        sys.modules["harness_plugin_probe"] = module
        spec.loader.exec_module(module)
except BaseException as exc:
    outcome = "raised " + type(exc).__name__
threads = [t.name for t in threading.enumerate()
           if t is not threading.main_thread() and not t.daemon and t.is_alive()]
if threads:
    outcome = "threads " + ", ".join(threads)
with open(result, "w") as fh:
    fh.write(outcome)
    fh.flush()
os._exit(0)
"""
_probed: dict[str, str | None] = {}
_refused: dict[str, str] = {}  # a method record's name -> why its plugin's record was refused


def _is_variant(obj: Any) -> bool:
    """Listed on request only: a second implementation of a registered method (a compiled
    variant), or an entry that declares itself on request (a stepper's `info.extra['on_request']`,
    a problem's tag `on-request`: the step-controlled steppers and the highly eccentric orbits the
    step-control experiment studies, which the gate's fixed-step rules were not built for)."""
    info = getattr(obj, "info", None)
    extra = getattr(info, "extra", None) or {}
    return "numpy_implementation" in extra or bool(extra.get("on_request")) or (
        "on-request" in getattr(obj, "tags", ()))


class Registry(Generic[T]):
    """A name -> object map for one kind of entry, filled lazily on the first lookup."""

    def __init__(self, kind: str, cls: type, group: str):
        self.kind = kind
        self.cls = cls
        self.group = group
        self._items: dict[str, T] = {}
        self._origin: dict[str, str] = {}
        self._loaded = False
        self._lock = threading.RLock()
        self.errors: list[str] = []

    def _ensure(self) -> None:
        if self._loaded:
            return
        with self._lock:
            if self._loaded:
                return
            self._loaded = True
            self._load_entry_points()

    def load_builtins(self) -> None:
        """Register the built-ins and entry points now (otherwise on first lookup)."""
        self._ensure()

    def _load_entry_points(self) -> None:
        """Register every entry point of `self.group`: this project's own (the built-ins) first,
        and an error there raises; then the others', each failure recorded in `errors`."""
        try:
            own, others = group_entry_points(self.group)
        except Exception as exc:  # a broken distribution must not take the registry down
            self.errors.append(f"entry points {self.group}: {exc}")
            return
        if not own:
            self.errors.append(missing_builtins(self.kind, self.group))
        for ep in own:
            for obj in expand(ep.load(), self.cls):
                self.register(obj, origin="builtin")
        for ep in others:
            try:
                loaded = ep.load()
                for obj in expand(loaded, self.cls):
                    self.register(obj, origin=f"entry point {ep.name} ({ep.value})")
            except Exception as exc:
                self.errors.append(f"entry point {ep.name!r} ({ep.value}): {type(exc).__name__}: {exc}")

    def register(self, obj: T, *, origin: str = "user", replace: bool = False) -> T:
        """Add `obj` under its own name.

        Parameters
        ----------
        obj : an instance of this registry's class; origin : str, where it came from (shown on a
        clash); replace : bool, may replace another object of that name (else InputError).

        Returns
        -------
        The object registered, so the method can serve as a decorator."""
        if not isinstance(obj, self.cls):
            raise InputError(f"only {self.cls.__name__} objects can be registered as {self.kind}s")
        name = _name_of(obj)
        if not isinstance(name, str) or not name:
            raise InputError(f"a {self.kind}'s name must be a non-empty string, got {name!r}")
        with self._lock:
            if name in self._items and not replace and self._items[name] is not obj:
                raise InputError(
                    f"{self.kind} name {name!r} is already registered (by {self._origin[name]})"
                )
            self._items[name] = obj
            self._origin[name] = origin
        return obj

    def unregister(self, name: str) -> None:
        """Remove the entry `name` (nothing happens when there is none).

        Parameters
        ----------
        name : str, the registered name."""
        with self._lock:
            self._items.pop(name, None)
            self._origin.pop(name, None)

    def get(self, name: Any) -> T:
        """The entry named `name`, the built-ins and entry points loaded first.

        Parameters
        ----------
        name : the str it was registered under.

        Returns
        -------
        The object; UnknownNameError names the closest names (or why a record was refused)."""
        self._ensure()
        if not isinstance(name, str) or not name:
            raise UnknownNameError(f"{self.kind} name must be a non-empty string, got {name!r}")
        try:
            return self._items[name]
        except KeyError:
            close = difflib.get_close_matches(name, self._items, n=3, cutoff=0.5)
            hint = f"; closest: {', '.join(close)}" if close else ""
            shown = name if len(name) <= 60 else name[:57] + "..."
            if self.kind == "stepper" and name in _refused:
                raise UnknownNameError(f"stepper {shown!r} is not registered: {_refused[name]}") from None
            raise UnknownNameError(
                f"unknown {self.kind} {shown!r}{hint} (see `harness list {self.kind}s`)"
            ) from None

    def origin(self, name: str) -> str:
        """Where the entry `name` was registered from.

        Parameters
        ----------
        name : str, a registered name (KeyError otherwise).

        Returns
        -------
        str: 'builtin', 'user', 'entry point NAME (VALUE)' or a plugin's description."""
        self._ensure()
        return self._origin[name]

    def names(self, *, variants: bool = False) -> list[str]:
        """Registered names. Entries listed on request (`_is_variant`: compiled variants, which
        share the facts and verdicts of their methods; experiment-specific entries) are found by
        name but listed (and scheduled by default) only with `variants=True`.

        Parameters
        ----------
        variants : bool, list the entries listed on request too.

        Returns
        -------
        list of str: the names, in registration order."""
        self._ensure()
        return [n for n, obj in self._items.items() if variants or not _is_variant(obj)]

    def all(self, *, variants: bool = False) -> list[T]:
        """The registered objects, in registration order.

        Parameters
        ----------
        variants : bool, include the entries listed on request.

        Returns
        -------
        list: the objects."""
        self._ensure()
        return [obj for obj in self._items.values() if variants or not _is_variant(obj)]

    def __contains__(self, name: object) -> bool:
        self._ensure()
        return name in self._items

    def __len__(self) -> int:
        self._ensure()
        return len(self._items)


def _name_of(obj: Any) -> str:
    return obj.info.name if isinstance(obj, Stepper) else obj.name


def expand(loaded: Any, cls: type) -> list:
    """The `cls` objects an entry point or plugin names: an instance, a subclass (instantiated),
    a callable returning either or a list of them, or a list; else `PluginError`.

    Parameters
    ----------
    loaded : what the entry point or plugin names; cls : the class the registry holds.

    Returns
    -------
    list: the `cls` instances, in order."""
    if isinstance(loaded, cls):
        return [loaded]
    if isinstance(loaded, type) and issubclass(loaded, cls):
        return [loaded()]
    if callable(loaded):
        return expand(loaded(), cls)
    if isinstance(loaded, Iterable) and not isinstance(loaded, str | bytes):
        out = []
        for item in loaded:
            out.extend(expand(item, cls))
        return out
    raise PluginError(
        f"expected a {cls.__name__}, a list of them, or a callable; got {type(loaded).__name__}"
    )


steppers: Registry[Stepper] = Registry("stepper", Stepper, "harness.steppers")
problems: Registry[Problem] = Registry("problem", Problem, "harness.problems")

_plugins: dict[str, list[str]] = {}
_plugin_errors: list[str] = []


def get_stepper(name: str) -> Stepper:
    """The registered stepper `name`.

    Parameters
    ----------
    name : str, a stepper's registered name.

    Returns
    -------
    Stepper: raises UnknownNameError naming the closest names."""
    return steppers.get(name)


def get_problem(name: str) -> Problem:
    """The registered problem `name` (see `get_stepper`).

    Parameters
    ----------
    name : str.

    Returns
    -------
    Problem."""
    return problems.get(name)


def plugin_errors() -> list[str]:
    """Every plugin file or entry point that failed to load, with its reason.

    Returns
    -------
    list of str: one line per failure, steppers' first, then problems', then plugin files'."""
    return [*steppers.errors, *problems.errors, *_plugin_errors]


def _build_records(records: Any, path: str | Path) -> list[Stepper]:
    """Steppers from a plugin's `METHODS` (method records, `harness.methods`): each record is
    built on its own, and one that fails its checks is reported by name in `plugin_errors()`
    while the others load."""
    if records is None:
        return []
    if isinstance(records, str | bytes) or not hasattr(records, "__iter__"):
        raise PluginError(f"plugin {str(path)!r}: `METHODS` must be a list of method records")
    out = []
    for i, record in enumerate(records):
        label = record.get("name", f"#{i}") if isinstance(record, dict) else getattr(record, "name", f"#{i}")
        try:
            method = record if isinstance(record, Method) else method_from_record(record)
            out.extend(method.steppers())
        except Exception as exc:  # one bad record never loses the others
            why = str(exc) if isinstance(exc, InputError | ValueError) else f"{type(exc).__name__}: {exc}"
            _plugin_errors.append(f"plugin {str(path)!r}: method {str(label)[:80]!r} not loaded: "
                                  f"{why}"[:600])
            _refused[str(label)] = f"plugin {str(path)!r} refused its record: {why}"[:600]
    return out


def probe_plugin(path: str | Path) -> None:
    """Import the plugin file in a child process first; raise `PluginError` naming the file when
    the import ends that process (`os._exit`, a fatal signal), leaves a non-daemon thread
    running, or takes longer than PLUGIN_PROBE_TIMEOUT_S. An ordinary exception is left to the
    real import, which reports it. Results are kept per file content for this process.

    Parameters
    ----------
    path : str or Path, the plugin file."""
    p = Path(path)
    try:
        digest = hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError as exc:
        raise PluginError(f"plugin {str(path)!r}: cannot be read ({exc.strerror or exc})") from None
    key = f"{p.resolve()}:{digest}"
    if key not in _probed:
        _probed[key] = _probe(p)
    if _probed[key] is not None:
        raise PluginError(f"plugin {str(path)!r} {_probed[key]}")


def _probe(p: Path) -> str | None:
    root = str(Path(__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        x for x in (root, os.environ.get("PYTHONPATH", "")) if x))
    fd, result = tempfile.mkstemp(prefix="harness-probe-", suffix=".txt")
    os.close(fd)
    try:
        try:
            proc = subprocess.run([sys.executable, "-c", _PROBE, str(p), result], env=env,
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, timeout=PLUGIN_PROBE_TIMEOUT_S,
                                  start_new_session=True)
        except subprocess.TimeoutExpired:
            return (f"did not finish importing within {PLUGIN_PROBE_TIMEOUT_S:g} s (an endless "
                    "loop or a wait at import?)")
        outcome = ""
        with contextlib.suppress(OSError):
            outcome = Path(result).read_text()
        if proc.returncode < 0:
            name = signal.Signals(-proc.returncode).name if -proc.returncode in signal.valid_signals() else ""
            return f"crashed the process importing it (signal {name or -proc.returncode})"
        if not outcome:
            return f"ended the process importing it (exit status {proc.returncode}, e.g. os._exit)"
        if outcome.startswith("threads "):
            return (f"starts non-daemon thread(s) at import ({outcome[8:][:100]}): the run could "
                    "never exit; make them daemon threads or start them later")
        return None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(result)


def load_plugin(path: str | Path, *, strict: bool = True, probe: bool = True) -> list[str]:
    """Import a user's plugin file and register its steppers and problems; return their names.

    A file that does not exist or does not import raises `PluginError` naming the file (or, with
    `strict=False`, records the error in `plugin_errors()` and returns []). With `probe` (the
    default) the file is first imported in a guarded child process (`probe_plugin`); worker
    processes pass `probe=False`.

    Parameters
    ----------
    path : str or Path, a .py file; strict : bool, raise on failure (else record it);
    probe : bool, import it in a guarded child process first.

    Returns
    -------
    list of str: the names registered (those of the first load when the file was loaded before)."""
    p = Path(path)
    key = str(p.resolve()) if p.exists() else str(p)
    if key in _plugins:
        return _plugins[key]
    try:
        if p.suffix != ".py":
            raise PluginError(f"plugin {str(path)!r}: `--plugin` must name a .py file")
        if not p.is_file():
            raise PluginError(f"plugin {str(path)!r}: no such file")
        if probe:
            probe_plugin(p)
        mod_name = "harness_plugin_" + hashlib.sha1(key.encode()).hexdigest()[:12]
        spec = importlib.util.spec_from_file_location(mod_name, p)
        if spec is None or spec.loader is None:
            raise PluginError(f"plugin {str(path)!r}: cannot be imported as a Python module")
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        folder = str(p.resolve().parent)  # the plugin imports its own folder's modules
        added = folder not in sys.path
        if added:
            sys.path.insert(0, folder)
        try:
            with contextlib.redirect_stdout(sys.stderr):
                spec.loader.exec_module(module)
        except BaseException as exc:  # SyntaxError, ImportError, anything the file raises
            sys.modules.pop(mod_name, None)
            if isinstance(exc, KeyboardInterrupt | SystemExit):
                raise PluginError(f"plugin {str(path)!r} exited while importing") from None
            if isinstance(exc, InputError):  # a definition refused by its own checks
                raise PluginError(f"plugin {str(path)!r}: {exc}") from None
            raise PluginError(
                f"plugin {str(path)!r} failed to import: {type(exc).__name__}: {exc}"
            ) from None
        finally:
            if added and folder in sys.path:
                sys.path.remove(folder)
        names: list[str] = []
        listed_s = getattr(module, "STEPPERS", None)
        listed_p = getattr(module, "PROBLEMS", None)
        records = getattr(module, "METHODS", None)
        objs = []
        if listed_s is not None or listed_p is not None:
            for label, listed in (("STEPPERS", listed_s), ("PROBLEMS", listed_p)):
                try:
                    with contextlib.redirect_stdout(sys.stderr):
                        objs += list(listed or [])
                except Exception as exc:  # a generator or iterable that raises
                    raise PluginError(
                        f"plugin {str(path)!r}: listing {label} failed: {type(exc).__name__}: {exc}"
                    ) from None
        elif records is None:
            objs = [v for v in vars(module).values() if isinstance(v, Stepper | Problem)]
        refused_before = len(_plugin_errors)
        objs += _build_records(records, path)
        for obj in objs:
            if not isinstance(obj, Stepper | Problem):
                raise PluginError(
                    f"plugin {str(path)!r}: STEPPERS/PROBLEMS may hold only Stepper or Problem "
                    f"objects, got {type(obj).__name__}"
                )
        steppers.load_builtins()  # built-ins first: a plugin entry named like one is the refused one
        problems.load_builtins()
        for obj in objs:  # one refused name (a built-in's, a duplicate) never loses the others
            reg = steppers if isinstance(obj, Stepper) else problems
            try:
                reg.register(obj, origin=f"plugin {p.name}", replace=False)
            except InputError as exc:
                _plugin_errors.append(f"plugin {str(path)!r}: {exc}; that entry is not loaded")
                continue
            names.append(_name_of(obj))
        if not names:
            refused = _plugin_errors[refused_before:]
            del _plugin_errors[refused_before:]
            if refused:  # every entry was refused: their reasons, not "defines nothing"
                raise PluginError("; ".join(refused)[:2000])
            raise PluginError(f"plugin {str(path)!r} defines no Stepper or Problem objects")
        _plugins[key] = names
        return names
    except PluginError as exc:
        if strict:
            raise
        _plugin_errors.append(str(exc))
        return []
    except InputError as exc:
        err = PluginError(f"plugin {str(path)!r}: {exc}")
        if strict:
            raise err from None
        _plugin_errors.append(str(err))
        return []
