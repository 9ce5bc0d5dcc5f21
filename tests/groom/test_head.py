# SPDX-License-Identifier: GPL-3.0-or-later
"""Presets land on any head: the head frame, Preset.place_keys, the bundled head mesh."""
import numpy as np
import pytest

from groom import (HeadFrame, Scalp, default_head, default_scalp, fit_head_frame, list_presets, load_obj,
                   load_preset, place_key, save_preset)
from groom.__main__ import main
from groom.frames import root_frames
from hairio import InputError, Strands

PRESETS = list_presets()
# The real meshes are Y up in their own space and face +Z (see test_the_real_meshes_face_plus_z).
Y_UP = {"up": (0.0, 1.0, 0.0), "front": (0.0, 0.0, 1.0)}


@pytest.fixture(scope="session")
def real_meshes(shared_data):
    return {name: load_obj(shared_data / f"{name}.obj") for name in ("neuralhaircut_final_scalp", "usc_head_model")}


@pytest.fixture(scope="session")
def head():
    return default_head()


def _random_similarity(seed):
    """(rotation, scale, shift) of a random proper rotation, uniform scale, far shift."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, float(rng.uniform(0.5, 2.0)), rng.uniform(-50.0, 50.0, 3)


def _open_edges(scalp):
    t = scalp.triangles
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return unique[count == 1]


def _distance_to_segments(points, a, b):
    ab = b - a
    t = np.clip(np.einsum("qsd,sd->qs", points[:, None] - a, ab) / np.einsum("sd,sd->s", ab, ab), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)


# --- the head frame --------------------------------------------------------------------------


def test_the_bundled_scalp_is_the_canonical_head(scalp):
    frame = fit_head_frame(scalp)
    assert frame.method == "ellipsoid"
    np.testing.assert_allclose(frame.centre, 0.0, atol=1e-13)
    np.testing.assert_allclose(frame.half_axes, [0.08, 0.1, 0.1], rtol=1e-12)
    np.testing.assert_array_equal(frame.rotation, np.eye(3))
    p = np.random.default_rng(0).normal(size=(20, 3)) * 0.1
    np.testing.assert_allclose(frame.to_scalp(p), p, atol=1e-15)


def test_the_frame_of_a_moved_turned_scaled_scalp_moves_with_it(scalp):
    rot, s, shift = _random_similarity(1)
    other = Scalp(s * scalp.vertices @ rot.T + shift, scalp.triangles)
    frame = fit_head_frame(other, rot @ [0, 0, 1], rot @ [0, -1, 0])
    np.testing.assert_allclose(frame.centre, shift, atol=1e-12 * np.abs(shift).max())
    np.testing.assert_allclose(frame.half_axes, s * np.array([0.08, 0.1, 0.1]), rtol=1e-10)
    np.testing.assert_allclose(frame.rotation, rot, atol=1e-12)
    p = np.random.default_rng(2).normal(size=(5, 3)) * 0.1
    np.testing.assert_allclose(frame.to_scalp(p), s * p @ rot.T + shift, atol=1e-10)
    np.testing.assert_allclose(frame.to_canonical(frame.to_scalp(p)), p, atol=1e-10)


def test_right_is_up_cross_front_and_the_frame_is_not_a_mirror():
    frame = HeadFrame([1, 2, 3], [0.1, 0.12, 0.11], up=(0, 1, 0), front=(0, 0, 1))
    np.testing.assert_allclose(frame.right, [1, 0, 0])
    assert np.linalg.det(frame.rotation) == pytest.approx(1.0)


def test_front_is_made_perpendicular_to_up(scalp):
    frame = fit_head_frame(scalp, up=(0, 0, 2), front=(0, -1, 0.3))
    np.testing.assert_allclose(frame.up, [0, 0, 1])
    np.testing.assert_allclose(frame.front, [0, -1, 0], atol=1e-15)


def test_the_real_meshes_face_plus_z(real_meshes):
    # Why front = +Z for both files: the USC head's nose is its farthest point along +Z and
    # lies below the cranium's centre; the cap reaches lower behind (the nape, -Z) than in front.
    head = real_meshes["usc_head_model"]
    centre = fit_head_frame(head, **Y_UP).centre
    nose = head.vertices[np.argmax(head.vertices[:, 2])]
    assert nose[1] < centre[1] - 0.03
    assert nose[2] - centre[2] > (centre[2] - head.vertices[:, 2].min()) + 0.01
    cap = real_meshes["neuralhaircut_final_scalp"]
    behind = cap.vertices[cap.vertices[:, 2] < -0.05, 1].min()
    in_front = cap.vertices[cap.vertices[:, 2] > 0.05, 1].min()
    assert behind < in_front - 0.05


def test_a_cap_and_the_whole_head_it_lies_on_give_the_same_cranium(real_meshes):
    # The two files share the USC frame and the cap lies on the head (within 7 mm): the fit
    # must find the same cranium in both, not one stretched by the head's jaw and neck.
    cap = fit_head_frame(real_meshes["neuralhaircut_final_scalp"], **Y_UP)
    head = fit_head_frame(real_meshes["usc_head_model"], **Y_UP)
    assert cap.method == head.method == "ellipsoid"
    assert np.linalg.norm(cap.centre - head.centre) < 0.01
    np.testing.assert_allclose(cap.half_axes, head.half_axes, rtol=0.05)
    for frame, mesh in ((cap, real_meshes["neuralhaircut_final_scalp"]), (head, real_meshes["usc_head_model"])):
        top = mesh.vertices[:, 1].max()
        assert abs(frame.centre[1] + frame.half_axes[2] - top) < 0.01  # the frame's crown is the head's
        assert 0.9 < frame.scale < 1.3
        assert frame.half_axes[2] < 1.1 * frame.half_axes[1]


def test_a_small_cap_falls_back_to_a_sphere_through_it():
    # A 25° cap around the crown of a sphere of radius 0.09 with 0.3 mm of bumps: too little
    # curvature for three half-axes.
    sphere = default_head(8)
    v = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    keep = (v[sphere.triangles][..., 2] > np.cos(np.radians(25))).all(axis=1)
    bumps = 1.0 + 0.003 * np.random.default_rng(3).standard_normal(len(v))
    cap = Scalp(0.09 * v * bumps[:, None], sphere.triangles[keep])
    frame = fit_head_frame(cap)
    assert frame.method == "sphere"
    np.testing.assert_allclose(frame.half_axes, 0.09, rtol=0.05)
    np.testing.assert_allclose(frame.centre, 0.0, atol=0.005)


@pytest.mark.parametrize("kwargs, word", [
    ({"up": (0, 0, float("nan"))}, "up"),
    ({"front": (0, float("inf"), 0)}, "front"),
    ({"up": (0, 0, 0)}, "up"),
    ({"front": (0, 0, 0)}, "front"),
    ({"up": (0, 0, 1), "front": (0, 0, -3)}, "parallel"),
    ({"up": (0, 1)}, "up"),
    ({"front": "ahead"}, "front"),
])
def test_bad_up_or_front_is_rejected_naming_it(scalp, kwargs, word):
    with pytest.raises(InputError, match=word):
        fit_head_frame(scalp, **kwargs)


def test_a_flat_patch_gets_its_box_and_the_keys_that_pile_up_are_named():
    patch = Scalp([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]], [[0, 1, 2], [0, 2, 3]])
    assert fit_head_frame(patch).method == "box"
    placement = load_preset("wavy").place_keys(patch)
    assert placement.collapsed and placement.off_scalp
    roots = np.array([k.root for k in placement.keys])
    assert np.abs(roots[:, 2]).max() < 1e-12


def test_a_scalp_with_no_extent_is_rejected():
    with pytest.raises(InputError, match="coincide"):
        fit_head_frame(Scalp(np.ones((3, 3)), [[0, 1, 2]]))


# --- placing presets -------------------------------------------------------------------------


@pytest.mark.parametrize("name", PRESETS)
def test_keys_on_the_bundled_scalp_are_the_anchors_own_places(scalp, name):
    # The frame is the identity there: a point anchor goes to its nearest scalp point and a
    # direction anchor to the outermost scalp point seen from the head's centre (the origin).
    preset = load_preset(name)
    placement = preset.place_keys(scalp)
    assert placement.collapsed == [] and placement.off_scalp == () and placement.warning() is None
    for spec, key in zip(preset.key_specs, placement.keys):
        kind, value = next(iter(spec["anchor"].items()))
        if kind == "point":
            tri, bary, root = scalp.closest_points(np.array([value]))
        else:  # the bundled direction anchors point at scalp vertices, e.g. the crown
            d = np.asarray(value, float)
            hit = d / np.linalg.norm(d / [0.08, 0.1, 0.1])  # the ellipsoid's point along d
            tri, bary, root = scalp.closest_points(hit[None])
        np.testing.assert_allclose(key.root, root[0], atol=1e-12)
        frame = root_frames(scalp.normals_at(tri, bary), preset.params.up, preset.params.front)[0]
        prof = np.asarray(spec["profile"])
        want = place_key(prof, root[0], frame, spec["angles"]) if spec["frame"] == "root" else root[0] + prof - prof[0]
        np.testing.assert_allclose(key.points, want, atol=1e-12)
    assert placement.params == preset.params.replace(parting=placement.params.parting)
    if preset.params.parting:
        for k in ("point", "normal"):
            np.testing.assert_allclose(placement.params.parting[k], preset.params.parting[k], atol=1e-15)


def _closest_gap(roots):
    roots = np.array([getattr(r, "root", r) for r in roots])
    if len(roots) == 1:
        return np.inf
    return (np.linalg.norm(roots[:, None] - roots[None], axis=-1) + np.eye(len(roots)) * 1e9).min()


def _surface(name, real_meshes, head, scalp):
    """A mesh by name, with its up and front."""
    if name in real_meshes:
        return real_meshes[name], Y_UP
    return {"bundled scalp": scalp, "bundled head": head}[name], {}


@pytest.mark.parametrize("mesh", ["bundled scalp", "bundled head", "neuralhaircut_final_scalp", "usc_head_model"])
@pytest.mark.parametrize("name", PRESETS)
def test_every_key_of_every_preset_lands_on_its_own_root(real_meshes, head, scalp, mesh, name):
    surface, axes = _surface(mesh, real_meshes, head, scalp)
    placement = load_preset(name).place_keys(surface, **axes)
    assert placement.collapsed == [], placement.warning()
    assert placement.off_scalp == (), placement.warning()
    assert placement.warning() is None
    roots = np.array([k.root for k in placement.keys])
    _, _, on = surface.closest_points(roots)
    np.testing.assert_allclose(on, roots, atol=1e-12)
    # Bundled anchors are 1.2 cm and more apart (six times the collapse distance); on any
    # head the roots keep most of that.
    assert _closest_gap(roots) >= 0.6 * _closest_gap(load_preset(name).keys_on(scalp)) * placement.frame.scale


@pytest.mark.parametrize("name", PRESETS)
def test_hair_grows_from_the_real_scalp_with_the_placed_keys(real_meshes, name):
    from groom import generate
    cap = real_meshes["neuralhaircut_final_scalp"]
    placement = load_preset(name).place_keys(cap, **Y_UP)
    result = generate(cap, placement.keys, placement.params.replace(count=200))
    assert np.isfinite(result.strands.points).all()
    # Long presets stay long: the tips hang below the roots along the head's up, not sideways.
    tips = result.strands.points[np.r_[result.strands.offsets[1:] - 1, result.strands.num_points - 1]]
    assert (tips[:, 1] - result.roots[:, 1]).mean() < 0


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name", PRESETS)
def test_keys_on_a_moved_turned_scaled_scalp_are_the_moved_keys(scalp, seed, name):
    rot, s, shift = _random_similarity(seed)
    other = Scalp(s * scalp.vertices @ rot.T + shift, scalp.triangles)
    preset = load_preset(name)
    here = preset.place_keys(scalp)
    there = preset.place_keys(other, up=rot @ preset.params.up, front=rot @ preset.params.front)
    assert there.collapsed == [] and there.off_scalp == ()
    size = s * 0.1
    for a, b in zip(here.keys, there.keys):
        np.testing.assert_allclose(b.root, s * rot @ a.root + shift, rtol=0, atol=1e-9 * size)
        # Profiles turn with the head and keep their lengths in metres.
        np.testing.assert_allclose(b.points - b.root, (a.points - a.root) @ rot.T, rtol=0, atol=1e-9 * size)
    if preset.params.parting:  # the parting plane moves with the head: keys keep their side
        np.testing.assert_array_equal(_parting_side(here), _parting_side(there))


def _parting_side(placement):
    part = placement.params.parting
    return (np.array([k.root for k in placement.keys]) - part["point"]) @ part["normal"] > 0


def test_keys_on_accepts_the_same_up_and_front(real_meshes):
    preset = load_preset("wavy")
    cap = real_meshes["neuralhaircut_final_scalp"]
    for a, b in zip(preset.keys_on(cap, **Y_UP), preset.place_keys(cap, **Y_UP).keys):
        np.testing.assert_array_equal(a.points, b.points)


def test_placement_params_carry_the_scalps_up_and_front(real_meshes):
    placement = load_preset("parted").place_keys(real_meshes["usc_head_model"], **Y_UP)
    assert placement.params.up == Y_UP["up"] and placement.params.front == Y_UP["front"]
    # The parting plane x = 0.02 of the bundled head, on this head: still facing +X.
    np.testing.assert_allclose(placement.params.parting["normal"], [1, 0, 0], atol=1e-12)


def test_a_scalp_the_wrong_way_up_is_reported_not_silent(real_meshes):
    # The Y-up cap read with the bundled head's Z up: keys pile up on the cap's edge.
    placement = load_preset("wavy").place_keys(real_meshes["neuralhaircut_final_scalp"])
    assert placement.collapsed and placement.off_scalp
    text = placement.warning()
    for group in placement.collapsed:
        assert " and ".join([", ".join(map(str, group[:-1])), str(group[-1])]) in text
    assert "up and front" in text and "(0, 0, 1)" in text


def test_keys_beyond_a_small_caps_edge_are_reported_on_that_edge(real_meshes):
    # The top 5 cm of the real cap cannot host the hairline keys: they must be named.
    cap = real_meshes["neuralhaircut_final_scalp"]
    top = cap.vertices[:, 1].max()
    keep = (cap.vertices[cap.triangles][..., 1] > top - 0.05).all(axis=1)
    small = Scalp(cap.vertices, cap.triangles[keep])
    placement = load_preset("long_straight").place_keys(small, **Y_UP)
    assert len(placement.off_scalp) >= 5
    edges = small.vertices[_open_edges(small)]
    roots = np.array([k.root for k in placement.keys])
    on_edge = _distance_to_segments(roots, edges[:, 0], edges[:, 1]) < 1e-9
    assert on_edge[list(placement.off_scalp)].all()
    # The crown key and the keys around it are on the cap, away from the edge.
    assert not on_edge[0] and 0 not in placement.off_scalp
    text = placement.warning()
    assert "off the scalp" in text
    assert all(str(i) in text for i in placement.off_scalp)


def test_a_head_in_centimetres_is_called_out():
    big = default_scalp()
    placement = load_preset("wavy").place_keys(Scalp(big.vertices * 100, big.triangles))
    assert placement.collapsed == []
    assert "units" in placement.warning()


def test_saved_keys_come_back_where_they_were_on_a_real_head(real_meshes, tmp_path):
    head = real_meshes["usc_head_model"]
    placement = load_preset("parted").place_keys(head, **Y_UP)
    path = tmp_path / "mine.json"
    save_preset(path, placement.keys, placement.params, scalp=head)
    back = load_preset(str(path))
    assert back.params.up == (0.0, 0.0, 1.0) and back.params.front == (0.0, -1.0, 0.0)
    again = back.place_keys(head, **Y_UP)
    for a, b in zip(placement.keys, again.keys):
        np.testing.assert_allclose(b.points, a.points, atol=1e-9)
    np.testing.assert_allclose(again.params.parting["point"], placement.params.parting["point"], atol=1e-9)
    # And in the bundled head's space the keys sit on the bundled scalp's part of the head.
    on_bundled = back.place_keys(default_scalp())
    assert on_bundled.collapsed == []


# --- the bundled head mesh -------------------------------------------------------------------


def test_the_bundled_head_is_closed_and_consistently_oriented(head):
    t = head.triangles
    assert len(t) <= 5000 and not head.degenerate.any()
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    # Every edge in two triangles, once each way: closed, and neighbours agree on the winding.
    assert len(np.unique(directed, axis=0)) == len(directed)
    assert len(np.unique(np.sort(directed, axis=1), axis=0)) * 2 == len(directed)
    p = head.vertices[t]
    volume = np.einsum("td,td->t", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    assert volume > 0.9 * 4.0 / 3.0 * np.pi * 0.08 * 0.1 * 0.1


def _winding_number(mesh, q):
    """Solid angle of the mesh seen from q over 4π (van Oosterom & Strackee): 1 inside, 0 outside."""
    a, b, c = (mesh.vertices[mesh.triangles[:, i]] - q for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.einsum("td,td->t", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("td,td->t", a, b) * lc + np.einsum("td,td->t", b, c) * la \
        + np.einsum("td,td->t", c, a) * lb
    return 2.0 * np.arctan2(num, den).sum() / (4.0 * np.pi)


def test_the_bundled_head_encloses_its_middle_and_nothing_outside(head):
    assert _winding_number(head, np.zeros(3)) == pytest.approx(1.0, abs=1e-9)
    assert _winding_number(head, np.array([0.0, -0.03, -0.105])) == pytest.approx(1.0, abs=1e-9)  # the chin
    for q in ([0.2, 0, 0], [0, 0, 0.11], [0, 0.05, -0.105], [0, 0.105, 0]):
        assert _winding_number(head, np.array(q, float)) == pytest.approx(0.0, abs=1e-9)


def test_the_bundled_scalp_lies_on_the_bundled_head(head, scalp):
    tri, _, on = head.closest_points(scalp.vertices)
    outside = np.einsum("nd,nd->n", scalp.vertices - on, head.face_normals[tri])
    distance = np.linalg.norm(scalp.vertices - on, axis=1)
    assert distance.max() < 1e-3
    assert outside.min() > -1e-3
    assert (outside > -1e-12).mean() > 0.99  # the head's flat triangles cut under the curved scalp


def test_the_bundled_head_has_a_jaw_not_a_bare_ellipsoid(head):
    v = head.vertices
    chin = v[np.argmin(v[:, 2])]
    assert chin[2] < -0.11 and chin[1] < 0  # lower than the ellipsoid, and on the face side
    face = v[:, 1] < -0.03
    jaw, brow = face & (np.abs(v[:, 2] + 0.05) < 0.01), face & (np.abs(v[:, 2] - 0.05) < 0.01)
    assert np.abs(v[jaw, 0]).max() < 0.95 * np.abs(v[brow, 0]).max()  # the bare ellipsoid: equal


# --- the command line ------------------------------------------------------------------------


def test_generate_with_up_and_front_lands_every_key_on_a_real_scalp(shared_data, tmp_path, capsys):
    out = tmp_path / "hair.npz"
    mesh = shared_data / "neuralhaircut_final_scalp.obj"
    assert main(["generate", "--preset", "wavy", "--scalp", str(mesh), "--up", "0,1,0", "--front", "0,0,1",
                 "--count", "100", "--out", str(out)]) == 0
    assert capsys.readouterr().err == ""
    assert Strands.load_npz(out).num_strands == 100


def test_generate_says_when_keys_collapse(shared_data, tmp_path, capsys):
    out = tmp_path / "hair.npz"
    mesh = shared_data / "neuralhaircut_final_scalp.obj"
    assert main(["generate", "--preset", "wavy", "--scalp", str(mesh), "--count", "100", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith("warning: preset 'wavy'") and "share a root" in err and "up and front" in err


def test_a_value_starting_with_a_minus_is_read_as_the_options_value(tmp_path, capsys):
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "curly", "--up", "0,0,1", "--front", "-0,-1,0", "--count", "50",
                 "--out", str(out)]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("args, word", [
    (["--up", "0,1"], "--up"),
    (["--up", "0,1,x"], "--up"),
    (["--front", "nan,0,1"], "--front"),
    (["--up", "0,0,0"], "--up"),
    (["--up", "0,1,0", "--front", "0,-2,0"], "--front: must not be parallel to --up"),
    (["--up", "0,-1,0"], "parallel"),
])
def test_bad_up_or_front_exits_2_naming_the_option(tmp_path, capsys, args, word):
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "wavy", *args, "--out", str(out)]) == 2
    assert word in capsys.readouterr().err
    assert not out.exists()
