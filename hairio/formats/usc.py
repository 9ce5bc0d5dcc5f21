# SPDX-License-Identifier: GPL-3.0-or-later
"""USC-HairSalon strands (.data), little-endian: int32 n, then per strand int32 k and
k x 3 float32 points (metres, Y up in the dataset; we convert nothing).

The dataset marks scalp positions without hair as strands with k = 1 (a lone root), and a
few tools write k = 0. `Strands` needs >= 2 points per strand, so the reader skips them;
`read_usc(path, return_skipped=True)` also says which file strands were skipped, so a caller
can keep per-strand data aligned. Only positions are stored: radius, color and alpha are not
part of the format (the writer drops them, the reader gives `Strands`' defaults).
"""
import numpy as np

from ..atomic import atomic_write
from ..validate import InputError
from ._common import check_strands, need, read_bytes, strands_without_short


def _strand_headers(words, n, path):
    """Word index of every strand's k. Records are variable length, so each header follows
    from the one before: try the common case (every k equal) as one array check, else walk
    the headers (one int per strand; the points themselves are never touched in Python).
    The walk must end exactly at the file's end: words left over mean the count or a k is
    wrong, and reading them as points would shift every coordinate after them."""
    if n == 0:
        if len(words) > 1:
            raise InputError(f"{path}: the file says 0 strands but {len(words) - 1:,} words follow the count; "
                             "the count is wrong or the file is not a USC .data file")
        return np.zeros(0, np.int64)
    # Every strand takes at least its header word: a count beyond that is a header's word
    # not to be taken (2**31 - 1 strands from an 8-byte file would ask for 16 GiB here).
    if n > len(words) - 1:
        raise InputError(f"{path}: the file says {n:,} strands but holds {len(words) - 1:,} words after the "
                         "count; truncated, or not a USC .data file")
    k0 = int(words[1])
    if 0 <= k0 and 1 + 3 * k0 < len(words):
        heads = 1 + np.arange(n, dtype=np.int64) * (1 + 3 * k0)
        if heads[-1] < len(words) and (words[heads] == k0).all() and heads[-1] + 1 + 3 * k0 == len(words):
            return heads
    heads = np.empty(n, np.int64)
    i = 1
    for s in range(n):
        if i >= len(words):
            raise InputError(f"{path}: truncated .data file: strand {s} of {n:,} missing")
        k = int(words[i])
        if k < 0:
            raise InputError(f"{path}: strand {s} has a negative point count {k}; not a USC .data file")
        heads[s] = i
        i += 1 + 3 * k
    if i > len(words):
        raise InputError(f"{path}: truncated .data file: last strand needs {i * 4:,} bytes, file has {len(words) * 4:,}")
    if i < len(words):
        raise InputError(f"{path}: {len(words) - i:,} words follow the last of the {n:,} strands the file "
                         "announces; the strand count or a point count is wrong, re-export it")
    return heads


def read_usc(path, return_skipped=False):
    """Strands from a USC-HairSalon .data file; strands with < 2 points are skipped."""
    data = read_bytes(path, ".data")
    need(data, 4, path, ".data")
    if len(data) % 4:
        raise InputError(f"{path}: {len(data)} bytes is not a whole number of 4-byte words; not a .data file")
    words = np.frombuffer(data, "<i4")
    n = int(words[0])
    if n < 0:
        raise InputError(f"{path}: negative strand count {n}; not a USC .data file")
    heads = _strand_headers(words, n, path)
    counts = words[heads].astype(np.int64)
    # Every word that is not the count or a strand header is a coordinate.
    is_coord = np.ones(len(words), bool)
    is_coord[0] = False
    is_coord[heads] = False
    points = words.view("<f4")[is_coord].reshape(-1, 3)
    del data, words, is_coord      # the file's bytes are copied out: free them before the checks copy again
    strands = strands_without_short(points, counts, source=path)
    if return_skipped:
        return strands, np.flatnonzero(counts < 2)
    return strands


def write_usc(path, strands):
    """Write `strands`' points as .data, atomically (radius, color and alpha are not stored)."""
    s = check_strands(strands)
    n_s, n_p = s.num_strands, s.num_points
    out = np.empty(1 + n_s + 3 * n_p, "<f4")
    ints = out.view("<i4")
    ints[0] = n_s
    heads = 1 + np.arange(n_s, dtype=np.int64) + 3 * s.offsets
    ints[heads] = s.counts
    is_coord = np.ones(len(out), bool)
    is_coord[0] = False
    is_coord[heads] = False
    out[is_coord] = s.points.ravel()
    with atomic_write(path) as f:
        f.write(out.tobytes())
