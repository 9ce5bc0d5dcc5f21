# SPDX-License-Identifier: GPL-3.0-or-later
"""The export command: every format, options reaching the writers, bad input exits 2 and
writes nothing."""
import json
import os
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


def test_an_installed_wheel_writes_grooms_with_guides(tmp_path):
    """`pip install` of the project's wheel into a fresh environment (no network: the wheel
    is built here, the libraries come from this one's site-packages) writes .abc and .usd
    with guides: hairio needs nothing outside itself (no checkout, no addon/)."""
    import importlib.util
    import venv
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    builder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(builder)
    wheel = builder.build_project_wheel(tmp_path)
    env_dir = tmp_path / "env"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    # numpy, alembic3d and usd-core from this environment, after the new one's own packages.
    new_site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                              capture_output=True, text=True, check=True).stdout.strip()
    import site
    pathlib.Path(new_site, "outer.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet",
                              "--no-deps", "--no-index", str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr
    s = make_wavy(30, (6, 12), seed=2)
    keys = make_wavy(3, (8, 8), seed=3)
    from hairio import Guides
    index = np.stack([s.wisp % 3, (s.wisp + 1) % 3, (s.wisp + 2) % 3], axis=1)
    weights = np.tile(np.float32([0.6, 0.3, 0.1]), (s.num_strands, 1))
    s.with_guides(Guides.from_arrays(keys, index, weights, num_strands=s.num_strands)).save_npz(tmp_path / "g.npz")
    code = ("import sys, hairio; from hairio.cli import export_main; print(hairio.__file__); "
            "print(export_main(['g.npz', '--out', 'g.abc', '--scale', '100']), export_main(['g.npz', '--out', 'g.usda']))")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run([str(python), "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.strip().splitlines()
    where, status = lines[0], lines[-1]
    assert pathlib.Path(where).is_relative_to(env_dir), where
    assert status == "0 0", run.stderr
    assert (tmp_path / "g.abc").read_bytes()[:5] == b"Ogawa"
    for name in ("g.abc", "g.usda"):
        back = read_strands(tmp_path / name)
        np.testing.assert_array_equal(back.guides.index, index, err_msg=name)
        assert back.guides.keys.num_strands == 3
    assert not list(tmp_path.glob(".tmp-*"))


def test_a_missing_groom_library_says_what_to_install_and_writes_nothing(npz, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "alembic3d", None)       # import alembic3d now fails
    src, s = npz
    assert export_main([str(src), "--out", str(tmp_path / "h.abc")]) == 2
    assert "pip install alembic3d" in capsys.readouterr().err
    assert list(tmp_path.glob("h.*")) == []


@pytest.mark.parametrize("args, message", [
    (["--pinned", "3"], "--pinned: .hair files take no such option"),
    (["--root-uv", "uv.npy"], "--root-uv: .hair files take no such option"),
    (["--follow-hairs", "4"], "--follow-hairs: .hair files take no such option"),
])
def test_an_option_the_format_does_not_take_is_refused(npz, tmp_path, args, message, capsys):
    src, s = npz
    assert export_main([str(src), "--out", str(tmp_path / "x.hair"), *args]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.hair").exists()


def test_help_lists_every_format_of_the_registry(capsys):
    from hairio.formats import FORMATS
    with pytest.raises(SystemExit):
        export_main(["--help"])
    out = capsys.readouterr().out
    for f in FORMATS:
        assert f"{f.name:5} {', '.join(f.extensions)}:\n" in out, f.name


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
