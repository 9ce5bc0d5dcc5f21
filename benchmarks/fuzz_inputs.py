# SPDX-License-Identifier: GPL-3.0-or-later
"""Hostile input for every entry point, made as an attacker would, and its outcome counted.

Sources: byte-level mutations of the real files in ../shared/data (read from there, never
copied: each mutated copy lives in a temporary folder for one case), hand-made files whose
headers lie (the sizes that once took memory on their word), and hypothesis-made arrays
and presets. Entry points: the readers (hairio.formats.read_strands), the commands
`python -m tracer render` and `python -m groom export` (their main functions, in process),
groom.load_obj, Strands.from_arrays and groom.load_preset (+ placing the preset's keys).

Every case ends in one of
  clean error      InputError (exit status 2 for a command) whose message names the input
                   (the file, the option or the array), and no file written;
  accepted         a result that passes its checks: strands finite with counts >= 2 that
                   add up; a scalp with finite vertices, indices in range, some area and
                   finite nearest points; a preset whose keys land on the bundled scalp;
                   a command's file that reads back;
and anything else is a failure: escaped (another exception, a traceback), memory (the case
ran past its address-space limit), wrong (accepted but failing its checks, a message that
does not name the input, or a file left behind by a failed command).

Memory: cases run in a child process. Before each case its address space is capped
(RLIMIT_AS, soft limit) at what the process already holds plus memory_bound(entry, bytes):
8 x the input + 64 MiB for the strand formats and the commands (a .data file's points
become strands of 2.7 x its size, plus the copies the checks make), 16 x + 64 MiB for OBJ
text (Python's line parsing), 64 MiB for arrays and presets made in memory. A reader that takes
memory on a header's word (16 GiB for a 128-byte .hair) fails its case as `memory`. Each
case's peak of Python and numpy heap memory is measured too (tracemalloc) for the readers and
the commands.
Deterministic: fixed seeds, hypothesis derandomized, bounded example counts.
"""
import contextlib
import functools
import io
import json
import os
import pathlib
import random
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zipfile
import zlib

CLEAN, ACCEPTED, ESCAPED, MEMORY, WRONG = "clean error", "accepted", "escaped", "memory", "wrong"
OUTCOMES = (CLEAN, ACCEPTED, ESCAPED, MEMORY, WRONG)
MIB = 1 << 20
ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = pathlib.Path(os.environ.get("HAIR_DATA", ROOT.parent / "shared" / "data"))

# The real file each format's mutations start from.
SOURCES = {"hair": "straight.hair", "tfx": "Ratboy_mohawk.tfx", "tfx-small": "sintel_hair.tfx",
           "data": "harolongo.data", "obj": "neuralhaircut_final_scalp.obj", "obj-big": "sintel.obj"}
# The .npz is made in the case's own folder from the real .hair (the first strands of it).
NPZ_STRANDS = 300
# Where the binary formats keep their headers: most mutations land there.
HEADER_BYTES = {"hair": 128, "tfx": 160, "tfx-small": 160, "data": 8, "npz": 128}


# The entry points whose heap peak is measured (tracemalloc); the others run under the cap alone.
MEASURED = ("read", "render", "export")


def memory_bound(entry, nbytes):
    """The address space a case may take beyond what the process held before it: a fixed
    multiple of its input, never what a header claims."""
    if entry in ("arrays", "preset"):
        return 64 * MIB
    if entry == "obj":
        return 16 * nbytes + 64 * MIB
    return 8 * nbytes + 64 * MIB


# ------------------------------------------------------------------------ mutations

_INTS = (0, 1, 2, 3, 7, 0xFF, 0xFFFF, 0x10000, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 0xFFFFFFFE, 1 << 24, 1 << 30)
_FLOATS = (float("nan"), float("inf"), -float("inf"), 3.4028235e38, -3.4028235e38, 1e30, -0.0, 1e-45, 0.0, 1e20)


def _position(rng, data, header):
    if data and (rng.random() < 0.6 and header):
        return rng.randrange(min(header, len(data)))
    return rng.randrange(len(data)) if data else 0


