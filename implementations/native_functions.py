"""A problem's functions as machine-code addresses, for the compiled family kernels to call.

The functions are heyoka's own compiled functions (`heyoka.cfunc`, Biscani & Izzo, heyoka's
documentation, "compiled functions"): the same machine code the NumPy steppers call through
heyoka's Python object, so the compiled and NumPy implementations evaluate a right-hand side
bit for bit alike. heyoka's Python object exposes no function address, but it does expose each
of its compiled states' object code (`cfunc.llvm_states[i].object_code`) and LLVM IR. This module
loads that object code into an llvmlite MCJIT engine of this process and takes the address of
its `cfunc` symbol. Nothing is compiled here: heyoka compiles (or loads from its disk cache, see
`harness.cache.configure_heyoka_cache`) when the problem builds the function, and loading the
object code takes about a millisecond.

heyoka's calling conventions, checked on each state's IR before it is loaded:
- state 0, one point: `void cfunc(double *out, const double *in, const double *par,
  const double *time)`;
- state 1, one point in strided arrays: the same with a last `int64 stride`; value i of a point is
  read from `in[i * stride]` and written to `out[i * stride]` (parameters alike), the time is
  `time[0]`;
- state 2, a SIMD batch of `cfunc.batch_size` points in strided arrays: the same arguments; value
  i of points k = 0 .. width-1 at `in[i * stride + k]`, times `time[0 .. width-1]`.
A state-form name (`rhs`, `accel`, `jac`) is state 0; a columns-form name (`rhs_cols`,
`accel_cols`) is states 2 and 1: the batch function on whole blocks of members, the one-point
strided function on the rest.

Contract:
1. `function_address(problem, name)` gives the address of one of `NAMES`, loaded once per
   problem and process; the engine holding the code lives as long as the problem.
2. Every external symbol the object code calls (libm's `sin`, `cos`, ...) is resolved before the
   code is loaded, from this process's libraries; one that cannot be resolved, a calling convention
   other than the above, or a platform whose objects are not ELF64 makes the function
   `UnsupportedExpression` with the reason (the NumPy implementation then runs), never a crash.
3. A loaded function is checked once against heyoka's own call, bit for bit, before its address
   is handed out: on the problem's start state (state form), on a batch and a half of perturbed
   copies of it (columns form: the batch and the strided code both run).
"""

from __future__ import annotations

import ctypes
import dataclasses
import os
import re
import struct
import threading
import time
import weakref
from typing import Any

import numpy as np

from harness.errors import InputError
from harness.problem import Problem

__all__ = [
    "UnsupportedExpression", "NativeFunction", "function_address", "native_function", "NAMES", "LOAD_LOG",
]


class UnsupportedExpression(InputError):
    """A problem function has no machine-code address the compiled kernels can call."""


#: name -> (kind of `Problem.compiled`, form: 'state' (one point) or 'columns' (strided points)).
NAMES: dict[str, tuple[str, str]] = {
    "rhs": ("rhs", "state"),
    "rhs_cols": ("rhs", "columns"),
    "accel": ("accel_q", "state"),
    "accel_cols": ("accel_q", "columns"),
    "jac": ("jac", "state"),
}
#: Widest SIMD batch the kernels' column calls take (their time vector's length).
MAX_BATCH = 16
#: One record per function loaded in this process: problem, name, seconds.
LOAD_LOG: list[dict[str, Any]] = []

_STATE = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)
_STRIDED = ctypes.CFUNCTYPE(
    None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64
)


@dataclasses.dataclass(frozen=True)
class NativeFunction:
    """One loaded function: its address, the engines that own the code, its output count.

    A state-form function's address is one integer; a columns-form function's is the triple
    (batch address, batch width, strided address) that `call_columns` takes: heyoka's SIMD batch
    function for whole blocks of `width` members, its one-point strided function for the rest."""

    name: str
    address: int | tuple[int, int, int]
    nouts: int
    engine: Any = dataclasses.field(repr=False, compare=False)

    def __call__(self, t: float, y: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        """Evaluate on one point (state form) or on the columns of (rows, N) arrays (columns
        form), through the machine code the kernels call (for checks and benchmarks)."""
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (out, y, p)]
        if arrays[0] is not out:
            raise InputError("`out` must be a C-contiguous float64 array")
        time = np.full(MAX_BATCH, t, dtype=np.float64)
        if NAMES[self.name][1] == "state":
            _STATE(self.address)(*(a.ctypes.data for a in arrays), time.ctypes.data)
            return
        batch, width, single = self.address
        N = arrays[1].shape[1]
        blocks = N // width
        calls = [(_STRIDED(batch), k * width) for k in range(blocks)]
        calls += [(_STRIDED(single), j) for j in range(blocks * width, N)]
        for fn, j in calls:
            fn(*(a.ctypes.data + 8 * j for a in arrays), time.ctypes.data, N)


