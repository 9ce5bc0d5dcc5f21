# SPDX-License-Identifier: GPL-3.0-or-later
"""groom generate --collider: the bundled head by default for the bundled scalp, none for a
mesh of your own, a file, or none; bad colliders refused by name; progress on stderr."""
import numpy as np
import pytest

import groom.__main__ as cli
from groom import default_collider, default_head
from groom.__main__ import main
from hairio import Strands
from hairio.obj import write_obj


def _depths(points):
    head = default_collider()
    near = head.value(points) < 0.99 * head.band
    return head.signed_distance(points[near])


def test_the_bundled_scalp_collides_with_the_bundled_head_by_default(tmp_path, capsys):
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "wavy", "--count", "1500", "--out", str(out)]) == 0
    assert "moved out of the bundled head" in capsys.readouterr().out
    s = Strands.load_npz(out)
    inner = np.delete(s.points, s.offsets, axis=0).astype(np.float64)
    assert _depths(inner).min() > 0


def test_collider_none_leaves_the_hair_where_the_keys_put_it(tmp_path, capsys):
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "wavy", "--count", "1500", "--collider", "none", "--out", str(out)]) == 0
    assert "moved out" not in capsys.readouterr().out
    s = Strands.load_npz(out)
    assert _depths(np.delete(s.points, s.offsets, axis=0).astype(np.float64)).min() < -1e-3


def test_a_collider_file_is_used_and_named(tmp_path, capsys):
    head = default_head()
    mesh = tmp_path / "my_head.obj"
    write_obj(mesh, head.vertices, head.triangles)
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "curly", "--count", "800", "--collider", str(mesh), "--out", str(out)]) == 0
    assert "moved out of my_head.obj" in capsys.readouterr().out


def test_a_scalp_of_your_own_has_no_collider_unless_given(tmp_path, capsys):
    mesh = tmp_path / "cap.obj"
    mesh.write_text("v -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0.1 0.1 0\nv -0.1 0.1 0\nv 0 0 0.1\n"
                    "f 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n")
    assert main(["generate", "--preset", "wavy", "--scalp", str(mesh), "--count", "100",
                 "--out", str(tmp_path / "h.npz")]) == 0
    assert "moved out" not in capsys.readouterr().out


@pytest.mark.parametrize("content, words", [
    (None, "--collider: scalp mesh"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    ("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "NaN/Inf"),
])
def test_a_bad_collider_file_exits_2_naming_it(tmp_path, capsys, content, words):
    mesh = tmp_path / "bad_head.obj"
    if content is not None:
        mesh.write_text(content)
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "wavy", "--count", "100", "--collider", str(mesh), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad_head.obj" in err and words in err
    assert not out.exists()


def test_a_collider_far_from_the_scalp_is_refused(tmp_path, capsys):
    head = default_head()
    mesh = tmp_path / "elsewhere.obj"
    write_obj(mesh, head.vertices + [0.0, 0.0, 0.6], head.triangles)
    assert main(["generate", "--preset", "wavy", "--count", "100", "--collider", str(mesh),
                 "--out", str(tmp_path / "h.npz")]) == 2
    assert "collider 'elsewhere.obj'" in capsys.readouterr().err


def test_work_over_the_threshold_shows_its_progress(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli, "PROGRESS_AFTER", 0.0)
    assert main(["generate", "--preset", "wavy", "--count", "500", "--out", str(tmp_path / "h.npz")]) == 0
    err = capsys.readouterr().err
    for stage in ("growing strands", "moving hair out of the collider", "100% done"):
        assert stage in err
