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

from numba import carray, njit, types
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


@njit(cache=True, inline="always")
def f64_view(a: Any, start: int, shape: Any) -> Any:
    """``a[start:start + prod(shape)].reshape(shape)`` for a C-contiguous float64 ``a``
    (a packed state or scratch array): the same memory as a C-contiguous view of ``shape``.

    Why not ``reshape``: numba's calls a C helper (``numba_attempt_nocopy_reshape``) every
    time, ≈ 20 ns; the twin's substep took 15 such views (issue 16, preflight9: ≈ 1.5 µs of a
    1 ms period's ≈ 11). The view does not keep ``a`` alive: take it from an array that
    outlives it (an argument or a local of the caller)."""
    return carray(f64_at(a.ctypes.data + 8 * start), shape)
