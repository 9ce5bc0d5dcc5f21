# SPDX-License-Identifier: GPL-3.0-or-later
"""Lights and render settings shared by the GPU tracer and the reference tracer."""
import math
from dataclasses import dataclass, field, replace

import numpy as np

from hairio import InputError

from . import hair_bsdf as hb
from . import layout
from .shading import DEFAULT_SHADING, shading_model

MAX_LIGHTS = 8
HAIR_COLORS = ("strand", "melanin")      # what a strand's colour means to the "chiang" model
# Samples are summed in float32 (additive blending): the sum of n samples can be off by up
# to n * 2^-24 of the pixel's value. 4096 keeps that below 0.025 %, a sixteenth of an 8-bit
# step; far past it more samples make the image worse, not better (10^6: up to 6 %).
MAX_SPP = 4096
# How a pixel's samples are taken: "independent", each its own ray and walk, one draw per
# sample; "pixel", all of a pixel's samples in one walk, each distinct strand shaded once
# (tracer/shaders/sampler_pixel.glsl; docs/DECISIONS.md, "Samples of one pixel share the walk").
SAMPLERS = ("independent", "pixel")


LIGHT_KINDS = ("directional", "point", "spot", "area", "environment")
# The shader's code for each kind (light_vec's w); a point light with fall-off is 2.
_KIND_CODE = {"directional": 0.0, "point": 1.0, "spot": 3.0, "area": 4.0, "environment": 5.0}


