# SPDX-License-Identifier: GPL-3.0-or-later
"""Checks applied where arrays enter the project, so deeper code can trust them."""
import os

import numpy as np

INT32_MAX = int(np.iinfo(np.int32).max)
FLOAT32_MAX = float(np.finfo(np.float32).max)


class InputError(ValueError):
    """Bad input: the message names the input and says what to do."""


def as_array(name, value):
    """np.asarray that reports what numpy cannot make an array of (ragged lists, mixed
    objects) as bad input instead of numpy's own error."""
    try:
        return np.asarray(value)
    except (TypeError, ValueError, OverflowError) as e:
        raise InputError(f"{name}: not an array of numbers ({e})") from None


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


def to_float32(name, array):
    """`array` (real numbers: floats or integers) as float32, rejecting NaN/Inf and values
    float32 cannot hold: a float64 1e39 would become Inf in the stored array without a word."""
    array = np.asarray(array)
    if array.dtype.kind not in "fiu":
        raise InputError(f"{name}: expected real numbers, got dtype {array.dtype}; convert them to floats")
    check_finite(name, array)
    with np.errstate(over="ignore"):
        out = array.astype(np.float32)
    if array.dtype.itemsize > 4 or array.dtype.kind in "iu":
        bad = ~np.isfinite(out)
        if bad.any():
            first = np.unravel_index(int(np.argmax(bad)), array.shape)
            raise InputError(f"{name}: {int(bad.sum())} value(s) beyond float32's range (±{FLOAT32_MAX:.4g}), "
                             f"first {array[first].item()!r} at index {tuple(int(i) for i in first)}; "
                             f"scale {name} down (or change units) first")
    return out


def to_int32(name, array, lo=None, allow_integral_floats=False):
    """`array` as int32, rejecting what the cast would change: values outside int32 (an
    int64 2**32 + 2 would wrap to 2), below `lo`, and, unless `allow_integral_floats`,
    anything that is not an integer type (with it: floats that hold whole finite numbers)."""
    array = np.asarray(array)
    if array.dtype.kind in "f" and allow_integral_floats:
        if array.size:
            finite = np.isfinite(array)
            whole = finite & (np.floor(np.where(finite, array, 0)) == np.where(finite, array, 0))
            if not whole.all():
                first = int(np.argmax(~whole.ravel()))
                raise InputError(f"{name}: value {array.ravel()[first].item()!r} at index {first} is not a whole number; "
                                 f"{name} holds integers")
    elif array.size and array.dtype.kind not in "iu":
        raise InputError(f"{name}: expected integers, got dtype {array.dtype}")
    if array.size:
        low, high = array.min(), array.max()
        floor = -INT32_MAX - 1 if lo is None else lo
        if low < floor or high > INT32_MAX:
            value = low if low < floor else high
            first = int(np.argmax(((array < floor) | (array > INT32_MAX)).ravel()))
            raise InputError(f"{name}: value {value.item()!r} (index {first}) outside {floor}..{INT32_MAX}; "
                             f"{name} must fit a 32-bit integer" + (f" >= {lo}" if lo is not None else ""))
    return array.astype(np.int32)


def available_memory():
    """Bytes of memory a new allocation can take now without swapping (Linux: MemAvailable;
    elsewhere the free physical pages where the system reports them), or None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def check_memory(name, needed, fix):
    """InputError before the work when its estimated memory `needed` (bytes) exceeds what is
    available: the message gives the estimate, the limit and `fix`."""
    free = available_memory()
    if free is not None and needed > free:
        raise InputError(f"{name}: needs about {needed / 2**30:,.2f} GiB of memory but {free / 2**30:,.2f} GiB "
                         f"are available; {fix}")
