# SPDX-License-Identifier: GPL-3.0-or-later
"""numpy's .npy arrays and .npz archives read from files anyone may have written.

np.load believes a .npy header: a 1 MB archive whose header claims a (10^9, 3) array makes
numpy allocate 11 GiB before it finds the data missing, and a damaged zip raises
BadZipFile or EOFError instead of a message. Here every size is checked before memory is
taken: a .npy header's shape against the bytes the file (or the archive's own directory)
says the member holds, and an archive's declared total against its size on disk.

Memory: reading takes at most the declared sizes of the arrays asked for, each checked
against its .npy header, and a compressed archive may declare at most
MAX_EXPANSION × its own size + EXPANSION_SLACK bytes (numpy's savez stores arrays
uncompressed; savez_compressed of real hair shrinks it 1–3×, far inside the bound).
"""
import lzma
import math
import os
import struct
import zipfile
import zlib

import numpy as np

from .validate import InputError

MAX_EXPANSION = 32
EXPANSION_SLACK = 64 << 20
# What a damaged or hostile zip makes zipfile and its decompressors raise.
_ZIP_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, zlib.error, lzma.LZMAError,
               NotImplementedError, RuntimeError, UnicodeDecodeError, struct.error, OverflowError)
# Plain numbers only: no objects (pickles), no records, no strings.
_KINDS = "biufc"
_CHUNK = 1 << 22


def _header(f, name):
    """(shape, fortran_order, dtype) of the .npy stream `f`, positioned at its data."""
    try:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            raise InputError(f"{name}: .npy format version {version[0]}.{version[1]} is not read here; "
                             "re-save the array with numpy.save")
    except ValueError as e:     # numpy's own words for a malformed magic or header
        if isinstance(e, InputError):
            raise
        raise InputError(f"{name}: not a .npy array ({e}); re-save it with numpy.save") from None
    if dtype.hasobject or dtype.fields is not None or dtype.shape != () or dtype.kind not in _KINDS:
        raise InputError(f"{name}: array of dtype {dtype} is not plain numbers; store floats or integers")
    if any(n < 0 for n in shape):
        raise InputError(f"{name}: .npy header claims the shape {shape}; the file is damaged")
    return shape, fortran, dtype


def _read_array(f, available, name):
    """The array of the .npy stream `f` whose data may take at most `available` bytes
    after its header (the file's length, or the archive's declared member size)."""
    start = f.tell()
    shape, fortran, dtype = _header(f, name)
    room = available - (f.tell() - start)
    count = math.prod(shape)
    nbytes = count * dtype.itemsize
    if nbytes > room:
        raise InputError(f"{name}: the .npy header claims shape {shape} of {dtype} ({nbytes:,} bytes) but only "
                         f"{max(room, 0):,} bytes follow it; the file is truncated or damaged, re-export it")
    data = f.read(nbytes)
    if len(data) != nbytes:
        raise InputError(f"{name}: truncated: the array needs {nbytes:,} bytes, the file has {len(data):,}")
    return np.frombuffer(data, dtype, count=count).reshape(shape, order="F" if fortran else "C")


def read_npy(path, what):
    """The array in the .npy file at `path`; `what` names it in messages (e.g. '--root-uv X')."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            return _read_array(f, os.fstat(f.fileno()).st_size, what)
    except OSError as e:
        raise InputError(f"{what}: cannot read it ({e.strerror or e})") from None


def read_npz(path, names, required=()):
    """{name: array} for each of `names` stored in the .npz at `path` (as NAME.npy);
    InputError naming the file when one of `required` is missing or anything is damaged."""
    path = os.fspath(path)
    try:
        size = os.path.getsize(path)
        with zipfile.ZipFile(path) as z:
            members = {i.filename: i for i in z.infolist()}
            missing = [n for n in required if n + ".npy" not in members]
            if missing:
                raise InputError(f"{path}: not a strand .npz, missing array(s) {missing}")
            wanted = [members[n + ".npy"] for n in names if n + ".npy" in members]
            declared = sum(i.file_size for i in wanted)
            packed = sum(i.compress_size for i in wanted)
            if declared > packed and declared > MAX_EXPANSION * size + EXPANSION_SLACK:
                raise InputError(f"{path}: the archive declares {declared:,} bytes of arrays from a {size:,}-byte "
                                 f"file, more than {MAX_EXPANSION}× its size; if it is real, re-save it "
                                 "uncompressed (numpy.savez)")
            out = {}
            for info in wanted:
                name = info.filename[:-4]
                with z.open(info) as f:
                    out[name] = _read_array(f, info.file_size, f"{path}: array {name!r}")
                    # Read to the member's end so zipfile checks its CRC: a flipped bit in
                    # the data is a damaged file, not different hair.
                    while f.read(_CHUNK):
                        pass
            return out
    except _ZIP_ERRORS as e:
        raise InputError(f"{path}: cannot read as .npz ({type(e).__name__}: {e}); re-export it") from None
