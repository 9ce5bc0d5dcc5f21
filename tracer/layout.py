# SPDX-License-Identifier: GPL-3.0-or-later
"""The one rule set the numpy side and the shaders share: constants of the cylinder rules,
the grid's limits and the layouts of the buffers both sides read or write.

Nothing here is copied into a shader. Every shader is compiled with `glsl_header()` after
its `#version` line (tracer/shader_source.py), generated from the values below when the
program is made, and the Python side reads them as `layout.NAME` at the call, not as a
name bound at import: change one here (a test sets the bend to 88°) and the numpy build,
the compute build, the trace shader and the references all follow.
"""
import numpy as np

# --- Coordinates the GPU can square ---------------------------------------------------------
# The shaders square distances in float32 (3.4e38 = (1.8e19)^2): past these a hit's
# arithmetic overflows and the image comes out empty while the float64 reference shows hair
# (a strand 1e20 from the origin did). Points (strands, meshes) within 1e18 seen from a
# camera within 1e19 keep every squared distance finite (measured: hair at 1e18 and cameras
# out to 3e19 render as the reference does).
MAX_POINT_COORDINATE = 1e18
MAX_CAMERA_COORDINATE = 1e19

# --- Cylinder rules (SPEC §6; tracer/cylinders.py says why) ---------------------------------
# Past this angle between two axes the shared plane would cut an unbounded piece: both
# cylinders end on a cap square to their own axis instead.
SHARP_BEND_DEG = 80.0
# Cap flags of a cylinder (its N2 texel's w): plane 1 / plane 2 is an end cap, not a joint.
CAP_PLANE1 = 1
CAP_PLANE2 = 2

# --- Cylinder buffer: per cylinder, TEXELS_PER_CYL consecutive RGBA32F texels ---------------
# 64 bytes, one cache line, so a cylinder test on a CPU driver touches one line.
#   TOP: xyz top, w radius   TIP: xyz tip, w alpha   N2: xyz unit normal of plane 2, w cap
#   flags   COL: rgb colour
CYL_TEXELS = ("TOP", "TIP", "N2", "COL")
TEXELS_PER_CYL = len(CYL_TEXELS)

# --- Buffers past the driver's limit ---------------------------------------------------------
# The cylinder buffer and the grid's cell lists may hold more texels than one buffer texture
# of the driver (GL_MAX_TEXTURE_BUFFER_SIZE, 2^27 on llvmpipe: 33 M cylinders, 134 M list
# entries). Past it they continue in up to this many buffer textures in all (tex_cyl,
# tex_cyl1, ...; tex_idx, tex_idx1, ...), each full but the last; a shader picks the one
# holding an id by comparing it with the parts' size (tracer/scene_buffers.py).
MAX_BUFFER_PARTS = 4

# --- Triangle buffer (meshes): per triangle, TEXELS_PER_TRI consecutive RGBA32F texels ------
#   V0: xyz corner 0, w red   V1: xyz corner 1, w green   V2: xyz corner 2, w blue
TRI_TEXELS = ("V0", "V1", "V2")
TEXELS_PER_TRI = len(TRI_TEXELS)
# A ray meets a triangle where its barycentric coordinates are each >= -TRI_EDGE_EPS and sum
# to <= 1 + TRI_EDGE_EPS: a sliver of overlap, so float32 rounding on a shared edge cannot
# open a crack between two triangles (both sides test the same rule).
TRI_EDGE_EPS = 1e-6
# Shadow rays leave a mesh this many times its box's diagonal off the surface (and ignore
# the triangle they leave), so a surface does not shadow itself through rounding.
MESH_SHADOW_OFFSET = 1e-5

