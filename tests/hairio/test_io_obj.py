# SPDX-License-Identifier: GPL-3.0-or-later
"""hairio.obj, the project's one OBJ parser: the tracer's meshes and groom's scalps."""
import numpy as np
import pytest

from hairio import InputError
from hairio.obj import parse_obj, read_obj


@pytest.mark.parametrize("face,match", [("f 0 2 3", "vertex index 0: OBJ indices count from 1"),
                                        ("f 1 2 99999999999999999999", "vertex index 99999999999999999999 lies "
                                                                       "outside the file"),
                                        ("f 1 2 -99999999999999999999", "lies outside the file"),
                                        ("f 1 2 -4", "vertex index -4 lies outside the file"),
                                        ("f 1 2 5", "a face refers to a vertex that does not exist"),
                                        ("f 1/0 2/1 3/1", "texture coordinate index 0"),
                                        ("f 1 2 x", "line 5: cannot parse 'f 1 2 x'")])
def test_indices_that_name_no_vertex_are_refused_naming_the_mesh(tmp_path, face, match):
    # A face before the last vertex: index 0 would otherwise wrap to the vertex read later.
    path = tmp_path / "bad.obj"
    path.write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\n{face}\nv 0 0 1\n")
    with pytest.raises(InputError, match=match) as e:
        read_obj(path, "head mesh")
    assert str(e.value).startswith(f"head mesh {str(path)!r}")


def test_faces_uvs_and_every_corner_form(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0.1 0.2\nvt 0.3\nvt 0.5 0.6\nvt 0.7 0.8\nvn 0 0 1\n"
                    "g quad\nusemtl skin\nf 1/1/1 2/2/1 3/3/1 4/4/1\nf -4/-4 -2/2 -1/-1\n")
    mesh = parse_obj(path)
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 2], [0, 2, 3], [0, 2, 3]])
    np.testing.assert_array_equal(mesh.triangle_uvs, [[0, 1, 2], [0, 2, 3], [0, 1, 3]])
    np.testing.assert_array_equal(mesh.uvs, [[0.1, 0.2], [0.3, 0.0], [0.5, 0.6], [0.7, 0.8]])
    verts, tris = read_obj(path)
    np.testing.assert_array_equal(verts, mesh.vertices)
    np.testing.assert_array_equal(tris, mesh.triangles)
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/1 3\n")
    assert parse_obj(path).triangle_uvs is None     # a corner without one: no UVs


@pytest.mark.parametrize("name", ["neuralhaircut_final_scalp.obj", "sintel.obj"])
def test_groom_reads_scalps_through_the_same_parser(shared_data, name):
    from groom import load_obj
    scalp = load_obj(shared_data / name)
    verts, tris = read_obj(shared_data / name)
    np.testing.assert_array_equal(scalp.vertices, verts)
    np.testing.assert_array_equal(scalp.triangles, tris)
