# SPDX-License-Identifier: GPL-3.0-or-later
"""Checks applied where arrays enter the project, so deeper code can trust them."""
import numpy as np


class InputError(ValueError):
    """Bad input: the message names the input and says what to do."""


def check_finite(name, array):
    """Reject NaN/Inf, naming the array and the first bad element."""
    array = np.asarray(array)
    if array.dtype.kind in "fc":
        bad = ~np.isfinite(array)
        if bad.any():
            first = np.unravel_index(int(np.argmax(bad)), array.shape)
            raise InputError(
                f"{name}: {int(bad.sum())} NaN/Inf value(s), first at index {tuple(int(i) for i in first)}; "
                f"remove or repair them before passing {name}")
    return array


def check_shape(name, array, shape):
    """shape: tuple with None for 'any length'."""
    array = np.asarray(array)
    if array.ndim != len(shape) or any(s is not None and a != s for a, s in zip(array.shape, shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(f"{name}: expected shape {want}, got {array.shape}")
    return array
