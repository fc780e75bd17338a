"""``rt.pointers.f64_view``: the compiled kernels' reshape without numba's C helper (issue 16).
It must be the reshape of the slice it names: the same memory (writes go through), shape and
C order, and, returned to Python, it must keep its array's memory alive as a slice does."""
from __future__ import annotations

import gc

import numpy as np
import pytest
from numba import njit

from rt.pointers import f64_view


@njit(cache=True)
def _matrix(a, start):
    return f64_view(a, start, (3, 4))


@njit(cache=True)
def _block(a, start, n):
    return f64_view(a, start, (n, 2, 3))


@pytest.mark.parametrize("start", [0, 5])
def test_the_view_is_the_slices_reshape_on_the_same_memory(start):
    a = np.arange(40.0)
    view = _matrix(a, start)
    assert view.shape == (3, 4) and view.flags.c_contiguous
    assert np.array_equal(view, a[start:start + 12].reshape(3, 4))
    view[2, 1] = -7.0                                    # the same memory: a write shows in a
    assert a[start + 9] == -7.0
    block = _block(a, start, 2)
    assert np.array_equal(block, a[start:start + 12].reshape(2, 2, 3))


def test_a_view_returned_to_python_keeps_its_array_alive():
    a = np.arange(40.0) * 0.5
    view = _matrix(a, 3)
    expected = a[3:15].reshape(3, 4).copy()
    del a
    gc.collect()
    np.zeros(4000).fill(9.0)                              # reuse freed memory, if it were
    assert np.array_equal(view, expected)


def test_a_view_of_anything_but_a_contiguous_float64_vector_is_refused():
    with pytest.raises(Exception, match="f64_view"):
        _matrix(np.arange(40), 0)                         # int64
