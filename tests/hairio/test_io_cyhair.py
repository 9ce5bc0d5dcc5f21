# SPDX-License-Identifier: GPL-3.0-or-later
"""Cem Yuksel .hair: round trips, an independent parse of what we write, the real file."""
import struct

import numpy as np
import pytest

from hairio import InputError, Strands
from hairio.formats import read_hair, read_strands, write_hair, write_strands


def parse_hair(path):
    """A minimal reader written from the format's description, independent of hairio."""
    data = open(path, "rb").read()
    sig, n_s, n_p, flags, d_seg = struct.unpack_from("<4s4I", data, 0)
    d_th, d_tr = struct.unpack_from("<2f", data, 20)
    d_col = struct.unpack_from("<3f", data, 28)
    info = data[40:128].split(b"\0")[0]
    pos, out = 128, {"sig": sig, "n_s": n_s, "n_p": n_p, "flags": flags, "d_seg": d_seg,
                     "d_th": d_th, "d_tr": d_tr, "d_col": d_col, "info": info}
    for bit, name, dt, per in ((1, "segments", "<u2", 0), (2, "points", "<f4", 3),
                               (4, "thickness", "<f4", 1), (8, "transparency", "<f4", 1),
                               (16, "colors", "<f4", 3)):
        if flags & bit:
            count = n_s if per == 0 else n_p * per
            out[name] = np.frombuffer(data, dt, count, pos)
            pos += out[name].nbytes
    out["end"] = pos
    out["size"] = len(data)
    return out


def test_header_and_arrays_match_the_spec(tmp_path, wavy):
    p = tmp_path / "w.hair"
    write_hair(p, wavy)
    h = parse_hair(p)
    assert h["sig"] == b"HAIR" and h["n_s"] == wavy.num_strands and h["n_p"] == wavy.num_points
    assert h["flags"] == 1 | 2 | 4 | 8 | 16            # counts, radius, alpha, color all vary
    assert h["end"] == h["size"]                        # nothing after the arrays
    assert b"keystrand-hair" in h["info"]
    np.testing.assert_array_equal(h["segments"], wavy.counts - 1)
    np.testing.assert_array_equal(h["points"].reshape(-1, 3), wavy.points)
    np.testing.assert_array_equal(h["thickness"], 2 * wavy.radius)
    np.testing.assert_allclose(h["transparency"], 1 - wavy.alpha, atol=1e-7)
    np.testing.assert_array_equal(h["colors"].reshape(-1, 3), wavy.color)


def test_round_trip_is_bit_exact_for_points_radius_color(tmp_path, wavy):
    p = tmp_path / "w.hair"
    write_strands(p, wavy)
    back = read_strands(p)
    np.testing.assert_array_equal(back.counts, wavy.counts)
    np.testing.assert_array_equal(back.points, wavy.points)
    np.testing.assert_array_equal(back.radius, wavy.radius)
    np.testing.assert_array_equal(back.color, wavy.color)
    np.testing.assert_allclose(back.alpha, wavy.alpha, atol=1.2e-7)


def test_uniform_arrays_go_to_the_header_defaults(tmp_path):
    pts = np.random.default_rng(1).normal(size=(30, 3))
    s = Strands.from_arrays(pts, np.full(5, 6), radius=np.full(30, 0.25), color=np.tile([0.1, 0.2, 0.3], (30, 1)),
                            alpha=np.full(30, 0.75))
    p = tmp_path / "u.hair"
    write_hair(p, s)
    h = parse_hair(p)
    assert h["flags"] == 2                               # points only
    assert h["d_seg"] == 5 and h["d_th"] == pytest.approx(0.5) and h["d_tr"] == pytest.approx(0.25)
    assert h["size"] == 128 + 30 * 12
    back = read_hair(p)
    np.testing.assert_array_equal(back.counts, s.counts)
    np.testing.assert_array_equal(back.radius, s.radius)
    np.testing.assert_allclose(back.color, s.color)
    # compact=False writes every array.
    write_hair(p, s, compact=False)
    assert parse_hair(p)["flags"] == 31


def test_real_file_straight_hair(shared_data, tmp_path):
    src = shared_data / "straight.hair"
    h = parse_hair(src)
    s = read_hair(src)
    assert h["flags"] == 2 | 16 and "segments" not in h
    assert s.num_strands == h["n_s"] == 10000
    assert (s.counts == h["d_seg"] + 1).all() and h["d_seg"] == 15
    np.testing.assert_array_equal(s.points.ravel(), h["points"])
    np.testing.assert_array_equal(s.color.ravel(), h["colors"])
    np.testing.assert_allclose(s.radius, h["d_th"] / 2)
    np.testing.assert_allclose(s.alpha, 1 - h["d_tr"], atol=1e-7)
    out = tmp_path / "again.hair"
    write_hair(out, s)
    again = read_hair(out)
    np.testing.assert_array_equal(again.points, s.points)
    np.testing.assert_array_equal(again.counts, s.counts)
    np.testing.assert_array_equal(again.color, s.color)
    np.testing.assert_array_equal(again.radius, s.radius)
    np.testing.assert_allclose(again.alpha, s.alpha, atol=1e-7)


def test_single_point_strands_are_dropped_on_read(tmp_path):
    pts = np.arange(3 * 7, dtype=np.float32).reshape(7, 3)
    head = struct.pack("<4s4I2f3f", b"HAIR", 3, 7, 1 | 2, 0, 1.0, 0.0, 1, 1, 1) + b"\0" * 88
    p = tmp_path / "short.hair"
    p.write_bytes(head + np.array([2, 0, 2], "<u2").tobytes() + pts.tobytes())
    s = read_hair(p)
    np.testing.assert_array_equal(s.counts, [3, 3])
    np.testing.assert_array_equal(s.points, np.concatenate([pts[:3], pts[4:]]))


@pytest.mark.parametrize("damage", ["signature", "truncated", "counts"])
def test_malformed_files_raise_input_error(tmp_path, wavy, damage):
    p = tmp_path / "w.hair"
    write_hair(p, wavy)
    data = bytearray(p.read_bytes())
    if damage == "signature":
        data[:4] = b"HAIX"
    elif damage == "truncated":
        data = data[:-5]
    else:
        struct.pack_into("<I", data, 8, wavy.num_points + 1)
    p.write_bytes(bytes(data))
    with pytest.raises(InputError, match=str(p.name)):
        read_hair(p)
