# SPDX-License-Identifier: GPL-3.0-or-later
"""The export command: every format, options reaching the writers, bad input exits 2 and
writes nothing."""
import json
import pathlib
import struct
import subprocess
import sys

import numpy as np
import pytest

from hairio.cli import export_main
from hairio.formats import read_strands, resample_strands

from hairio_scenes import make_wavy

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def npz(tmp_path):
    s = make_wavy(40, (6, 20), seed=5)
    p = tmp_path / "in.npz"
    s.save_npz(p)
    return p, s


@pytest.mark.parametrize("ext", ["hair", "tfx", "npz", "data"])
def test_each_numpy_format_by_extension(npz, tmp_path, ext, capsys):
    src, s = npz
    out = tmp_path / f"out.{ext}"
    assert export_main([str(src), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    back = read_strands(out)
    want = resample_strands(s, 32) if ext == "tfx" else s
    np.testing.assert_array_equal(back.points, want.points)


def test_tfx_options_and_separate_guides(npz, tmp_path):
    src, s = npz
    keys = make_wavy(6, (4, 4), seed=1)
    keys.save_npz(tmp_path / "keys.npz")
    out = tmp_path / "hair.tfx"
    assert export_main([str(src), "--format", "tfx", "--out", str(out), "--vertices-per-strand", "8",
                        "--pinned", "3", "--guides", str(tmp_path / "keys.npz"), "--pad-strands"]) == 0
    for path, n_s in ((out, 64), (tmp_path / "hair_guides.tfx", 64)):
        data = path.read_bytes()
        version, count, n_v, o_pos = struct.unpack_from("<fIII", data)
        assert (version, count, n_v, o_pos) == (4.0, n_s, 8, 160)
        w = np.frombuffer(data, "<f4", count * n_v * 4, o_pos).reshape(count, n_v, 4)[..., 3]
        assert (w[:, :3] == 0).all() and (w[:, 3:] == 1).all()


def test_scale_and_axis_reach_the_file(npz, tmp_path):
    src, s = npz
    out = tmp_path / "ue.hair"
    assert export_main([str(src), "--out", str(out), "--scale", "100", "--axis", "unreal"]) == 0
    back = read_strands(out)
    np.testing.assert_allclose(back.points, s.points * [100, -100, 100], rtol=1e-6)
    np.testing.assert_allclose(back.radius, s.radius * 100, rtol=1e-6)
    out = tmp_path / "ue.npz"
    assert export_main([str(src), "--out", str(out), "--scale", "100", "--axis", "y-up"]) == 0
    meta = json.loads((tmp_path / "ue.npz.json").read_text())
    assert meta["units"] == "cm" and meta["axes"] == {"up": "Y", "front": "+Z", "handedness": "right"}
    np.testing.assert_allclose(read_strands(out).points[:, 1], 100 * s.points[:, 2], rtol=1e-6)


def _nan_npz(tmp_path):
    p = tmp_path / "nan.npz"
    pts = np.zeros((4, 3), np.float32)
    pts[2, 1] = np.nan
    np.savez(p, points=pts, counts=np.array([2, 2], np.int32))
    return p


@pytest.mark.parametrize("case", ["vertices", "pinned", "nan", "missing-input", "missing-folder",
                                  "unknown-ext", "guides-not-tfx", "bad-axis", "bad-scale", "abc-axis",
                                  "root-uv-shape"])
def test_bad_input_exits_2_and_writes_nothing(npz, tmp_path, case, capsys):
    src, s = npz
    out = tmp_path / "out" / "x.tfx" if case == "missing-folder" else tmp_path / "x.tfx"
    args = {
        "vertices": [str(src), "--out", str(out), "--vertices-per-strand", "12"],
        "pinned": [str(src), "--out", str(out), "--pinned", "99"],
        "nan": [str(_nan_npz(tmp_path)), "--out", str(out)],
        "missing-input": [str(tmp_path / "none.npz"), "--out", str(out)],
        "missing-folder": [str(src), "--out", str(out)],
        "unknown-ext": [str(src), "--out", str(tmp_path / "x.fbx")],
        "guides-not-tfx": [str(src), "--out", str(tmp_path / "x.hair"), "--guides", str(src)],
        "bad-axis": [str(src), "--out", str(out), "--axis", "sideways"],
        "bad-scale": [str(src), "--out", str(out), "--scale", "-1"],
        "abc-axis": [str(src), "--out", str(tmp_path / "x.abc"), "--axis", "unreal"],
        "root-uv-shape": [str(src), "--out", str(out), "--root-uv", str(tmp_path / "uv.npy")],
    }[case]
    np.save(tmp_path / "uv.npy", np.zeros((3, 2)))
    before = sorted(p.name for p in tmp_path.iterdir())
    assert export_main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_abc_and_usd_through_blender_in_a_subprocess(npz, tmp_path):
    src, s = npz
    # the command runs bpy in a child process and never imports it itself
    code = ("import sys; from hairio.cli import export_main; "
            f"rc = export_main([{str(src)!r}, '--out', {str(tmp_path / 'h.abc')!r}, '--scale', '100']); "
            "print(rc, 'bpy' in sys.modules)")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.stdout.strip().splitlines()[-1] == "0 False", run.stderr
    assert (tmp_path / "h.abc").read_bytes()[:5] == b"Ogawa"
    assert export_main([str(src), "--out", str(tmp_path / "h.usda")]) == 0
    text = (tmp_path / "h.usda").read_text()
    assert 'type = "linear"' in text and "primvars:groom_color" in text
    assert not list(tmp_path.glob(".tmp-*"))


def test_module_entry_point(npz, tmp_path):
    src, s = npz
    run = subprocess.run([sys.executable, "-m", "hairio.cli", "export", str(src), "--out", str(tmp_path / "m.data")],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "bpy" not in run.stdout
    np.testing.assert_array_equal(read_strands(tmp_path / "m.data").points, s.points)
    run = subprocess.run([sys.executable, "-m", "hairio.cli", str(src), "--out", str(tmp_path / "m.tfx"),
                          "--vertices-per-strand", "5"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "vertices_per_strand" in run.stderr
    assert not (tmp_path / "m.tfx").exists()
