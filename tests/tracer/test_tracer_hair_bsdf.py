# SPDX-License-Identifier: GPL-3.0-or-later
"""The fibre model (tracer/hair_bsdf.py, shaders/shading_chiang.glsl): energy, symmetry,
limits, and the GLSL against the float64 reference."""
import numpy as np
import pytest

from tracer import hair_bsdf as hb

UP = np.array([0.0, 0.0, 1.0])


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def sphere_grid(n, rng):
    """Directions on a jittered equal-area grid (z = sin theta and phi uniform): n x 2n
    cells of equal solid angle, one direction in each."""
    z = (np.arange(n) + rng.uniform(size=n)) / n * 2.0 - 1.0
    phi = (np.arange(2 * n) + rng.uniform(size=2 * n)) / (2 * n) * 2.0 * np.pi - np.pi
    Z, P = np.meshgrid(z, phi, indexing="ij")
    c = np.sqrt(1.0 - Z.ravel() ** 2)
    return np.stack([c * np.cos(P.ravel()), c * np.sin(P.ravel()), Z.ravel()], axis=1)


def evaluate(wi, wo, h, sigma_a, lobes, tangent=UP):
    wi = np.atleast_2d(wi)
    n = len(wi)
    return hb.hair_bsdf(wi, np.broadcast_to(wo, (n, 3)), np.broadcast_to(tangent, (n, 3)),
                        np.broadcast_to(h, (n,)), np.broadcast_to(sigma_a, (n, 3)), lobes)


def furnace(wo, h, lobes, sigma_a=(0.0, 0.0, 0.0), n=300, seed=7):
    """Integral of the BSDF (cosine included) over the sphere of light directions."""
    wi = sphere_grid(n, np.random.default_rng(seed))
    return evaluate(wi, wo, h, sigma_a, lobes).mean(axis=0) * 4.0 * np.pi


# White furnace: with no absorption R + TT + TRT + TRRT+ carry all the light (their Ap sum to
# 1 exactly) and each Mp and Np is normalised, so the integral is 1. Tolerance 2 %: the
# Mp normalisation holds to ~0.5 % for these variances, the jittered 300 x 600 grid adds
# < 1 % for the narrowest lobe (TT at roughness 0.2: v/4 = 0.011). The cuticle tilt is 0:
# the tilt moves lobes past the poles, where the model loses or gains light (pbrt's test
# likewise runs without it).
@pytest.mark.parametrize("roughness", [0.2, 0.3, 0.6, 1.0])
def test_white_furnace_no_absorption_integrates_to_one(roughness):
    lobes = hb.fibre_lobes(roughness, roughness, ior=1.55, offset=0.0)
    rng = np.random.default_rng(3)
    for _ in range(4):
        wo = unit(rng.normal(size=3))
        wo = unit(wo - UP * np.clip(wo @ UP, -0.8, 0.8) + UP * np.clip(wo @ UP, -0.8, 0.8))
        total = furnace(wo, rng.uniform(-0.95, 0.95), lobes)
        np.testing.assert_allclose(total, 1.0, atol=0.02, err_msg=f"roughness {roughness}, wo {wo}")


def test_furnace_with_absorption_loses_light_in_colour_order():
    lobes = hb.fibre_lobes(0.3, 0.3, offset=0.0)
    sigma = hb.sigma_a_from_melanin(0.5, 0.5)
    wo = unit([0.3, -1.0, 0.2])
    total = furnace(wo, 0.3, lobes, sigma)
    # Melanin absorbs blue most: less energy in blue than green than red, all below 1 but
    # above the surface reflection R alone (a few percent).
    assert 0.04 < total[2] < total[1] < total[0] < 0.98, total


def test_reciprocal_at_zero_offset_mirror_angles_and_no_tilt():
    """Swapping wi and wo gives the same value where the model's one-sided terms (Ap,
    gamma_t at theta_o) agree: h = 0, |theta_i| = |theta_o|, no tilt."""
    lobes = hb.fibre_lobes(0.4, 0.5, offset=0.0)
    rng = np.random.default_rng(11)
    sigma = hb.sigma_a_from_melanin(0.6, 0.3)
    for _ in range(20):
        theta = rng.uniform(-1.2, 1.2)
        sign = rng.choice([-1.0, 1.0])
        phi_a, phi_b = rng.uniform(-np.pi, np.pi, size=2)
        a = np.array([np.cos(theta) * np.cos(phi_a), np.cos(theta) * np.sin(phi_a), np.sin(theta)])
        b = np.array([np.cos(theta) * np.cos(phi_b), np.cos(theta) * np.sin(phi_b), sign * np.sin(theta)])
        np.testing.assert_allclose(evaluate(a, b, 0.0, sigma, lobes), evaluate(b, a, 0.0, sigma, lobes),
                                   rtol=1e-9, atol=1e-12)


