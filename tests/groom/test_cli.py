# SPDX-License-Identifier: GPL-3.0-or-later
import os
import subprocess
import sys

import numpy as np
import pytest

from groom.__main__ import main
from hairio import Strands

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_generate_writes_the_strand_arrays_and_reports_them(tmp_path, capsys):
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "short_intelligent", "--count", "200", "--seed", "3",
                 "--out", str(out)]) == 0
    s = Strands.load_npz(out)
    assert s.num_strands == 200
    text = capsys.readouterr().out
    assert "200 strands" in text and f"{s.num_points} points" in text and "cylinders" in text


def test_generate_places_keys_on_a_given_mesh(tmp_path):
    mesh = tmp_path / "head.obj"
    # A small pyramid cap standing on z = 0.
    mesh.write_text("v -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0.1 0.1 0\nv -0.1 0.1 0\nv 0 0 0.1\n"
                    "f 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n")
    out = tmp_path / "hair.npz"
    assert main(["generate", "--preset", "wavy", "--scalp", str(mesh), "--count", "100", "--out", str(out)]) == 0
    s = Strands.load_npz(out)
    roots = s.points[s.offsets]
    assert roots[:, 2].min() >= -1e-6 and roots[:, 2].max() <= 0.1 + 1e-6


@pytest.mark.parametrize("args, word", [
    (["--preset", "nonesuch"], "nonesuch"),
    (["--preset", "wavy", "--count", "0"], "--count"),
    (["--preset", "wavy", "--scalp", "MISSING.obj"], "MISSING.obj"),
    (["--preset", "wavy", "--scalp", "{notris}"], "no faces"),
    (["--preset", "wavy", "--scalp", "{nan}"], "NaN"),
])
def test_bad_input_exits_2_naming_it_and_writes_nothing(tmp_path, capsys, args, word):
    (tmp_path / "notris.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n")
    args = [a.format(notris=tmp_path / "notris.obj", nan=tmp_path / "nan.obj") for a in args]
    out = tmp_path / "hair.npz"
    assert main(["generate", *args, "--out", str(out)]) == 2
    assert word in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["nan.obj", "notris.obj"]  # no output, no temporary file


def test_python_dash_m_groom_runs_and_fails_cleanly(tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT)
    ok = subprocess.run([sys.executable, "-m", "groom", "generate", "--preset", "curly", "--count", "50",
                         "--out", str(tmp_path / "c.npz")], capture_output=True, text=True, env=env)
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "c.npz").exists()
    bad = subprocess.run([sys.executable, "-m", "groom", "generate", "--preset", "curly", "--count", "-5",
                          "--out", str(tmp_path / "d.npz")], capture_output=True, text=True, env=env)
    assert bad.returncode == 2 and "--count" in bad.stderr
    assert not (tmp_path / "d.npz").exists()


def test_export_subcommand_delegates_to_the_exporter(tmp_path):
    npz = tmp_path / "h.npz"
    assert main(["generate", "--preset", "short_intelligent", "--count", "20", "--out", str(npz)]) == 0
    out = tmp_path / "h.hair"
    assert main(["export", str(npz), "--out", str(out)]) == 0
    assert out.stat().st_size > 0


def test_head_writes_the_bundled_head_as_obj_that_reads_back_as_the_same_closed_mesh(tmp_path):
    from groom import default_head
    from hairio.obj import read_obj
    out = tmp_path / "head.obj"
    assert main(["head", "--out", str(out)]) == 0
    vertices, triangles = read_obj(out)
    head = default_head()
    np.testing.assert_array_equal(triangles, head.triangles)
    np.testing.assert_array_equal(vertices, head.vertices)
    # Closed: every edge is shared by exactly two triangles, so the tracer's head hides what is behind it.
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert (uses == 2).all()


def test_head_to_a_folder_exits_2_and_writes_nothing(tmp_path, capsys):
    assert main(["head", "--out", str(tmp_path)]) == 2
    assert "--out" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
