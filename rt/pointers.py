"""Raw pointers for compiled code: an int64 address (``ndarray.ctypes.data``) as a typed
pointer that ``numba.carray`` wraps into an array view without a copy.

Why: the fused cycle (:mod:`rt.components.fused_kernel`), the signal tap
(:mod:`rt.components.blocks`) and the fake comedi card's instruction list
(:mod:`rt.drivers.kernels`) bind many buffers once, as a table of addresses, so a cycle is
one compiled call with a handful of arguments instead of dozens of arrays (numba's dispatch
of each array argument costs ≈ 0.1-0.2 µs). The addresses are only valid while their
buffers live: the binder keeps them referenced.

Changing this module invalidates the numba caches of every module that uses it (numba
checks only a function's own file): clear them, ``find . -name '*.nbi' -o -name '*.nbc'``.
"""
from __future__ import annotations

from typing import Any

from numba import types
from numba.extending import intrinsic


def _pointer_to(element: Any) -> Any:
    """An intrinsic ``f(addr: int64) -> CPointer(element)``."""
    pointer = types.CPointer(element)

    def typer(typingctx: Any, addr: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            return builder.inttoptr(args[0], context.get_value_type(pointer))
        return pointer(types.int64), codegen

    return intrinsic(typer)


#: float64* at an address.
f64_at = _pointer_to(types.float64)
#: int64* at an address.
i64_at = _pointer_to(types.int64)
#: uint32* at an address (comedi's ``lsampl_t``).
u32_at = _pointer_to(types.uint32)



@intrinsic
def f64_view(typingctx: Any, a: Any, start: Any, shape: Any) -> Any:
    """``a[start:start + prod(shape)].reshape(shape)`` for a 1-D C-contiguous float64 ``a``
    (a packed state or scratch array): a C-contiguous view of ``shape`` on the same memory,
    owning a reference to ``a``'s memory as a slice does (returned to Python, it keeps ``a``
    alive). ``start`` and ``shape`` are not checked against ``a``'s length: the callers'
    layouts are fixed offsets.

    Why not ``reshape``: numba's calls a C helper (``numba_attempt_nocopy_reshape``) every
    time, ≈ 20 ns; the twin's substep took 15 such views (issue 16, preflight9: ≈ 1.5 µs of a
    1 ms period's ≈ 11)."""
    if not (isinstance(a, types.Array) and a.dtype == types.float64 and a.ndim == 1
            and a.layout == "C"):
        return None
    if not isinstance(shape, types.BaseTuple) or not isinstance(start, types.Integer):
        return None
    ndim = len(shape)
    result = types.Array(types.float64, ndim, "C")

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        from numba.core import cgutils
        from numba.core.imputils import impl_ret_borrowed
        from numba.np.arrayobj import make_array, populate_array

        src = make_array(signature.args[0])(context, builder, args[0])
        out = make_array(result)(context, builder)
        intp = context.get_value_type(types.intp)
        dims = [context.cast(builder, v, t, types.intp) for v, t in
                zip(cgutils.unpack_tuple(builder, args[2]), signature.args[2])]
        strides: list[Any] = []
        stride = context.get_constant(types.intp, 8)
        for dim in reversed(dims):
            strides.insert(0, stride)
            stride = builder.mul(stride, dim)
        offset = context.cast(builder, args[1], signature.args[1], types.intp)
        populate_array(out, data=builder.gep(src.data, [offset]),
                       shape=cgutils.pack_array(builder, dims, intp),
                       strides=cgutils.pack_array(builder, strides, intp),
                       itemsize=context.get_constant(types.intp, 8), meminfo=src.meminfo,
                       parent=None)
        return impl_ret_borrowed(context, builder, result, out._getvalue())

    return result(a, start, shape), codegen
