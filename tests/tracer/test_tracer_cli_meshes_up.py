# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m tracer render with --mesh/--mesh-color and --up; groom export --up."""
import numpy as np
import pytest

from hairio import Strands
from hairio.cli import export_main
from hairio.formats import read_strands
from hairio.formats.up_axis import file_frame, strands_to_z_up
from tracer.__main__ import main

from test_tracer_io import _decode_png
from tracer_scenes import make_strands, uv_sphere


def _write_obj(path, verts, tris, nan_vertex=None):
    lines = [f"v {x} {y} {z}" for x, y, z in verts]
    if nan_vertex is not None:
        lines[nan_vertex] = "v nan 0 0"
    lines += ["f " + " ".join(str(i + 1) for i in t) for t in tris]
    path.write_text("\n".join(lines) + "\n")


def test_render_with_a_mesh_shows_the_mesh_in_its_colour(tmp_path, capsys):
    hair = make_strands([[[-0.5, 0.3, -0.4], [-0.5, 0.3, 0.4]], [[0.5, 0.3, -0.4], [0.5, 0.3, 0.4]]], radius=0.03)
    hair.save_npz(str(tmp_path / "h.npz"))
    _write_obj(tmp_path / "ball.obj", *uv_sphere((0, 0, 0), 0.3))
    out = tmp_path / "o.png"
    assert main(["render", str(tmp_path / "h.npz"), "--out", str(out), "--size", "48x48", "--no-shadows",
                 "--mesh", str(tmp_path / "ball.obj"), "--mesh-color", "0,0.8,0"]) == 0
    assert f"{len(uv_sphere((0, 0, 0), 0.3)[1])} mesh triangles" in capsys.readouterr().out
    img = _decode_png(out.read_bytes())
    centre = img[24, 24]
    assert centre[3] == 255 and centre[0] == centre[2] == 0 and centre[1] > 100     # the green ball
    # Beside it the hair, which has red in it.
    assert ((img[..., 3] == 255) & (img[..., 0] > 50)).sum() > 20


@pytest.mark.parametrize("args,message", [
    (["--mesh-color", "1,0,0"], "--mesh-color: 1 colours for 0 meshes"),
    (["--mesh", "MISSING.obj"], "cannot read it"),
    (["--mesh", "BAD.obj"], "BAD.obj: vertex 1 has NaN"),
    (["--mesh", "BALL.obj", "--mesh-color", "1,x,0"], "--mesh-color '1,x,0'"),
])
def test_bad_meshes_on_the_command_line_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    make_strands([[[0, 0, 0], [0, 0, 1]]]).save_npz(str(tmp_path / "h.npz"))
    verts, tris = uv_sphere((0, 0, 0), 0.3)
    _write_obj(tmp_path / "BAD.obj", verts, tris, nan_vertex=1)
    _write_obj(tmp_path / "BALL.obj", verts, tris)
    args = [str(tmp_path / a) if a.endswith(".obj") else a for a in args]
    out = tmp_path / "o.png"
    assert main(["render", str(tmp_path / "h.npz"), "--out", str(out)] + args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_up_auto_recognises_y_up_formats():
    assert file_frame("a.tfx", "auto") == file_frame("a.data", "auto") == "y-up"
    assert file_frame("a.npz", "auto") == file_frame("a.hair", "auto") == "none"
    assert file_frame("a.tfx", "z") == "none" and file_frame("a.npz", "y") == "y-up"


def test_the_mohawk_stands_up_and_faces_the_camera(shared_data):
    path = str(shared_data / "Ratboy_mohawk.tfx")
    raw = read_strands(path)
    turned = strands_to_z_up(raw, path, "auto")
    lo, hi = turned.bounds()
    extent = hi - lo
    # A mohawk: tallest up (Z), long front to back (Y), narrow across (X), so the default
    # camera (from -Y) sees a tall narrow crest. Read as it is, its height lies along Y.
    assert extent[2] > extent[1] > extent[0]
    rlo, rhi = raw.bounds()
    assert np.argmax(rhi - rlo) == 1
    np.testing.assert_array_equal(turned.points[:, 2], raw.points[:, 1])
    # Its strands sweep back from the brow: tips lie behind (+Y) their roots.
    roots, tips = turned.points[turned.offsets], turned.points[turned.offsets + turned.counts - 1]
    assert np.mean(tips[:, 1] > roots[:, 1]) > 0.6


def test_render_up_z_and_auto_differ_only_by_the_turn(tmp_path, shared_data):
    path = str(shared_data / "Ratboy_mohawk.tfx")
    auto, asis = tmp_path / "auto.png", tmp_path / "z.png"
    assert main(["render", path, "--out", str(auto), "--size", "32x32"]) == 0
    assert main(["render", path, "--out", str(asis), "--size", "32x32", "--up", "z"]) == 0
    a, z = _decode_png(auto.read_bytes()), _decode_png(asis.read_bytes())
    rows_a, cols_a = np.nonzero(a[..., 3])
    rows_z, cols_z = np.nonzero(z[..., 3])
    # From the front the crest is taller than wide; read Z-up it is seen from below, wider.
    assert np.ptp(rows_a) > 2 * np.ptp(cols_a)
    assert np.ptp(cols_z) > np.ptp(cols_a)


def test_groom_export_up_turns_the_input(tmp_path, shared_data):
    path = str(shared_data / "Ratboy_mohawk.tfx")
    out = tmp_path / "m.npz"
    assert export_main([path, "--out", str(out), "--up", "auto"]) == 0
    got = Strands.load_npz(str(out))
    np.testing.assert_array_equal(got.points, strands_to_z_up(read_strands(path), path, "auto").points)
    assert export_main([path, "--out", str(tmp_path / "k.npz")]) == 0       # default z: as it is
    np.testing.assert_array_equal(Strands.load_npz(str(tmp_path / "k.npz")).points, read_strands(path).points)
