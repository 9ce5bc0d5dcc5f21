# SPDX-License-Identifier: GPL-3.0-or-later
"""TressFX .tfx v4: header and layout parsed independently, resampling, pinning, UVs,
padding, guides + render strands, the real files."""
import pathlib
import struct

import numpy as np
import pytest

from hairio import InputError, Strands
from hairio.formats import (load_tfx, loaded_strand_count, padding_strands, read_strands, read_tfx,
                            resample_strands, resampling_error, resampling_errors, spherical_root_uv,
                            write_tfx, write_tfx_pair)

from hairio_scenes import make_wavy


def parse_tfx(path):
    """Minimal reader from TressFXTFXFileHeader (160 bytes), independent of hairio."""
    data = open(path, "rb").read()
    version, n_s, n_v = struct.unpack_from("<fII", data, 0)
    offs = struct.unpack_from("<5I", data, 12)
    reserved = struct.unpack_from("<32I", data, 32)
    out = {"version": version, "n_s": n_s, "n_v": n_v, "offsets": offs, "reserved": reserved, "size": len(data)}
    o_pos, o_suv, o_vuv, o_th, o_col = offs
    out["pos"] = np.frombuffer(data, "<f4", n_s * n_v * 4, o_pos).reshape(n_s, n_v, 4)
    if o_suv:
        out["uv"] = np.frombuffer(data, "<f4", n_s * 2, o_suv).reshape(n_s, 2)
    if o_th:
        out["thickness"] = np.frombuffer(data, "<f4", n_s, o_th)
    if o_col:
        out["color"] = np.frombuffer(data, "<f4", n_s * n_v * 4, o_col).reshape(n_s, n_v, 4)
    return out


def distance_to_polylines(points, polylines):
    """(S, n) distances from each strand's points (S, n, 3) to the same strand's polyline
    (S, m, 3): brute force over every segment, float64."""
    p = points.astype(np.float64)[:, :, None, :]
    a = polylines.astype(np.float64)[:, None, :-1, :]
    ab = polylines.astype(np.float64)[:, None, 1:, :] - a
    den = np.maximum((ab * ab).sum(-1), 1e-300)
    u = np.clip(((p - a) * ab).sum(-1) / den, 0, 1)
    return np.linalg.norm(p - (a + u[..., None] * ab), axis=-1).min(axis=2)


def polyline_length(p):
    return np.linalg.norm(np.diff(p, axis=0), axis=1).sum()


def test_layout_matches_the_v4_header(tmp_path, wavy):
    p = tmp_path / "w.tfx"
    n = write_tfx(p, wavy, vertices_per_strand=16, pinned=3)
    t = parse_tfx(p)
    assert n == t["n_s"] == wavy.num_strands and t["n_v"] == 16 and t["version"] == 4.0
    assert t["offsets"][0] == 160 and all(o % 8 == 0 for o in t["offsets"])
    assert t["reserved"] == (0,) * 32
    assert t["offsets"][2] == 0                        # no per-vertex UVs
    ends = [t["offsets"][0] + t["pos"].nbytes, t["offsets"][1] + t["uv"].nbytes,
            t["offsets"][3] + t["thickness"].nbytes, t["offsets"][4] + t["color"].nbytes]
    assert max(ends) == t["size"]
    w = t["pos"][..., 3]
    assert (w[:, :3] == 0).all() and (w[:, 3:] == 1).all()
    # roots and tips are kept exactly; thickness is 2 * root radius
    np.testing.assert_array_equal(t["pos"][:, 0, :3], wavy.points[wavy.offsets])
    np.testing.assert_allclose(t["pos"][:, -1, :3], wavy.points[wavy.offsets + wavy.counts - 1], atol=1e-7)
    np.testing.assert_array_equal(t["thickness"], 2 * wavy.radius[wavy.offsets])


