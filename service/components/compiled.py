"""Helpers of the components whose step is compiled (numba): their arguments as one-dimensional float
arrays, and a member's value of an array of the ensemble's length or of length one (the contract's
broadcasting, ``docs/components.md``, *Compiled steps*)."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["as_row", "member_value"]


def as_row(values) -> np.ndarray:
    """``values`` as a one-dimensional float array (as it is, where it already is one)."""
    if type(values) is np.ndarray and values.ndim == 1 and values.dtype == np.float64:
        return values
    return np.atleast_1d(np.asarray(values, dtype=float))


@njit(inline="always")
def member_value(values, member: int) -> float:
    """Member ``member``'s value of a per-member array, or the one value of an array of one."""
    return values[member] if values.shape[0] > 1 else values[0]