def test_longitudinal_lobe_is_symmetric_and_normalised():
    rng = np.random.default_rng(5)
    for v in (0.02, 0.0847, 0.3, 2.0):
        si, so = rng.uniform(-1, 1, size=2)
        ci, co = np.sqrt(1 - si * si), np.sqrt(1 - so * so)
        assert hb.mp(si, ci, so, co, v) == pytest.approx(hb.mp(so, co, si, ci, v), rel=1e-12)
        # Integral over theta_i of Mp cos theta_i is 1 (Chiang eq. 4's normalisation).
        theta = np.linspace(-np.pi / 2, np.pi / 2, 20001)
        m = hb.mp(np.sin(theta), np.cos(theta), so, co, v) * np.cos(theta)
        assert np.trapz(m, theta) == pytest.approx(1.0, abs=0.01), v


def test_azimuthal_lobes_are_normalised_and_centred_on_delta_phi():
    s = hb.logistic_scale(0.3)
    phi = np.linspace(-np.pi, np.pi, 200001)
    for p, (go, gt) in enumerate([(0.4, 0.25), (-0.7, -0.42), (0.0, 0.0)]):
        n = hb.np_lobe(phi, p, s, go, gt)
        assert np.trapz(n, phi) == pytest.approx(1.0, abs=1e-4)
        assert hb.wrap_angle(phi[np.argmax(n)] - hb.delta_phi(p, go, gt)) == pytest.approx(0.0, abs=1e-4)


def test_opaque_fibre_reflects_only_the_r_lobe():
    """Absorption without bound leaves the surface reflection: Fresnel * Mp(v_r) * N0."""
    lobes = hb.fibre_lobes(0.3, 0.3)
    rng = np.random.default_rng(2)
    wi, wo = unit(rng.normal(size=(16, 3))), unit(rng.normal(size=(16, 3)))
    h = rng.uniform(-0.9, 0.9, size=16)
    got = hb.hair_bsdf(wi, wo, np.broadcast_to(UP, (16, 3)), h, np.full((16, 3), 1e4), lobes)
    X, Y, Z = hb.fibre_frame(np.broadcast_to(UP, (16, 3)), wo)
    sin_o, sin_i = wo[:, 2], wi[:, 2]
    cos_o, cos_i = np.sqrt(1 - sin_o ** 2), np.sqrt(1 - sin_i ** 2)
    (s_r, c_r), _, _ = hb.tilted_angles(sin_i, cos_i, lobes.alpha)
    phi = np.arctan2(np.einsum("ij,ij->i", wi, Z), np.einsum("ij,ij->i", wi, Y)) - np.arctan2(
        np.einsum("ij,ij->i", wo, Z), np.einsum("ij,ij->i", wo, Y))
    gamma_o = np.arcsin(h)
    gamma_t = np.arcsin(h * cos_o / np.sqrt(lobes.eta ** 2 - sin_o ** 2))
    want = (hb.fresnel_dielectric(cos_o * np.sqrt(1 - h * h), lobes.eta)
            * hb.mp(s_r, c_r, sin_o, cos_o, lobes.v_r) * hb.np_lobe(phi, 0, lobes.s, gamma_o, gamma_t))
    np.testing.assert_allclose(got, np.repeat(want[:, None], 3, axis=1), rtol=1e-9, atol=1e-300)


def test_index_one_and_no_absorption_is_pure_forward_transmission():
    """eta = 1: no Fresnel reflection, no refraction: all light goes straight through (TT,
    centred on phi = pi), whatever h."""
    lobes = hb.fibre_lobes(0.2, 0.2, ior=1.0, offset=0.0)
    wo = unit([0.0, -1.0, 0.3])
    for h in (-0.8, 0.0, 0.6):
        ahead = evaluate(-wo, wo, h, 0.0, lobes)[0, 0]                            # light behind
        mirror = evaluate(wo * np.array([1, 1, -1]), wo, h, 0.0, lobes)[0, 0]     # light in front
        assert ahead > 1e3 * mirror, (h, ahead, mirror)
        np.testing.assert_allclose(furnace(wo, h, lobes), 1.0, atol=0.02)