@pytest.mark.parametrize("n", [4, 8, 16, 32, 64])
def test_resampled_chords_are_equal_within_one_percent_and_stay_on_the_strand(wavy, n):
    r = resample_strands(wavy, n)
    assert (r.counts == n).all()
    pts = r.points.reshape(-1, n, 3).astype(np.float64)
    chord = np.linalg.norm(np.diff(pts, axis=1), axis=2)
    np.testing.assert_array_less(np.abs(chord / chord.mean(axis=1, keepdims=True) - 1), 0.01)
    # every vertex lies on its own strand's polyline; root and tip are kept
    polylines = np.split(wavy.points.astype(np.float64), np.cumsum(wavy.counts)[:-1])
    d = [distance_to_polylines(p[None], q[None]).max() for p, q in zip(pts, polylines)]
    assert max(d) < 1e-6
    np.testing.assert_array_equal(pts[:, 0], wavy.points[wavy.offsets])
    np.testing.assert_allclose(pts[:, -1], wavy.points[wavy.offsets + wavy.counts - 1], atol=1e-7)
    # a straight strand resamples exactly evenly
    line = Strands.from_arrays(np.array([[0, 0, 0], [0, 0, 0.1], [0, 0, 1.0]]), [3])
    z = resample_strands(line, 5).points[:, 2]
    np.testing.assert_allclose(z, [0, 0.25, 0.5, 0.75, 1.0], atol=1e-7)


def test_equal_arc_steps_would_leave_curled_chords_far_apart():
    """What the chord equalisation is for: on curled strands equal arc steps give chords that
    differ by far more than 1 % (a chord across a curl is shorter than its arc)."""
    curly = make_wavy(40, (64, 96), seed=3, curl=6.0)
    from hairio.formats.tressfx import _arc_table, _points_at
    pts, g, roots, tips = _arc_table(curly)
    arc = (g[tips] - g[roots])[:, None] * np.linspace(0, 1, 16)[None, :]
    chord = np.linalg.norm(np.diff(_points_at(pts, g, roots, tips, arc), axis=1), axis=2)
    assert np.abs(chord / chord.mean(axis=1, keepdims=True) - 1).max() > 0.05
    r = resample_strands(curly, 16).points.reshape(-1, 16, 3).astype(np.float64)
    chord = np.linalg.norm(np.diff(r, axis=1), axis=2)
    assert np.abs(chord / chord.mean(axis=1, keepdims=True) - 1).max() < 0.01


@pytest.fixture(scope="module")
def curly_groom():
    """The curly preset on the default scalp, 3,000 strands of 32 points: tight curls where
    marching chords of one length leaps a curl and lands a few percent apart."""
    import groom
    scalp = groom.default_scalp()
    preset = groom.load_preset("curly")
    params = preset.params.replace(count=3000, seed=0, resolution_mode="fixed", points_per_strand=32)
    return groom.generate(scalp, preset.keys_on(scalp), params).strands


@pytest.mark.parametrize("n", [4, 8, 16, 32, 64])
def test_every_curly_strand_has_equal_chords_within_one_percent(curly_groom, n):
    from hairio.formats.tressfx import CHORD_TOLERANCE, chord_parameters
    s = curly_groom
    r = resample_strands(s, n)
    pts = r.points.reshape(-1, n, 3).astype(np.float64)
    chord = np.linalg.norm(np.diff(pts, axis=1), axis=2)
    apart = np.abs(chord / chord.mean(axis=1, keepdims=True) - 1).max(axis=1)
    assert apart.max() < 0.01, (n, int((apart > 0.01).sum()), float(apart.max()))
    # the writer's own aim, with room for the float32 points the file stores
    assert apart.max() < CHORD_TOLERANCE + 1e-5
    # root and tip are kept exactly; the vertices stay in order along the strand
    np.testing.assert_array_equal(pts[:, 0], s.points[s.offsets])
    np.testing.assert_array_equal(pts[:, -1], s.points[s.offsets + s.counts - 1])
    assert (np.diff(chord_parameters(s, n), axis=1) > 0).all()


def test_marching_places_equal_chords_across_a_corner():
    """A right-angled corner: the chord across it is shorter than its arc, and which chord
    crosses it changes as vertices move. Marching chords of one length (solved so the last
    one ends at the tip) makes them equal all the same, every vertex on the strand."""
    from hairio.formats.tressfx import _arc_table, _march_equal_chords, _points_at
    t = np.linspace(0, 1, 40)[:, None]
    corner = np.concatenate([t * [0, 0, 1.0], [0, 0, 1.0] + t[1:] * [0.7, 0, 0]])
    s = Strands.from_arrays(corner, [len(corner)])
    pts, g, roots, tips = _arc_table(s)
    for n in (5, 8, 13):
        arc, apart = _march_equal_chords(pts, g, roots, tips, n)
        q = _points_at(pts, g, roots, tips, arc)[0]
        chord = np.linalg.norm(np.diff(q, axis=0), axis=1)
        assert apart[0] < 1e-6 and np.ptp(chord) < 1e-6 * chord.mean(), n
        np.testing.assert_allclose(q[[0, -1]], corner[[0, -1]], atol=1e-12)
        assert (np.diff(arc[0]) > 0).all()


