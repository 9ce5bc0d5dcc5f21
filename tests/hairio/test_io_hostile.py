# SPDX-License-Identifier: GPL-3.0-or-later
"""Hostile files and arrays: each is refused with an InputError that names it, before memory
is taken on a header's word, and nothing is stored that differs from what was given."""
import io
import resource
import struct
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from hairio import InputError, Strands
from hairio.formats import read_strands
from hairio.npyfile import MAX_EXPANSION, read_npy

from benchmarks import fuzz_inputs as fz

HOSTILE = [(fmt, label, data) for fmt, label, data in fz.hostile_files() if label not in fz.LEGIT]


@pytest.mark.parametrize("fmt,label,data", HOSTILE, ids=[f"{f}: {label}" for f, label, _ in HOSTILE])
def test_hostile_file_is_refused_naming_it(tmp_path, fmt, label, data):
    path = tmp_path / f"hostile.{fmt}"
    path.write_bytes(data)
    with pytest.raises(InputError) as e:
        read_strands(path)
    assert str(path) in str(e.value)


def test_header_claims_take_no_memory(tmp_path):
    """The claims that once allocated 11-16 GiB, read under a 512 MiB address-space cap."""
    paths = []
    for fmt, label, data in HOSTILE:
        if "claimed" in label or "past int64" in label or "2^32-1" in label:
            paths.append(tmp_path / f"{len(paths)}.{fmt}")
            paths[-1].write_bytes(data)
    assert len(paths) >= 5
    code = f"""
import resource, sys
sys.path.insert(0, {str(fz.ROOT)!r})
from hairio import InputError
from hairio.formats import read_strands
import numpy
held = int(open('/proc/self/status').read().split('VmSize:')[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (held + (512 << 20), resource.RLIM_INFINITY))
for p in {[str(p) for p in paths]!r}:
    try:
        read_strands(p)
    except InputError as e:
        print('refused', p)
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         env={"OPENBLAS_NUM_THREADS": "1", "MALLOC_ARENA_MAX": "1", "PATH": ""})
    assert run.returncode == 0, run.stderr
    assert run.stdout.count("refused") == len(paths), run.stdout + run.stderr


def test_data_with_words_after_the_last_strand(tmp_path):
    path = tmp_path / "t.data"
    path.write_bytes(struct.pack("<ii6fi", 1, 2, 0, 0, 0, 1, 1, 1, 7))
    with pytest.raises(InputError, match="1 words follow the last of the 1 strands"):
        read_strands(path)


def test_hair_default_segments_must_match_the_point_count(tmp_path):
    h = bytearray(128)
    h[:4] = b"HAIR"
    struct.pack_into("<IIII", h, 4, 3, 6, 2, 1)      # 3 strands of 2 points = 6 points: fine
    path = tmp_path / "ok.hair"
    path.write_bytes(bytes(h) + np.arange(18, dtype="<f4").tobytes())
    assert read_strands(path).counts.tolist() == [2, 2, 2]
    struct.pack_into("<I", h, 16, 2)                   # 3 points each would be 9
    path.write_bytes(bytes(h) + np.arange(18, dtype="<f4").tobytes())
    with pytest.raises(InputError, match="9 points but the header says 6"):
        read_strands(path)


def test_npz_deflate_bomb_is_refused_before_inflating(tmp_path):
    path = tmp_path / "bomb.npz"
    path.write_bytes(fz._bomb(points=8 << 20))
    size = path.stat().st_size
    assert (8 << 20) > MAX_EXPANSION * size       # the bomb would pass a plain ratio
    # The slack lets an honest small archive through; this one declares more than it.
    path.write_bytes(fz._bomb(points=96 << 20))
    with pytest.raises(InputError, match=r"more than 32× its size"):
        read_strands(path)


def test_npz_reads_what_numpy_writes_in_every_layout(tmp_path):
    pts = np.arange(12, dtype=">f8").reshape(4, 3)
    path = tmp_path / "f.npz"
    np.savez_compressed(path, points=np.asfortranarray(pts), counts=np.array([2, 2], np.int64),
                        wisp=np.array([1.0, 3.0]))
    s = read_strands(path)
    np.testing.assert_array_equal(s.points, pts.astype(np.float32))
    assert s.wisp.tolist() == [1, 3] and s.counts.dtype == np.int32


def test_npz_flipped_data_bit_fails_the_crc(tmp_path):
    s = Strands.from_arrays(np.arange(12.0).reshape(4, 3), [2, 2])
    path = tmp_path / "s.npz"
    s.save_npz(path)
    data = bytearray(path.read_bytes())
    i = data.index(np.float32(5.0).tobytes())
    data[i] ^= 0x10
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="CRC"):
        read_strands(path)


def test_read_npy_checks_its_header(tmp_path):
    path = tmp_path / "uv.npy"
    path.write_bytes(fz._npy("<f4", (10 ** 9, 2), bytes(16)))
    with pytest.raises(InputError, match="--root-uv x: the .npy header claims shape"):
        read_npy(path, "--root-uv x")
    np.save(path, np.ones((3, 2)))
    assert read_npy(path, "uv").shape == (3, 2)


# --------------------------------------------------------------- Strands.from_arrays

def _two_points(**kw):
    return Strands.from_arrays(kw.pop("points", np.zeros((2, 3))), kw.pop("counts", [2]), **kw)


@pytest.mark.parametrize("kw,match", [
    (dict(points=np.array([[0, 0, 0], [1e39, 0, 0]])), r"points: 1 value\(s\) beyond float32's range"),
    (dict(radius=np.array([1e39, 1.0])), r"radius: 1 value\(s\) beyond float32's range"),
    (dict(color=np.full((2, 3), -1e300)), "color: 6 value"),
    (dict(counts=np.array([2 ** 32 + 2], np.int64)), "counts: value 4294967298"),
    (dict(counts=np.array([2], np.uint64) + np.uint64(2 ** 63)), "counts: value"),
    (dict(wisp=[np.nan]), "wisp: value nan at index 0 is not a whole number"),
    (dict(wisp=[1.5]), "wisp: value 1.5"),
    (dict(wisp=np.array([2 ** 40])), "wisp: value 1099511627776"),
    (dict(wisp=["a"]), "wisp: expected integers"),
    (dict(points=np.array([["a", "b", "c"]] * 2)), "points: expected real numbers, got dtype <U1"),
    (dict(points=np.array([[None] * 3] * 2)), "points: expected real numbers, got dtype object"),
    (dict(radius=np.array([1j, 1j])), "radius: expected real numbers, got dtype complex128"),
    (dict(points=np.ones((2, 3), bool)), "points: expected real numbers, got dtype bool"),
    (dict(points=[[0, 0, 0], [1, 2]]), "points: not an array of numbers"),
    (dict(alpha=[0.5, 1.5]), r"alpha: values outside \[0, 1\]"),
])
def test_from_arrays_refuses_what_a_cast_would_change(kw, match):
    with pytest.raises(InputError, match=match):
        _two_points(**kw)


def test_from_arrays_keeps_what_fits():
    big = np.float64(np.finfo(np.float32).max)
    s = _two_points(points=np.array([[0, 0, 0], [big, -big, 1e-300]]), counts=np.array([2], np.uint64),
                    wisp=np.array([7.0]), radius=np.array([0, 3], np.int16))
    assert s.points[1, 0] == np.finfo(np.float32).max and np.isfinite(s.points).all()
    assert s.points[1, 2] == 0.0 and s.wisp.tolist() == [7] and s.radius.tolist() == [0, 3]


# ------------------------------------------------------------------- one policy

POLICY = [(fmt, label, data) for fmt, label, data in HOSTILE if fmt in ("hair", "tfx", "data", "npz")][::2]


@pytest.mark.parametrize("fmt,label,data", POLICY, ids=[f"{f}: {label}" for f, label, _ in POLICY])
def test_export_and_render_give_the_same_bad_file_the_same_answer(tmp_path, fmt, label, data, capsys):
    """Both commands read through hairio.formats: same message, exit 2, nothing written."""
    from hairio.cli import export_main
    from tracer.__main__ import main as render_main
    path = tmp_path / f"bad.{fmt}"
    path.write_bytes(data)
    assert export_main([str(path), "--out", str(tmp_path / "out.hair")]) == 2
    export_err = capsys.readouterr().err
    assert render_main(["render", str(path), "--out", str(tmp_path / "out.png")]) == 2
    render_err = capsys.readouterr().err
    assert export_err == render_err and export_err.startswith(f"error: {path}")
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@pytest.mark.parametrize("case", ["folder", "unwritable", "root-uv claims"])
def test_export_checks_its_destination_and_root_uv_before_the_work(tmp_path, case, capsys):
    from hairio.cli import export_main
    src = tmp_path / "in.npz"
    Strands.from_arrays(np.arange(12.0).reshape(4, 3), [2, 2]).save_npz(src)
    (tmp_path / "dir.tfx").mkdir()
    (tmp_path / "uv.npy").write_bytes(fz._npy("<f4", (10 ** 9, 2), bytes(16)))
    argv = {"folder": ["--out", str(tmp_path / "dir.tfx")],
            "unwritable": ["--out", "/proc/keystrand-test.tfx"],
            "root-uv claims": ["--out", str(tmp_path / "x.tfx"), "--root-uv", str(tmp_path / "uv.npy")]}[case]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert export_main([str(src)] + argv) == 2
    err = capsys.readouterr().err
    want = {"folder": "is a folder", "unwritable": "cannot write in",
            "root-uv claims": "--root-uv " + str(tmp_path / "uv.npy") + ": the .npy header claims"}[case]
    assert want in err and err.startswith("error: --")
    assert sorted(p.name for p in tmp_path.iterdir()) == before
