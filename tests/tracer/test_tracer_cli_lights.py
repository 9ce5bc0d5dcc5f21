# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m tracer render --light TYPE:... and --ambient: Blender's lights on the command line,
as Cycles lights with them (the same Light the add-on makes of a Blender light); bad ones exit 2
naming the option and write nothing."""
import math

import numpy as np
import pytest

from tracer import Camera, Light, RenderSettings, Renderer
from tracer.__main__ import main, parse_light

from test_tracer_cli_meshes_up import _write_obj
from test_tracer_io import _decode_png
from tracer_scenes import make_strands, plane


@pytest.mark.parametrize("text,want", [
    ("sun:0.3,0.2,-1:3:0.5", Light("directional", (0.3, 0.2, -1.0), intensity=3.0, angle=math.radians(0.5))),
    ("sun:0,0,-1", Light("directional", (0.0, 0.0, -1.0))),
    ("point:0,-1,1:100:0.1", Light("point", (0.0, -1.0, 1.0), intensity=100 / (4 * math.pi), falloff=True,
                                   radius=0.1)),
    ("spot:0,-1,1:0,0,0:50:40:0.2", Light("spot", (0.0, -1.0, 1.0), intensity=50 / (4 * math.pi), axis=(0, 1, -1),
                                          spot_size=math.radians(40), spot_blend=0.2)),
    ("area:0,-1,1:0,0,0:30:0.5:0.2", Light("area", (0.0, -1.0, 1.0), intensity=30 / math.pi, axis=(0, 1, -1),
                                           size=(0.5, 0.2), tangent=(1, 0, 0))),
])
def test_a_light_on_the_command_line_is_the_blender_light_of_those_settings(text, want):
    got = parse_light(text)
    for field in ("kind", "falloff", "shape"):
        assert getattr(got, field) == getattr(want, field), field
    for field in ("vector", "intensity", "angle", "radius", "size", "spot_size", "spot_blend"):
        np.testing.assert_allclose(getattr(got, field), getattr(want, field), rtol=1e-12, err_msg=field)
    if want.kind in ("spot", "area"):
        np.testing.assert_allclose(np.asarray(got.axis) / np.linalg.norm(got.axis),
                                   np.asarray(want.axis) / np.linalg.norm(want.axis), rtol=1e-12)
    if want.kind == "area":     # its width level
        assert abs(np.asarray(got.tangent) @ [0, 0, 1]) < 1e-12 and abs(np.asarray(got.tangent) @ got.axis) < 1e-12


def test_render_under_command_line_lights_is_the_librarys_render(tmp_path):
    """A floor under a point light and an area light with no ambient: the PNG is the library's
    render with the same Lights (its pixels, after sRGB, within one level of 255)."""
    _write_obj(tmp_path / "floor.obj", *plane(0.0, 1.0))
    hair = make_strands([[[-0.3, 0.0, 0.2], [0.3, 0.0, 0.25]]], radius=0.02)
    hair.save_npz(str(tmp_path / "h.npz"))
    out = tmp_path / "lit.png"
    lights = ["point:0.4,-0.3,0.6:20:0.05", "area:-0.5,-0.5,0.8:0,0,0:10:0.3"]
    args = ["render", str(tmp_path / "h.npz"), "--out", str(out), "--size", "40x40", "--spp", "4",
            "--camera", "0,-0.01,2.5:0,0,0:40", "--mesh", str(tmp_path / "floor.obj"), "--mesh-color", "0.7,0.7,0.7",
            "--ambient", "0"]
    for light in lights:
        args += ["--light", light]
    assert main(args) == 0
    got = _decode_png(out.read_bytes()).astype(np.float64)
    renderer = Renderer()
    renderer.set_strands(hair)
    renderer.set_meshes([(*plane(0.0, 1.0), (0.7, 0.7, 0.7))])
    settings = RenderSettings(spp=4, ambient=0.0, background=(0, 0, 0, 0), lights=tuple(map(parse_light, lights)))
    want = renderer.render(Camera.look_at((0, -0.01, 2.5), (0, 0, 0), fov_deg=40, size=(40, 40)), settings)
    srgb = np.where(want[..., :3] <= 0.0031308, 12.92 * want[..., :3],
                    1.055 * np.power(np.clip(want[..., :3], 0.0031308, None), 1 / 2.4) - 0.055)
    assert got[..., :3].std() > 10, "a flat image: the lights would prove nothing"
    assert np.abs(got[..., :3] - 255 * np.clip(srgb, 0, 1)).max() <= 1.0
    # The default lighting (the tracer's sun and ambient) is another picture.
    assert main(args[:args.index("--light")] + ["--out", str(tmp_path / "plain.png")]) == 0
    plain = _decode_png((tmp_path / "plain.png").read_bytes()).astype(np.float64)
    assert np.abs(plain[..., :3] - got[..., :3]).mean() > 10


@pytest.mark.parametrize("args,message", [
    (["--light", "lamp:1,2,3:5"], "--light 'lamp:1,2,3:5': unknown type 'lamp'"),
    (["--light", "point:0,1:5"], "--light 'point:0,1:5': expected point:X,Y,Z:POWER"),
    (["--light", "sun:0,0,-1:nan"], "--light 'sun:0,0,-1:nan': expected sun:"),
    (["--light", "area:0,0,1:0,0,1:5:1"], "light needs the direction it shines along"),
    (["--light", "spot:0,0,1:0,0,0:5:400"], "spot_size"),
    (["--light", "sun:0,0,-1"] * 9, "--light: 9 given; use at most 8"),
    (["--ambient", "-1"], "--ambient -1.0: use a finite number >= 0"),
])
def test_bad_lights_on_the_command_line_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    make_strands([[[0, 0, 0], [0, 0, 1]]]).save_npz(str(tmp_path / "h.npz"))
    out = tmp_path / "o.png"
    assert main(["render", str(tmp_path / "h.npz"), "--out", str(out)] + args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