def mutate(data, rng, header):
    """One mutated copy of `data` and a short label of what was done."""
    data = bytearray(data)
    ops = []
    for _ in range(1 if rng.random() < 0.7 else rng.randint(2, 4)):
        op = rng.randrange(8)
        if not data:
            op = 5
        if op == 0:
            i = _position(rng, data, header)
            data[i] ^= 1 << rng.randrange(8)
            ops.append(f"bit@{i}")
        elif op == 1:
            i = _position(rng, data, header)
            data[i] = rng.choice((0, 0xFF, 0x7F, 0x80, rng.randrange(256)))
            ops.append(f"byte@{i}")
        elif op in (2, 3):
            i = _position(rng, data, header) & ~3
            if i + 4 > len(data):
                continue
            word = struct.pack("<I", rng.choice(_INTS)) if op == 2 else struct.pack("<f", rng.choice(_FLOATS))
            data[i:i + 4] = word
            ops.append(f"{'int' if op == 2 else 'float'}@{i}")
        elif op == 4:
            n = rng.choice((0, 1, header - 1, header, header + 1, rng.randrange(len(data) + 1)))
            del data[max(0, min(n, len(data))):]
            ops.append(f"cut@{n}")
        elif op == 5:
            extra = bytes(rng.randrange(256) for _ in range(rng.choice((1, 3, 4, 12, 64))))
            data += extra
            ops.append(f"append{len(extra)}")
        elif op == 6:
            i = rng.randrange(len(data))
            n = rng.randrange(1, 65)
            del data[i:i + n]
            ops.append(f"delete{n}@{i}")
        else:
            i = rng.randrange(len(data))
            n = rng.randrange(1, 65)
            data[i:i] = data[i:i + n]
            ops.append(f"repeat{n}@{i}")
    return bytes(data), "+".join(ops) or "none"


def mutate_obj(text, rng):
    """A mutated copy of an OBJ's text: one of its lines changed the way files go wrong."""
    lines = text.split(b"\n")
    faces = [i for i, ln in enumerate(lines) if ln.startswith(b"f ")]
    verts = [i for i, ln in enumerate(lines) if ln.startswith(b"v ")]
    op = rng.randrange(6)
    if op == 0 and faces:
        i = rng.choice(faces)
        corners = lines[i].split()[1:]
        k = rng.randrange(len(corners))
        value = rng.choice((b"0", b"-99999", b"99999999999999999999", b"1e3", b"nan", b"-0", b"1//", b"/",
                            str(len(verts) + 1).encode()))
        corners[k] = value + corners[k][len(corners[k].split(b"/")[0]):]
        lines[i] = b"f " + b" ".join(corners)
        return b"\n".join(lines), f"face{i}:{value.decode()}"
    if op == 1 and verts:
        i = rng.choice(verts)
        xyz = lines[i].split()[1:]
        xyz[rng.randrange(len(xyz))] = rng.choice((b"nan", b"inf", b"1e400", b"-1e308", b"x", b"1e20"))
        lines[i] = b"v " + b" ".join(xyz)
        return b"\n".join(lines), f"vertex{i}"
    if op == 2 and faces:
        i = rng.choice(faces)
        a = lines[i].split()[1]
        lines[i] = b"f " + b" ".join([a, a, lines[i].split()[2]])
        return b"\n".join(lines), f"twin-corner{i}"
    if op == 3:
        return b"\n".join(ln for ln in lines if not ln.startswith(rng.choice((b"v ", b"f ")))), "drop-lines"
    data, label = mutate(text, rng, 0)
    return data, "bytes:" + label


# ------------------------------------------------------------------ hand-made files

def _npy(descr, shape, payload=b"", fortran=False, version=(1, 0)):
    head = repr({"descr": descr, "fortran_order": fortran, "shape": shape}).encode("latin1")
    pad = 64 - (10 + len(head) + 1) % 64
    head += b" " * pad + b"\n"
    if version == (1, 0):
        return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + payload
    return b"\x93NUMPY" + bytes(version) + struct.pack("<I", len(head)) + head + payload


