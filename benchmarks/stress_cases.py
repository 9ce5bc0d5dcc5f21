# SPDX-License-Identifier: GPL-3.0-or-later
"""Numerical stress cases (SPEC §9) end to end: scalp + keys → groom → strands → tracer →
pixels, each ending in finite, plausible output or a clear `InputError`, never silently wrong.

Used by the benchmark report (counts of outcomes) and by tests/stress (one test per case).

"Silently wrong" means a run that raised nothing but broke a promise:
  * a strand array holds NaN/Inf, or counts are < 2 or do not sum to the points;
  * a strand does not start at its own root, or a root is off the scalp surface;
  * a strand is longer than max_length × the longest key (blending and rotation cannot
    lengthen a curve, trimming only shortens it);
  * an image pixel is NaN/Inf, alpha leaves [0, 1], or colour is negative;
  * visible hair renders to an empty image;
  * the GPU image disagrees with the float64 reference of the same model (coverage masks
    agree on < 97 % of pixels, or RMSE > 0.05) — the same rays, so only float32 error and
    real bugs can separate them.
Any other exception (not an InputError) is a crash, also a failure.
"""
from dataclasses import dataclass, field

import numpy as np

from hairio import InputError, Strands

FINITE, CLEAR_ERROR, SILENTLY_WRONG, CRASH = "finite", "clear error", "silently wrong", "crash"
IMAGE = 24
COVERAGE_MIN_AGREE = 0.97
RMSE_MAX = 0.05


@dataclass
class Outcome:
    kind: str
    detail: str = ""
    checks: dict = field(default_factory=dict)

    @property
    def ok(self):
        return self.kind in (FINITE, CLEAR_ERROR)


# ----------------------------------------------------------------------------- checks

def strand_problems(strands, roots=None, scalp_points=None, max_length=None):
    """What is silently wrong with generated strands (empty list: nothing)."""
    bad = []
    for name in ("points", "radius", "color", "alpha"):
        a = getattr(strands, name)
        if a.size and not np.isfinite(a).all():
            bad.append(f"{name} holds NaN/Inf")
    if strands.num_strands and strands.counts.min() < 2:
        bad.append("a strand has fewer than 2 points")
    if int(strands.counts.sum()) != strands.num_points:
        bad.append("counts do not sum to the points")
    if bad or not strands.num_strands:
        return bad
    scale = max(float(np.abs(strands.points).max()), 1e-30)
    ext = max(float(np.ptp(strands.points, axis=0).max()), 1e-30)
    # float32 storage: a root may move by a few ulps of the coordinates' magnitude.
    tol = 8 * np.finfo(np.float32).eps * scale + 1e-6 * ext
    first = strands.points[strands.offsets]
    if roots is not None:
        off = np.abs(first - np.asarray(roots)).max()
        if off > tol:
            bad.append(f"strands leave their roots (by {off:.3g}, tolerance {tol:.3g})")
    if scalp_points is not None:
        off = np.abs(np.asarray(scalp_points) - np.asarray(roots)).max()
        if off > tol:
            bad.append(f"roots are off the scalp surface (by {off:.3g})")
    if max_length is not None:
        seg = np.linalg.norm(np.diff(strands.points.astype(np.float64), axis=0), axis=1)
        starts = strands.offsets
        keep = np.ones(len(seg), bool)
        keep[(starts[1:] - 1)] = False
        owner = np.repeat(np.arange(strands.num_strands), strands.counts)[:-1]
        lengths = np.bincount(owner[keep], weights=seg[keep], minlength=strands.num_strands)
        if lengths.max() > max_length * (1 + 1e-4) + tol:
            bad.append(f"a strand is {lengths.max():.4g} long, over the bound {max_length:.4g}")
    return bad


def image_problems(img, expect_visible):
    bad = []
    if not np.isfinite(img).all():
        bad.append(f"{int((~np.isfinite(img)).any(axis=-1).sum())} pixel(s) NaN/Inf")
        return bad
    if img[..., 3].min() < -1e-6 or img[..., 3].max() > 1 + 1e-5:
        bad.append(f"alpha outside [0, 1] ({img[..., 3].min():.3g}..{img[..., 3].max():.3g})")
    if img[..., :3].min() < -1e-6:
        bad.append("negative colour")
    if expect_visible and not (img[..., 3] > 0).any():
        bad.append("visible hair rendered to an empty image")
    return bad


# ----------------------------------------------------------------------------- pipeline

_RENDERER = None


