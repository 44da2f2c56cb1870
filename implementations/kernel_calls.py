"""The intrinsics through which the family kernels (`implementations.kernels`) call a problem's
functions: heyoka's compiled code at an address (`implementations.native_functions`), called as a
C loop calls through a function pointer. Imported only with the kernels, when a kernel is
compiled or loaded, not by every process that lists the steppers; the kernels' cache directory
is named by a digest that includes this file, so numba's cache follows its changes.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from implementations.native_functions import MAX_BATCH

__all__ = ["call_state", "call_state_into", "call_columns"]


# The family kernels are compiled once for every problem: they receive each problem function as
# the integer address of heyoka's compiled code (`implementations.native_functions`) and call it
# through these intrinsics (an indirect call, as a C loop calling through a function pointer).
#   state form:   void f(double *out, const double *x, const double *p, const double *time)
#   strided form: void f(double *out, const double *x, const double *p, const double *time,
#                        int64 stride)  (value i of the point at x[i * stride], time[0])
# `call_columns` loops the strided form over members j0 <= j < j1 of arrays shaped (rows, N), C
# order (stride N, each member's pointers offset by j).
def _data_pointer(context, builder, array_type, value):
    return context.make_array(array_type)(context, builder, value).data


def _state_type():
    dptr = ir.DoubleType().as_pointer()
    return ir.FunctionType(ir.VoidType(), [dptr, dptr, dptr, dptr])


def _pointers(context, builder, signature, args, indices):
    """The data pointers (double *) of the array arguments at `indices`."""
    dptr = ir.DoubleType().as_pointer()
    return [builder.bitcast(_data_pointer(context, builder, signature.args[i], args[i]), dptr)
            for i in indices]


def _call_state_form(builder, address, t, out_ptr, x_ptr, p_ptr) -> None:
    time = cgutils.alloca_once_value(builder, t)
    fn = builder.inttoptr(address, _state_type().as_pointer())
    builder.call(fn, [out_ptr, x_ptr, p_ptr, time])


@intrinsic
def call_state(typingctx, address, t, x, p, out):
    """Call the state-form function at `address` with the arrays' data.

    Call the state-form function at `address` with the arrays' data (a numba intrinsic).

    Parameters
    ----------
    typingctx : numba's typing context (passed by numba); address : the function's address;
    t : float, the time; x, p, out : the state, parameters and output arrays.

    Returns
    -------
    tuple: (signature, codegen), as a numba intrinsic returns them.
    """
    sig = types.void(address, t, x, p, out)

    def codegen(context, builder, signature, args):
        x_ptr, p_ptr, out_ptr = _pointers(context, builder, signature, args, (2, 3, 4))
        _call_state_form(builder, args[0], args[1], out_ptr, x_ptr, p_ptr)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def call_state_into(typingctx, address, t, x, x_offset, p, out, out_offset):
    """As `call_state`, reading `x`'s data from element `x_offset` on and writing `out`'s from
    element `out_offset` on (rows of a flat array, without making views).

    As `call_state`, reading `x`'s data from element `x_offset` on and writing `out`'s from
    element `out_offset` on (rows of a flat array, without making views).

    Parameters
    ----------
    typingctx, address, t, x, p, out : as in `call_state`; x_offset, out_offset : element offsets.

    Returns
    -------
    tuple: (signature, codegen), as a numba intrinsic returns them.
    """
    sig = types.void(address, t, x, x_offset, p, out, out_offset)

    def codegen(context, builder, signature, args):
        x_ptr, p_ptr, out_ptr = _pointers(context, builder, signature, args, (2, 4, 5))
        x_ptr = builder.gep(x_ptr, [args[3]])
        out_ptr = builder.gep(out_ptr, [args[6]])
        _call_state_form(builder, args[0], args[1], out_ptr, x_ptr, p_ptr)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def call_columns(typingctx, address, t, X, P, Out, j0, j1):
    """Call the columns-form function `address` = (batch, width, strided) for members
    j0 <= j < j1 of `X`: the SIMD batch function on whole blocks of `width` members, the one-point
    strided function on the rest.

    Call the columns-form function `address` = (batch, width, strided) for members j0 <= j < j1
    of `X`: the SIMD batch function on whole blocks of `width` members, the one-point strided
    function on the rest.

    Parameters
    ----------
    typingctx : numba's typing context; address : the (batch, width, strided) tuple; t : float,
    the time; X : (dim, n) states; P : (n_par, n) parameters; Out : (dim, n) written; j0, j1 : the
    members' range.

    Returns
    -------
    tuple: (signature, codegen), as a numba intrinsic returns them.
    """
    sig = types.void(address, t, X, P, Out, j0, j1)

    def codegen(context, builder, signature, args):
        dptr = ir.DoubleType().as_pointer()
        i64 = ir.IntType(64)
        x_ptr, p_ptr, out_ptr = _pointers(context, builder, signature, args, (2, 3, 4))
        x_array = context.make_array(signature.args[2])(context, builder, args[2])
        n = cgutils.unpack_tuple(builder, x_array.shape, 2)[1]
        stride, start, stop = (
            builder.sext(v, i64) if v.type.width < 64 else v for v in (n, args[5], args[6])
        )
        batch, width, single = (builder.extract_value(args[0], i) for i in range(3))
        times = cgutils.alloca_once(builder, ir.ArrayType(ir.DoubleType(), MAX_BATCH))
        for k in range(MAX_BATCH):
            builder.store(args[1], builder.gep(times, [ir.Constant(i64, 0), ir.Constant(i64, k)]))
        time = builder.bitcast(times, dptr)
        fnty = ir.FunctionType(ir.VoidType(), [dptr, dptr, dptr, dptr, i64]).as_pointer()
        blocks = builder.sdiv(builder.sub(stop, start), width)
        with cgutils.for_range(builder, blocks, intp=i64) as loop:
            j = builder.add(start, builder.mul(loop.index, width))
            member = [builder.gep(ptr, [j]) for ptr in (out_ptr, x_ptr, p_ptr)]
            builder.call(builder.inttoptr(batch, fnty), [*member, time, stride])
        rest = builder.add(start, builder.mul(blocks, width))
        with cgutils.for_range_slice(builder, rest, stop, ir.Constant(i64, 1), intp=i64) as (j, _):
            member = [builder.gep(ptr, [j]) for ptr in (out_ptr, x_ptr, p_ptr)]
            builder.call(builder.inttoptr(single, fnty), [*member, time, stride])
        return context.get_dummy_value()

    return sig, codegen