def _zip(members, compression=zipfile.ZIP_STORED):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _bomb(points=96 * MIB):
    """A deflated .npz whose points member honestly expands to `points` bytes of zeros."""
    buf = io.BytesIO()
    chunk = bytes(16 * MIB)
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("counts.npy", _npy("<i4", (points // 24,), b"\2\0\0\0" * (points // 24)))
        with z.open("points.npy", "w", force_zip64=True) as f:
            f.write(_npy("<f4", (points // 12, 3)))
            for _ in range(points // len(chunk)):
                f.write(chunk)
            f.write(bytes(points % len(chunk)))
    return buf.getvalue()


# Hand-made cases that are valid and must be read; every other hand-made case must be refused.
LEGIT = {"big-endian float64, Fortran order", "npy version 2.0", "a valid preset", "twin corner",
         # a preset is data: its count is checked against memory when hair is grown from it
         "count 1e9", "count 2^62", "profile 10^5 points", "anchor huge"}


@functools.lru_cache(maxsize=1)
def hostile_files():
    """[(format, label, bytes)]: the files whose headers lie, as the attacks that found the
    holes made them."""
    f32 = struct.pack("<3f", 0, 0, 0)
    hair = bytearray(128)
    hair[:4] = b"HAIR"
    out = []

    def hair_with(n_s, n_p, flags, d_seg=0, tail=b""):
        h = bytearray(hair)
        struct.pack_into("<IIII", h, 4, n_s, n_p, flags, d_seg)
        return bytes(h) + tail

    out += [("hair", "2^31 strands claimed", hair_with(1 << 31, 1 << 31, 2)),
            ("hair", "2^32-1 strands, segments array", hair_with(0xFFFFFFFF, 2, 3, tail=b"\1\0" + f32 * 2)),
            ("hair", "default segments 2^32-1", hair_with(1, 2, 2, 0xFFFFFFFF, f32 * 2)),
            ("hair", "no points flag", hair_with(1, 2, 1)),
            ("hair", "header only", bytes(hair)),
            ("hair", "segments sum mismatch", hair_with(2, 4, 3, tail=b"\1\0\5\0" + f32 * 4))]
    tfx = bytearray(160)

    def tfx_with(n_s, n_v, off=160, version=4.0, tail=b""):
        t = bytearray(tfx)
        struct.pack_into("<fIII", t, 0, version, n_s, n_v, off)
        return bytes(t) + tail

    out += [("tfx", "strand x vertex product past int64", tfx_with(0xFFFFFFFF, 0xFFFFFFFF)),
            ("tfx", "2^32-1 strands of 32", tfx_with(0xFFFFFFFF, 32)),
            ("tfx", "positions inside the header", tfx_with(1, 4, off=8, tail=bytes(64))),
            ("tfx", "version NaN", tfx_with(1, 4, version=float("nan"), tail=bytes(64))),
            ("tfx", "1 vertex per strand", tfx_with(1, 1, tail=bytes(16)))]
    out += [("data", "2^31-1 strands claimed", struct.pack("<ii", 0x7FFFFFFF, 2)),
            ("data", "a word after the last strand", struct.pack("<ii6fi", 1, 2, 0, 0, 0, 1, 1, 1, 7)),
            ("data", "three words after the last strand", struct.pack("<ii6f3i", 1, 2, 0, 0, 0, 1, 1, 1, 7, 7, 7)),
            ("data", "k = 2^31-1", struct.pack("<ii", 1, 0x7FFFFFFF) + f32),
            ("data", "empty", b""),
            ("data", "0 strands then data", struct.pack("<ii", 0, 5))]
    counts = _npy("<i4", (1,), struct.pack("<i", 2))
    pts = _npy("<f4", (2, 3), f32 * 2)
    out += [("npz", "empty file", b""),
            ("npz", "not a zip", b"PK\x03\x04" + bytes(60)),
            ("npz", "shape (10^9, 3) claimed", _zip({"points.npy": _npy("<f4", (10 ** 9, 3), bytes(1000)),
                                                      "counts.npy": counts})),
            ("npz", "negative shape", _zip({"points.npy": _npy("<f4", (-1, 3)), "counts.npy": counts})),
            ("npz", "object array", _zip({"points.npy": _npy("|O", (2, 3), bytes(48)), "counts.npy": counts})),
            ("npz", "record array", _zip({"points.npy": _npy([("x", "<f4")], (6,), bytes(24)), "counts.npy": counts})),
            ("npz", "big-endian float64, Fortran order",
             _zip({"points.npy": _npy(">f8", (2, 3), struct.pack(">6d", 0, 0, 0, 1, 2, 3), fortran=True),
                   "counts.npy": counts})),
            ("npz", "npy version 2.0", _zip({"points.npy": _npy("<f4", (2, 3), f32 * 2, version=(2, 0)),
                                             "counts.npy": counts})),
            ("npz", "npy version 3.0", _zip({"points.npy": _npy("<f4", (2, 3), f32 * 2, version=(3, 0)),
                                             "counts.npy": counts})),
            ("npz", "npy header garbage", _zip({"points.npy": b"\x93NUMPY\x01\x00\x10\x00{'descr': 1}    \n",
                                                "counts.npy": counts})),
            ("npz", "counts 2^32 + 2", _zip({"points.npy": pts, "counts.npy": _npy("<i8", (1,), struct.pack("<q", 2 ** 32 + 2))})),
            ("npz", "float64 beyond float32", _zip({"points.npy": _npy("<f8", (2, 3), struct.pack("<6d", 0, 0, 0, 1e39, 0, 0)),
                                                    "counts.npy": counts})),
            ("npz", "wisp NaN", _zip({"points.npy": pts, "counts.npy": counts, "wisp.npy": _npy("<f8", (1,), struct.pack("<d", float("nan")))})),
            ("npz", "wisp 1.5", _zip({"points.npy": pts, "counts.npy": counts, "wisp.npy": _npy("<f8", (1,), struct.pack("<d", 1.5))})),
            ("npz", "points missing", _zip({"counts.npy": counts})),
            ("npz", "deflate bomb, 96 MiB of points from a small file", _bomb()),
            ("npz", "points member not an .npy", _zip({"points": b"12", "points.npy": b"xx", "counts.npy": counts})),
            ("npz", "deflated and damaged", _zip({"points.npy": pts, "counts.npy": counts}, zipfile.ZIP_DEFLATED)[:-30])]
    return out


def hostile_objs():
    tri = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    return [("index past int64", tri + b"f 1 2 99999999999999999999\n"),
            ("index 0 before a later vertex", tri + b"f 0 2 3\nv 0 0 1\n"),
            ("index 0", tri + b"v 0 0 1\nf 0 2 3\n"),
            ("every triangle degenerate", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"),
            ("slivers only", b"v 0 0 0\nv 1 0 0\nv 2 1e-16 0\nf 1 2 3\n"),
            ("twin corner", tri + b"v 1 1 0\nf 1 2 3\nf 2 2 4\n"),
            ("no faces", tri),
            ("empty", b""),
            ("binary garbage", bytes(range(256)) * 4),
            ("float index", tri + b"f 1.5 2 3\n"),
            ("vertex 1e400", b"v 0 0 1e400\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")]


def hostile_presets():
    """[(label, text)] preset files that broke the loader."""
    key = {"anchor": {"direction": [0, 0, 1]}, "profile": [[0, 0, 0], [0, 0, 0.05], [0, 0.01, 0.1]]}
    ok = {"name": "x", "params": {"count": 50}, "keys": [key]}
    cases = [("keys 5", dict(ok, keys=5)), ("keys a string", dict(ok, keys="abc")), ("keys an object", dict(ok, keys={"a": 1})),
             ("keys null", dict(ok, keys=None)), ("params a list", dict(ok, params=[1])),
             ("count 1e9", dict(ok, params={"count": 10 ** 9})), ("count 2^62", dict(ok, params={"count": 2 ** 62})),
             ("count 1.5", dict(ok, params={"count": 1.5})), ("profile NaN", dict(ok, keys=[dict(key, profile=[[0, 0, float("nan")]] * 2)])),
             ("profile nested", dict(ok, keys=[dict(key, profile=[[[0, 0, 0]]])])),
             ("profile 10^5 points", dict(ok, keys=[dict(key, profile=[[0, 0, i * 1e-4] for i in range(100000)])])),
             ("anchor huge", dict(ok, keys=[dict(key, anchor={"point": [1e308, 0, 0]})])),
             ("a valid preset", ok)]
    out = [(label, json.dumps(data, allow_nan=True)) for label, data in cases]
    out.append(("keys nested 100k deep", '{"params": {}, "keys": ' + "[" * 100000 + "]" * 100000 + "}"))
    out.append(("params nested 100k deep", '{"keys": [], "params": ' + '{"a":' * 100000 + "1" + "}" * 100000 + "}"))
    out.append(("not JSON", "{'keys': []"))
    out.append(("not UTF-8", "\udcff"))
    return out


# ------------------------------------------------------------------ checking outcomes

def _strand_problems(s):
    import numpy as np
    bad = []
    for name in ("points", "radius", "color", "alpha"):
        a = getattr(s, name)
        if a.dtype != np.float32 or (a.size and not np.isfinite(a).all()):
            bad.append(f"{name} not finite float32")
    if s.counts.dtype != np.int32 or s.wisp.dtype != np.int32:
        bad.append("counts or wisp not int32")
    if s.num_strands and s.counts.min() < 2:
        bad.append("a strand of < 2 points")
    if int(s.counts.sum(dtype=np.int64)) != s.num_points:
        bad.append("counts do not add up to the points")
    if s.num_points and (s.radius.min() < 0 or s.alpha.min() < 0 or s.alpha.max() > 1):
        bad.append("radius < 0 or alpha outside [0, 1]")
    return bad


def _scalp_problems(scalp):
    import numpy as np
    bad = []
    if not np.isfinite(scalp.vertices).all():
        bad.append("vertices not finite")
    if scalp.triangles.min() < 0 or scalp.triangles.max() >= len(scalp.vertices):
        bad.append("a triangle index out of range")
    if scalp.degenerate.all():
        bad.append("every triangle degenerate, yet accepted")
    # Queries beside vertices reach every kind of triangle, degenerate ones included.
    v = scalp.vertices[:: max(1, len(scalp.vertices) // 64)]
    size = float(np.ptp(scalp.vertices, axis=0).max()) or 1.0
    _, bary, pts = scalp.closest_points(v + 0.01 * size * scalp.vertex_normals[:: max(1, len(scalp.vertices) // 64)])
    if not (np.isfinite(bary).all() and np.isfinite(pts).all()):
        bad.append("closest_points not finite")
    return bad


def _names(message, names):
    return any(n in message for n in names)


# ------------------------------------------------------------------ the child process

def _status(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return 0


class _Limits:
    """Per case: cap the address space at what the process holds now + a bound, and, while
    `measure` is on, measure the case's peak of Python and numpy heap memory (tracemalloc
    sees numpy's array buffers, not the GL driver's own memory; it slows pure-Python work
    several times, so the jobs whose inputs are made in memory or parsed in Python run
    under the cap alone)."""

    def __init__(self):
        import resource
        import tracemalloc
        self.resource, self.tracemalloc = resource, tracemalloc
        self.measure = False

    def set_measure(self, on):
        if on and not self.tracemalloc.is_tracing():
            self.tracemalloc.start(1)
        elif not on and self.tracemalloc.is_tracing():
            self.tracemalloc.stop()
        self.measure = on

    @contextlib.contextmanager
    def case(self, bound, record):
        r, tm = self.resource, self.tracemalloc
        vm = _status("VmSize")
        if self.measure:
            tm.reset_peak()
            held = tm.get_traced_memory()[0]
        r.setrlimit(r.RLIMIT_AS, (vm + bound, r.RLIM_INFINITY))
        try:
            yield
        finally:
            r.setrlimit(r.RLIMIT_AS, (r.RLIM_INFINITY, r.RLIM_INFINITY))
            record["peak"] = max(0, tm.get_traced_memory()[1] - held) if self.measure else None


def _classify(record, run, check, names):
    """Run `run()` -> result; `check(result)` -> problems; InputError messages must name one of `names`."""
    from hairio import InputError
    try:
        result = run()
    except InputError as e:
        msg = str(e)
        record["detail"] = msg[:240]
        record["kind"] = CLEAN if _names(msg, names) else WRONG
        if record["kind"] == WRONG:
            record["detail"] = "message does not name the input: " + record["detail"]
        return
    except MemoryError as e:
        record.update(kind=MEMORY, detail=f"MemoryError: {e}"[:240])
        return
    except RecursionError as e:
        record.update(kind=ESCAPED, detail=f"RecursionError: {e}"[:240])
        return
    except Exception as e:      # the outcome being counted: anything else escaped
        record.update(kind=ESCAPED, detail=f"{type(e).__name__}: {e}"[:240])
        return
    problems = check(result)
    record.update(kind=WRONG if problems else ACCEPTED, detail="; ".join(problems)[:240])


def _command(fn, argv):
    """(exit status, stderr text) of a command's main function."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        try:
            rc = fn(argv)
        except SystemExit as e:     # argparse's own usage errors exit 2 with a message
            rc = e.code
    return rc, err.getvalue()


class _Runner:
    def __init__(self, folder):
        self.folder = pathlib.Path(folder)
        self.limits = _Limits()

    def file_case(self, entry, fmt, label, data, refuse=False):
        ext = {"tfx-small": "tfx", "obj-big": "obj"}.get(fmt, fmt)
        case_dir = self.folder / "case"
        shutil.rmtree(case_dir, ignore_errors=True)
        case_dir.mkdir()
        path = case_dir / f"case.{ext}"
        path.write_bytes(data)
        record = {"entry": entry, "format": fmt, "label": label, "bytes": len(data)}
        names = [str(path)]
        with self.limits.case(memory_bound(entry, len(data)), record):
            if entry == "read":
                from hairio.formats import read_strands
                _classify(record, lambda: read_strands(path), _strand_problems, names)
            elif entry == "obj":
                import groom
                _classify(record, lambda: groom.load_obj(path), _scalp_problems, names)
            else:
                self._command_case(record, entry, path, case_dir)
        if refuse and record["kind"] == ACCEPTED:
            record.update(kind=WRONG, detail="accepted a file that must be refused")
        left = sorted(p.name for p in case_dir.iterdir()
                      if p.name != path.name and (record["kind"] != ACCEPTED or p.name.startswith(".tmp-")))
        if left:
            record.update(kind=WRONG, detail=f"left {left} after: " + record.get("detail", ""))
        del data
        return self._relative(record)

    def _relative(self, record):
        """The case folder is a fresh temporary one: messages name it as <case>, so two runs agree."""
        record["detail"] = record.get("detail", "").replace(str(self.folder), "<case>")
        return record

    def _command_case(self, record, entry, path, case_dir):
        if entry == "render":
            from tracer.__main__ import main
            out = case_dir / "out.png"
            fn, argv = main, ["render", str(path), "--out", str(out), "--size", "16x16"]
        else:
            from hairio.cli import export_main
            out = case_dir / "out.hair"
            fn, argv = export_main, [str(path), "--out", str(out)]
        try:
            rc, err = _command(fn, argv)
        except MemoryError as e:
            record.update(kind=MEMORY, detail=f"MemoryError: {e}"[:240])
            return
        except Exception as e:      # counted, not raised: this is what the fuzzer looks for
            record.update(kind=ESCAPED, detail=f"{type(e).__name__}: {e}"[:240])
            return
        if rc == 2:
            ok = err.startswith("error: ") and _names(err, [str(path), "--out"])
            record.update(kind=CLEAN if ok else WRONG, detail=err.strip()[:240])
        elif rc == 0:
            problems = [] if out.is_file() else ["exit 0 but no output"]
            if not problems and entry == "export":
                from hairio.formats import read_strands
                problems = _strand_problems(read_strands(out))
            if not problems and entry == "render":
                problems = [] if out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" else ["not a PNG"]
            record.update(kind=WRONG if problems else ACCEPTED, detail="; ".join(problems))
        else:
            record.update(kind=ESCAPED, detail=f"exit status {rc}: {err.strip()[-240:]}")

    def preset_case(self, label, text, refuse=False):
        path = self.folder / "preset.json"
        path.write_text(text, encoding="utf-8", errors="surrogateescape")
        record = {"entry": "preset", "format": "json", "label": label, "bytes": len(text)}

        def run():
            import groom
            preset = groom.load_preset(str(path))
            return preset.place_keys(groom.default_scalp()).keys

        def check(keys):
            import numpy as np
            return [] if all(np.isfinite(k.points).all() for k in keys) else ["a key is not finite"]

        with self.limits.case(memory_bound("preset", len(text)) + 4 * len(text), record):
            _classify(record, run, check, [str(path), "preset"])
        if refuse and record["kind"] == ACCEPTED:
            record.update(kind=WRONG, detail="accepted a preset that must be refused")
        return self._relative(record)


def _file_cases(fmt, n, seed, folder):
    """[(label, bytes)]: `n` mutations of the format's real file (the .npz made from .hair)."""
    rng = random.Random(f"{seed}:{fmt}")
    if fmt == "npz":
        from hairio import Strands
        from hairio.formats import read_strands
        s = read_strands(DATA / SOURCES["hair"])
        k = min(NPZ_STRANDS, s.num_strands)
        m = int(s.counts[:k].sum())
        sub = Strands.from_arrays(s.points[:m], s.counts[:k], s.radius[:m], s.color[:m], s.alpha[:m], s.wisp[:k])
        src = pathlib.Path(folder) / "source.npz"
        sub.save_npz(src)
        base = src.read_bytes()
    else:
        base = (DATA / SOURCES[fmt]).read_bytes()
    out = []
    for _ in range(n):
        if fmt.startswith("obj"):
            out.append(tuple(reversed(mutate_obj(base, rng))))
        else:
            data, label = mutate(base, rng, HEADER_BYTES[fmt])
            out.append((label, data))
    return out


def _arrays_cases(runner, n, seed):
    """Strands.from_arrays on hypothesis-made arrays: every dtype, shape and extreme value."""
    import numpy as np
    from hypothesis import HealthCheck, given, settings, strategies as st
    from hypothesis.extra import numpy as hnp
    from hairio import Strands

    records = []
    dtypes = st.sampled_from(["<f2", "<f4", "<f8", ">f8", "<i1", "<i4", "<i8", "<u8", "?", "<c8", "O", "<U2"])
    elements = {"f": st.floats(allow_nan=True, allow_infinity=True, width=64) | st.sampled_from([1e39, -1e39, 3.4e38]),
                "i": st.integers(-2 ** 63, 2 ** 63 - 1) | st.integers(-3, 40)}

    @st.composite
    def array(draw, shape):
        dt = np.dtype(draw(dtypes))
        kind = dt.kind
        if kind == "O":
            return np.array([None] * int(np.prod(shape)), object).reshape(shape)
        if kind == "U":
            return np.full(shape, "ab")
        if kind == "f":
            el = st.floats(allow_nan=True, allow_infinity=True, width=dt.itemsize * 8)
            if dt.itemsize == 8:
                el = el | st.sampled_from([1e39, -1e39, 1e300])
            return draw(hnp.arrays(dt, shape, elements=el))
        if kind in "iu":
            info = np.iinfo(dt)
            return draw(hnp.arrays(dt, shape, elements=st.integers(int(info.min), int(info.max)) | st.integers(
                max(int(info.min), -3), 40)))
        return draw(hnp.arrays(dt, shape))

    @st.composite
    def scene(draw):
        n_s = draw(st.integers(0, 5))
        counts = draw(st.one_of(
            st.lists(st.integers(2, 5), min_size=n_s, max_size=n_s).map(lambda c: np.array(c, np.int64)),
            array((n_s,)), array((draw(st.integers(0, 3)),))))
        try:
            total = int(np.clip(np.asarray(counts, np.float64), 0, 50).sum())
        except (TypeError, ValueError):
            total = 4
        n_p = draw(st.sampled_from([total, total + 1, max(0, total - 1)]))
        shape = draw(st.sampled_from([(n_p, 3), (n_p, 3), (n_p, 2), (n_p,), (n_p, 3, 1)]))
        pts = draw(st.one_of(hnp.arrays(np.float64, shape, elements=st.floats(-10, 10)), array(shape)))
        kw = {}
        for name, shp in (("radius", (n_p,)), ("color", (n_p, 3)), ("alpha", (n_p,)), ("wisp", (n_s,))):
            if draw(st.booleans()):
                kw[name] = draw(st.one_of(array(shp), st.just([0.5] * shp[0]), array((shp[0] + 1,) + shp[1:])))
        return pts, counts, kw

    def check(s):
        return _strand_problems(s)

    @settings(max_examples=n, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(scene())
    def explore(case):
        pts, counts, kw = case
        record = {"entry": "arrays", "format": "arrays", "label": f"points {getattr(pts, 'dtype', '?')} "
                  f"{getattr(pts, 'shape', '?')}", "bytes": int(getattr(pts, "nbytes", 0))}
        with runner.limits.case(memory_bound("arrays", 0), record):
            _classify(record, lambda: Strands.from_arrays(pts, counts, **kw), check,
                      ["points", "counts", "radius", "color", "alpha", "wisp"])
        records.append(record)

    explore()
    return records


def _preset_cases(runner, n, seed):
    from hypothesis import HealthCheck, given, settings, strategies as st
    records = [runner.preset_case(label, text, label not in LEGIT) for label, text in hostile_presets()]
    scalars = st.none() | st.booleans() | st.integers(-2 ** 70, 2 ** 70) | st.floats() | st.text(max_size=4)
    values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["anchor", "point", "direction", "profile", "frame", "kind", "angles", "color", "count",
                         "group", "root_radius", "x"]), inner, max_size=4), max_leaves=20)
    vec = st.lists(st.floats(-1e3, 1e3) | st.floats(), min_size=0, max_size=4)
    key = st.fixed_dictionaries({"anchor": st.sampled_from(["point", "direction"]).flatmap(
        lambda k: st.fixed_dictionaries({k: vec})) | values,
        "profile": st.lists(vec, min_size=0, max_size=5) | values},
        optional={"frame": st.sampled_from(["root", "world", "x"]) | values, "kind": st.sampled_from(["bezier", "cubic", "x"]),
                  "angles": vec, "color": vec | st.none(), "root_radius": st.floats() | st.none(), "group": values})
    params = st.fixed_dictionaries({}, optional={"count": st.integers(-5, 2 ** 64) | st.floats() | values,
                                                 "seed": st.integers(-5, 2 ** 64), "radius": st.floats(),
                                                 "up": vec, "front": vec, "tidiness": st.floats(), "x": values})
    preset = st.fixed_dictionaries({"keys": st.lists(key, max_size=3) | values}, optional={"params": params | values,
                                                                                           "name": st.text(max_size=5)})

    @settings(max_examples=n, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(preset)
    def explore(data):
        records.append(runner.preset_case("hypothesis", json.dumps(data, allow_nan=True)))

    explore()
    return records


def child_main():
    """Run the cases the JSON on stdin asks for; print one JSON list of records."""
    spec = json.loads(sys.stdin.read())
    folder = tempfile.mkdtemp(prefix="fuzz-")
    records = []
    try:
        runner = _Runner(folder)
        deadline = time.monotonic() + spec.get("seconds", 1e9)
        import numpy  # noqa: F401  (held before the first case: it is not the case's memory)
        import hairio.formats  # noqa: F401
        for job in spec["jobs"]:
            entry, fmt, n = job["entry"], job["format"], job["n"]
            runner.limits.set_measure(entry in MEASURED)
            if entry == "render":
                _command(__import__("tracer.__main__", fromlist=["main"]).main, ["--help"])
                _warm_renderer()
            if entry in ("export",):
                import hairio.cli  # noqa: F401
            if entry == "obj":
                import groom  # noqa: F401
            if entry == "arrays":
                records += _arrays_cases(runner, n, spec["seed"])
                continue
            if entry == "preset":
                import groom  # noqa: F401
                groom.default_scalp()
                records += _preset_cases(runner, n, spec["seed"])
                continue
            cases = []
            if job.get("hostile"):
                if fmt.startswith("obj"):
                    cases += [(label, data, label not in LEGIT) for label, data in hostile_objs()]
                else:
                    cases += [(label, data, label not in LEGIT) for f, label, data in hostile_files() if f == fmt]
            cases += [(label, data, False) for label, data in _file_cases(fmt, n, spec["seed"], folder)]
            for label, data, refuse in cases:
                if time.monotonic() > deadline:
                    break
                records.append(runner.file_case(entry, fmt, label, data, refuse))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    sys.stdout.write(json.dumps(records))


def _warm_renderer():
    """The GL context and shaders are the process's, made once before any case counts."""
    import numpy as np
    from hairio import Strands
    from tracer import Camera, RenderSettings
    from tracer.renderer import Renderer
    r = Renderer()
    r.set_strands(Strands.from_arrays(np.array([[0, 0, 0], [0, 0, 1.0]]), [2], radius=[0.1, 0.1]))
    r.render(Camera.frame_bounds((-1, -1, 0), (1, 1, 1), (16, 16)), RenderSettings())


def run_jobs(jobs, seed=18, seconds=None, timeout=600):
    """Run `jobs` ([{entry, format, n, hostile}]) in a fresh child process; its records."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               # Fewer threads, fewer arenas: the address space a case is given is its own.
               OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MALLOC_ARENA_MAX="1", LP_NUM_THREADS="0",
               KEYSTRAND_THREADS=os.environ.get("KEYSTRAND_THREADS", "1"))
    spec = {"jobs": jobs, "seed": seed}
    if seconds:
        spec["seconds"] = seconds
    proc = subprocess.run([sys.executable, "-c", "from benchmarks.fuzz_inputs import child_main; child_main()"],
                          input=json.dumps(spec), capture_output=True, text=True, cwd=ROOT, env=env, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"fuzz child exited {proc.returncode}: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout)


def tally(records):
    """{(entry, format): {tried, each outcome's count, peak (bytes, None where not measured),
    peak_ratio, bytes}}: the largest heap peak, the largest peak / input of the inputs of 64 KiB or more (below that
    the fixed cost of a call is all a ratio shows) and the largest input."""
    out = {}
    for r in records:
        key = (r["entry"], r["format"])
        row = out.setdefault(key, {"tried": 0, **{k: 0 for k in OUTCOMES}, "peak": None, "peak_ratio": 0.0, "bytes": 0})
        row["tried"] += 1
        row[r["kind"]] += 1
        peak = r.get("peak")
        if peak is not None:
            row["peak"] = max(row["peak"] or 0, peak)
        row["bytes"] = max(row["bytes"], r["bytes"])
        if peak is not None and r["bytes"] >= 64 << 10:
            row["peak_ratio"] = max(row["peak_ratio"], peak / r["bytes"])
    return out


def failures(records):
    return [r for r in records if r["kind"] not in (CLEAN, ACCEPTED)]