def renderer():
    global _RENDERER
    if _RENDERER is None:
        from tracer import Renderer
        _RENDERER = Renderer()
    return _RENDERER


def render_checked(strands, camera=None, expect_visible=True, reference=True, settings=None):
    """Render `strands` small with the GPU tracer (and the float64 reference); problems list."""
    from tracer import Camera, RenderSettings, reference_render
    if camera is None:
        lo, hi = strands.bounds()
        camera = Camera.frame_bounds(lo, hi, (IMAGE, IMAGE))
    # 4 stratified samples and minimum pixel width: thin hair still lands on samples.
    settings = settings or RenderSettings(spp=4, shadows=True, layers=4, min_pixel_width=True)
    r = renderer()
    r.set_strands(strands)
    img = r.render(camera, settings)
    bad = image_problems(img, expect_visible)
    checks = {"coverage": float((img[..., 3] > 0).mean())}
    if reference and not bad:
        from benchmarks.metrics import image_error
        e = image_error(img, reference_render(strands, camera, settings))
        checks.update(rmse=e["rmse"], coverage_agree=e["coverage_agree"])
        if e["coverage_agree"] < COVERAGE_MIN_AGREE or e["rmse"] > RMSE_MAX:
            bad.append(f"GPU differs from the float64 reference (coverage agreement "
                       f"{100 * e['coverage_agree']:.1f} %, RMSE {e['rmse']:.3g})")
    return bad, checks


def run_groom_case(scalp_fn, keys_fn, params_kw, render=True, expect_visible=True, reference=True):
    """Build scalp, keys and params (each may raise InputError), generate, check, render."""
    import groom
    try:
        scalp = scalp_fn()
        keys = keys_fn(scalp)
        params = groom.GroomParams(**params_kw)
        result = groom.generate(scalp, keys, params)
    except InputError as e:
        return _clear(e)
    except Exception as e:  # noqa: BLE001 — any other exception is what we are counting
        return Outcome(CRASH, f"{type(e).__name__}: {e}")
    s = result.strands
    longest = max(k.length() for k in keys) * params.max_length
    on_scalp = scalp.points_at(result.root_tri, result.root_bary)
    bad = strand_problems(s, result.roots, on_scalp, longest)
    if len(result.roots) != params.count or s.num_strands != params.count:
        bad.append(f"asked for {params.count} strands, got {s.num_strands}")
    checks = {"strands": s.num_strands}
    if not bad and render:
        try:
            more, c = render_checked(s, expect_visible=expect_visible, reference=reference)
            bad += more
            checks.update(c)
        except InputError as e:
            return _clear(e)
        except Exception as e:  # noqa: BLE001
            return Outcome(CRASH, f"render: {type(e).__name__}: {e}")
    return Outcome(SILENTLY_WRONG, "; ".join(bad), checks) if bad else Outcome(FINITE, "", checks)


def run_strands_case(make_strands, camera_fn=None, expect_visible=True, reference=True):
    """Strands made directly (tracer-only cases): validate, render, check."""
    try:
        s = make_strands()
        bad = strand_problems(s)
        if bad:
            return Outcome(SILENTLY_WRONG, "; ".join(bad))
        cam = camera_fn(s) if camera_fn else None
        more, checks = render_checked(s, cam, expect_visible=expect_visible, reference=reference)
    except InputError as e:
        return _clear(e)
    except Exception as e:  # noqa: BLE001
        return Outcome(CRASH, f"{type(e).__name__}: {e}")
    return Outcome(SILENTLY_WRONG, "; ".join(more), checks) if more else Outcome(FINITE, "", checks)


def _clear(e):
    msg = str(e)
    # A clear error names what was wrong: a non-trivial message.
    if len(msg) < 10:
        return Outcome(CRASH, f"InputError with an unclear message: {msg!r}")
    return Outcome(CLEAR_ERROR, msg)


# ----------------------------------------------------------------------------- scenes

def head_scalp(offset=(0.0, 0.0, 0.0), scale=1.0):
    import groom
    s = groom.default_scalp()
    return groom.Scalp(s.vertices * scale + np.asarray(offset), s.triangles, s.density, s.uv)


def key_at(scalp, profile, root_query, scale=1.0, kind="bezier"):
    """A key strand of local shape `profile` (root-relative, x down the head, z along the
    normal) planted at the scalp point nearest `root_query`."""
    import groom
    from groom.frames import root_frames
    tri, bary, pts = scalp.closest_points(np.asarray(root_query, np.float64)[None])
    normal = scalp.normals_at(tri, bary)
    frame = root_frames(normal)[0]
    return groom.KeyStrand(groom.place_key(np.asarray(profile, np.float64) * scale, pts[0], frame), kind=kind)