def test_round_trip_within_the_resampling_error(tmp_path, wavy):
    p = tmp_path / "w.tfx"
    write_tfx(p, wavy, vertices_per_strand=64)
    back = read_tfx(p)
    assert (back.counts == 64).all() and back.num_strands == wavy.num_strands
    err = resampling_error(wavy, 64)
    assert 0 < err["max"] < 1e-3
    # the file's vertices are exactly the resampled strands, float32
    np.testing.assert_array_equal(back.points, resample_strands(wavy, 64).points)
    # every original point lies within the reported error of the file's strand
    fixed = make_wavy(wavy.num_strands, (20, 20))
    write_tfx(p, fixed, vertices_per_strand=64)
    d = distance_to_polylines(fixed.points.reshape(-1, 20, 3), read_tfx(p).points.reshape(-1, 64, 3))
    assert d.max() <= resampling_error(fixed, 64)["max"] + 1e-7


def test_resampling_error_falls_with_more_vertices():
    curly = make_wavy(40, (64, 96), seed=3, curl=6.0)
    errs = resampling_errors(curly)
    assert list(errs) == [4, 8, 16, 32, 64]
    values = np.array(list(errs.values()))
    assert (np.diff(values) < 0).all()
    assert values[0] > 10 * values[-1]


def test_resampling_error_of_a_zigzag_is_its_amplitude():
    # A zigzag of amplitude h resampled to its two ends: the error is h exactly.
    h = 0.25
    pts = np.array([[0, 0, 0], [h, 0, 1], [0, 0, 2], [h, 0, 3], [0, 0, 4]], float)
    s = Strands.from_arrays(pts, [5])
    # 4 vertices along 4 equal segments: targets land at arc 0, 4/3, 8/3, 4
    e = resampling_error(s, 2)
    assert e["max"] == pytest.approx(h, rel=1e-6)


def test_pinned_tip_and_no_pin(tmp_path, wavy):
    p = tmp_path / "w.tfx"
    write_tfx(p, wavy, vertices_per_strand=8, pinned=0, pin_tip=True)
    w = parse_tfx(p)["pos"][..., 3]
    assert (w[:, :-1] == 1).all() and (w[:, -1] == 0).all()


def test_strand_uvs_from_the_scalp_map_and_flipped_for_directx(tmp_path, wavy):
    uv = np.random.default_rng(2).uniform(size=(wavy.num_strands, 2)).astype(np.float32)
    p = tmp_path / "w.tfx"
    write_tfx(p, wavy, vertices_per_strand=4, root_uv=uv, flip_v=False)
    np.testing.assert_array_equal(parse_tfx(p)["uv"], uv)
    write_tfx(p, wavy, vertices_per_strand=4, root_uv=uv)
    np.testing.assert_allclose(parse_tfx(p)["uv"], np.stack([uv[:, 0], 1 - uv[:, 1]], 1), atol=1e-7)


def test_spherical_projection_puts_front_at_u_half_and_top_at_v_one():
    # around the centroid (origin): front (-Y) -> u 0.5, side +X -> u 0.75, top -> v 1
    roots = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1], [0, 0, -1], [-1, 0, 0], [0, 1, 0]], float)
    uv = spherical_root_uv(roots)
    np.testing.assert_allclose(uv[0], [0.5, 0.5], atol=1e-6)
    np.testing.assert_allclose(uv[1], [0.75, 0.5], atol=1e-6)
    np.testing.assert_allclose(uv[2:4, 1], [1, 0], atol=1e-6)
    # another frame: Y up, +Z front (a Y-up scene) gives the same picture
    turned = roots[:, [0, 2, 1]] * [1, 1, -1]
    np.testing.assert_allclose(spherical_root_uv(turned, up=(0, 1, 0), front=(0, 0, 1)), uv, atol=1e-6)
    # a root on the centroid gives a finite UV
    assert np.isfinite(spherical_root_uv(np.zeros((3, 3)))).all()