@dataclass(frozen=True)
class Light:
    """kind "directional": `vector` is the direction the light travels (a sun shining down is
    (0, 0, -1)); the others: `vector` is the position. A point light has by default no
    fall-off with distance: the thesis's Phong model uses a constant light intensity Il =
    color * intensity. `falloff` (point lights): the inverse-square law, intensity then the
    radiant intensity (W/sr, a Blender point light's Power / 4 pi) and color * intensity / d²
    the irradiance at distance d, as Cycles lights (blender_light).

    kind "spot" (always the inverse-square law): a point light whose light leaves within a
    cone along `axis` of full angle `spot_size` (radians), its edge softened over `spot_blend`
    (0..1) of the cosine range as Blender's spot lights (smoothstep of (cos - cos half angle) /
    ((1 - cos half angle) · blend)); intensity as a point light's (Power / 4 pi inside the cone).
    kind "area" (always the inverse-square law): a Lambertian emitter at `vector` facing `axis`,
    intensity the radiant intensity along the axis (a Blender area light's Power / pi), times
    the cosine from the axis, none behind; of `size` (below), else lit from its centre alone.
    `shadows` False: nothing shadows this light (RenderSettings.shadows turns them all off).

    Lights with an extent are sampled, a point of them per shading point and light (drawn by a
    fixed hash of the pixel, the sample, the layer and the light, the same in the references),
    so their shadows are soft over the samples of a pixel and the passes of a refinement:
    `angle` (directional): the sun's angular diameter (radians), its directions spread evenly
    over a disk of radius tan(angle / 2) across the direction; `radius` (point and spot): a
    sphere, sampled as the disk of that radius facing the shading point; `size` (area: width
    along `tangent`, height across it, metres) with `shape` "rectangle" or "ellipse": the area
    light's surface, sampled evenly, each point lighting as the whole light would from there
    (radiant intensity × the cosine from the axis / d², an unbiased estimate of the area's
    light).

    kind "environment": an even world around everything, of radiance color × intensity / 4 pi
    from every direction (Blender's world of one colour, its Strength: intensity = 4 pi ×
    Strength); each shading point takes one direction of it, drawn evenly over the sphere, with
    its shadow ray, so hair and meshes hide the sky from what lies under them, as in Cycles.
    `vector` plays no part."""
    kind: str = "directional"
    vector: tuple = (0.4, 0.6, -1.0)
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    falloff: bool = False
    axis: tuple = (0.0, 0.0, -1.0)
    spot_size: float = float(np.pi)
    spot_blend: float = 0.0
    shadows: bool = True              # False: no shadow rays toward it (Blender's Cast Shadow off)
    angle: float = 0.0                # directional: angular diameter (radians)
    radius: float = 0.0               # point, spot: the sphere's radius
    size: tuple = (0.0, 0.0)          # area: width along `tangent`, height across it
    tangent: tuple = (1.0, 0.0, 0.0)  # area: the direction of its width (across `axis`)
    shape: str = "rectangle"          # area: "rectangle" or "ellipse"

    def packed(self):
        """(vec4, rgb) as the shader wants them: w = 0 for a directional light, 1 for a point
        light, 2 for a point light with the inverse-square fall-off, 3 for a spot light, 4 for
        an area light."""
        v = np.asarray(self.vector, np.float64)
        rgb = tuple(np.asarray(self.color, np.float64) * self.intensity)
        if self.kind == "directional":
            return (*(v / np.linalg.norm(v)), 0.0), rgb
        if self.kind == "environment":
            return (0.0, 0.0, 0.0, _KIND_CODE["environment"]), rgb
        code = 2.0 if self.kind == "point" and self.falloff else _KIND_CODE[self.kind]
        return (*v, code), rgb

    def target(self):
        """The point every shadow ray toward this light ends at: its position for a point, spot
        or area light without extent; None for a directional or environment light, or one whose
        points are sampled."""
        if self.kind in ("directional", "environment") or any(np.concatenate(self.extent())):
            return None
        return tuple(float(x) for x in self.vector)

    def cone(self):
        """(vec4, float) as the shader wants them: the unit axis and the cosine of the half
        angle (spot lights; -2 for the others), and the width of the cosine range the edge is
        softened over (0: a hard edge)."""
        a = np.asarray(self.axis, np.float64)
        if self.kind not in ("spot", "area"):
            return (0.0, 0.0, -1.0, -2.0), 0.0
        a = a / np.linalg.norm(a)
        if self.kind == "area":
            return (*a, -2.0), 0.0
        cos_half = float(np.cos(0.5 * self.spot_size))
        return (*a, cos_half), (1.0 - cos_half) * float(self.spot_blend)

    def extent(self):
        """(vec4, vec4) as the shader wants them (light_u, light_v): an area light's half width
        and half height as vectors, u.w = 1 for an ellipse; v.w the sampled disk's radius of a
        point or spot light (its sphere), or of a directional light (tan(angle / 2)); zeros for
        a light without extent."""
        if self.kind == "area" and max(self.size) > 0.0:
            a = np.asarray(self.axis, np.float64)
            a = a / np.linalg.norm(a)
            t = np.asarray(self.tangent, np.float64)
            t = t - a * (t @ a)
            t = t / np.linalg.norm(t)
            b = np.cross(a, t)
            hw, hh = 0.5 * float(self.size[0]), 0.5 * float(self.size[1])
            return (*(t * hw), 1.0 if self.shape == "ellipse" else 0.0), (*(b * hh), 0.0)
        disk = 0.0
        if self.kind == "directional":
            disk = float(np.tan(0.5 * self.angle))
        elif self.kind in ("point", "spot"):
            disk = float(self.radius)
        return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, disk)

    def towards(self, p, u):
        """Float64, per point: the unit direction (N, 3) from each point p (N, 3) toward the
        light's point drawn by u (N, 2) in [0, 1) (its centre without extent) and its distance
        (BIG for a directional light): the shader's light_dir."""
        from .reference.shapes import BIG
        ext_u, ext_v = (np.asarray(e, np.float64) for e in self.extent())
        vec = np.asarray(self.packed()[0], np.float64)
        if self.kind == "environment":      # evenly over the sphere
            z = 1.0 - 2.0 * u[:, 0]
            r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
            phi = 2.0 * np.pi * u[:, 1]
            return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), np.full(len(p), BIG)
        if self.kind == "directional":
            L = np.broadcast_to(-vec[:3], p.shape).copy()
            if ext_v[3] > 0.0:
                t, b = _basis(L)
                dx, dy = _concentric(u)
                L = L + ext_v[3] * (dx[:, None] * t + dy[:, None] * b)
                L /= np.linalg.norm(L, axis=1)[:, None]
            return L, np.full(len(p), BIG)
        q = np.broadcast_to(vec[:3], p.shape).copy()
        if self.kind == "area":           # zero half sides leave its centre
            sx, sy = _concentric(u) if ext_u[3] > 0.5 else (2.0 * u[:, 0] - 1.0, 2.0 * u[:, 1] - 1.0)
            q = q + sx[:, None] * ext_u[:3] + sy[:, None] * ext_v[:3]
        elif ext_v[3] > 0.0:
            c = q - p
            t, b = _basis(c / np.maximum(np.linalg.norm(c, axis=1), 1e-30)[:, None])
            dx, dy = _concentric(u)
            q = q + ext_v[3] * (dx[:, None] * t + dy[:, None] * b)
        L = q - p
        dist = np.linalg.norm(L, axis=1)
        return L / np.maximum(dist, 1e-30)[:, None], dist

    def scale(self, L, dist):
        """Float64, per point: what the light's colour is multiplied by at points whose unit
        directions toward the light are L (N, 3) and distances dist (N,): 1 without fall-off,
        else 1 / dist² times the spot's cone or the area light's cosine (the references' model;
        the shader's is light_at in shaders/trace_main.glsl)."""
        if self.kind in ("directional", "environment") or (self.kind == "point" and not self.falloff):
            return np.ones(len(dist))
        f = 1.0 / np.maximum(dist * dist, 1e-30)
        if self.kind == "point":
            return f
        axis, smooth = self.cone()
        c = -(L @ np.asarray(axis[:3], np.float64))          # the cosine from the light's axis
        if self.kind == "area":
            return f * np.maximum(c, 0.0)
        t = c - axis[3]
        edge = np.clip(t / smooth, 0.0, 1.0) if smooth > 0 else np.ones_like(t)
        return f * np.where(t > 0.0, edge * edge * (3.0 - 2.0 * edge), 0.0)

    def check(self):
        if self.kind not in LIGHT_KINDS:
            raise InputError(f"light kind: {self.kind!r}; use one of {', '.join(map(repr, LIGHT_KINDS))}")
        v = np.asarray(self.vector, np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise InputError(f"light vector: {self.vector}; expected three finite numbers")
        if self.kind == "environment" and self.falloff:
            raise InputError("light falloff: an environment light is infinitely far; use falloff with a point light")
        if self.kind == "directional" and np.linalg.norm(v) == 0:
            raise InputError("light vector: a directional light needs a non-zero direction")
        if self.kind == "directional" and self.falloff:
            raise InputError("light falloff: a directional light has no distance to fall off with; "
                             "use falloff with a point light")
        if self.kind in ("spot", "area"):
            a = np.asarray(self.axis, np.float64)
            if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
                article = "an" if self.kind == "area" else "a"
                raise InputError(f"light axis: {self.axis}; {article} {self.kind} light needs the direction it "
                                 "shines along, three finite numbers, not all zero")
        if self.kind == "spot" and not (np.isfinite(self.spot_size) and 0.0 < self.spot_size <= np.pi):
            raise InputError(f"light spot_size: {self.spot_size}; use the cone's full angle, 0 < angle <= pi radians")
        if self.kind == "spot" and not (np.isfinite(self.spot_blend) and 0.0 <= self.spot_blend <= 1.0):
            raise InputError(f"light spot_blend: {self.spot_blend}; use 0..1")
        c = np.asarray(self.color, np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)) or not np.isfinite(self.intensity):
            raise InputError(f"light color/intensity: {self.color}, {self.intensity}; expected finite values")
        if not (np.isfinite(self.angle) and 0.0 <= self.angle < np.pi):
            raise InputError(f"light angle: {self.angle}; use the sun's angular diameter, 0 <= angle < pi radians")
        if not (np.isfinite(self.radius) and self.radius >= 0.0):
            raise InputError(f"light radius: {self.radius}; use a finite radius >= 0")
        size = np.asarray(self.size, np.float64)
        if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size < 0.0):
            raise InputError(f"light size: {self.size}; use (width, height), two finite sizes >= 0")
        if self.shape not in ("rectangle", "ellipse"):
            raise InputError(f"light shape: {self.shape!r}; use 'rectangle' or 'ellipse'")
        if self.kind == "area" and np.any(size > 0.0):
            t = np.asarray(self.tangent, np.float64)
            a = np.asarray(self.axis, np.float64)
            if (t.shape != (3,) or not np.all(np.isfinite(t))
                    or np.linalg.norm(np.cross(t, a)) <= 1e-9 * np.linalg.norm(t) * np.linalg.norm(a)):
                raise InputError(f"light tangent: {self.tangent}; an area light with a size needs the direction "
                                 "of its width, three finite numbers across its axis")


