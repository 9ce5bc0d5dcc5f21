# SPDX-License-Identifier: GPL-3.0-or-later
"""USC .data and .npz + sidecar: independent parses, round trips, the real file, and the
choice of format by extension."""
import json
import struct

import numpy as np
import pytest

from hairio import InputError, Strands
from hairio.formats import read_sidecar, read_strands, read_usc, write_strands, write_usc


def parse_usc(path):
    """Minimal sequential reader from the format's description."""
    data = open(path, "rb").read()
    (n,), pos, strands = struct.unpack_from("<i", data, 0), 4, []
    for _ in range(n):
        (k,) = struct.unpack_from("<i", data, pos)
        strands.append(np.frombuffer(data, "<f4", 3 * k, pos + 4).reshape(k, 3))
        pos += 4 + 12 * k
    assert pos == len(data)
    return strands


def test_usc_layout_and_round_trip(tmp_path, wavy):
    p = tmp_path / "w.data"
    write_usc(p, wavy)
    parsed = parse_usc(p)
    assert [len(a) for a in parsed] == wavy.counts.tolist()
    np.testing.assert_array_equal(np.concatenate(parsed), wavy.points)
    back = read_strands(p)
    np.testing.assert_array_equal(back.points, wavy.points)
    np.testing.assert_array_equal(back.counts, wavy.counts)


def test_usc_empty_strands_are_skipped_and_reported(tmp_path):
    rng = np.random.default_rng(0)
    ks = [3, 1, 0, 2, 1, 4]
    blob = struct.pack("<i", len(ks))
    kept = []
    for k in ks:
        pts = rng.normal(size=(k, 3)).astype("<f4")
        blob += struct.pack("<i", k) + pts.tobytes()
        if k >= 2:
            kept.append(pts)
    p = tmp_path / "e.data"
    p.write_bytes(blob)
    s, skipped = read_usc(p, return_skipped=True)
    np.testing.assert_array_equal(s.counts, [3, 2, 4])
    np.testing.assert_array_equal(skipped, [1, 2, 4])
    np.testing.assert_array_equal(s.points, np.concatenate(kept))


def test_usc_real_file(shared_data, tmp_path):
    src = shared_data / "harolongo.data"
    parsed = parse_usc(src)
    s = read_usc(src)
    assert s.num_strands == len(parsed) == 7905 and (s.counts == 21).all()
    np.testing.assert_array_equal(s.points, np.concatenate(parsed))
    out = tmp_path / "again.data"
    write_usc(out, s)
    assert out.read_bytes() == src.read_bytes()          # byte for byte
    np.testing.assert_array_equal(read_usc(out).points, s.points)


@pytest.mark.parametrize("damage", ["truncated", "negative", "odd"])
def test_usc_malformed(tmp_path, wavy, damage):
    p = tmp_path / "w.data"
    write_usc(p, wavy)
    data = bytearray(p.read_bytes())
    if damage == "truncated":
        data = data[:-12]
    elif damage == "negative":
        struct.pack_into("<i", data, 4, -5)
    else:
        data += b"\0"
    p.write_bytes(bytes(data))
    with pytest.raises(InputError, match=p.name):
        read_usc(p)


def test_npz_holds_exactly_the_spec_names_and_a_sidecar(tmp_path, wavy):
    p = tmp_path / "w.npz"
    write_strands(p, wavy, source="test")
    with np.load(p) as z:
        assert sorted(z.files) == sorted(["points", "counts", "radius", "color", "alpha", "wisp"])
        assert z["points"].dtype == np.float32 and z["counts"].dtype == np.int32
        np.testing.assert_array_equal(z["points"], wavy.points)
        np.testing.assert_array_equal(z["wisp"], wavy.wisp)
    meta = json.loads((tmp_path / "w.npz.json").read_text())
    assert meta["units"] == "m" and meta["axes"]["up"] == "Z"
    assert meta["counts"] == {"strands": wavy.num_strands, "points": wavy.num_points,
                              "segments": wavy.num_segments}
    assert meta["tool"]["name"] == "keystrand-hair" and meta["tool"]["version"]
    assert meta["source"] == "test"
    assert read_sidecar(p) == meta
    back = read_strands(p)
    for name, a in wavy.arrays().items():
        np.testing.assert_array_equal(getattr(back, name), a)


def test_unknown_extension_and_missing_file(tmp_path, wavy):
    with pytest.raises(InputError, match=r"\.npz, \.hair, \.tfx, \.data"):
        write_strands(tmp_path / "w.obj", wavy)
    with pytest.raises(InputError, match="unknown"):
        read_strands(tmp_path / "w.xyz")
    with pytest.raises(InputError, match="no such file"):
        read_strands(tmp_path / "missing.hair")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # numpy's zip, closed mid-write
@pytest.mark.parametrize("ext", ["npz", "hair", "tfx", "data"])
def test_failed_exports_leave_no_file(tmp_path, wavy, ext, monkeypatch):
    # a missing folder
    with pytest.raises(FileNotFoundError):
        write_strands(tmp_path / "nope" / f"w.{ext}", wavy)
    # not Strands (e.g. arrays with NaN never become Strands)
    with pytest.raises(InputError):
        write_strands(tmp_path / f"w.{ext}", {"points": np.full((4, 3), np.nan)})
    # an exception in the middle of writing: half of the first sizeable write lands, then
    # the disk is full
    import hairio.atomic
    real_fdopen = hairio.atomic.os.fdopen

    class DiskFull:
        def __init__(self, f):
            self.f = f

        def write(self, b):
            if len(b) > 64:
                self.f.write(bytes(b)[:len(b) // 2])
                raise OSError(28, "No space left on device")
            return self.f.write(b)

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return self.f.__exit__(*exc)

    monkeypatch.setattr(hairio.atomic.os, "fdopen", lambda *a, **k: DiskFull(real_fdopen(*a, **k)))
    with pytest.raises(OSError, match="space"):
        write_strands(tmp_path / f"w.{ext}", wavy)
    assert sorted(x.name for x in tmp_path.iterdir()) == []


def test_nan_never_reaches_a_writer():
    with pytest.raises(InputError, match="points"):
        Strands.from_arrays(np.array([[0, 0, 0], [np.nan, 0, 0]]), [2])