def test_loader_padding_rule_and_padded_files(tmp_path, wavy):
    # AMD's LoadHairData: (n - n % 64) + 64, even for whole groups; follow hairs multiply
    assert loaded_strand_count(2228) == 2240
    assert loaded_strand_count(64) == 128
    assert loaded_strand_count(50, follow_per_guide=3) == 256
    p = tmp_path / "pad.tfx"
    n = write_tfx(p, wavy, vertices_per_strand=8, pad_strands=True)
    t = parse_tfx(p)
    assert n == t["n_s"] == 64
    np.testing.assert_array_equal(t["pos"][wavy.num_strands:], np.repeat(t["pos"][wavy.num_strands - 1:wavy.num_strands], 64 - wavy.num_strands, 0))


@pytest.mark.parametrize("shuffle", [None, 5])
def test_a_padded_file_reads_back_without_its_padding(tmp_path, wavy, shuffle):
    p = tmp_path / "pad.tfx"
    write_tfx(p, wavy, vertices_per_strand=8, pad_strands=True, shuffle_seed=shuffle)
    assert parse_tfx(p)["n_s"] == 64
    assert padding_strands(load_tfx(p)) == 64 - wavy.num_strands
    back = read_tfx(p)
    assert back.num_strands == wavy.num_strands
    want = resample_strands(wavy, 8).points.reshape(-1, 8, 3)
    got = back.points.reshape(-1, 8, 3)
    if shuffle is None:
        np.testing.assert_array_equal(got, want)
    else:
        np.testing.assert_array_equal(np.sort(got[:, 0], axis=0), np.sort(want[:, 0], axis=0))


def test_whole_groups_of_different_strands_are_no_padding(tmp_path):
    s = make_wavy(128, (6, 6), seed=8)
    p = tmp_path / "whole.tfx"
    write_tfx(p, s, vertices_per_strand=4, pad_strands=True)
    assert padding_strands(load_tfx(p)) == 0 and read_tfx(p).num_strands == 128
    # the last strand repeated without whole-group padding (65 strands) is kept as written
    last = make_wavy(64, (6, 6), seed=8)
    twice = Strands.from_arrays(np.concatenate([last.points, last.points[-6:]]), np.full(65, 6))
    write_tfx(p, twice, vertices_per_strand=4)
    assert read_tfx(p).num_strands == 65


def test_shuffle_keeps_every_strand(tmp_path, wavy):
    p = tmp_path / "s.tfx"
    write_tfx(p, wavy, vertices_per_strand=8, shuffle_seed=7)
    roots = parse_tfx(p)["pos"][:, 0, :3]
    want = wavy.points[wavy.offsets]
    assert not np.array_equal(roots, want)
    np.testing.assert_array_equal(np.sort(roots, axis=0), np.sort(want, axis=0))


def test_guides_and_render_strands_go_to_separate_files(tmp_path, wavy):
    guides = make_wavy(7, (4, 6), seed=9)
    a, b = write_tfx_pair(tmp_path / "hair.tfx", wavy, guides, vertices_per_strand=16)
    assert b.endswith("hair_guides.tfx")
    assert parse_tfx(a)["n_s"] == wavy.num_strands and parse_tfx(b)["n_s"] == 7
    np.testing.assert_array_equal(parse_tfx(b)["pos"][:, 0, :3], guides.points[guides.offsets])