CURVE = [[0, 0, 0], [0.02, 0, 0.03], [0.08, 0.01, 0.02], [0.15, 0.0, -0.02]]
HAIRPIN = [[0, 0, 0], [0.1, 0, 0.0], [0.1, 0, 0.01], [0.0, 0, 0.01]]  # folds back on itself: 180°


def spec_cases():
    """(name, runner) for every SPEC §9 case; runner() -> Outcome. Small scenes: fast."""
    base = dict(count=60, seed=1, radius=4e-4)
    top = (0.0, 0.0, 0.2)   # above the crown: nearest scalp point is on the central line
    back = (0.0, 0.12, 0.05)
    side = (0.09, 0.0, 0.05)

    def keys_std(scalp, scale=1.0, offset=(0, 0, 0)):
        o = np.asarray(offset)
        return [key_at(scalp, CURVE, np.asarray(q) * scale + o, scale) for q in (top, back, side)]

    cases = [
        ("root on the crown / central line",
         lambda: run_groom_case(head_scalp, lambda s: [key_at(s, CURVE, top)], {**base, "count": 40})),
        ("root on a key root (d = 0)",
         lambda: run_groom_case(head_scalp, lambda s: _keys_on_roots(s, base), base)),
        ("two coincident keys",
         lambda: run_groom_case(head_scalp, lambda s: [key_at(s, CURVE, back), key_at(s, CURVE, back),
                                                       key_at(s, CURVE, side)], base)),
        ("one key only", lambda: run_groom_case(head_scalp, lambda s: [key_at(s, CURVE, back)], base)),
        ("zero-area and sliver triangles", lambda: run_groom_case(_degenerate_scalp, keys_std, base)),
        ("offset by 1e4", lambda: run_groom_case(lambda: head_scalp((1e4, -1e4, 1e4)),
                                                 lambda s: keys_std(s, 1.0, (1e4, -1e4, 1e4)), base)),
        ("scaled by 1e-3", lambda: run_groom_case(lambda: head_scalp(scale=1e-3), lambda s: keys_std(s, 1e-3),
                                                  {**base, "radius": 4e-7, "tolerance": 3e-7})),
        ("scaled by 1e3", lambda: run_groom_case(lambda: head_scalp(scale=1e3), lambda s: keys_std(s, 1e3),
                                                 {**base, "radius": 0.4, "tolerance": 0.3})),
        ("radius 1e-6 of the scene", lambda: run_groom_case(head_scalp, keys_std, {**base, "radius": 3e-7},
                                                            expect_visible=False)),
        ("zero-length key (all control points equal)",
         lambda: run_groom_case(head_scalp, lambda s: [key_at(s, [[0, 0, 0]] * 4, back)], base,
                                expect_visible=False)),
        ("repeated control points",
         lambda: run_groom_case(head_scalp, lambda s: [key_at(s, [CURVE[0], CURVE[0], CURVE[1], CURVE[1], CURVE[3]],
                                                              back)], base)),
        ("hairpin (180°) bend", lambda: run_groom_case(head_scalp, lambda s: [key_at(s, HAIRPIN, back)], base)),
        ("ray parallel to a cylinder axis and the grid axes", _parallel_rays),
        ("camera inside the hair volume", _camera_inside),
        ("grazing rays", _grazing),
        ("cells holding thousands of cylinders", _crowded_cell),
        ("empty scene", _empty_scene),
        ("NaN in strand points", lambda: _expect_error(lambda: Strands.from_arrays(
            np.array([[0, 0, 0], [np.nan, 0, 1.0]]), [2]), "points")),
        ("Inf in strand radius", lambda: _expect_error(lambda: Strands.from_arrays(
            np.array([[0, 0, 0], [0, 0, 1.0]]), [2], radius=[1e-3, np.inf]), "radius")),
        ("NaN in scalp vertices", lambda: _expect_error(lambda: head_scalp((np.nan, 0, 0)), "scalp")),
        ("NaN in key strand points", lambda: _expect_error(
            lambda: __import__("groom").KeyStrand([[0, 0, 0], [np.nan, 0, 1]]), "key")),
    ]
    return cases