# --- Grid -------------------------------------------------------------------------------------
MAX_DIM = 1024          # cells per axis; 3D textures of GL 3.3 guarantee 256, every driver we target >= 2048
MAX_CELLS = 1 << 23     # cells in all (the cell table is one buffer texel each)
BLOCK = 4               # cells per side of the empty-space-skipping blocks
# The trace shader reads up to two list entries past a cell's list (it reads ahead); the
# index buffer carries this many zeros after the last list.
IDX_SLACK = 2
# Cell table: per cell (id x + nx*(y + ny*z)) one ivec2 texel, x = first slot of its list
# (EMPTY_BLOCK: the whole BLOCK³ block of this cell is empty), y = list length.
EMPTY_BLOCK = -1

# --- BVH (tracer/bvh.py, shaders/accel_bvh.glsl) ---------------------------------------------
# Pieces per leaf at most; a leaf's code in the walk's texels is first << LEAF_BITS | count.
LEAF_MAX = 4
LEAF_BITS = 3
# A piece's code in tex_order's y: k | K << PIECE_BITS (piece k of K of its cylinder's axis).
PIECE_BITS = 8
MAX_PIECES = 8
# RGBA32I texels per entry (node or leaf) of the walk: (lo, skip) (hi, leaf code or BVH_NODE).
WALK_TEXELS = 2
BVH_NODE = -1
# Slots of the primary rays' near-first walk's stack (kept in registers; shaders/accel_bvh.glsl).
BVH_SHORT_STACK = 16

# --- Beams (tracer/beams.py, shaders/accel_beams.glsl, shaders/beams_build.glsl) -----------
# A beam entry is one 32-bit word: the cylinder id in its low bits, the depth slice of its key
# above them: one of BEAM_SLICES slices over the scene's depth range cut into 2^sub finer ones,
# and a list is in order of those. sub is at most what the scene's cylinder ids leave
# (beam_sub_bits; ids take BEAM_ID_BITS - sub bits, 26: 67 M cylinders), and no more than
# keeps BEAM_REFS_PER_FILL references a fine slice filled (tracer/beams.py, fine_bits): the
# compute passes fill a list's fine slices one dispatch each, which costs more than the
# shorter walks save where the lists are short.
BEAM_ID_BITS = 26
BEAM_SLICES = 64
BEAM_SUB_BITS_MAX = 6
BEAM_REFS_PER_FILL = 65536
# The other way to fill (tracer/beams.py, fill_plan): the cylinders in id order in one
# dispatch, then each bin's entries sorted by fine slice. It reads the cylinders in their own
# order (the fill by fine slice reads them scattered, a cache miss each) and costs a sort of
# every entry: it pays where most cylinders are listed (the fill goes over them all) in at
# most BEAM_SORT_REFS_PER_CYLINDER references each. Its fine slices: no more of them than
# BEAM_SORT_SLICES_PER_ENTRY times the lists' entries a bin (the sort's work per bin goes over
# them all), at most BEAM_SLICES << BEAM_SORT_SUB_BITS_MAX (a sort's counters, 2 KB).
# Entries with marks (two uint32 each, tracer/gpu_beams.py) take BEAM_SORT_REFS_PER_MARKED
# instead: their sort moves twice the bytes and was slower at every count measured (none).
BEAM_SORT_REFS_PER_CYLINDER = 5.0
BEAM_SORT_REFS_PER_MARKED = 0.0
BEAM_SORT_SLICES_PER_ENTRY = 1.0
BEAM_SORT_SUB_BITS_MAX = 3
# References one family's lists may hold (one buffer texture's worth and then some room).
BEAM_MAX_REFS = 96_000_000
# Bins one family may have (its bin table is one ivec2 texel a bin).
BEAM_MAX_BINS = 1 << 22
# The scan of the bins' counts (beams_build.glsl) sums this many bins per invocation.
BEAM_SCAN_CHUNK = 256
# The listing's own margin, in bins: covers the float32 rounding of the shaders' projection
# (bins are compared with coordinates of at most a few thousand bins).
BEAM_BIN_EPS = 1e-3
# Radians a capsule must lie past a spot light's cone for its lists to leave it out
# (tracer/beams.py, outside_cone): the GPU's float32 and the host's float64 then agree.
BEAM_CONE_MARGIN = 1e-3
# A key is filed this fraction of a slice low, so that float32 rounding cannot put an entry in
# a slice that starts past its key (the walks stop at a slice's start).
BEAM_SLICE_EPS = 1e-4
# A capsule nearer the camera's plane than this fraction of the scene's depth range, or one
# whose listing could take more than this many bins, leaves the family without beams (its
# rays walk the grid): tracer/beams.py, BeamsUnfit.
BEAM_NEAR_FRACTION = 1e-4
BEAM_MAX_BINS_PER_CYLINDER = 4096