def test_follow_hair_guides_come_from_the_wisps(tmp_path):
    """Guides for TressFX's follow hairs: every wisp gets about one guide per F + 1 of its
    strands, each a strand of that wisp near its patch's middle; the radius covers the
    patches' roots; the JSON beside the guides holds the loader's three numbers."""
    import json
    from hairio.formats import follow_hair_guides, write_strands
    s = make_wavy(300, (12, 20), seed=6)
    follow = 4
    index, load = follow_hair_guides(s, follow)
    assert load["numFollowHairsPerGuideHair"] == follow
    assert len(np.unique(index)) == len(index)
    for w in np.unique(s.wisp):
        in_wisp = int((s.wisp == w).sum())
        assert int((s.wisp[index] == w).sum()) == -(-in_wisp // (follow + 1)), w
    roots = s.points[s.offsets].astype(np.float64)
    # each strand's nearest guide of its own wisp lies within about the radius
    near = [np.linalg.norm(roots[index[s.wisp[index] == s.wisp[i]]] - roots[i], axis=1).min()
            for i in range(s.num_strands)]
    assert np.median(near) <= load["maxRadiusAroundGuideHair"] + 1e-9
    assert load["maxRadiusAroundGuideHair"] > 0 and load["tipSeparationFactor"] >= 0
    written = write_strands(tmp_path / "h.tfx", s, follow_hairs=follow, vertices_per_strand=8)
    assert [pathlib.Path(w).name for w in written] == ["h.tfx", "h_guides.tfx", "h_guides.tfx.json"]
    assert parse_tfx(tmp_path / "h.tfx")["n_s"] == s.num_strands
    guides = parse_tfx(tmp_path / "h_guides.tfx")
    np.testing.assert_array_equal(guides["pos"][:, 0, :3], s.points[s.offsets][index])
    meta = json.loads((tmp_path / "h_guides.tfx.json").read_text())
    assert meta["numFollowHairsPerGuideHair"] == follow and meta["guides"] == len(index)
    assert meta["maxRadiusAroundGuideHair"] == pytest.approx(load["maxRadiusAroundGuideHair"])


def test_follow_hairs_and_key_guides_are_one_or_the_other(tmp_path, wavy):
    from hairio.formats import write_strands
    with pytest.raises(InputError, match="give one"):
        write_strands(tmp_path / "h.tfx", wavy, follow_hairs=3, guides=make_wavy(3, (4, 4)))
    with pytest.raises(InputError, match="follow_hairs"):
        write_strands(tmp_path / "h.tfx", wavy, follow_hairs=0)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("bad", [dict(vertices_per_strand=12), dict(vertices_per_strand=128),
                                 dict(pinned=40), dict(root_uv=np.zeros((3, 2)))])
def test_bad_options_raise_and_write_nothing(tmp_path, wavy, bad):
    p = tmp_path / "bad.tfx"
    with pytest.raises(InputError):
        write_tfx(p, wavy, **bad)
    assert list(tmp_path.iterdir()) == []


def test_failed_pair_leaves_neither_file(tmp_path, wavy):
    with pytest.raises(InputError):
        write_tfx_pair(tmp_path / "hair.tfx", wavy, Strands.empty(), vertices_per_strand=16)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name,n_s,has_uv", [("Ratboy_mohawk.tfx", 2228, True), ("sintel_hair.tfx", 228, False)])
def test_real_files_read_and_write_back(shared_data, tmp_path, name, n_s, has_uv):
    src = shared_data / name
    raw = parse_tfx(src)
    s = read_strands(src)
    assert s.num_strands == raw["n_s"] == n_s and (s.counts == raw["n_v"]).all()
    np.testing.assert_array_equal(s.points.reshape(n_s, -1, 3), raw["pos"][..., :3])
    assert ("uv" in raw) == has_uv
    t = load_tfx(src)
    if has_uv:
        np.testing.assert_array_equal(t.strand_uv, raw["uv"])
    # Written back at the same vertex count and read again: the same strands, i.e. every
    # vertex we wrote lies on the original strand, and every original vertex lies within the
    # reported resampling error of the strand we wrote.
    out = tmp_path / name
    write_tfx(out, s, vertices_per_strand=raw["n_v"], root_uv=t.strand_uv, flip_v=False)
    again = read_tfx(out)
    n_v = raw["n_v"]
    scale = np.abs(s.points).max()
    np.testing.assert_array_equal(again.points[s.offsets], s.points[s.offsets])
    on_original = distance_to_polylines(again.points.reshape(n_s, n_v, 3), s.points.reshape(n_s, n_v, 3))
    assert on_original.max() <= 1e-6 * scale
    back_to_written = distance_to_polylines(s.points.reshape(n_s, n_v, 3), again.points.reshape(n_s, n_v, 3))
    assert back_to_written.max() <= resampling_error(s, n_v)["max"] + 1e-6 * scale
    if has_uv:
        np.testing.assert_array_equal(load_tfx(out).strand_uv, t.strand_uv)
    assert (load_tfx(out).positions[:, :2, 3] == 0).all()


def test_malformed_tfx(tmp_path, wavy):
    p = tmp_path / "w.tfx"
    write_tfx(p, wavy, vertices_per_strand=8)
    data = bytearray(p.read_bytes())
    struct.pack_into("<f", data, 0, 3.0)
    p.write_bytes(bytes(data))
    with pytest.raises(InputError, match="version"):
        read_tfx(p)
    p.write_bytes(p.read_bytes()[:100])
    with pytest.raises(InputError, match="truncated"):
        read_tfx(p)