_entries: weakref.WeakKeyDictionary[Problem, dict[str, NativeFunction | str]] = weakref.WeakKeyDictionary()
_lock = threading.RLock()
_target: list[Any] = []


def native_function(problem: Problem, name: str) -> NativeFunction:
    """`problem`'s function `name` (one of NAMES), loaded; raises UnsupportedExpression.

    Parameters
    ----------
    problem : Problem (InputError otherwise); name : str, one of NAMES (InputError otherwise).

    Returns
    -------
    NativeFunction: loaded once per problem and name (a refusal is remembered too).
    """
    if name not in NAMES:
        raise InputError(f"`name` must be one of {list(NAMES)}, got {name!r}")
    if not isinstance(problem, Problem):
        raise InputError(f"`problem` must be a Problem, got {type(problem).__name__}")
    with _lock:
        entries = _entries.setdefault(problem, {})
        entry = entries.get(name)
        if entry is None:
            try:
                entry = _load(problem, name)
            except UnsupportedExpression as exc:
                entry = str(exc)
            entries[name] = entry
    if isinstance(entry, str):
        raise UnsupportedExpression(entry)
    return entry


def function_address(problem: Problem, name: str) -> int | tuple[int, int, int]:
    """The address of `problem`'s function `name` (a columns-form function: the triple `call_columns`
    takes); raises UnsupportedExpression.

    Parameters
    ----------
    problem : Problem, the problem; name : str, one of NAMES.

    Returns
    -------
    int, or (batch, width, strided) for a columns-form function.
    """
    return native_function(problem, name).address


# -- loading -------------------------------------------------------------------------------------
def _load(problem: Problem, name: str) -> NativeFunction:
    kind, form = NAMES[name]
    if kind == "accel_q" and (problem.newtonian is None or problem.velocity_dependent):
        raise UnsupportedExpression(
            f"problem {problem.name!r} has no acceleration of the positions alone"
        )
    start = time.perf_counter()
    fn = problem.compiled(kind, None)
    if fn is None:
        raise UnsupportedExpression(f"problem {problem.name!r} has no {kind} expressions")
    states = fn.llvm_states
    if fn.compact_mode or len(states) != 3:
        raise UnsupportedExpression(
            f"heyoka's {kind} function of {problem.name!r} is not in the three-state form"
        )
    what = f"{problem.name!r} {name}"
    if form == "state":
        engine, address = _load_state(states[0], 4, what)
        loaded = NativeFunction(name, address, fn.nouts, engine)
    else:
        width = int(fn.batch_size)
        if not 1 <= width <= MAX_BATCH:
            raise UnsupportedExpression(f"heyoka's batch of {width} for {what} is over {MAX_BATCH}")
        batch_engine, batch = _load_state(states[2], 5, what + " (batch)")
        engine, single = _load_state(states[1], 5, what)
        loaded = NativeFunction(name, (batch, width, single), fn.nouts, (batch_engine, engine))
    _check_values(problem, fn, loaded)
    LOAD_LOG.append({"what": f"{problem.name} {name}", "seconds": time.perf_counter() - start})
    return loaded


def _load_state(state: Any, nargs: int, what: str) -> tuple[Any, int]:
    _check_signature(state.ir, nargs, what)
    obj = state.object_code
    for symbol in _undefined_symbols(obj, what):
        _resolve(symbol, what)
    engine, address = _engine(obj)
    if not address:
        raise UnsupportedExpression(f"heyoka's object code for {what} has no `cfunc` symbol")
    return engine, address


_ARGUMENTS = ["%out_ptr", "%in_ptr", "%par_ptr", "%time_ptr", "%stride"]


def _check_signature(ir_text: str, nargs: int, what: str) -> None:
    """The `define` line of `cfunc` names heyoka's arguments in order: pointers to the outputs,
    inputs, parameters and time, then (strided form) `i64 %stride`."""
    for line in ir_text.splitlines():
        if line.startswith("define void @cfunc("):
            names = re.findall(r"%[A-Za-z_][\w.]*", line.split("{")[0])
            pointers = all("ptr noalias" in part for part in line.split(",")[:1])
            if names == _ARGUMENTS[:nargs] and pointers and (nargs == 4 or "i64 %stride" in line):
                return
            raise UnsupportedExpression(
                f"heyoka's function for {what} has an unexpected signature: {line[:120]}"
            )
    raise UnsupportedExpression(f"heyoka's IR for {what} defines no `cfunc`")


