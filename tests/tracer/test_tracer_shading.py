# SPDX-License-Identifier: GPL-3.0-or-later
"""Shading models come from one registry (tracer.shading): settings, the command line, the
GPU tracer and the float64 reference all read it, so a model added there is a model
everywhere."""
import shutil

import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, RenderSettings, reference_render, shading
from tracer import shader_source
from tracer.__main__ import build_parser

from tracer_scenes import curls

FLAT_GLSL = """
// A test model: the base colour times the diffuse weight, whatever the light.
vec3 shade_light(Surface s, vec3 L) { return material.y * s.color; }
"""


def _flat_reference(s, L, settings):
    return settings.diffuse * s.color


def test_every_model_has_its_glsl_and_reference():
    for m in shading.SHADING_MODELS:
        assert "vec3 shade_light(Surface s, vec3 L)" in shader_source.load_shader(m.glsl)
        assert callable(m.reference) and m.label and m.description
    assert shading.DEFAULT_SHADING == shading.SHADING_MODELS[0].name
    with pytest.raises(InputError, match="kajiya-kay"):
        RenderSettings(shading="toon").check()


def test_a_model_added_to_the_registry_plugs_in_everywhere(renderer, monkeypatch, tmp_path):
    for f in shader_source.SHADER_DIR.glob("*.glsl"):
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "shading_flat.glsl").write_text(FLAT_GLSL)
    monkeypatch.setattr(shader_source, "SHADER_DIR", tmp_path)
    flat = shading.ShadingModel("flat", "Flat", "Colour only", "shading_flat.glsl", _flat_reference,
                                needs_normal=False)
    monkeypatch.setattr(shading, "SHADING_MODELS", shading.SHADING_MODELS + (flat,))
    settings = RenderSettings(shading="flat", shadows=True, lights=(Light(vector=(0.3, 0.5, -1.0)),))
    settings.check()
    args = build_parser().parse_args(["render", "x.npz", "--out", "x.png", "--shading", "flat"])
    assert args.shading == "flat"
    assert ("flat", "Flat", "Colour only") in shading.enum_items()
    s = curls(10, 8, radius=0.02)
    renderer.set_strands(s)
    lo, hi = s.bounds()
    cam = Camera.frame_bounds(lo, hi, (40, 40))
    img = renderer.render(cam, settings)
    ref = reference_render(s, cam, settings)
    hair = img[..., 3] > 0
    assert hair.sum() > 100
    np.testing.assert_allclose(img, ref, atol=2e-4)
    # Flat: lit hair is ambient + diffuse times its colour, shadowed hair ambient only.
    col = np.array([0.7, 0.45, 0.25])
    levels = img[hair][:, :3] / col
    assert np.all(np.isclose(levels, settings.ambient, atol=1e-4) |
                  np.isclose(levels, settings.ambient + settings.diffuse, atol=1e-4))