def _keys_on_roots(scalp, params_kw):
    """Keys planted exactly on roots the generator will sample (same count, seed, mode), so
    those strands are at distance 0 from their main key."""
    import groom
    from groom.frames import root_frames
    from groom.sampling import sample_roots
    s = sample_roots(scalp, params_kw["count"], params_kw["seed"], "uniform")
    frames = root_frames(scalp.normals_at(s.tri, s.bary))
    return [groom.KeyStrand(groom.place_key(np.asarray(CURVE, np.float64), s.points[i], frames[i]))
            for i in (0, len(s.points) // 2)]


def limit_probes():
    """(name, runner) for scenes beyond the SPEC §9 range, where float32 storage (hairio.Strands
    and the GPU) runs out: reported by the benchmark, not promised by the tests."""
    def probe(offset, scale):
        off = np.asarray(offset, np.float64)
        return lambda: run_groom_case(
            lambda: head_scalp(off, scale),
            lambda s: [key_at(s, CURVE, np.asarray(q) * scale + off, scale) for q in ((0, 0.12, 0.05), (0.09, 0, 0.05))],
            dict(count=40, seed=3, radius=4e-4 * scale, tolerance=1e-4 * scale))
    return [
        ("0.2 mm head 170 m from the origin (scale 1e-3, offset 1e2)", probe((100, -100, 50), 1e-3)),
        ("2 mm head 15 km from the origin (scale 1e-2, offset 1e4)", probe((1e4, -1e4, 5e3), 1e-2)),
        ("0.2 mm head 15 km from the origin (scale 1e-3, offset 1e4)", probe((1e4, -1e4, 5e3), 1e-3)),
    ]


def _degenerate_scalp():
    import groom
    s = groom.default_scalp()
    v = s.vertices
    t = s.triangles
    n = len(v)
    extra = np.array([v[0], v[0], v[0],                          # zero area: one point three times
                      v[1], v[2], v[1] + 1e-9 * (v[2] - v[1])])  # sliver: collinear within 1e-9
    tris = np.vstack([t, [[n, n + 1, n + 2], [n + 3, n + 4, n + 5]]])
    return groom.Scalp(np.vstack([v, extra]), tris)


def _line_strands(points, radius=1e-3):
    pts = np.asarray(points, np.float64)
    return Strands.from_arrays(pts, [len(pts)], radius=np.full(len(pts), radius))


def _parallel_rays():
    from tracer import Camera

    def cam(s):
        # Orthographic, looking straight down the strand's axis (= the grid's z axis).
        return Camera.look_at((0, 0, 1.0), (0, 0, 0), up=(0, 1, 0), size=(IMAGE, IMAGE), type="ORTHO",
                              ortho_scale=0.01)
    return run_strands_case(lambda: _line_strands([[0, 0, 0], [0, 0, 0.1], [0, 0, 0.2]]), cam)


def _camera_inside():
    from tracer import Camera
    rng = np.random.default_rng(3)
    n = 300
    roots = rng.uniform(-0.1, 0.1, (n, 3))
    pts = np.stack([roots, roots + [0, 0, 0.05], roots + [0.01, 0, 0.1]], axis=1).reshape(-1, 3)

    def cam(s):
        return Camera.look_at((0, 0, 0.03), (0.0, 1.0, 0.03), size=(IMAGE, IMAGE), fov_deg=90)
    return run_strands_case(lambda: Strands.from_arrays(pts, np.full(n, 3), radius=np.full(3 * n, 2e-3)), cam)


def _grazing():
    from tracer import Camera
    r = 1e-3

    def cam(s):
        # Orthographic rays along x, the image's centre row passing exactly at distance r
        # from the axis: every ray of that row grazes the surface.
        return Camera.look_at((1.0, 0.0, r), (0.0, 0.0, r), up=(0, 0, 1), size=(IMAGE, IMAGE), type="ORTHO",
                              ortho_scale=8 * r)
    return run_strands_case(lambda: _line_strands([[0, -0.05, 0], [0, 0.0, 0], [0, 0.05, 0]], r), cam,
                            expect_visible=True)


def _crowded_cell():
    # 3,000 short strands crossing one point: one cell lists thousands of cylinders.
    rng = np.random.default_rng(5)
    n = 3000
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = np.stack([-0.01 * d, 0.01 * d], axis=1).reshape(-1, 3)
    return run_strands_case(lambda: Strands.from_arrays(pts, np.full(n, 2), radius=np.full(2 * n, 2e-5)))


def _empty_scene():
    from tracer import Camera
    return run_strands_case(lambda: Strands.empty(),
                            lambda s: Camera.look_at((0, -1, 0), (0, 0, 0), size=(IMAGE, IMAGE)),
                            expect_visible=False)


def _expect_error(fn, must_name):
    """The input is bad: only an InputError naming `must_name` is right."""
    try:
        fn()
    except InputError as e:
        if must_name.lower() not in str(e).lower():
            return Outcome(SILENTLY_WRONG, f"InputError does not name {must_name!r}: {e}")
        return Outcome(CLEAR_ERROR, str(e))
    except Exception as e:  # noqa: BLE001
        return Outcome(CRASH, f"{type(e).__name__}: {e}")
    return Outcome(SILENTLY_WRONG, f"bad input with NaN/Inf was accepted (expected an error naming {must_name})")


# ----------------------------------------------------------------------------- randomised

# SPEC §9 offsets a head-sized scene by 1e4: offsets up to this many times the scene scale are
# the promised range; larger ones probe the limit of float32 on the GPU.
SPEC_OFFSET_RATIO = 1e4


def within_spec(spec):
    return spec["offset"] <= SPEC_OFFSET_RATIO * spec["scale"]


def random_scene_strategy(spec_range_only=False):
    """A hypothesis strategy of (scale, offset, key specs, params) with degenerate inputs mixed
    in; `spec_range_only` keeps offsets within SPEC_OFFSET_RATIO × scale."""
    from hypothesis import strategies as st
    finite = dict(allow_nan=False, allow_infinity=False)
    key_pt = st.tuples(st.floats(-0.2, 0.2, **finite), st.floats(-0.2, 0.2, **finite), st.floats(-0.05, 0.3, **finite))
    degenerate = st.sampled_from(["none", "repeat", "zero", "hairpin", "coincident"])
    key = st.tuples(st.lists(key_pt, min_size=2, max_size=6), degenerate,
                    st.sampled_from([(0, 0, 0.2), (0, 0.12, 0.05), (0.09, 0, 0.05), (-0.07, -0.05, 0.06),
                                     (0, 0, 0.11)]))
    scenes = st.fixed_dictionaries({
        "scale": st.sampled_from([1e-3, 1e-2, 1.0, 1e2, 1e3]),
        "offset": st.sampled_from([0.0, 1.0, 1e2, 1e4]),
        "keys": st.lists(key, min_size=1, max_size=4),
        "count": st.integers(1, 80),
        "tidiness": st.floats(0, 1, **finite),
        "n_influence": st.floats(0, 100, **finite),
        "neighbour_mode": st.sampled_from(["root", "key", "interpolate"]),
        "intelligence": st.booleans(),
        "min_length": st.floats(0.05, 1.0, **finite),
        "resolution_mode": st.sampled_from(["adaptive", "fixed"]),
        "points": st.integers(2, 40),
        "seed": st.integers(0, 2**16),
        "degenerate_scalp": st.booleans(),
    })
    return scenes.filter(within_spec) if spec_range_only else scenes


def run_random_scene(spec, render=True, reference=True):
    scale, off = spec["scale"], spec["offset"]
    offset = np.array([off, -off, 0.5 * off])

    def scalp_fn():
        s = _degenerate_scalp() if spec["degenerate_scalp"] else head_scalp()
        import groom
        return groom.Scalp(s.vertices * scale + offset, s.triangles)

    def keys_fn(scalp):
        keys = []
        for pts, deg, where in spec["keys"]:
            prof = np.asarray(pts, np.float64)
            prof = prof - prof[0]
            if deg == "repeat":
                prof = np.repeat(prof, 2, axis=0)
            elif deg == "zero":
                prof = np.zeros_like(prof)
            elif deg == "hairpin":
                prof = np.asarray(HAIRPIN, np.float64)
            k = key_at(scalp, prof, np.asarray(where) * scale + offset, scale)
            keys.append(k)
            if deg == "coincident":
                keys.append(k)
        return keys

    params = dict(count=spec["count"], seed=spec["seed"], tidiness=spec["tidiness"],
                  n_influence=spec["n_influence"], neighbour_mode=spec["neighbour_mode"],
                  intelligence=spec["intelligence"], min_length=spec["min_length"], max_length=1.0,
                  resolution_mode=spec["resolution_mode"], points_per_strand=spec["points"],
                  radius=4e-4 * scale, tolerance=1e-4 * scale)
    return run_groom_case(scalp_fn, keys_fn, params, render=render, expect_visible=False, reference=reference)
