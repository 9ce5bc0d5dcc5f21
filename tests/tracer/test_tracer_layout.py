# SPDX-License-Identifier: GPL-3.0-or-later
"""One rule set: the constants of tracer/layout.py reach the numpy build, the compute build
and the trace shader alike, so changing one there changes every side together."""
import re

import numpy as np
import pytest

from tracer import Camera, Light, RenderSettings, Renderer, layout, reference_render, strands_to_cylinders
from tracer.gl_state import shared_context
from tracer.gpu_build import compute_available
from tracer.shader_source import SHADER_DIR

from tracer_scenes import make_strands

BEND_DEG = 85.0     # between the shipped sharp-bend limit (80°) and the 88° the tests set


def _bent_strands():
    """Strands that turn by BEND_DEG at their second point, and a straight one."""
    a = np.radians(BEND_DEG)
    lines = []
    for k in range(6):
        x = 0.06 * k
        turn = np.array([np.sin(a), 0.0, np.cos(a)]) * 0.2
        lines.append(np.array([[x, 0, 0], [x, 0, 0.2], [x, 0, 0.2] + turn, [x, 0, 0.2] + 2 * turn]))
    lines.append(np.array([[-0.1, 0.05, 0], [-0.1, 0.05, 0.3]]))
    return make_strands(lines, radius=0.012)


def _joint_is_cap(cylinders):
    """Per bent strand: is the joint at its second point a cap (on both of its cylinders)?"""
    first = cylinders.flags[0:18:3]     # three cylinders per bent strand
    second = cylinders.flags[1:18:3]
    return (first & layout.CAP_PLANE2 > 0) & (second & layout.CAP_PLANE1 > 0)


def _pairs(r):
    g = r.grid
    return set(zip(np.repeat(np.arange(g.num_cells), g.cell_count).tolist(), r.grid_indices().tolist()))


@pytest.mark.parametrize("limit", [80.0, 88.0])
def test_the_bend_limit_moves_both_builds_together(monkeypatch, limit):
    if not compute_available(shared_context()):
        pytest.skip("this driver has no compute shaders (OpenGL 4.3); only the numpy build exists")
    monkeypatch.setattr(layout, "SHARP_BEND_DEG", limit)
    s = _bent_strands()
    c = strands_to_cylinders(s)
    assert _joint_is_cap(c).all() == (limit < BEND_DEG) and _joint_is_cap(c).any() == (limit < BEND_DEG)
    gpu, cpu = Renderer(build="gpu", accel="grid"), Renderer(build="numpy", accel="grid")
    gpu.set_strands(s)
    cpu.set_strands(s)
    n = len(c)
    got = np.frombuffer(gpu.buffers["tex_cyl"].read(n * layout.TEXELS_PER_CYL), np.float32).reshape(n, -1, 4)
    want = layout.cylinder_texels(c).reshape(n, -1, 4)
    n2 = layout.CYL_TEXELS.index("N2")
    np.testing.assert_array_equal(got[:, n2, 3], want[:, n2, 3])          # the cap flags
    np.testing.assert_allclose(got, want, atol=1e-6)
    # One frame, one listing: the GPU grid is the numpy grid.
    assert gpu.stats.grid_build == "gpu"
    for field in ("lo", "cell_size", "dims"):
        np.testing.assert_array_equal(getattr(gpu.grid, field), getattr(cpu.grid, field))
    assert _pairs(gpu) == _pairs(cpu)
    # And the images agree with each other and with the float64 reference.
    lo, hi = s.bounds()
    cam = Camera.look_at(0.5 * (lo + hi) + np.array([0.2, -1.5, 0.3]), 0.5 * (lo + hi), size=(48, 40), fov_deg=30)
    settings = RenderSettings(shadows=True, lights=(Light(vector=(0.3, 0.6, -1.0)),))
    a, b = gpu.render(cam, settings), cpu.render(cam, settings)
    assert a[..., 3].sum() > 50
    np.testing.assert_array_equal(a, b)
    ref = reference_render(s, cam, settings)
    assert np.mean(np.abs(a - ref) > 1e-3) < 0.01


def test_no_shader_spells_a_layout_constant():
    """Every constant of the header comes from tracer/layout.py only."""
    header = layout.glsl_header()
    names = re.findall(r"#define (\w+) ", header)
    cos_digits = repr(layout.cos_sharp())[:8]
    for path in sorted(SHADER_DIR.glob("*.glsl")):
        text = path.read_text()
        for name in names:
            assert not re.search(rf"#define\s+{name}\b", text), f"{path.name} defines {name} itself"
            assert not re.search(rf"\b(const\s+\w+\s+|uniform\s+\w+\s+){name}\b", text), f"{path.name}: {name}"
        assert cos_digits not in text, f"{path.name} spells cos(SHARP_BEND_DEG)"
        assert "4 * id" not in text and "id << 2" not in text, f"{path.name} spells the texels per cylinder"


def test_both_builds_lay_the_same_frame(grid_renderer):
    s = _bent_strands()
    grid_renderer.set_strands(s)
    numpy_build = Renderer(build="numpy", accel="grid")
    numpy_build.set_strands(s)
    for field in ("lo", "cell_size", "dims"):
        np.testing.assert_array_equal(getattr(grid_renderer.grid, field), getattr(numpy_build.grid, field))