def blender_light(kind, power, vector, color=(1.0, 1.0, 1.0), axis=(0.0, 0.0, -1.0), shadows=True, angle=0.0,
                  radius=0.0, size=(0.0, 0.0), tangent=(1.0, 0.0, 0.0), shape="rectangle", spot_size=math.pi,
                  spot_blend=0.0):
    """A Light as Cycles lights with a Blender light of type `kind` ('SUN', 'POINT', 'SPOT',
    'AREA') and `power` (a sun's Strength in W/m², the others' Power in W, times 2^Exposure
    where Blender has it); `vector` the sun's direction of travel or the light's position,
    `axis` the way a spot or an area light shines, the rest Blender's settings of the same
    meaning (angle in radians, an area light's size (width, height) along `tangent`, shape
    "rectangle" or "ellipse"). Measured against Cycles (docs/DECISIONS.md, "The preview's
    lights are Cycles' lights"): a point light of Power P radiates P / 4 pi W/sr, a spot the
    same inside its cone, an area light P / pi along its axis, all falling off with distance."""
    common = dict(color=tuple(color), shadows=bool(shadows))
    if kind == "SUN":
        return Light("directional", tuple(vector), intensity=float(power), angle=float(angle), **common)
    if kind == "POINT":
        return Light("point", tuple(vector), intensity=float(power) / (4.0 * math.pi), falloff=True,
                     radius=float(radius), **common)
    if kind == "SPOT":
        return Light("spot", tuple(vector), intensity=float(power) / (4.0 * math.pi), axis=tuple(axis),
                     spot_size=float(spot_size), spot_blend=float(spot_blend), radius=float(radius), **common)
    if kind == "AREA":
        return Light("area", tuple(vector), intensity=float(power) / math.pi, axis=tuple(axis),
                     size=tuple(float(x) for x in size), tangent=tuple(tangent), shape=shape, **common)
    raise InputError(f"light type: {kind!r}; use 'SUN', 'POINT', 'SPOT' or 'AREA'")


