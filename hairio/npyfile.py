# SPDX-License-Identifier: GPL-3.0-or-later
"""numpy's .npy arrays and .npz archives read from files anyone may have written, and
.npz archives written an array block at a time (NpzWriter).

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
import queue
import struct
import tempfile
import threading
import zipfile
import zlib

import numpy as np

from .atomic import atomic_write
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


class NpzWriter:
    """An .npz in numpy.savez's layout (one uncompressed NAME.npy member per array, in the
    order of `names`) written an array block at a time, for arrays too large to hold at
    once: a head of ten million strands grown block by block.

    append(name, rows) adds rows to an array (dtype and trailing shape set by its first
    block); commit() writes the archive atomically (hairio.atomic: all or nothing). The
    blocks stay in memory until they take `spill_bytes` in all; from then on each array's
    blocks go to a temporary file of its own beside `path` (a zip member cannot grow while
    another does, and a .npy header holds the final shape), copied into its member by
    commit() and removed as soon as it is copied. Memory: at most spill_bytes of blocks and
    a copy buffer. Disk while committing: the archive plus, at most, all arrays once and the
    largest twice. A writer left without commit() (an error, or discard()) leaves no file.
    """

    COPY_BYTES = 1 << 22
    SPILL_BYTES = 128 << 20

    def __init__(self, path, names, spill_bytes=SPILL_BYTES):
        self.path = os.fspath(path)
        self.names = list(names)
        self.spill_bytes = spill_bytes
        self._kind = {}      # name -> (dtype, trailing shape)
        self._rows = dict.fromkeys(self.names, 0)
        self._held = {name: [] for name in self.names}
        self._files = {}     # name -> (open temporary file, its path), once spilled
        self._held_bytes = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.discard()

    @property
    def spilled(self):
        return bool(self._files)

    def append(self, name, rows):
        """Add `rows` (an array of at least one dimension) to the array `name`."""
        rows = np.ascontiguousarray(rows)
        kind = (rows.dtype, rows.shape[1:])
        if self._kind.setdefault(name, kind) != kind:
            raise ValueError(f"NpzWriter: {name} is {self._kind[name]}, a block of {kind} cannot join it")
        self._rows[name] += len(rows)
        if name in self._files:
            self._files[name][0].write(rows.data)
            return
        self._held[name].append(rows)
        self._held_bytes += rows.nbytes
        if self._held_bytes > self.spill_bytes:
            self._spill()

    def _spill(self):
        folder = os.path.dirname(os.path.abspath(self.path))
        for name in self.names:
            if name not in self._files:
                fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=f"-{name}.part", dir=folder)
                self._files[name] = (os.fdopen(fd, "w+b"), tmp)
            for block in self._held[name]:
                self._files[name][0].write(block.data)
            self._held[name] = []
        self._held_bytes = 0

    def nbytes(self, name):
        dtype, tail = self._kind[name]
        return self._rows[name] * math.prod(tail) * dtype.itemsize

    def commit(self, progress=None):
        """Write the archive at `path` (atomically) and remove the temporary files.
        progress: None or a callable(fraction of the bytes written)."""
        missing = [n for n in self.names if n not in self._kind]
        if missing:
            raise ValueError(f"NpzWriter: no data for {missing}")
        total = max(1, sum(self.nbytes(n) for n in self.names))
        done = 0
        try:
            with atomic_write(self.path) as f, zipfile.ZipFile(f, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
                for name in self.names:
                    dtype, tail = self._kind[name]
                    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                              "shape": (self._rows[name],) + tail}
                    with z.open(name + ".npy", "w", force_zip64=True) as member:
                        np.lib.format.write_array_header_1_0(member, header)
                        if name in self._files:
                            src, tmp = self._files.pop(name)
                            src.seek(0)
                            while True:
                                chunk = src.read(self.COPY_BYTES)
                                if not chunk:
                                    break
                                member.write(chunk)
                                done += len(chunk)
                                if progress is not None:
                                    progress(done / total)
                            _remove(src, tmp)
                        else:
                            for block in self._held[name]:
                                member.write(block.data)
                                done += block.nbytes
                            self._held[name] = []
                            if progress is not None:
                                progress(done / total)
        finally:
            self.discard()

    def discard(self):
        """Drop everything held and remove the temporary files (no archive is written)."""
        for f, tmp in self._files.values():
            _remove(f, tmp)
        self._files = {}
        self._held = {name: [] for name in self.names}
        self._held_bytes = 0


class AppendBehind:
    """NpzWriter.append on a thread of its own, one batch behind the caller, so the caller
    makes its next block while the last is written (writing to a file leaves the
    interpreter free). put({name: rows, ...}) hands a batch over once the one before is
    written, so two batches at most are held: the one being written and the caller's next.
    An error of the writes is raised by the next put or by close; after it nothing more is
    written. close() (or leaving the `with`) waits for the writes to end."""

    def __init__(self, writer):
        self.writer = writer
        self._batches = queue.Queue()
        self._error = None
        self._thread = threading.Thread(target=self._run, name="npz-append", daemon=True)
        self._thread.start()

    def _run(self):
        while True:
            batch = self._batches.get()
            try:
                if batch is None:
                    return
                if self._error is None:
                    for name, rows in batch.items():
                        self.writer.append(name, rows)
            except BaseException as e:  # noqa: BLE001 -- raised on the caller's thread
                self._error = e
            finally:
                del batch
                self._batches.task_done()

    def _raise(self):
        if self._error is not None:
            raise self._error

    def put(self, batch):
        self._batches.join()
        self._raise()
        self._batches.put(batch)

    def close(self):
        if self._thread.is_alive():
            self._batches.put(None)
            self._thread.join()
        self._raise()

    def __enter__(self):
        return self

    def __exit__(self, kind, *rest):
        if kind is None:
            self.close()
        else:   # the caller's error stands; the writes still end before the writer goes
            self._batches.put(None)
            self._thread.join()


def _remove(f, path):
    f.close()
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
