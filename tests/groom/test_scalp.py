# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom import Scalp, load_obj
from hairio import InputError


def test_default_scalp_is_a_head_cap_of_about_a_thousand_triangles(scalp):
    assert 800 <= scalp.num_triangles <= 1200
    v = scalp.vertices
    # A cap over a ~0.1 m head: crown on top (Z up), hairline lower at the back (+Y) than the front (-Y).
    assert v[:, 2].max() == pytest.approx(0.1, rel=0.05)
    front = v[v[:, 1] < -0.05]
    back = v[v[:, 1] > 0.05]
    assert front[:, 2].min() > back[:, 2].min()
    assert scalp.uv is not None and scalp.uv.shape == (len(v), 2)
    assert (scalp.uv >= 0).all() and (scalp.uv <= 1).all()


def test_default_scalp_faces_outward_and_is_a_manifold_disc(scalp):
    centres = scalp.vertices[scalp.triangles].mean(axis=1)
    assert (np.einsum("td,td->t", scalp.face_normals, centres) > 0).all()
    e = np.sort(np.concatenate([scalp.triangles[:, [0, 1]], scalp.triangles[:, [1, 2]],
                                scalp.triangles[:, [2, 0]]]), axis=1)
    _, uses = np.unique(e, axis=0, return_counts=True)
    assert uses.max() == 2


@pytest.mark.parametrize("bad, word", [
    (dict(vertices=[[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], triangles=[[0, 1, 2]]), "scalp vertices"),
    (dict(vertices=[[0, 0, 0], [1, 0, 0], [0, np.inf, 0]], triangles=[[0, 1, 2]]), "NaN/Inf"),
    (dict(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], triangles=[[0, 1, 3]]), "scalp triangles"),
    (dict(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], triangles=np.zeros((0, 3), int)), "at least one triangle"),
    (dict(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], triangles=[[0, 1, 2]], density=[1, -1, 1]), "density"),
])
def test_scalp_rejects_bad_arrays_naming_them(bad, word):
    with pytest.raises(InputError, match=word):
        Scalp(**bad)


def test_vertex_normals_are_area_weighted_averages():
    # Two faces meeting at vertex 0: a big one in the XY plane, a small one in the XZ plane.
    v = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, -0.2], [0.2, 0, 0]], float)
    s = Scalp(v, [[0, 1, 2], [0, 3, 4]])
    n_big, n_small = s.face_normals
    expect = 2.0 * n_big + 0.02 * n_small
    expect /= np.linalg.norm(expect)
    np.testing.assert_allclose(s.vertex_normals[0], expect, atol=1e-12)


def test_interpolated_normals_are_continuous_across_an_edge_and_face_normals_are_not(scalp):
    # Points just either side of the edge shared by two triangles.
    t = scalp.triangles
    a, b = 100, None
    edge = {frozenset(e) for e in [(t[a, 0], t[a, 1]), (t[a, 1], t[a, 2]), (t[a, 2], t[a, 0])]}
    for j in range(len(t)):
        if j != a and any(frozenset(e) in edge for e in [(t[j, 0], t[j, 1]), (t[j, 1], t[j, 2]), (t[j, 2], t[j, 0])]):
            b = j
            break
    shared = [x for x in t[a] if x in t[b]]
    mid = scalp.vertices[shared].mean(axis=0)

    def bary_near(tri, eps=1e-9):
        w = np.array([0.5 if x in shared else 0.0 for x in t[tri]])
        w[w == 0] = eps
        return w / w.sum()
    ba, bb = bary_near(a), bary_near(b)
    assert np.allclose(scalp.points_at([a], ba[None]), mid, atol=1e-9)
    na = scalp.normals_at(np.array([a]), ba[None])
    nb = scalp.normals_at(np.array([b]), bb[None])
    assert np.linalg.norm(na - nb) < 1e-6
    fa = scalp.normals_at(np.array([a]), ba[None], mode="face")
    fb = scalp.normals_at(np.array([b]), bb[None], mode="face")
    assert np.linalg.norm(fa - fb) > 1e-3


def test_zero_area_and_sliver_triangles_give_finite_unit_normals():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 1e-12, 0], [3, 0, 0]], float)
    # a good face, a zero-area face (collinear), a sliver, a face using one point three times
    s = Scalp(v, [[0, 1, 2], [1, 3, 5], [0, 3, 4], [2, 2, 2]])
    for n in (s.face_normals, s.vertex_normals,
              s.normals_at(np.arange(4), np.full((4, 3), 1 / 3))):
        assert np.isfinite(n).all()
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