def test_narrower_roughness_concentrates_the_highlight():
    """The R lobe sharpens as the roughness drops, and its peak moves to the mirror angle
    turned by 2 alpha (a wide Mp peaks further from it)."""
    wo = unit([0.0, -1.0, 0.4])
    sin_o = wo[2]
    thetas = np.linspace(-1.4, 1.4, 2801)
    peaks, where = [], []
    for r in (0.5, 0.3, 0.15, 0.1):
        lobes = hb.fibre_lobes(r, 0.3, offset=np.radians(3.0))
        wi = np.stack([np.zeros_like(thetas), -np.cos(thetas), np.sin(thetas)], axis=1)
        f = evaluate(wi, wo, 0.0, 1e4, lobes)[:, 0]          # opaque: R only
        peaks.append(f.max())
        where.append(abs(thetas[np.argmax(f)] - (-np.arcsin(sin_o) - 2 * np.radians(3.0))))
    assert peaks[0] < peaks[1] < peaks[2] < peaks[3]
    assert where[0] > where[1] > where[2] and where[3] < 0.003, where


def test_melanin_and_colour_mappings_match_cycles_node():
    # Cycles: melanin 0.8, redness 1.0 -> pheomelanin -log(0.2) = 1.609.
    np.testing.assert_allclose(hb.sigma_a_from_melanin(0.8, 1.0), 1.6094379 * hb.PHEOMELANIN_SIGMA_A, rtol=1e-6)
    np.testing.assert_allclose(hb.sigma_a_from_melanin(0.0, 0.5), 0.0)
    # Direct colouring: white hair absorbs nothing; darker colour, more absorption.
    np.testing.assert_allclose(hb.sigma_a_from_color([1.0, 1.0, 1.0], 0.3), 0.0)
    s = hb.sigma_a_from_color([0.5, 0.2, 0.05], 0.3)
    assert s[0] < s[1] < s[2]
    # Roughness maps through Chiang et al. eq. 7/8: 0.3 -> v = 0.0847, s = 0.1170.
    lobes = hb.fibre_lobes(0.3, 0.3, coat=0.5)
    assert lobes.v == pytest.approx((0.726 * 0.3 + 0.812 * 0.09 + 3.7 * 0.3 ** 20) ** 2)
    assert lobes.s == pytest.approx((0.265 * 0.3 + 1.194 * 0.09) * np.sqrt(np.pi / 8))
    assert lobes.v_r == pytest.approx(hb.longitudinal_variance(0.15))


def test_log_i0_joins_the_series():
    x = np.array([0.0, 1.0, 5.0, 11.9])
    np.testing.assert_allclose(hb.log_i0(x), np.log(hb.i0(x)))
    # The series is I0 where it converges; the asymptotic form is close past the switch.
    np.testing.assert_allclose(hb.i0(np.array([0.5, 3.0, 6.0])), np.i0([0.5, 3.0, 6.0]), rtol=1e-5)
    np.testing.assert_allclose(hb.log_i0(np.array([20.0, 100.0])), np.log(np.i0([20.0, 100.0])), rtol=1e-3)


# --- the GLSL against the reference -------------------------------------------------------