def _basis(n):
    """Two unit vectors (N, 3) across the unit vectors n (N, 3), as the shader's basis()."""
    t = np.where(np.abs(n[:, 2:3]) < 0.999, np.cross(n, [0.0, 0.0, 1.0]), np.cross(n, [1.0, 0.0, 0.0]))
    t /= np.linalg.norm(t, axis=1)[:, None]
    return t, np.cross(n, t)


def _concentric(u):
    """Shirley's concentric map of u (N, 2) in [0, 1)² onto the unit disk, as the shader's."""
    a, b = 2.0 * u[:, 0] - 1.0, 2.0 * u[:, 1] - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    safe_a = np.where(a == 0.0, 1.0, a)
    safe_b = np.where(b == 0.0, 1.0, b)
    phi = np.where(first, 0.25 * np.pi * (b / safe_a), 0.5 * np.pi - 0.25 * np.pi * (a / safe_b))
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def pixel_list_holds(spp, layers):
    """Whether one walk of the pixel sampler keeps every layer of `spp` samples: with one
    layer (opaque hair) each sample keeps its own nearest hit; with more, a walk keeps
    layout.PIXEL_LIST distinct cylinders, which spp × layers hits can outgrow."""
    return layers == 1 or spp * layers <= layout.PIXEL_LIST


