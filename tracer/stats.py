# SPDX-License-Identifier: GPL-3.0-or-later
"""What a Renderer did: times, bytes, the grid it built and the work of its last render."""
from dataclasses import asdict, dataclass
from typing import Optional


@dataclass
class RenderStats:
    """Renderer.stats. Cumulative: bytes_uploaded, uploads (a render adds nothing to
    either: only set_strands/update_strands upload), renders, grid_rebuilds. Of the last
    set_strands/update_strands: cylinders_s, upload_s, grid_s, num_cylinders and the grid's
    grid_build ("gpu" or "numpy"), grid_dims, grid_refs, cylinders_per_full_cell,
    full_cell_fraction, or the BVH's accel_s (build or refit), bvh_refit, bvh_entries (nodes
    and leaves), bvh_pieces; accel ("grid" or "bvh") and accel_bytes (the structure's
    buffers; for the grid its lists and cell table). Of the last set_meshes: num_triangles,
    mesh_s. Of the pixel sampler's wide grid (built on its first render of new strands,
    beside the scene's grid): wide_grid_s, wide_grid_refs. Of the last render with beams
    (accel "beams"): beams_s (seconds building beams; 0 when the last ones were kept), of
    which camera_beams_s and sun_beams_s, camera_beams (the camera's bin size, or why it has
    none and walks the grid), beam_refs (entries of the camera's and the suns' lists), of
    which camera_beam_refs and sun_beam_refs. Of the last render: render_s, layers_max (layers the shader was
    compiled for), screen_box and traversed_pixels (the projected bounds that were traced),
    and with RenderSettings(count=True) the counters shadow_rays, layers_traced,
    cells_visited, cylinder_tests (summed over samples; cells: grid cells, BVH boxes, or a
    ray of beams' bin and the list entries it reads; full intersection tests: a ray of beams
    whose entries come with marks, a sun's or a camera's whole bins, counts only the listed
    cylinders whose capsule holds its point). gl_backend: the shared context's
    (egl, glx, wgl or cgl). None: not measured yet."""
    gl_backend: str = ""
    bytes_uploaded: int = 0
    uploads: int = 0
    renders: int = 0
    grid_rebuilds: int = 0
    cylinders_s: float = 0.0
    upload_s: float = 0.0
    grid_s: float = 0.0
    render_s: float = 0.0
    num_cylinders: Optional[int] = None
    num_triangles: int = 0
    mesh_s: float = 0.0
    grid_build: Optional[str] = None
    grid_dims: Optional[tuple] = None
    grid_refs: Optional[int] = None
    cylinders_per_full_cell: Optional[float] = None
    full_cell_fraction: Optional[float] = None
    accel: str = ""
    accel_s: Optional[float] = None
    accel_bytes: Optional[int] = None
    bvh_refit: Optional[bool] = None
    bvh_entries: Optional[int] = None
    bvh_pieces: Optional[int] = None
    wide_grid_s: Optional[float] = None
    wide_grid_refs: Optional[int] = None
    beams_s: Optional[float] = None
    camera_beams: Optional[str] = None
    beam_refs: Optional[int] = None
    camera_beams_s: Optional[float] = None
    sun_beams_s: Optional[float] = None
    camera_beam_refs: Optional[int] = None
    sun_beam_refs: Optional[int] = None
    layers_max: Optional[int] = None
    screen_box: Optional[tuple] = None
    traversed_pixels: Optional[int] = None
    shadow_rays: Optional[int] = None
    layers_traced: Optional[int] = None
    cells_visited: Optional[int] = None
    cylinder_tests: Optional[int] = None

    def as_dict(self):
        """A plain dict of every field (for reports and the worker's answers)."""
        return asdict(self)