_VERTEX = """#version 330 core
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""


def run_probe(probe, inputs, outputs):
    """Run `probe` (a GLSL main) once per row of `inputs` (n, k, 4) in a fragment shader
    after shading_chiang.glsl: fragment (0, i) reads its k input texels with fetch(j) and
    writes `outputs` vec4s out0, out1, ...; returns (n, outputs, 4).
    A fragment shader, as the tracer runs the model (transform feedback is not on every
    driver)."""
    import moderngl
    from tracer.gl_state import shared_context
    from tracer.shader_source import shader_source
    ctx = shared_context()
    n, k, _ = inputs.shape
    outs = "".join(f"layout(location = {j}) out vec4 out{j};\n" for j in range(outputs))
    # trace_scene.glsl first: it defines the Surface of the file's shade_light.
    head = (shader_source(330, ["trace_scene.glsl", "shading_chiang.glsl"], {"COUNT": 0})
            + "uniform sampler2D tex_in;\n" + outs
            + "vec4 fetch(int j) { return texelFetch(tex_in, ivec2(j, int(gl_FragCoord.y)), 0); }\n")
    prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=head + probe)
    tex = ctx.texture((k, n), 4, np.ascontiguousarray(inputs, "f4").tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    targets = [ctx.texture((1, n), 4, dtype="f4") for _ in range(outputs)]
    fbo = ctx.framebuffer(color_attachments=targets)
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], "f4").tobytes())
    vao = ctx.vertex_array(prog, [(quad, "2f", "in_pos")])
    fbo.use()
    tex.use(0)
    prog["tex_in"].value = 0
    vao.render(moderngl.TRIANGLE_STRIP)
    result = np.stack([np.frombuffer(t.read(), "f4").reshape(n, 4) for t in targets], axis=1)
    for obj in (vao, quad, fbo, *targets, tex, prog):
        obj.release()
    return result.astype(np.float64)


def rows(*columns):
    """(n, k, 4) texels from columns of widths that sum to 4 per texel."""
    flat = np.concatenate([np.asarray(c, np.float64).reshape(len(c), -1) for c in columns], axis=1)
    pad = (-flat.shape[1]) % 4
    flat = np.concatenate([flat, np.zeros((len(flat), pad))], axis=1)
    return flat.reshape(len(flat), -1, 4)


_BSDF_PROBE = """
void main() {
    vec4 a = fetch(0), b = fetch(1), c = fetch(2), d = fetch(3), e = fetch(4);
    // wi = a.xyz, wo = (a.w, b.xy), tangent = (b.zw, c.x), h = c.y, sigma = (c.zw, d.x),
    // lobes = (d.yzw, e.xy)
    FibreLobes lobes = FibreLobes(d.y, d.z, d.w, e.x, e.y);
    out0 = vec4(hair_bsdf(a.xyz, vec3(a.w, b.xy), vec3(b.zw, c.x), c.y, vec3(c.zw, d.x), lobes), 1.0);
}
"""


def test_glsl_matches_the_float64_reference():
    """2000 random (wi, wo, tangent, h, absorption, lobes): float32 GLSL within 1e-3 relative
    of the float64 reference, plus 1e-4 of the largest value for the lobes' tails."""
    rng = np.random.default_rng(2024)
    n = 2000
    wi, wo = unit(rng.normal(size=(n, 3))), unit(rng.normal(size=(n, 3)))
    tangent = unit(rng.normal(size=(n, 3)))
    h = rng.uniform(-0.99, 0.99, size=n)
    sigma = np.where(rng.uniform(size=(n, 1)) < 0.5,
                     hb.sigma_a_from_melanin(rng.uniform(0, 0.95, n), rng.uniform(0, 1, n)),
                     hb.sigma_a_from_color(rng.uniform(0.02, 1.0, (n, 3)), 0.3))
    params = [hb.fibre_lobes(r, rr, c, ior, off) for r, rr, c, ior, off in zip(
        rng.uniform(0.08, 1.0, n), rng.uniform(0.08, 1.0, n), rng.uniform(0, 0.8, n),
        rng.uniform(1.3, 1.8, n), np.radians(rng.uniform(-6, 6, n)))]
    lobes_rows = np.array([[p.v, p.v_r, p.s, p.alpha, p.eta] for p in params])
    want = np.concatenate([hb.hair_bsdf(wi[i:i + 1], wo[i:i + 1], tangent[i:i + 1], h[i:i + 1], sigma[i:i + 1], p)
                           for i, p in enumerate(params)])
    got = run_probe(_BSDF_PROBE, rows(wi, wo, tangent, h, sigma, lobes_rows), 1)[:, 0, :3]
    assert np.all(np.isfinite(got))
    assert want.max() > 1.0 and (want > 1e-3).mean() > 0.5     # the set holds peaks and tails
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-4 * want.max())


_HELPER_PROBE = """
void main() {
    vec4 a = fetch(0), b = fetch(1), c = fetch(2);
    // p = a.xyz, tangent = (a.w, b.xy), wo = (b.zw, c.x), colour = c.yzw
    vec3 col = c.yzw;
    out0 = vec4(fibre_offset(a.xyz, vec3(0.0), vec3(a.w, b.xy), vec3(b.zw, c.x), 0.5),
                sigma_a_from_melanin(col.x, col.y));
    out1 = vec4(sigma_a_from_color(col, 0.3), 0.0);
}
"""


def test_glsl_offset_and_absorption_helpers_match():
    rng = np.random.default_rng(8)
    n = 500
    p, t, wo = rng.normal(size=(n, 3)) * 0.3, unit(rng.normal(size=(n, 3))), unit(rng.normal(size=(n, 3)))
    col = rng.uniform(0.01, 0.95, size=(n, 3))
    got = run_probe(_HELPER_PROBE, rows(p, t, wo, col), 2)
    np.testing.assert_allclose(got[:, 0, 0], hb.fibre_offset(p, np.zeros((n, 3)), t, wo, 0.5), atol=2e-5)
    np.testing.assert_allclose(got[:, 0, 1:4], hb.sigma_a_from_melanin(col[:, 0], col[:, 1]), rtol=1e-5)
    np.testing.assert_allclose(got[:, 1, :3], hb.sigma_a_from_color(col, 0.3), rtol=1e-4, atol=1e-7)
