# SPDX-License-Identifier: GPL-3.0-or-later
"""The "chiang" shading model in the tracer: the default, its settings, the GPU against the
float64 reference, and what a strand's colour means."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, RenderSettings, reference_render, shading
from tracer import hair_bsdf as hb
from tracer.shading import chiang

from tracer_scenes import curls, make_strands

SUN = Light("directional", (0.4, 0.6, -1.0), (1.0, 1.0, 1.0), 3.0)


def test_chiang_is_the_default_and_the_others_stay():
    assert RenderSettings().shading == shading.DEFAULT_SHADING == "chiang"
    assert ("chiang", "Principled hair (Chiang)") == shading.enum_items()[0][:2]
    assert {"kajiya-kay", "phong"} <= set(shading.shading_names())


def test_settings_default_to_cycles_principled_hair():
    s = RenderSettings()
    assert (s.hair_melanin, s.hair_melanin_redness, s.hair_roughness, s.hair_radial_roughness,
            s.hair_coat, s.hair_ior) == (0.8, 1.0, 0.3, 0.3, 0.0, 1.55)
    assert s.hair_cuticle_tilt == pytest.approx(2.0)
    assert s.hair_color == "strand"


@pytest.mark.parametrize("field, value", [("hair_color", "dyed"), ("hair_melanin", 1.5), ("hair_roughness", -0.1),
                                          ("hair_radial_roughness", float("nan")), ("hair_coat", 2.0),
                                          ("hair_ior", 0.5), ("hair_cuticle_tilt", 120.0),
                                          ("hair_melanin_redness", -1.0)])
def test_bad_hair_settings_are_refused_by_name(field, value):
    with pytest.raises(InputError, match=field):
        RenderSettings(**{field: value}).check()


def _tuft():
    s = curls(10, 8, radius=0.02)
    lo, hi = s.bounds()
    return s, Camera.frame_bounds(lo, hi, (48, 48))


@pytest.mark.parametrize("settings", [
    RenderSettings(shadows=True, lights=(SUN,)),
    RenderSettings(shadows=True, hair_color="melanin", hair_melanin=0.3, hair_melanin_redness=0.6,
                   hair_roughness=0.5, hair_radial_roughness=0.6, hair_coat=0.4, hair_ior=1.45,
                   hair_cuticle_tilt=-3.0, ambient=0.0,
                   lights=(Light("directional", (-0.3, -1.0, 0.2), (1.0, 0.9, 0.8), 2.0), SUN)),
], ids=["defaults", "melanin-two-lights"])
def test_gpu_matches_the_float64_reference(renderer, settings):
    s, cam = _tuft()
    renderer.set_strands(s)
    img = renderer.render(cam, settings).astype(np.float64)
    ref = reference_render(s, cam, settings)
    hair = ref[..., 3] > 0
    assert hair.sum() > 200
    assert ref[hair][:, :3].max() > 0.2          # lit, with highlights: an empty image fails
    same = (img[..., 3] > 0) == hair
    assert same.mean() > 0.99
    # float32 against float64 through narrow lobes: a few 1e-3 at most, RMSE far below.
    err = np.abs(img - ref)[same]
    assert np.quantile(err, 0.99) < 3e-3, err.max()
    assert np.sqrt(np.mean(err ** 2)) < 1e-3


def test_reference_shade_is_the_fibre_model_times_irradiance():
    """One strand, no shadows, no ambient: every hair pixel of the reference equals
    E * hair_bsdf at its hit (h from the normal), so the tracer's plumbing adds nothing."""
    from tracer.reference import shade
    from tracer.reference.shapes import CylinderSet
    from tracer.cylinders import strands_to_cylinders
    s = make_strands([[[0.0, 0.0, -0.5], [0.0, 0.0, 0.5]]], radius=0.1, color=(0.6, 0.4, 0.2))
    settings = RenderSettings(shadows=False, ambient=0.0, lights=(SUN,))
    cyl = CylinderSet(strands_to_cylinders(s))
    x = np.linspace(-0.099, 0.099, 9)
    o = np.stack([x, np.full(9, -2.0), np.zeros(9)], axis=1)
    d = np.tile([0.0, 1.0, 0.0], (9, 1))
    t = 2.0 - np.sqrt(0.1 ** 2 - x ** 2)
    got = shade(cyl, np.zeros(9, np.int64), np.zeros(9, np.int64), o, d, t, settings, np.zeros(9, np.uint32), 0)
    L = -np.asarray(SUN.packed()[0][:3])
    h = -x / 0.1        # Y = X x wo = z x (0, -1, 0) = +x: h = -x / r
    want = 3.0 * hb.hair_bsdf(np.tile(L, (9, 1)), -d, np.tile([0.0, 0.0, 1.0], (9, 1)), h,
                              np.tile(hb.sigma_a_from_color([0.6, 0.4, 0.2], 0.3), (9, 1)), chiang.lobes(settings))
    np.testing.assert_allclose(got, want, rtol=1e-6)   # hit points: the quadratic against sqrt(r² - x²)