# --- Pixel sampler (RenderSettings.sampler "pixel", shaders/sampler_pixel.glsl) -------------
# The most distinct cylinders one walk may keep: a walk of g samples with layers keeps
# g × layers (all its samples can see; with one layer each sample keeps its own nearest
# instead), so g × layers may not pass this (the list's loops are unrolled; at 40 and 48 slots
# they were not, and llvmpipe's loop cap ended the walks; walks of 8 samples × 4 layers cost
# as much as twice as many walks of 4); cylinders shaded per walk, the heaviest, each with its
# own shadow rays (one more, drawn by weight, stands for the rest); with one layer, strands
# shaded per walk (every one a walk of 16 samples meets), with one set of shadow rays from
# one of them drawn by its light (and one more standing for the rest); the most samples one
# walk takes (a sample is a bit of a 32-bit mask; 5² = 25; a pixel with more takes several
# walks: settings.pixel_group). Measured choices: docs/DECISIONS.md, "Samples of one pixel
# share the walk".
PIXEL_LIST = 24
PIXEL_SHADE = 4
PIXEL_SHADE_ONE = 16
PIXEL_MAX_SPP = 25

# --- Compute passes (GL 4.3) -----------------------------------------------------------------
GROUP = 64                  # local_size_x of the build shaders
MAX_VISITS = 60000          # loop steps one invocation may take (llvmpipe stops at 65,535)
# Loop steps the shadow walks of one trace invocation may take through sun and light beams
# between them (renderer.within_walk_steps): llvmpipe counts the steps of all the loops of an
# invocation together and stops every loop at 65,535 (two loops of 40,000 steps: the second
# stopped after 17,000), which the camera's walk and the layers' loops share; a walk of a
# light's lists is a list's entries and its runs of BEAM_RUN at the most.
BEAM_WALK_STEPS = 48_000
BEAM_RUN = 32               # entries a beam walk's run takes (shaders/accel_beams.glsl; a uint's bits at most)
MAX_REPEATS = 4096          # repeated-point candidates one cylinder pass reports


def cos_sharp():
    """cos(SHARP_BEND_DEG): joints whose axes meet at a smaller cosine are caps."""
    return float(np.cos(np.radians(SHARP_BEND_DEG)))


def beam_sub_bits(n):
    """The most bits of finer slices (above) the beam entries of a scene of `n` cylinders hold."""
    return max(0, min(BEAM_SUB_BITS_MAX, BEAM_ID_BITS - max(int(n) - 1, 1).bit_length()))


def tan_sharp():
    """tan(SHARP_BEND_DEG): how far (in radii) a bent cylinder can reach past its tip."""
    return float(np.tan(np.radians(SHARP_BEND_DEG)))


