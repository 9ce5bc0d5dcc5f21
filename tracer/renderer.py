# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU tracer: one standalone OpenGL 3.3 core context per process (tracer/gl_state.py),
scene data in buffer textures (tracer/scene_buffers.py), one fragment shader that traces
every pixel (tracer/draw.py).

`Renderer` only says what happens in which order; each job has its module: the two upload
paths (tracer/strand_upload.py), the acceleration structure (the grid, tracer/scene_grid.py,
or the BVH, tracer/scene_bvh.py), meshes (tracer/meshes.py, tracer/mesh_upload.py), drawing
(tracer/draw.py).
Only `set_strands`/`update_strands` upload; a render with a new camera, light or setting
sends uniforms and nothing else (`stats.bytes_uploaded` proves it).
"""
import dataclasses
import time

import numpy as np

from hairio import InputError, Strands

from . import layout
from .cylinders import column_bounds, plan_cylinders, points_reach
from .draw import Drawer, screen_bounds, sun_slots_within
from .gl_state import context_backend, shared_context
from .gpu_build import compute_available
from .grid import refs_per_cylinder
from .meshes import mesh_set
from .mesh_upload import upload_meshes
from .scene_buffers import SceneBuffers
from .scene_bvh import build_scene_bvh, bvh_bounds
from .scene_beams import BeamPlan, BeamState, beam_scene_box, camera_beams, sun_beams, sun_slots
from .scene_grid import build_scene_grid, build_wide_grid, grid_indices, grid_refs, lists_capacity
from .settings import ACCELS, DEFAULT_ACCEL, GRID_WIDEN_CAP, RenderSettings, pixel_group
from .stats import RenderStats
from .strand_upload import GpuUpload, NumpyUpload, Scene, select_strands

BUILDS = ("auto", "gpu", "numpy")
# A render builds the grid again, finer, when its rays pay for more than this many times the
# references per cylinder of the grid there (tracer/grid.py, refs_per_cylinder): 1,000,000
# wavy strands, 16 samples at 512x512 (a build of 18.6 s saves 4 s a sample), not 4 samples;
# a scene of fewer cylinders, whose grid aims at 8 already, never (12 at most).
REFINE_GRID = 1.5


class Renderer:
    """GPU tracer of one scene at a time; `stats` (tracer.stats.RenderStats) says what it
    did."""

    def __init__(self, max_buffer_texels=None, build="auto", accel=DEFAULT_ACCEL):
        """`max_buffer_texels`: the most texels one buffer texture may hold (default: the
        driver's GL_MAX_TEXTURE_BUFFER_SIZE, 2^27 on llvmpipe and current desktop GPUs, i.e.
        33 M cylinders or 134 M grid references); the cylinders and the grid's lists are split
        over up to layout.MAX_BUFFER_PARTS buffers past it (tracer/scene_buffers.py), and
        scenes past that get an InputError.
        `build`: where cylinders and grid are made — "gpu" (compute shaders, GL 4.3+),
        "numpy", or "auto" (the GPU where the driver has compute shaders).
        `accel`: what rays walk — "beams" (tracer/beams.py: camera rays and shadow rays toward
        suns look up their family's bins; other rays walk the grid, built only when some ray
        needs it; built by the compute passes, so with the numpy build the grid instead),
        "grid" (tracer/grid.py) or "bvh" (tracer/bvh.py, built in numpy whatever the build)."""
        self.ctx = shared_context()
        if accel not in ACCELS:
            raise InputError(f"accel: expected one of {', '.join(ACCELS)}, got {accel!r}")
        if build not in BUILDS:
            raise InputError(f"build: expected one of {', '.join(BUILDS)}, got {build!r}")
        if build == "gpu" and not compute_available(self.ctx):
            raise InputError(f"build: 'gpu' needs compute shaders (OpenGL 4.3); this driver offers "
                             f"{self.ctx.info['GL_VERSION']}; use 'numpy' or 'auto'")
        self.build = "numpy" if build == "numpy" or not compute_available(self.ctx) else "gpu"
        # Beams are built by the compute passes (a camera or light change then uploads nothing);
        # with the numpy build every ray walks the grid.
        if accel == "beams" and self.build == "numpy":
            accel = "grid"
        self.accel = accel
        self.stats = RenderStats(gl_backend=context_backend(), accel=accel)
        self.buffers = SceneBuffers(self.ctx, max_buffer_texels or self.ctx.info["GL_MAX_TEXTURE_BUFFER_SIZE"],
                                    self.stats)
        self.scene = Scene()
        self.meshes = None          # tracer.meshes.MeshSet, or None
        self.mesh_grid = None
        self._upload = GpuUpload(self.buffers) if self.build == "gpu" else NumpyUpload(self.buffers)
        self._drawer = Drawer(self.ctx)
        self._widened_last = False   # the last render asked for minimum pixel width (set_strands)
        self.beam_state = BeamState()   # accel "beams": the beams kept between renders

    @property
    def max_buffer_texels(self):
        return self.buffers.max_texels

    # --- the scene ----------------------------------------------------------------------
    @property
    def strands(self):
        return self.scene.strands

    @property
    def num_cylinders(self):
        """Cylinders of the scene; None until set_strands."""
        return self.scene.num_cylinders

    @property
    def grid(self):
        return self.scene.grid

    @property
    def bvh(self):
        return self.scene.bvh

    @property
    def all_opaque(self):
        return self.scene.all_opaque

    @property
    def cylinders(self):
        """The scene's tracer.cylinders.Cylinders. The GPU build never needs them on the CPU,
        so there they are made on first access (for tests and tools), not on upload."""
        return self.scene.cylinders

    def grid_indices(self):
        """The grid's cell lists as int32 (read back from the GPU when built there)."""
        return grid_indices(self.scene.grid, self.buffers)

    def set_strands(self, strands):
        """Upload `strands` (hairio.Strands) and build the grid. Strands the tracer cannot
        resolve are refused before anything changes; when the upload itself fails (a scene
        too large for the driver's buffers), the renderer holds no scene afterwards: a
        render says so instead of tracing half of one."""
        if not isinstance(strands, Strands):
            raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}; "
                             "build one with Strands.from_arrays")
        t0 = time.perf_counter()
        # One pass over the points for their bounds: the range checks' reach and the grid's
        # frame (with a plan that keeps every point) come from it.
        bounds = column_bounds(strands.points) if strands.num_points else None
        reach = points_reach(strands.points, bounds)
        check_gpu_range(strands, reach)
        plan = plan_cylinders(strands, drop_repeats=self._upload.drops_repeats, reach=reach)
        plan_s = time.perf_counter() - t0
        # New strands get an unpadded grid: renders on one padded for minimum pixel width
        # cost 15-30 % more. Minimum pixel width pads every one of its renders, so after one
        # the padding stays.
        if not self._widened_last:
            self.scene.grid_pad = 1.0
        self.scene.grid_aim = self.scene.grid_aim_failed = 0.0
        try:
            cylinders_s, upload_s, bounds = self._upload.set(self.scene, strands, plan, bounds)
            self._finish_upload(plan_s + cylinders_s, upload_s, bounds)
        except Exception:
            self.scene.forget()
            raise

    def set_meshes(self, meshes):
        """Opaque triangle meshes beside the strands: a list of (vertices (V,3), triangles
        (F,3) int, rgb), each optionally followed by a name for messages; [] or None for
        none. Checked where they enter (tracer/meshes.py: InputError naming the mesh for
        NaN, indices outside its vertices, no faces, ...), then uploaded as float32 with a
        grid of their own; they stay until the next set_meshes, whatever the strands do.
        They hide hair from the camera and the lights, take the hair's shadows and cast
        their own, and are shaded diffusely with their colour."""
        t0 = time.perf_counter()
        checked = mesh_set(meshes)      # nothing changes when this refuses them
        self.meshes = self.mesh_grid = None
        if checked is not None:
            self.mesh_grid = upload_meshes(self.buffers, checked)
            self.meshes = checked
        self.stats.num_triangles = 0 if checked is None else len(checked)
        self.stats.mesh_s = time.perf_counter() - t0

    def update_strands(self, strand_ids, strands):
        """`strands` is the whole new set; only strands `strand_ids` changed. When their point
        counts are unchanged, only their data is re-uploaded (their cylinders with the numpy
        build, their points with the GPU build, which then remakes just their cylinders; in
        chunks of UPLOAD_CHUNK) and the grid is rebuilt; otherwise everything is uploaded
        again. As in set_strands, changed strands the tracer cannot resolve are refused
        before anything changes, and a failed upload leaves no scene."""
        scene = self.scene
        if scene.strands is None or not isinstance(strands, Strands) \
                or not np.array_equal(strands.counts, scene.strands.counts):
            self.set_strands(strands)
            return
        ids = np.unique(np.asarray(strand_ids, np.int64))
        if ids.size and (ids[0] < 0 or ids[-1] >= strands.num_strands):
            raise InputError(f"strand_ids: values must lie in [0, {strands.num_strands}); got {ids.min()}..{ids.max()}")
        if not ids.size:
            scene.strands = strands
            return
        t0 = time.perf_counter()
        changed = select_strands(strands, ids)
        check_gpu_range(changed)
        sub = plan_cylinders(changed)
        if not np.array_equal(sub.counts, scene.plan.counts[ids]):
            self.set_strands(strands)    # a repeated point appeared or vanished
            return
        plan_s = time.perf_counter() - t0
        # The same points per strand are left: point and cylinder numbering are unchanged.
        # A scene with no cylinders has none to make on the GPU: the numpy path keeps it.
        upload = self._upload if scene.num_cylinders else NumpyUpload(self.buffers)
        try:
            cylinders_s, upload_s = upload.update(scene, ids, strands, sub)
            self._finish_upload(plan_s + cylinders_s, upload_s, refit=True)
        except Exception:
            scene.forget()
            raise

    def _finish_upload(self, cylinders_s, upload_s, bounds=None, refit=False):
        """Builds the acceleration structure after an upload (`refit`: the cylinders moved
        but kept their ids, so a BVH keeps its tree) and records the upload's stats."""
        grid_upload_s = self._build_structure(bounds, refit)
        self.stats.cylinders_s = cylinders_s
        self.stats.upload_s = upload_s + grid_upload_s
        self.stats.num_cylinders = self.scene.num_cylinders

    def _build_structure(self, bounds=None, refit=False):
        """The grid or the BVH of the scene, built and uploaded; the seconds uploading. With
        beams nothing is built here: a render builds the beams it needs (and the grid, when
        some ray needs one)."""
        if self.accel == "beams":
            self.scene.grid = self.scene.bvh = self.scene.wide_grid = None
            self.scene.box = beam_scene_box(self.scene.plan, bounds, GRID_WIDEN_CAP) if self.scene.num_cylinders \
                else None
            self.beam_state.forget()
            self.stats.grid_s = self.stats.accel_s = 0.0
            self.stats.accel_bytes = 0
            return 0.0
        if self.accel == "grid":
            self.scene.bvh = None
            upload_s = build_scene_grid(self.scene, self.buffers, self.build == "gpu", bounds)
            g = self.scene.grid
            self.stats.accel_s = self.stats.grid_s
            self.stats.accel_bytes = 4 * self.stats.grid_refs + 8 * g.num_cells
            return upload_s
        self.scene.grid = None
        return build_scene_bvh(self.scene, self.buffers, refit)

    def _wide_grid(self):
        """The grid the pixel sampler walks: the scene's own when that is padded already
        (after minimum pixel width), else its wide grid beside it, built on first use after
        new strands (tracer/scene_grid.py, build_wide_grid), so the renders of the other
        samplers and every shadow ray keep the shorter lists. None (pad the scene's grid
        instead) when the wide lists outgrow one buffer texture."""
        scene = self.scene
        if scene.grid_pad >= GRID_WIDEN_CAP or not scene.num_cylinders:
            return scene.grid
        if scene.wide_grid is None:
            t0 = time.perf_counter()
            try:
                build_wide_grid(scene, self.buffers, self.build == "gpu", GRID_WIDEN_CAP)
            except InputError:
                return None
            self.stats.grid_rebuilds += 1
            self.stats.wide_grid_s = time.perf_counter() - t0
            self.stats.wide_grid_refs = grid_refs(scene.wide_grid)
        return scene.wide_grid

    @property
    def structure(self):
        """The scene's grid or BVH, whichever `accel` asked for (with beams the grid, or None
        while no ray has needed it)."""
        return self.scene.bvh if self.accel == "bvh" else self.scene.grid

    def _grid_aim(self, settings, box):
        """Whether this render's rays (`settings.spp` a pixel of pixel box `box`) pay for a
        finer grid than the scene's: the references per cylinder to aim at (tracer/grid.py,
        refs_per_cylinder), or 0.0 where the grid there is (or would be) within REFINE_GRID of
        that or its lists outgrew the buffers at that aim before."""
        scene = self.scene
        count = scene.num_cylinders
        aim = refs_per_cylinder(count, settings.spp * (box[2] - box[0]) * (box[3] - box[1]),
                                lists_capacity(self.buffers, "tex_idx"))
        if scene.grid_aim_failed and aim >= scene.grid_aim_failed:
            return 0.0
        return aim if aim > REFINE_GRID * (scene.grid_aim or refs_per_cylinder(count)) else 0.0

    def _grid_for_beams(self, settings, box):
        """With beams: the scene's grid, built now if it is not there yet (some ray needs it)
        or finer where this render's rays pay for it (_grid_aim), padded for minimum pixel
        width where that is on."""
        scene = self.scene
        if settings.min_pixel_width and scene.grid_pad < GRID_WIDEN_CAP:
            scene.grid_pad = GRID_WIDEN_CAP
            scene.grid = None
        aim = self._grid_aim(settings, box) if scene.num_cylinders and box is not None else 0.0
        if aim:
            scene.grid_aim, scene.grid = aim, None
        if scene.grid is None and scene.num_cylinders:
            upload_s = build_scene_grid(scene, self.buffers, self.build == "gpu")
            self.stats.upload_s += upload_s
            self.stats.grid_rebuilds += 1
        return scene.grid

    def _beam_plan(self, camera, settings, box):
        """What a render with beams walks (tracer/scene_beams.py, BeamPlan): the camera's
        beams over the traced pixels `box`, sun beams for the shadowed suns, and the grid
        where some ray is left to it; records what it built in the stats."""
        st, state = self.stats, self.beam_state
        ox, oy = camera.pixel_origin
        whole = (box[0] + ox, box[1] + oy, box[2] + ox, box[3] + oy)
        pad = GRID_WIDEN_CAP if settings.min_pixel_width else 1.0
        pixel_n = settings.spp_n if settings.sampler == "pixel" else 0
        cam, shift, cam_s = camera_beams(state, self.scene, self.buffers, camera, whole, pad, settings.spp, pixel_n)
        slots = sun_slots(settings, sun_slots_within(self.ctx.info["GL_MAX_TEXTURE_IMAGE_UNITS"]))
        shadowed = [settings.shadows and light.shadows for light in settings.lights]
        # Whether the grid is built for this render whatever the suns get: then a sun's beams
        # must pay for themselves against it (scene_beams.SUN_REFS_PER_RAY).
        grid_anyway = cam is None or any(s and k < 0 for s, k in zip(shadowed, slots)) or self.scene.grid is not None
        area = (box[2] - box[0]) * (box[3] - box[1])
        traced = settings.spp * area
        rays = traced if grid_anyway else None
        suns, light_sun, sun_s = [None] * len(state.suns), [], 0.0
        for light, slot in zip(settings.lights, slots):
            if slot < 0:
                light_sun.append(-1)
                continue
            beams, s = sun_beams(state, self.scene, self.buffers, light, slot, rays, traced,
                                 settings.samples_to_come * area)
            sun_s += s
            suns[slot] = beams
            light_sun.append(slot if beams is not None else -1)
        walks = shadow_walks(settings, self.effective_layers(settings), self.meshes is not None)
        light_sun = within_walk_steps(light_sun, suns, walks)
        state.renders += 1
        state.traced += traced
        plan = BeamPlan(cam, suns, light_sun, shift)
        st.beams_s, st.camera_beams_s, st.sun_beams_s = cam_s + sun_s, cam_s, sun_s
        st.camera_beams = (("pixel centres" if cam.frame.centres else f"{cam.frame.bin_px} px bins") if cam is not None
                           else f"none: {state.camera_why}")
        st.camera_beam_refs = cam.refs if cam is not None else 0
        st.sun_beam_refs = sum(b.refs for b in suns if b is not None)
        st.beam_refs = st.camera_beam_refs + st.sun_beam_refs
        return plan, cam is None or any(s and k < 0 for s, k in zip(shadowed, light_sun))

    # --- rendering ----------------------------------------------------------------------
    def effective_layers(self, settings):
        """One layer when every alpha is 1 and nothing lowers it (minimum pixel width does)."""
        if self.scene.all_opaque and not settings.min_pixel_width:
            return 1
        return settings.layers

    def sampler_for(self, settings):
        """`settings`, or where the pixel sampler cannot keep one sample's layers, the same
        with the independent sampler. With more than one layer (see-through hair) one walk
        of the pixel sampler keeps a list of layout.PIXEL_LIST distinct cylinders, and its
        samples may need up to samples × layers of them, so a pixel's samples are walked in
        groups small enough for the list (settings.pixel_group: 16 samples × 4 layers in four
        walks of 4); one list ran over on dense see-through hair and samples lost their far
        layers (straight.hair, alpha 0.64, 16 samples × 4 layers: mean alpha 0.75 against
        0.90; a longer list runs into llvmpipe's loop cap). Opaque hair (one layer) keeps a
        nearest hit per sample and never runs over."""
        layers = self.effective_layers(settings)
        if settings.sampler == "pixel" and not pixel_group(settings.spp, layers):
            return dataclasses.replace(settings, sampler="independent")
        return settings

    def screen_bounds(self, camera):
        """Pixel rectangle (x0, y0, x1, y1), y from the top, that the strands' structure box
        (grid or BVH) and the meshes' box can cover; None when nothing can be seen."""
        strands_box = None
        if self.scene.num_cylinders:
            strands_box = {"beams": lambda: self.scene.box, "grid": lambda: (self.scene.grid.lo, self.scene.grid.hi),
                           "bvh": lambda: bvh_bounds(self.scene.bvh)}[self.accel]()
        boxes = [b for b in (strands_box, (self.mesh_grid.lo, self.mesh_grid.hi) if self.meshes is not None
                             else None) if b is not None]
        if not boxes:
            return None
        return screen_bounds(np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0), camera)

    def render(self, camera, settings=None):
        """(H, W, 4) float32 linear RGBA, premultiplied, row 0 = top of the image."""
        settings = settings or RenderSettings()
        settings.check()
        if self.scene.num_cylinders is None:
            raise InputError("render: no strands; call set_strands first")
        self._drawer.check_camera(camera, settings)
        t0 = time.perf_counter()
        settings = self.sampler_for(settings)
        self._widened_last = settings.min_pixel_width
        pixel = settings.sampler == "pixel"
        box = self.screen_bounds(camera)
        beams, walk = None, True
        if self.accel == "beams" and box is not None:
            if self.scene.num_cylinders:
                beams, walk = self._beam_plan(camera, settings, box)
                if walk:
                    self._grid_for_beams(settings, box)
            else:       # meshes alone: no strand to walk at all
                beams, walk = BeamPlan(None, [None] * len(self.beam_state.suns), [-1] * len(settings.lights)), False
        # The pixel sampler walks its grid only for camera rays (with beams, when the camera
        # has none).
        grid_camera = self.accel == "grid" or (self.accel == "beams" and (beams is None or beams.camera is None))
        wide = self._wide_grid() if pixel and grid_camera and self.scene.grid is not None else None
        # Minimum pixel width widens strands, and the pixel sampler's samples stray up to a pixel
        # from the ray it walks: both want every cylinder listed where its widened capsule
        # reaches. The pixel sampler gets a grid of its own beside the scene's (_wide_grid),
        # unless that does not fit one buffer; a BVH's pixel walk grows each box by the
        # samples' reach itself (shaders/accel_bvh.glsl), so its boxes stay as they are.
        padded_for_pixel = pixel and wide is None and grid_camera and self.scene.grid is not None
        if (settings.min_pixel_width or padded_for_pixel) and self.scene.grid_pad < GRID_WIDEN_CAP \
                and self.accel != "beams":
            self.scene.grid_pad = GRID_WIDEN_CAP
            self._build_structure(refit=True)      # a BVH keeps its tree: wider boxes only
            self.stats.grid_rebuilds += 1
        elif padded_for_pixel and self.scene.grid_pad < GRID_WIDEN_CAP:
            self.scene.grid_pad = GRID_WIDEN_CAP
            self.scene.grid = None
            self._grid_for_beams(settings, box)
        elif self.accel == "grid" and box is not None and self.scene.num_cylinders:
            aim = self._grid_aim(settings, box)
            if aim:
                self.scene.grid_aim = aim
                self._build_structure()
                self.stats.grid_rebuilds += 1
        layers = self.effective_layers(settings)
        mesh_offset = 0.0 if self.meshes is None else self.meshes.shadow_offset()
        img, counts = self._drawer.draw(self.buffers, self.structure if walk else None, camera, settings, layers,
                                        box, self.mesh_grid, mesh_offset, wide, beams)
        st = self.stats
        st.render_s = time.perf_counter() - t0
        st.renders += 1
        st.layers_max = layers
        st.screen_box = box
        st.traversed_pixels = 0 if box is None else (box[2] - box[0]) * (box[3] - box[1])
        if settings.count:
            st.shadow_rays, st.layers_traced, st.cells_visited, st.cylinder_tests = (int(c) for c in counts)
        return img