def test_strand_colour_shows_as_the_hair_colour():
    """hair_color "strand": a red strand renders red, a blue one blue (Direct Coloring);
    "melanin": white strands take the melanin's colour, the same for both."""
    red = make_strands([[[-0.15, 0.0, -0.5], [-0.15, 0.0, 0.5]]], radius=0.06, color=(0.6, 0.1, 0.05))
    blue = make_strands([[[0.15, 0.0, -0.5], [0.15, 0.0, 0.5]]], radius=0.06, color=(0.05, 0.1, 0.6))
    cam = Camera.look_at((0.0, -2.0, 0.0), (0.0, 0.0, 0.0), fov_deg=20, size=(40, 40))
    for strands, channel in ((red, 0), (blue, 2)):
        img = reference_render(strands, cam, RenderSettings(shadows=False, ambient=0.0, lights=(SUN,)))
        mean = img[img[..., 3] > 0.99][:, :3].mean(axis=0)
        assert np.argmax(mean) == channel, mean
    white = make_strands([[[0.0, 0.0, -0.5], [0.0, 0.0, 0.5]]], radius=0.06, color=(1.0, 1.0, 1.0))
    img = reference_render(white, cam, RenderSettings(shadows=False, ambient=0.0, lights=(SUN,),
                                                      hair_color="melanin", hair_melanin=0.5,
                                                      hair_melanin_redness=0.8))
    mean = img[img[..., 3] > 0.99][:, :3].mean(axis=0)
    assert mean[0] > mean[1] > mean[2], mean          # pheomelanin: auburn


def test_cli_takes_the_hair_sliders(tmp_path, monkeypatch):
    """Every slider on the command line reaches the settings the image is rendered with."""
    import tracer.__main__ as cli
    seen = {}

    def capture(renderer, camera, settings, out):
        seen["settings"] = settings
        return 0.0

    monkeypatch.setattr(cli, "render_png", capture)
    src = tmp_path / "in.npz"
    curls(3, 4).save_npz(src)
    assert cli.main(["render", str(src), "--out", str(tmp_path / "out.png"), "--hair-color", "melanin",
                     "--melanin", "0.2", "--melanin-redness", "0.4", "--roughness", "0.45",
                     "--radial-roughness", "0.55", "--coat", "0.1", "--ior", "1.6", "--cuticle-tilt", "-3"]) == 0
    s = seen["settings"]
    assert (s.shading, s.hair_color, s.hair_melanin, s.hair_melanin_redness, s.hair_roughness,
            s.hair_radial_roughness, s.hair_coat, s.hair_ior, s.hair_cuticle_tilt) == (
        "chiang", "melanin", 0.2, 0.4, 0.45, 0.55, 0.1, 1.6, -3.0)


@pytest.mark.parametrize("flag, value, field", [("--melanin", "2", "hair_melanin"), ("--ior", "0.9", "hair_ior"),
                                                 ("--cuticle-tilt", "100", "hair_cuticle_tilt")])
def test_cli_refuses_bad_hair_sliders(tmp_path, capsys, flag, value, field):
    from tracer.__main__ import main
    src = tmp_path / "in.npz"
    curls(3, 4).save_npz(src)
    assert main(["render", str(src), "--out", str(tmp_path / "out.png"), flag, value]) == 2
    assert field in capsys.readouterr().err
    assert not (tmp_path / "out.png").exists()


def test_chiang_hair_beside_a_mesh_matches_the_reference(renderer):
    """A roof (out of view) shadows the left half of the tuft from a sun behind the camera:
    shadowed hair gets the ambient term only, lit hair the fibre model on top, on the GPU as
    in the float64 reference."""
    from tracer_scenes import plane
    from test_tracer_meshes import _matches_reference
    tuft = curls(16, 8, radius=0.015)
    # The sun shines along (0, 0.8, -0.6): from a hair point the way to it climbs 0.6 for every
    # 0.8 toward -y, so at z = 1.3 a roof over y in [-1.9, -0.3], x < -0.1 covers the left half.
    roof = plane(1.3, 0.8, centre=(-0.9, -1.1))
    cam = Camera.look_at((0, -2.6, 0.5), (0, 0, 0.5), size=(64, 48), fov_deg=40)
    settings = RenderSettings(shadows=True, lights=(Light("directional", (0.0, 0.8, -0.6), (1, 1, 1), 3.0),))
    try:
        img, _ = _matches_reference(renderer, tuft, [(*roof, (0.6, 0.6, 0.6))], cam, settings)
    finally:
        renderer.set_meshes(None)
    ambient = 0.7 * settings.ambient                 # curls' red channel times the ambient term
    hair = img[..., 3] > 0.99
    left, right = hair & (np.arange(64) < 28)[None], hair & (np.arange(64) > 36)[None]
    assert left.sum() > 30 and right.sum() > 30
    shadowed = np.isclose(img[..., 0], ambient, atol=2e-3)
    assert (shadowed & left).sum() > 0.8 * left.sum()
    assert (shadowed & right).sum() < 0.4 * right.sum()    # some in the shadow of strands in front