def _undefined_symbols(obj: bytes, what: str) -> list[str]:
    """Names of the undefined symbols of an ELF64 little-endian relocatable object."""
    if len(obj) < 64 or obj[:4] != b"\x7fELF" or obj[4] != 2 or obj[5] != 1:
        raise UnsupportedExpression(f"heyoka's object code for {what} is not ELF64 little-endian")
    shoff = struct.unpack_from("<Q", obj, 0x28)[0]
    shentsize, shnum = struct.unpack_from("<HH", obj, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * shentsize) for i in range(shnum)]
    names = []
    for _, kind, _, _, offset, size, link, _, _, entsize in sections:
        if kind != 2 or not entsize:  # SHT_SYMTAB
            continue
        strings = sections[link][4]
        for k in range(size // entsize):
            st_name, _, _, st_shndx, _, _ = struct.unpack_from("<IBBHQQ", obj, offset + k * entsize)
            if st_shndx == 0 and st_name:
                end = obj.index(b"\0", strings + st_name)
                names.append(obj[strings + st_name : end].decode())
    return names


def _resolve(symbol: str, what: str) -> None:
    """Make `symbol` known to LLVM's dynamic linker: from LLVM's own table, the process's global
    namespace (libm), or any shared library already mapped into this process (heyoka's SLEEF)."""
    import llvmlite.binding as llvm

    if llvm.address_of_symbol(symbol):
        return
    for library in _libraries():
        try:
            found = getattr(library, symbol)
        except AttributeError:
            continue
        llvm.add_symbol(symbol, ctypes.cast(found, ctypes.c_void_p).value)
        return
    raise UnsupportedExpression(
        f"heyoka's code for {what} calls `{symbol}`, which no library loaded in this process provides"
    )


_library_cache: list[Any] = []


def _libraries():
    yield ctypes.CDLL(None)
    if not _library_cache:
        try:
            with open("/proc/self/maps") as fh:
                paths = sorted({line.split()[-1] for line in fh if ".so" in line.split()[-1]})
        except OSError:
            paths = []
        for path in paths:
            if os.path.isfile(path):
                try:
                    _library_cache.append(ctypes.CDLL(path))
                except OSError:
                    continue
    yield from _library_cache


def _engine(obj: bytes) -> tuple[Any, int]:
    """A new MCJIT engine holding `obj` and the address of its `cfunc`. The engine owns (and frees
    with itself) its module and its target machine, so each engine gets its own of both."""
    import llvmlite.binding as llvm

    if not _target:
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        _target.append(llvm.Target.from_default_triple())
    engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), _target[0].create_target_machine())
    engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
    engine.finalize_object()
    return engine, engine.get_function_address("cfunc")


def _check_values(problem: Problem, fn: Any, loaded: NativeFunction) -> None:
    """The loaded code against heyoka's own call, bit for bit: on the start state (state form), or
    on a batch and a half of perturbed start states (columns form: batch and strided code)."""
    kind, form = NAMES[loaded.name]
    y = np.asarray(problem.y0, dtype=np.float64)
    if kind == "accel_q":
        y = y[: len(problem.newtonian.positions)]
    if form == "state":
        pars = np.asarray(problem.pars_for(1, None), dtype=np.float64).reshape(-1)
        out = np.empty(loaded.nouts)
    else:
        N = loaded.address[1] + max(loaded.address[1] // 2, 1)
        y = y[:, None] * (1.0 + 1e-3 * np.arange(N))[None, :]
        pars = np.ascontiguousarray(problem.pars_for(N, None), dtype=np.float64)
        out = np.empty((loaded.nouts, N))
    loaded(0.25, y, pars, out)
    time = 0.25 if form == "state" else np.full(y.shape[1], 0.25)
    expected = fn(y, pars=pars, time=time) if fn.nparams else fn(y, time=time)
    if not np.array_equal(out, np.asarray(expected), equal_nan=True):
        raise UnsupportedExpression(
            f"the loaded {loaded.name} of {problem.name!r} disagrees with heyoka's own call on "
            + ("the start state" if form == "state" else "perturbed copies of the start state")
        )