def shadow_walks(settings, layers, meshes=False):
    """Shadow rays one invocation of the trace casts toward each light at the most: one a layer
    of its sample, or the pixel sampler's shaded strands' (tracer/layout.py, PIXEL_SHADE) and
    one more; with `meshes` one more, from the mesh behind."""
    if settings.sampler != "pixel":
        return layers + int(meshes)
    return (2 if layers == 1 else layout.PIXEL_SHADE + 1) + int(meshes)


def within_walk_steps(light_sun, suns, walks):
    """`light_sun` (per light, its beam set or -1) with the sets whose lists are longest left
    to the grid (-1) until `walks` walks of each remaining set's longest list, runs of
    BEAM_RUN entries included, take no more than layout.BEAM_WALK_STEPS loop steps: llvmpipe
    stops every loop of an invocation once they have taken 65,535 steps between them, which
    would drop a sample's farther layers."""
    used = sorted({k for k in light_sun if k >= 0})

    def steps():
        return walks * sum(suns[k].longest for k in used) * (1.0 + 1.0 / layout.BEAM_RUN)
    while used and steps() > layout.BEAM_WALK_STEPS:
        worst = max(used, key=lambda k: suns[k].longest)
        used.remove(worst)
        light_sun = [-1 if k == worst else k for k in light_sun]
    return light_sun


def check_gpu_range(strands, reach=None):
    """InputError when strands lie farther from the origin than the GPU's float32 arithmetic
    can square (layout.MAX_POINT_COORDINATE), naming how far they reach. `reach`:
    cylinders.points_reach of their points when the caller has it."""
    if not strands.num_points:
        return
    far = (points_reach(strands.points) if reach is None else reach) + float(strands.radius.max())
    if not far <= layout.MAX_POINT_COORDINATE:
        raise InputError(f"points: coordinates reach {far:.3g}; the GPU tracer squares distances in float32, so "
                         f"it takes strands within ±{layout.MAX_POINT_COORDINATE:.0e} of the origin: scale them down "
                         "(and the camera with them) or recentre them")
