# SPDX-License-Identifier: GPL-3.0-or-later
"""The scenes every section measures: the default scalp, preset key strands, one camera that
Blender and the tracer both use, one light. Built from the project's own packages."""
import os

import numpy as np

from benchmarks.harness import NotMeasured

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.environ.get("HAIR_DATA", os.path.join(os.path.dirname(ROOT), "shared", "data"))

LENS_MM = 50.0
SENSOR_MM = 36.0
# The way the camera looks: from behind the head (+Y; Blender's front is -Y), a little to the
# left and above, where the hair is.
VIEW_DIRECTION = np.array([0.55, -1.0, -0.4])
SUN_DIRECTION = np.array([0.35, -0.45, -0.8])   # light travels this way: down, from behind the camera


def groom_api():
    try:
        import groom
        return groom
    except ImportError as e:
        raise NotMeasured(f"groom is not importable yet ({e})") from e


def tracer_api():
    try:
        import tracer
        for name in ("Camera", "RenderSettings", "Renderer", "reference_render", "Light"):
            getattr(tracer, name)
        return tracer
    except (ImportError, AttributeError) as e:
        raise NotMeasured(f"the tracer's public API is not complete yet ({e})") from e


def load_preset(name):
    """groom.load_preset, accepting the report's short names ('straight' → 'long_straight')."""
    groom = groom_api()
    names = groom.list_presets()
    if name not in names:
        alias = [n for n in names if n.endswith("_" + name) or n.startswith(name + "_")]
        if alias:
            name = alias[0]
    return groom.load_preset(name)


def key_profiles(scalp, keys, params):
    """Each key's control points in its own root frame (the inverse of groom.place_key), so a
    preset's shapes can be planted at any number of roots."""
    from groom.frames import root_frames
    roots = np.array([k.root for k in keys])
    tri, bary, _ = scalp.closest_points(roots)
    normals = scalp.normals_at(tri, bary, params.normal_mode)
    frames = root_frames(normals, params.up, params.front)
    return [((k.points - k.root) @ f, k.kind, k.color, k.root_radius) for k, f in zip(keys, frames)]


def n_keys(scalp, preset, n, seed=7, length_scale=1.0):
    """`n` key strands on `scalp`: the preset's shapes (cycled) planted at `n` area-uniform roots
    in each root's frame. `length_scale` stretches every key about its root (curls grow too;
    the section on length says so)."""
    groom = groom_api()
    from groom.frames import root_frames
    from groom.sampling import sample_roots
    params = preset.params
    base = preset.keys_on(scalp)
    profiles = key_profiles(scalp, base, params)
    s = sample_roots(scalp, int(n), seed, "uniform")
    normals = scalp.normals_at(s.tri, s.bary, params.normal_mode)
    frames = root_frames(normals, params.up, params.front)
    keys = []
    for i in range(int(n)):
        prof, kind, color, rr = profiles[i % len(profiles)]
        pts = groom.place_key(prof * length_scale, s.points[i], frames[i])
        keys.append(groom.KeyStrand(pts, kind=kind, color=color, root_radius=rr))
    return keys


def groom_scene(preset_name="wavy", count=10000, n_key=None, points=None, resolution="fixed",
                seed=0, length_scale=1.0, **overrides):
    """(scalp, keys, params, result) for a preset at `count` strands.

    n_key None keeps the preset's own keys; an integer plants that many keys (see n_keys).
    points None keeps the preset's points_per_strand (the most an adaptive strand may use)."""
    groom = groom_api()
    scalp = groom.default_scalp()
    preset = load_preset(preset_name)
    if n_key is None and length_scale == 1.0:
        keys = preset.keys_on(scalp)
    else:
        keys = n_keys(scalp, preset, n_key or len(preset.keys_on(scalp)), length_scale=length_scale)
    if points is not None:
        overrides["points_per_strand"] = int(points)
    params = preset.params.replace(count=int(count), seed=seed, resolution_mode=resolution, **overrides)
    return scalp, keys, params, groom.generate(scalp, keys, params)


def view_matrix(lo, hi, size, direction=VIEW_DIRECTION, margin=1.08):
    """A Blender camera matrix_world looking at the box from `direction`, far enough that the
    box's bounding sphere fits the smaller image side with the 50 mm lens on a 36 mm sensor."""
    from benchmarks.blender_anchors import look_at_matrix
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-9)
    w, h = size
    # AUTO sensor fit: the sensor width spans the larger image side.
    half_fov_small = np.arctan(0.5 * SENSOR_MM / LENS_MM * min(w, h) / max(w, h))
    dist = margin * radius / np.sin(half_fov_small)
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    return look_at_matrix(centre - d * dist, centre)


def tracer_camera(matrix, size):
    """The tracer's camera for a Blender camera with our lens and sensor: the one mapping both
    renderers use, so images line up pixel for pixel."""
    tracer = tracer_api()
    return tracer.Camera.from_blender(matrix, (int(size[0]), int(size[1])), type="PERSP", lens=LENS_MM,
                                      sensor_width=SENSOR_MM, sensor_fit="AUTO")


def orbit(matrix, angle_rad, centre):
    """The camera matrix turned about the vertical axis through `centre` (a camera move)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    rot = np.eye(4)
    rot[:2, :2] = [[c, -s], [s, c]]
    to = np.eye(4)
    to[:3, 3] = -np.asarray(centre)
    back = np.eye(4)
    back[:3, 3] = np.asarray(centre)
    return back @ rot @ to @ np.asarray(matrix)


def sun_light():
    tracer = tracer_api()
    return make_light(tracer, SUN_DIRECTION)


def make_light(tracer, direction, intensity=3.0):
    """A directional light travelling along `direction` (the sun of the Cycles scene)."""
    return tracer.Light(kind="directional", vector=tuple(float(x) for x in direction),
                        intensity=float(intensity))


def settings(**kw):
    """RenderSettings with one shadow-casting sun unless told otherwise."""
    tracer = tracer_api()
    kw.setdefault("lights", (sun_light(),))
    return tracer.RenderSettings(**kw)


def real_strands(name="straight.hair"):
    path = os.path.join(DATA, name)
    if not os.path.exists(path):
        raise NotMeasured(f"{path} is missing (put ../shared/data beside the checkout or set HAIR_DATA)")
    try:
        from hairio.formats import read_strands
    except ImportError as e:
        raise NotMeasured(f"hairio.formats is not importable yet ({e})") from e
    return read_strands(path)


def crop_camera(camera, x0, y0, w, h):
    """The tracer camera that sees exactly pixels [x0, x0+w) × [y0, y0+h) of `camera`'s image,
    pixel for pixel, with the samples those pixels have there (Camera.window). The float64
    reference costs rays × cylinders, so its comparisons run on such windows of the real image."""
    return camera.window(x0, y0, w, h)


def pick_window(image, w, h, step=None):
    """(x0, y0) of the w×h window whose hair coverage is closest to one half: it holds both
    silhouette edges and interior, where errors show."""
    alpha = np.asarray(image)[..., 3]
    H, W = alpha.shape
    step = step or max(1, min(w, h) // 2)
    best, best_xy = np.inf, (max(0, (W - w) // 2), max(0, (H - h) // 2))
    for y0 in range(0, max(1, H - h + 1), step):
        for x0 in range(0, max(1, W - w + 1), step):
            cov = float((alpha[y0:y0 + h, x0:x0 + w] > 0.5).mean())
            score = abs(cov - 0.5)
            if score < best:
                best, best_xy = score, (x0, y0)
    return best_xy