def pixel_group(spp, layers):
    """The samples of a pixel that share one walk of the pixel sampler: the most that divide
    `spp`, fit a walk's sample mask (layout.PIXEL_MAX_SPP) and keep all their `layers`
    (pixel_list_holds); a pixel takes spp / group walks, one draw each. 0 when not even one
    sample's layers fit (the renderer then takes the independent sampler)."""
    return next((g for g in range(min(spp, layout.PIXEL_MAX_SPP), 0, -1)
                 if spp % g == 0 and pixel_list_holds(g, layers)), 0)


@dataclass(frozen=True)
class RenderSettings:
    spp: int = 1                      # samples per pixel, a square (1, 4, 9, 16, ...)
    sampler: str = "independent"      # one of SAMPLERS
    shadows: bool = True
    shadow_mode: str = "hard"         # "hard": any hit darkens; "transmittance": product of (1 - alpha)
    layers: int = 4                   # alpha layers composited front to back
    shading: str = DEFAULT_SHADING    # a name of tracer.shading.SHADING_MODELS
    lights: tuple = field(default_factory=lambda: (Light(),))
    background: tuple = (0.0, 0.0, 0.0, 0.0)   # straight RGBA; alpha 0 = transparent
    min_pixel_width: bool = False
    min_pixel_width_cap: float = 4.0  # largest r'/r; the grid is built for up to GRID_WIDEN_CAP
    ambient: float = 0.08
    diffuse: float = 0.8
    specular: float = 0.25
    shininess: float = 40.0
    transmittance_eps: float = 1e-3   # stop compositing (and shadow products) below this
    tile: int = 512                   # pixels per side of one draw call (GPU watchdogs)
    count: bool = False               # write per-pixel work counters into Renderer.stats
    # Samples a pixel that later renders of this view are to add (a progressive preview's
    # refinement up to its target): what a render builds and keeps for the scene (a sun's
    # lists, tracer/scene_beams.py) is sized for their rays too. The image does not depend on it.
    samples_to_come: int = 0
    # The "chiang" model's sliders, named and defaulted as Cycles' Principled Hair BSDF
    # (tracer/hair_bsdf.py); hair_color says what a strand's colour means (shading/chiang.py).
    hair_color: str = "strand"        # "strand": the hair's colour; "melanin": a tint over the melanin
    hair_melanin: float = hb.DEFAULT_MELANIN
    hair_melanin_redness: float = hb.DEFAULT_MELANIN_REDNESS
    hair_roughness: float = hb.DEFAULT_ROUGHNESS
    hair_radial_roughness: float = hb.DEFAULT_RADIAL_ROUGHNESS
    hair_coat: float = hb.DEFAULT_COAT
    hair_ior: float = hb.DEFAULT_IOR
    hair_cuticle_tilt: float = float(np.degrees(hb.DEFAULT_OFFSET))   # degrees

    @property
    def spp_n(self):
        return int(round(np.sqrt(self.spp)))

    def refinement(self, opaque):
        """The settings of a refinement pass (passes averaged after a first image, as the
        Blender preview's): the pixel sampler with the most samples one walk of a pixel keeps
        without losing layers (opaque hair, one layer: layout.PIXEL_MAX_SPP; see-through hair:
        n² samples with n² × layers within the pixel's list, layout.PIXEL_LIST), or these
        settings themselves where that would not be more samples than their own, or they ask
        for minimum pixel width (which the pixel sampler does not take) or the pixel sampler
        already. `opaque`: every alpha of the strands is 1 (Renderer.all_opaque)."""
        if self.sampler != "independent" or self.min_pixel_width:
            return self
        layers = 1 if opaque else self.layers
        n = max(n for n in range(1, math.isqrt(layout.PIXEL_MAX_SPP) + 1) if pixel_list_holds(n * n, layers))
        if n * n <= self.spp:
            return self
        return replace(self, sampler="pixel", spp=n * n)

    def check(self):
        if self.spp < 1 or self.spp_n ** 2 != self.spp:
            raise InputError(f"spp: {self.spp}; use a square number (1, 4, 9, 16, ...) for stratified sampling")
        if self.spp > MAX_SPP:
            raise InputError(f"spp: {self.spp} samples per pixel, summed in float32, can be off by up to "
                             f"{self.spp * 2.0 ** -24:.2%} of a pixel's value; use at most {MAX_SPP} "
                             f"(error {MAX_SPP * 2.0 ** -24:.3%})")
        if not isinstance(self.samples_to_come, (int, np.integer)) or self.samples_to_come < 0:
            raise InputError(f"samples_to_come: {self.samples_to_come}; use 0 or more samples a pixel")
        if self.sampler not in SAMPLERS:
            raise InputError(f"sampler: {self.sampler!r}; use one of {', '.join(map(repr, SAMPLERS))}")
        if self.sampler == "pixel":
            if self.min_pixel_width:
                raise InputError("min_pixel_width with sampler 'pixel': the pixel sampler finds a pixel's coverage "
                                 "from its samples, so widening strands would count them twice; turn one off")
        if self.shadow_mode not in ("hard", "transmittance"):
            raise InputError(f"shadow_mode: {self.shadow_mode!r}; use 'hard' or 'transmittance'")
        shading_model(self.shading)
        if not 1 <= self.layers <= 64:
            raise InputError(f"layers: {self.layers}; use 1..64")
        if not 1 <= len(self.lights) <= MAX_LIGHTS:
            raise InputError(f"lights: {len(self.lights)} given; use 1..{MAX_LIGHTS}")
        for light in self.lights:
            light.check()
        if not 1.0 <= self.min_pixel_width_cap <= GRID_WIDEN_CAP:
            raise InputError(f"min_pixel_width_cap: {self.min_pixel_width_cap}; use 1..{GRID_WIDEN_CAP}")
        if len(self.background) != 4 or not np.all(np.isfinite(self.background)):
            raise InputError(f"background: {self.background}; expected four finite numbers (RGBA)")
        if self.tile < 16:
            raise InputError(f"tile: {self.tile}; use >= 16 pixels")
        for name in ("ambient", "diffuse", "specular", "shininess"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise InputError(f"{name}: {value}; use a finite number >= 0")
        self._check_hair()

    def _check_hair(self):
        if self.hair_color not in HAIR_COLORS:
            raise InputError(f"hair_color: {self.hair_color!r}; use one of {', '.join(map(repr, HAIR_COLORS))}")
        for name in ("hair_melanin", "hair_melanin_redness", "hair_roughness", "hair_radial_roughness",
                     "hair_coat"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"{name}: {value}; use 0..1 (as Cycles' Principled Hair BSDF)")
        if not (np.isfinite(self.hair_ior) and 1.0 <= self.hair_ior <= 3.0):
            raise InputError(f"hair_ior: {self.hair_ior}; use 1..3 (hair keratin: 1.55)")
        if not (np.isfinite(self.hair_cuticle_tilt) and -90.0 <= self.hair_cuticle_tilt <= 90.0):
            raise InputError(f"hair_cuticle_tilt: {self.hair_cuticle_tilt}; use -90..90 degrees (hair: 2 to 4)")

    def premultiplied_background(self):
        r, g, b, a = (float(x) for x in self.background)
        return (r * a, g * a, b * a, a)


# What rays walk (Renderer(accel=...)): the thesis's uniform grid (tracer/grid.py) or a BVH
# over cylinder pieces (tracer/bvh.py). Same hits, same image (the tests render both). The
# default is the one that measured faster on the benchmark scenes (benchmarks/sections/accel.py,
# llvmpipe, 512², CPU time): the grid; the BVH took 1.27x its time on the real straight.hair,
# 1.5x on 1,000 and 10,000 wavy strands and 1.17x on 100,000 (1.0-1.6x over three runs on a
# shared machine), with 2-5x fewer cylinder tests per ray, and builds in numpy 1-3.4x slower.
# "beams" (tracer/beams.py): camera rays and shadow rays toward suns look up a bin of their
# family's beams, nearest first; other rays walk the grid, built only when some ray needs it.
ACCELS = ("beams", "grid", "bvh")
DEFAULT_ACCEL = "beams"

# The grid lists every cylinder with its radius times this factor, so minimum pixel width can
# widen a radius up to it without hits falling outside the cells the cylinder is listed in.
GRID_WIDEN_CAP = 8.0
