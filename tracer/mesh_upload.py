# SPDX-License-Identifier: GPL-3.0-or-later
"""Meshes to the GPU: their triangles (tracer/layout.py's triangle texels), their grid
(tracer/mesh_grid.py) and its cell table, into the scene's buffers tex_tri, tex_mesh_idx
and tex_mesh_cell."""
import numpy as np

from . import layout
from .mesh_grid import build_mesh_grid

MESH_BUFFERS = ("tex_tri", "tex_mesh_idx", "tex_mesh_cell")


def upload_meshes(buffers, mesh_set):
    """Uploads a tracer.meshes.MeshSet; returns its grid."""
    grid = build_mesh_grid(mesh_set)
    buffers.upload("tex_tri", layout.triangle_texels(mesh_set.corners, mesh_set.color), 4, "f4")
    buffers.upload("tex_mesh_idx", grid.indices, 1, "i4", slack=layout.IDX_SLACK)
    cells = np.stack([grid.cell_start, grid.cell_count], axis=1).astype(np.int32)
    buffers.upload("tex_mesh_cell", cells, 2, "i4")
    return grid