def glsl_header():
    """`#define`s of every constant above, for the shaders (generated, never edited)."""
    values = {
        "SHARP_BEND_DEG": float(SHARP_BEND_DEG), "COS_SHARP": cos_sharp(),
        "CAP_PLANE1": CAP_PLANE1, "CAP_PLANE2": CAP_PLANE2,
        "TEXELS_PER_CYL": TEXELS_PER_CYL,
        **{f"CYL_{name}": slot for slot, name in enumerate(CYL_TEXELS)},
        "TEXELS_PER_TRI": TEXELS_PER_TRI, **{f"TRI_{name}": slot for slot, name in enumerate(TRI_TEXELS)},
        "TRI_EDGE_EPS": float(TRI_EDGE_EPS),
        "MAX_DIM": MAX_DIM, "MAX_CELLS": MAX_CELLS, "BLOCK": BLOCK, "IDX_SLACK": IDX_SLACK,
        "EMPTY_BLOCK": EMPTY_BLOCK,
        "LEAF_MAX": LEAF_MAX, "LEAF_BITS": LEAF_BITS, "PIECE_BITS": PIECE_BITS, "MAX_PIECES": MAX_PIECES,
        "WALK_TEXELS": WALK_TEXELS, "BVH_NODE": BVH_NODE, "BVH_SHORT_STACK": BVH_SHORT_STACK,
        "BEAM_ID_BITS": BEAM_ID_BITS, "BEAM_SLICES": BEAM_SLICES, "BEAM_SCAN_CHUNK": BEAM_SCAN_CHUNK,
        "BEAM_BIN_EPS": float(BEAM_BIN_EPS), "BEAM_CONE_MARGIN": float(BEAM_CONE_MARGIN),
        "BEAM_SLICE_EPS": float(BEAM_SLICE_EPS), "BEAM_RUN": BEAM_RUN,
        "PIX_SHADE": PIXEL_SHADE, "PIX_SHADE_ONE": PIXEL_SHADE_ONE, "GROUP": GROUP, "MAX_VISITS": MAX_VISITS, "MAX_REPEATS": MAX_REPEATS,
    }
    lines = ["// Generated from tracer/layout.py when the program is made: edit the numbers there."]
    lines += [f"#define {k} {_glsl_literal(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def _glsl_literal(v):
    if isinstance(v, float):
        text = repr(v)
        return text if ("." in text or "e" in text) else text + ".0"
    return str(int(v))


def cylinder_texels(c, a=0, b=None):
    """Cylinders a..b of `c` (tracer.cylinders.Cylinders) as RGBA float32 texels,
    TEXELS_PER_CYL per cylinder one after the other, in the CYL_TEXELS order."""
    b = len(c) if b is None else b
    out = np.zeros((b - a, TEXELS_PER_CYL, 4), np.float32)
    top, tip, n2, col = (CYL_TEXELS.index(k) for k in ("TOP", "TIP", "N2", "COL"))
    out[:, top, :3], out[:, top, 3] = c.top[a:b], c.radius[a:b]
    out[:, tip, :3], out[:, tip, 3] = c.tip[a:b], c.alpha[a:b]
    out[:, n2, :3], out[:, n2, 3] = c.n2[a:b], c.flags[a:b]
    out[:, col, :3] = c.color[a:b]
    return out.reshape(-1, 4)


def triangle_texels(corners, color):
    """Triangles as RGBA float32 texels, TEXELS_PER_TRI per triangle in the TRI_TEXELS order:
    `corners` (F, 3, 3) their corners, `color` (F, 3) their base colours."""
    out = np.zeros((len(corners), TEXELS_PER_TRI, 4), np.float32)
    out[:, :, :3] = corners
    out[:, :, 3] = color
    return out.reshape(-1, 4)


def cell_table(start, count, in_full_block):
    """(cells, 2) int32 of the cell table: each cell's first slot where its block holds any
    cylinder, EMPTY_BLOCK where it does not, and its list length."""
    cells = np.empty((len(count), 2), np.int32)
    cells[:, 0] = np.where(in_full_block, start, EMPTY_BLOCK)
    cells[:, 1] = count
    return cells


def leaf_code(first, count):
    """A leaf's code in the walk's texels: its first slot of tex_order and its piece count."""
    return (np.asarray(first, np.int64) << LEAF_BITS) | count


def piece_code(k, K):
    """Piece k of K of a cylinder's axis, as tex_order's y holds it."""
    return np.asarray(k, np.int64) | (np.asarray(K, np.int64) << PIECE_BITS)