def test_load_obj_fan_triangulates_polygons_and_reads_all_index_forms(tmp_path):
    p = tmp_path / "quad.obj"
    p.write_text("# a quad and a triangle\n"
                 "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n"
                 "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0\n"
                 "vn 0 0 1\n"
                 "f 1/1/1 2/2/1 3/3/1 4/4/1\n"
                 "f -4//1 5//1 -3//1\n")
    s = load_obj(p)
    assert s.num_triangles == 3
    np.testing.assert_array_equal(s.triangles[:2], [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(s.triangles[2], [1, 4, 2])
    assert s.total_area == pytest.approx(1.5)


def test_load_obj_keeps_uvs_when_every_corner_has_one(tmp_path):
    p = tmp_path / "uv.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.1 0.2\nvt 0.3 0.4\nvt 0.5 0.6\nf 1/1 2/2 3/3\n")
    np.testing.assert_allclose(load_obj(p).uv, [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])


@pytest.mark.parametrize("text, word", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    ("", "no vertices"),
    ("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "NaN"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "does not exist"),
    ("v 0 0 zero\n", "cannot parse"),
])
def test_load_obj_rejects_bad_meshes_naming_the_file(tmp_path, text, word):
    p = tmp_path / "bad.obj"
    p.write_text(text)
    with pytest.raises(InputError, match=word) as e:
        load_obj(p)
    assert "bad.obj" in str(e.value)


def test_load_obj_reports_an_unreadable_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_obj(tmp_path / "missing.obj")


def test_closest_points_lie_on_the_surface(scalp):
    q = np.array([[0.0, 0.0, 0.2], [0.05, 0.05, 0.09], [0.3, 0.0, 0.0]])
    tri, bary, pts = scalp.closest_points(q)
    assert (bary >= -1e-12).all() and np.allclose(bary.sum(axis=1), 1)
    np.testing.assert_allclose(pts[0], [0, 0, 0.1], atol=1e-9)
    # No vertex is nearer than the closest surface point.
    d_vert = np.linalg.norm(scalp.vertices[None] - q[:, None], axis=2).min(axis=1)
    assert (np.linalg.norm(pts - q, axis=1) <= d_vert + 1e-12).all()


@pytest.mark.parametrize("mesh", ["head", "slivers"])
def test_closest_points_match_a_search_of_every_triangle(scalp, mesh):
    from groom.scalp import Scalp, _closest_on_triangles
    if mesh == "slivers":  # zero-area and needle triangles, an unused vertex
        v = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.2, 0, 0], [0.1, 1e-12, 0], [0.3, 0, 0], [5, 5, 5]], float)
        s = Scalp(v, [[0, 1, 2], [1, 3, 5], [0, 3, 4], [2, 2, 2]])
    else:
        s = scalp
    rng = np.random.default_rng(4)
    q = np.concatenate([rng.normal(scale=0.15, size=(200, 3)), s.vertices[:20], [[0, 0, 0], [1e-3, 0, 0.3]]])
    tri, bary, pts = s.closest_points(q)
    a, b, c = (s.vertices[s.triangles[:, i]] for i in range(3))
    for j, p in enumerate(q):  # the plain search: every triangle, first minimum
        on = _closest_on_triangles(np.broadcast_to(p, a.shape), a, b, c)
        near = on[:, :1] * a + on[:, 1:2] * b + on[:, 2:] * c
        best = int(np.argmin(((near - p) ** 2).sum(axis=1)))
        assert np.linalg.norm(pts[j] - near[best]) <= 1e-12
        assert tri[j] == best or np.isclose(((near[tri[j]] - p) ** 2).sum(), ((near[best] - p) ** 2).sum(), rtol=1e-12)


def test_a_triangle_with_two_identical_corners_has_finite_nearest_points():
    """The nearest point on the segment it reduces to, not NaN (0/0 on its zero-length edge)."""
    s = Scalp(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]), np.array([[0, 1, 2], [1, 1, 3]]))
    tri, bary, pts = s.closest_points(np.array([[1.0, 0.5, 0.3], [1.2, 0.9, 0.0], [1.0, 1.2, 0.0]]))
    assert np.isfinite(bary).all()
    np.testing.assert_allclose(pts, [[1, 0.5, 0], [1, 0.9, 0], [1, 1, 0]], atol=1e-12)


def test_a_scalp_whose_every_triangle_is_degenerate_is_refused():
    with pytest.raises(InputError, match="every one of its 2 triangle"):
        Scalp(np.array([[0.0, 0, 0], [1, 0, 0], [2, 1e-16, 0], [3, 0, 0]]), np.array([[0, 1, 2], [1, 2, 3]]))


@pytest.mark.parametrize("face,match", [("f 0 2 3", "vertex index 0: OBJ indices count from 1"),
                                        ("f 1 2 99999999999999999999", "lies outside the file"),
                                        ("f 1 2 -99999999999999999999", "lies outside the file"),
                                        ("f 1/0 2/1 3/1", "texture coordinate index 0")])
def test_obj_indices_that_name_no_vertex_are_refused(tmp_path, face, match):
    # A face before the last vertex: index 0 would otherwise wrap to the vertex read later.
    path = tmp_path / "bad.obj"
    path.write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\n{face}\nv 0 0 1\n")
    with pytest.raises(InputError, match=match) as e:
        load_obj(path)
    assert str(path) in str(e.value)
