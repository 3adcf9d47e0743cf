"""Named records of the arrays a compiled kernel works on (typing.NamedTuple subclasses, which
numba takes as one argument with attribute access): the field's annotation says its shape,
so a record of the right types can be built without an object behind it (:func:`placeholder`).
"""
from __future__ import annotations

import typing
from typing import NewType

import numpy as np

Vector = NewType('Vector', np.ndarray)     # 1-d float64
Matrix = NewType('Matrix', np.ndarray)     # 2-d float64
Tensor3 = NewType('Tensor3', np.ndarray)   # 3-d float64
NDIM = {Vector: 1, Matrix: 2, Tensor3: 3}


def placeholder(record: type):
    """A ``record`` of small zero arrays of its fields' shapes: the argument types a kernel
    compiles for when its object is absent (a closed loop without an estimator)."""
    hints = typing.get_type_hints(record)
    return record(*(np.zeros((2,) * NDIM[hints[f]]) for f in record._fields))


def entry_point(kernel, *example):
    """``kernel``'s compiled function for the types of ``example`` (compiled, or loaded from
    the cache, now). For calls per tick from Python with a record: numba's dispatcher types a
    tuple argument in Python on every call (the estimator's 21 arrays: 6.3 us a call with
    them as separate arguments, 8.2 us as a record, 6.1 us through this)."""
    import numba
    return kernel.compile(tuple(numba.typeof(a) for a in example))
