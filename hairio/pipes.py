# SPDX-License-Identifier: GPL-3.0-or-later
"""Messages between a process and the worker process it started (the tracer's renderer,
groom's growing processes): each message an 8-byte little-endian length followed by a
pickle, on the worker's stdin and stdout. Pickle is used because both ends are this
package; only the parent that started a worker writes to its stdin."""
import importlib.util
import os
import pickle
import struct

_HEADER = struct.Struct("<Q")


def _read_exact(stream, n):
    buf = bytearray(n)
    view, got = memoryview(buf), 0
    while got < n:
        k = stream.readinto(view[got:])
        if not k:
            raise EOFError("stream closed")
        got += k
    return buf


def read_message(stream):
    (n,) = _HEADER.unpack(_read_exact(stream, _HEADER.size))
    return pickle.loads(_read_exact(stream, n))


def write_message(stream, obj):
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def import_root(name):
    """The sys.path folder that `name` (a top-level module or package) imports from, found
    without importing it; None when it is not importable."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.has_location or not spec.origin:
        return None
    folder = os.path.dirname(os.path.abspath(spec.origin))
    return os.path.dirname(folder) if spec.submodule_search_locations is not None else folder


def package_paths(names):
    """The folders the top-level packages `names` import from in this process, each once."""
    paths = []
    for path in (import_root(name) for name in names):
        if path and path not in paths:
            paths.append(path)
    return paths
