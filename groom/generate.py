# SPDX-License-Identifier: GPL-3.0-or-later
"""Scalp + key strands + parameters -> a head of ordinary strands (SPEC §2–6).

`generate` is the one-shot form; `Generator` keeps what does not depend on the keys
(roots, frames, random numbers) and, when keys change, recomputes only the strands whose
wisp or neighbours use a changed key. Its result is bit-identical to a full regeneration
because every per-strand computation is element-wise (see interpolate.py). For the same
reason the work over strands can run in ranges on a pool of threads (parallel.py), and the
strands grow in blocks of at most BLOCK_STRANDS (so the per-point temporaries live for one
block, not the whole head), side by side on the threads once each block gets PARALLEL_BLOCK
strands, without changing a number. `BlockGenerator` hands the blocks over one
at a time and holds none of them, nor any per-root state: `generate_to_npz` writes a head
of any size to a file in the memory of one block.
"""
import mmap
import os
import shutil
import time
import warnings
from dataclasses import dataclass
from functools import partial

import numpy as np

from hairio import InputError, Strands
from hairio.atomic import check_destination
from hairio.npyfile import AppendBehind, NpzWriter
from hairio.strands import GUIDE_NPZ_NAMES, NPZ_NAMES
from hairio.validate import check_memory

from .cylinders import (adaptive_sigma, alpha_is_one, alpha_profile, fill_strand_rows, ones, radius_alpha_rows,
                        radius_profile, strand_attributes, strand_colors)
from .frames import frame_axes, root_frames
from .interpolate import (EXACT_SAMPLES, FINE_SAMPLES, KEY_SAMPLES, curvature_bound, evaluate_strands, key_offsets,
                          key_rows, lerp_errors, nested_table, table_samples, LERP_SHARE,
                          length_fractions, strand_transforms, tidiness_angles, uniform_sigma)
from .keys import KeyStrand
from .params import GroomParams
from .sampling import sample_roots
from .scalp import Scalp
from . import processes
from .parallel import MIN_SPLIT, cpu_threads, one_thread, ranges, run_each, run_jobs
from .collide import CollisionReport, CollisionStats, StrandCollision, first_pass, walk_into
from .shaping import clump_arguments, shape_strands, shaping_bound
from .wisps import check_groups, guide_weights_by_guide, root_groups_for


@dataclass(frozen=True, eq=False)
class GroomResult:
    """strands: hairio.Strands (wisp = main key index); roots (S,3) float64; root_uv (S,2) or
    None; guides (S,3) int32 (main, n1, n2 key index); guide_weights (S,3) float32;
    root_ids (S,) int64 (stable per-root ids seeding each strand's random stream);
    root_tri (S,), root_bary (S,3): where each root lies on the scalp; collision: a
    collide.CollisionReport, or None when no collider was given; warning: what the adaptive
    resolution could not meet (strands the cylinder cap stopped short of the tolerance), or
    None (also issued as a ResolutionWarning)."""
    strands: Strands
    roots: np.ndarray
    root_uv: np.ndarray
    guides: np.ndarray
    guide_weights: np.ndarray
    root_ids: np.ndarray
    root_tri: np.ndarray
    root_bary: np.ndarray
    collision: object = None
    warning: str = None


class ResolutionWarning(UserWarning):
    """Adaptive resolution: some strands exceed the tolerance because points_per_strand caps
    their cylinders (GroomResult.warning says how many, by how much, and what would do)."""


def _check_inputs(scalp, keys, params, in_memory=True):
    if not isinstance(scalp, Scalp):
        raise InputError(f"scalp: expected a groom.Scalp, got {type(scalp).__name__}")
    if not isinstance(params, GroomParams):
        raise InputError(f"params: expected a groom.GroomParams, got {type(params).__name__}")
    keys = list(keys.values()) if isinstance(keys, dict) else list(keys)
    if not keys:
        raise InputError("keys: no key strands; give at least one")
    for i, k in enumerate(keys):
        if not isinstance(k, KeyStrand):
            raise InputError(f"keys[{i}]: expected a groom.KeyStrand, got {type(k).__name__}")
    if in_memory:
        check_memory(f"count {params.count:,}", params.count * params.points_per_strand * _BYTES_PER_POINT,
                     f"grow fewer strands, or fewer points per strand (points_per_strand {params.points_per_strand}), "
                     f"or write them to a file as they grow (python -m groom generate, groom.generate_to_npz), "
                     f"which takes the memory of one block of {BLOCK_STRANDS:,} strands whatever the count")
    return keys


# Peak memory while growing, per strand and point of points_per_strand, with room for the
# caller's copy (measured: 39 bytes at 1M strands of wavy, 62 of its 96 points a strand; the
# result itself takes 32 bytes a point, SPEC §0 arrays, and a copy of it as many again).
_BYTES_PER_POINT = 64

# Strands grown at a time. Each block's temporaries (curve parameters, per-point attributes
# before they are joined, the collision's look-ups) take some 60 bytes a point, about 250 MB
# for 65,536 strands of 62 points; smaller blocks cost more numpy calls for the same work.
BLOCK_STRANDS = 1 << 16


def _block_ranges(n, size):
    """[(lo, hi), ...] covering 0..n in blocks of at most `size`, as equal as can be."""
    parts = max(1, -(-n // max(int(size), 1)))
    edges = [n * i // parts for i in range(parts + 1)]
    return list(zip(edges[:-1], edges[1:]))


def _block_workers(n):
    """Threads or processes the blocks of n strands are grown on, side by side (one block
    each at a time): one per CPU when each still gets PROCESS_BLOCK strands (in worker
    processes) or PARALLEL_BLOCK (on threads), else one (whose stages then split their own
    work over the threads)."""
    threads = cpu_threads()
    return threads if n >= threads * (PROCESS_BLOCK if processes.available() else PARALLEL_BLOCK) else 1


# Strands a block needs before the blocks are grown side by side, one per thread, rather than
# one at a time with each stage's work split over the threads. Measured on 2 cores with
# `wavy`, alternating the two in one process: at 100,000 strands (two blocks of 50,000) side
# by side took 0.85-0.90 of the wall time and 0.80-0.88 of the CPU time (four runs); at
# 10,000 (two of 5,000) 1.2 times the wall time, as each block's collision walk is left with
# a few hundred strands a step.
PARALLEL_BLOCK = 32768
# The same for blocks in worker processes (groom.processes), which do not take turns in one
# interpreter: measured on 2 cores with `wavy`, alternating with one block in one process,
# two blocks in processes took 1.06x the time at 2,000 strands, 0.90x at 4,000, 0.78x at
# 10,000, 0.62x at 30,000 and 0.72x at 100,000 (against two on threads there).
PROCESS_BLOCK = 2048


def _block_size(n, most, workers):
    """Strands per block of n: at most `most`, and as many blocks as a multiple of the
    workers, so each thread grows as many strands (not always as much work: a block whose
    strands collide takes longer, docs/DECISIONS.md)."""
    parts = max(-(-n // max(int(most), 1)), workers)
    parts = -(-parts // workers) * workers
    return -(-n // parts)


def _quiet(fraction, stage):
    """The progress report of a block grown on a worker thread: nothing (the thread that
    asked for progress reports it as the blocks finish)."""


def _plain_empty(shape, dtype=np.float32):
    """np.empty, but a large array gets plain pages of its own (an anonymous mapping) rather
    than numpy's, which it advises the kernel to back with 2 MB pages: for the result of a
    million strands (2 GB) that advice cost 5 to 7 s of system time a generate, against 1.6
    to 3.8 s on plain pages (docs/DECISIONS.md). Below _PLAIN_PAGES_FROM the 2 MB pages
    cost less (fewer faults)."""
    size = int(np.prod(shape)) * np.dtype(dtype).itemsize
    if size < _PLAIN_PAGES_FROM:
        return np.empty(shape, dtype)
    return np.frombuffer(mmap.mmap(-1, size), dtype).reshape(shape)


# Arrays of the whole result from this size on get plain pages (_plain_empty).
_PLAIN_PAGES_FROM = 128 << 20


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_float32(reach, rows, radii):
    """Strands are made from groom's own arrays without re-validating them (see _build), so
    make sure here that they stay finite in float32: a point lies within 4·max|table row| of
    its root in each coordinate (B is a rotation, the weights sum to 1, the lerp stays
    between samples), and a radius within the largest key radius."""
    extent = float(np.abs(rows).max()) if rows.size else 0.0
    if not reach + 4.0 * extent < _FLOAT32_MAX:
        raise InputError(f"strand points: roots up to {reach:.3g} and key offsets up to {extent:.3g} from their roots "
                         f"exceed float32 (SPEC §0 points are float32); scale the scalp and keys down")
    if not float(radii.max()) < _FLOAT32_MAX:
        raise InputError(f"radius: {float(radii.max()):.3g} exceeds float32 (SPEC §0); give a smaller radius")


# Roots a job of the per-root work takes (sampling's state, frames, guides): more than
# parallel.RANGE_SIZE, as its calls are many and small. Measured, two threads, 100,000 roots
# of `wavy`: 61 ms against 89 ms with ranges of 8,192 (1,000,000: 476 against 651 ms;
# 65,536 no better); the numbers are each root's own whatever the ranges.
_ROOT_RANGE = 32768


def _threads_for(n_strands):
    """Worker threads for work over n strands: below parallel.MIN_SPLIT strands handing the
    work to other threads costs more than it saves (measured: 1,000 strands take longer on
    two threads than on one)."""
    return 1 if n_strands < MIN_SPLIT else None


def _root_state(scalp, p, samples, lo, hi, frac, uv, transforms):
    """Length fraction, UV and transform B of roots lo..hi of `samples`, written into frac
    (S,), uv (S, 2) (None: the scalp has none) and transforms (9, S) at lo..hi."""
    ids, tri, bary = samples.ids[lo:hi], samples.tri[lo:hi], samples.bary[lo:hi]
    frac[lo:hi] = length_fractions(p.seed, ids, p.min_length, p.max_length)
    if uv is not None:
        uv[lo:hi] = scalp.uv_at(tri, bary)
    angles = tidiness_angles(p.seed, ids, p.tidiness, p.theta_max)
    axes = frame_axes(scalp.normals_blend(tri, bary, p.normal_mode), p.up, p.front)
    transforms[:, lo:hi] = strand_transforms(axes, angles, p.intelligence)


def _resolution_shortfall(met, asked, needed):
    """(strands whose tolerance the cylinder cap stopped, the worst met/asked among them, the
    most cylinders one of them needs): what the resolution warning says, from per-strand
    arrays; blocks' answers combine by sum, max, max."""
    over = met > asked * (1 + 1e-9)
    if not over.any():
        return 0, 0.0, 0.0
    return int(over.sum()), float((met[over] / asked[over]).max()), float(needed[over].max())


def _combined_shortfall(a, b):
    return a[0] + b[0], max(a[1], b[1]), max(a[2], b[2])


def _resolution_message(p, shortfall, total):
    """The resolution warning for `shortfall` (_resolution_shortfall) of `total` strands, or None."""
    over, ratio, needed = shortfall
    if not over:
        return None
    units = "root radii" if p.tolerance_units == "radius" else "scene units"
    cap = p.points_per_strand - 1
    got = (f"they got {cap} cylinders each, placed to stay within {ratio:.3g} times the tolerance at worst"
           if np.isfinite(ratio) else f"they got {cap} equal steps, with no bound on their error")
    loosen = f", or loosen the tolerance to {p.tolerance * ratio:.3g} {units}" if np.isfinite(ratio) else ""
    return (f"adaptive resolution: {over:,} of {total:,} strands need more than the {cap} cylinders "
            f"points_per_strand {p.points_per_strand} allows to stay within the tolerance {p.tolerance:g} {units}; "
            f"{got}. To meet the tolerance raise points_per_strand to at least "
            f"{int(np.ceil(needed)) + 1}{loosen}")


class _Grower:
    """What Generator and BlockGenerator share: the keys' tables and blend rows, the
    collider, and the growing of a block of strands from their per-strand inputs."""

    def _setup_keys(self, collider, n):
        """The keys' tables and blend rows, and the collider (for n strands)."""
        p = self.params
        self._key_data = self._prepare_keys(self.keys)
        self._samples = self._table_samples(self._key_data)
        self._set_rows(self._key_data, self._samples)
        self._exact_rows = None
        self._resolution = None     # adaptive: (tolerance met, tolerance asked, cylinders needed) per strand
        self._collision = None
        if collider is not None and p.collision:
            self._report(0.15, "preparing the collider")
            self._collision = StrandCollision(collider, self.scalp, p, n)
            self._collision.check_keys(self.keys, p)

    @property
    def _colors_per_strand(self):
        """Whether the strands' colour is kept a strand at a time (hairio.Strands.strand_color):
        where it does not change along them (no colour_variation_point)."""
        return not np.any(self.params.color_variation_point)

    def _report(self, fraction, stage):
        if self.progress is not None:
            self.progress(float(fraction), stage)

    def _prepare_keys(self, keys):
        """Per key: its arc-length table (FINE_SAMPLES at adaptive resolution, for the
        curvature bound, else KEY_SAMPLES), curvature bound (adaptive only), root frame, root,
        group, radius and colour; the blend rows come from _set_rows. The keys' roots are
        placed on the scalp all at once."""
        p = self.params
        tri, bary, _ = self.scalp.closest_points(np.array([k.root for k in keys]))
        normal = self.scalp.normals_at(tri, bary, p.normal_mode)
        frames = root_frames(normal, p.up, p.front)
        out = []
        adaptive = p.resolution_mode == "adaptive"
        tables = key_offsets(keys, frames, p.intelligence, FINE_SAMPLES if adaptive else KEY_SAMPLES)
        for key, frame, (table, length) in zip(keys, frames, tables):  # a few keys, not strands
            bound = curvature_bound(table, length) if adaptive else None
            radius = p.radius if key.root_radius is None else key.root_radius
            color = np.asarray(p.color if key.color is None else key.color, dtype=np.float64)
            out.append({"table": table, "key": key, "frame": frame, "bound": bound, "root": key.root.copy(),
                        "group": key.group, "radius": radius, "color": color})
        return out

    def _table_samples(self, data):
        """Samples of the blend tables for keys `data`: KEY_SAMPLES at fixed resolution; at
        adaptive resolution as many as keep the lerp between them within LERP_SHARE of the
        smallest tolerance a strand can have (interpolate.table_samples). InputError when
        not even MAX_TABLE_SAMPLES do: a tolerance the tables cannot follow."""
        p = self.params
        if p.resolution_mode != "adaptive":
            return KEY_SAMPLES
        radii = np.array([d["radius"] for d in data], np.float64)
        # Keys too large for float32 points are that error, not one of tolerance.
        _check_float32(self._reach, np.array([np.abs(d["table"]).max() for d in data]), radii)
        bounds = np.stack([d["bound"] for d in data])
        floor = p.tolerance * (float(radii[radii > 0].min()) if p.tolerance_units == "radius" and (radii > 0).any()
                               else 1.0)
        samples = table_samples(bounds, floor)
        lerp = float(lerp_errors(bounds, samples).max())
        if lerp > LERP_SHARE * floor:
            units = "root radii" if p.tolerance_units == "radius" else "scene units"
            least = p.tolerance * lerp / (LERP_SHARE * floor)
            raise InputError(f"tolerance: {p.tolerance:g} {units} is finer than the keys' tables follow (their "
                             f"{samples:,} samples stray up to {lerp:.3g} from the curves, which must stay within "
                             f"1/{round(1 / LERP_SHARE)} of the tolerance); use a tolerance of at least {least:.3g}")
        return samples

    def _set_rows(self, data, samples):
        """The blend rows (interpolate.key_rows) of keys `data` at `samples` samples: taken from
        their tables where those nest, else resampled."""
        p = self.params
        for d in data:
            table = d["table"]
            if (len(table) - 1) % (samples - 1) == 0:
                table = nested_table(table, samples)
            else:
                table = key_offsets([d["key"]], [d["frame"]], p.intelligence, samples)[0][0]
            d["rows"] = key_rows(table)

    def _block_report(self, i, n, start=0.2):
        """progress(fraction of block i of n, stage), mapped onto the growing's share (start-0.95)."""
        def report(fraction, stage):
            self._report(start + (0.95 - start) * (i + fraction) / n, stage)
        return report

    def _blend_context(self):
        """What every block's blend reads: the keys' radii (K,), blend rows (K, M, 8) f32, roots
        (K, 3) and, at adaptive resolution, curvature bins with the shaping's share."""
        p, kd = self.params, self._key_data
        radii = np.array([d["radius"] for d in kd], dtype=np.float64)
        rows = np.stack([d["rows"] for d in kd])
        _check_float32(self._reach, rows, radii)
        bins = None if p.resolution_mode == "fixed" else shaping_bound(np.stack([d["bound"] for d in kd]), rows, p)
        return {"radii": radii, "rows": rows, "key_roots": np.array([d["root"] for d in kd]), "bins": bins}

    def _plan(self, context, roots, g, w, frac, idx):
        """(σ flat (P,) or None, counts (S,)) of one block of strands: equal steps at fixed
        resolution (σ made in the blend), else cylinders.adaptive_sigma's (noting per strand
        what it met). roots (3, n), g, w (3, n), frac (n,) and idx as for _grow."""
        p = self.params
        max_cyl = p.points_per_strand - 1
        if p.resolution_mode == "fixed":
            return None, np.full(len(frac), max_cyl + 1, np.int64)
        radii = context["radii"]
        base_radius = w[0] * radii[g[0]] + w[1] * radii[g[1]] + w[2] * radii[g[2]]
        asked = p.tolerance * (base_radius if p.tolerance_units == "radius" else np.ones(len(frac)))
        tol = np.maximum(asked, 1e-300)
        clump = clump_arguments(p, g[0], roots, context["key_roots"])
        res = adaptive_sigma(frac, g.T, w.T, context["bins"], tol, max_cyl, table_step=1.0 / (self._samples - 1),
                             clump=clump)
        self._note_resolution(idx, res.met, tol, res.needed)
        return res.sigma, res.counts

    def _grow(self, context, roots, transforms, g, w, frac, ids, idx, report, plan=None, into=None, collide=True):
        """Points and attributes (points, counts, radius, colour, alpha) of one block of
        strands from their per-strand inputs, component-major: roots (3, n), transforms (9,
        n), guides g (3, n), weights w (3, n), length fractions and ids (n,); idx: where they
        lie among the strands (a slice or indices), for the resolution and collision notes;
        plan: their _plan, made here when None; into: None or (points, radius, colour, alpha)
        arrays of the block's rows of the whole result, written where the work allows (the
        arrays returned are then those; colour (n, 3), a row a strand, where
        _colors_per_strand); collide False: the caller moves them out of the
        collider itself. The sixth item returned: the collision's CollisionStats of the
        block, or None without a collider (or collide False)."""
        p = self.params
        radii, rows = context["radii"], context["rows"]
        report(0.0, "growing strands")
        sigma, counts = self._plan(context, roots, g, w, frac, idx) if plan is None else plan
        del plan
        base_radius = w[0] * radii[g[0]] + w[1] * radii[g[1]] + w[2] * radii[g[2]]
        args = (roots, transforms, g, w.astype(np.float32))
        threads = _threads_for(len(frac))
        clump = clump_arguments(p, g[0], roots, context["key_roots"])
        if sigma is None:
            n = p.points_per_strand
            along = np.arange(n) / (n - 1)
            jobs, attrs = self._attribute_jobs(ids, counts, along, g, w, base_radius)
            pts, done = evaluate_strands(*args, counts, rows, frac=frac, also=jobs, threads=threads, clump=clump,
                                         out=None if into is None else into[0])
            attrs = attrs or done[0]
        else:
            pts, _ = evaluate_strands(*args, counts, rows, sigma=sigma, threads=threads, clump=clump,
                                      out=None if into is None else into[0])
            attrs = self._attributes(ids, counts, (sigma, frac), g, w, base_radius,
                                     out=None if into is None else into[1:])
        del args, clump
        report(0.5, "frizz and curl")
        shape_strands(pts, counts, sigma, frac, transforms, g[0], ids, rows, p, threads)
        del sigma
        stats = None
        if self._collision is not None and collide:
            report(0.6, "moving hair out of the collider")
            pts, stats = self._collision.apply(pts, counts, attrs[0], idx, threads)
        return (pts, counts) + tuple(attrs) + (stats,)

    def _attributes(self, ids, counts, along, g, w, base_radius, out=None):
        """(radius, colour, alpha) per point (cylinders.strand_attributes) from the guides'
        colours; where _colors_per_strand, colour (S,3) a strand at a time, clamped, and alpha
        None for an opaque groom (its result's alpha is cylinders.ones)."""
        if not self._colors_per_strand:
            return strand_attributes(self.params.seed, ids, counts, along, base_radius, self._base_color(g, w),
                                     self.params, out=out)
        p = self.params
        color = self._strand_rgb(ids, g, w)
        if out is None:
            n_pts = int(counts.sum())
            out = (np.empty(n_pts, np.float32), None, None if alpha_is_one(p) else np.empty(n_pts, np.float32))
        else:
            out[1][...] = color
        radius_alpha_rows(along, counts, base_radius, p, out[0], out[2])
        return out[0], color, out[2]

    def _strand_rgb(self, ids, g, w):
        """Colour a strand (S,3) float32, clamped to [0, 1] (as the points' would be)."""
        return np.clip(strand_colors(self.params.seed, ids, self._base_color(g, w), self.params), 0.0, 1.0)

    def _base_color(self, g, w):
        """The guides' colours blended by the weights, (S,3) float64."""
        colors = np.stack([d["color"] for d in self._key_data])
        return np.stack([w[0] * colors[g[0], c] + w[1] * colors[g[1], c] + w[2] * colors[g[2], c]
                         for c in range(3)], axis=1)

    def _attribute_jobs(self, ids, counts, along, g, w, base_radius):
        """(jobs, arrays) for strands that all have len(along) points: the jobs fill the
        arrays (radius, colour, alpha) a range of strands each, to run beside the blend. With
        per-point colour variation: one job returning the arrays, and arrays None."""
        p, n = self.params, len(along)
        if np.any(p.color_variation_point):
            return [partial(self._attributes, ids, counts, along, g, w, base_radius)], None
        s = along.astype(np.float32)
        r_prof, a_prof = radius_profile(s, p), alpha_profile(s, p)
        n_pts = len(ids) * n
        per_strand = self._colors_per_strand
        out = (np.empty(n_pts, np.float32), np.empty((len(ids) if per_strand else n_pts, 3), np.float32),
               np.empty(n_pts, np.float32))

        def fill(lo, hi):
            if per_strand:
                out[1][lo:hi] = self._strand_rgb(ids[lo:hi], g[:, lo:hi], w[:, lo:hi])
                fill_strand_rows(out[0][lo * n:hi * n], None, out[2][lo * n:hi * n], base_radius[lo:hi], None,
                                 r_prof, a_prof)
                return
            color = strand_colors(p.seed, ids[lo:hi], self._base_color(g[:, lo:hi], w[:, lo:hi]), p)
            fill_strand_rows(*(a[lo * n:hi * n] for a in out), base_radius[lo:hi], color, r_prof, a_prof)
        return [partial(fill, lo, hi) for lo, hi in ranges(len(ids))], out


def _unchanged_runs(sel, n):
    """[(a, b), ...]: the runs of strands a..b-1 of 0..n-1 that are not in `sel` (sorted)."""
    starts = np.concatenate([[0], np.asarray(sel) + 1])
    stops = np.concatenate([sel, [n]])
    keep = stops > starts
    return list(zip(starts[keep].tolist(), stops[keep].tolist()))


def _rows_of(whole, lo, hi, strands=None):
    """Rows lo..hi of each array of the whole result (None stays None: an opaque groom's
    alpha); strands: None, or (a, b) the strands of those rows, whose rows of the colour
    are taken where it is kept a strand at a time."""
    return tuple(None if a is None else a[slice(*strands) if k == 2 and strands is not None else slice(lo, hi)]
                 for k, a in enumerate(whole))


def _keep_rows(rows, grown):
    """Copy into the result's rows what _grow made in arrays of its own (the work does not
    always allow writing in place)."""
    for whole, part in zip(rows, grown[:1] + grown[2:5]):
        if whole is not None and not np.may_share_memory(whole, part):
            whole[...] = part


class _WorkerGrower(_Grower):
    """A worker process's side of Generator._grown_in_processes: grows blocks from the
    inputs the parent sends, with the parent's keys' rows and collider (_worker_spec)."""

    def __init__(self, spec):
        self.params, self._samples, self.context = spec["params"], spec["samples"], spec["context"]
        self._key_data = [{"color": c} for c in spec["colors"]]
        self.progress = None
        self._collision = None
        if spec["collider"] is not None:
            c = object.__new__(StrandCollision)
            c.collider, c.margin, c.keys_inside = processes.kept(spec["collider"]), spec["margin"], ()
            c.moved, c.last = None, CollisionStats()
            self._collision = c
        self.notes = None

    def _note_resolution(self, idx, met, asked, needed):
        self.notes = (met, asked, needed)


# Strands a range of the collision's first pass when the sides share the collision out
# (Generator._collide_shared), the ranges dealt to the sides in turn: at most this many, and
# at least _COLLIDE_TURNS ranges a side (10,000 strands of wavy in ranges of 2,048: this
# process found 1,074 strands to walk in its three, the worker 184 in its two).
_COLLIDE_RANGE = 2048
_COLLIDE_TURNS = 16


def _collide_share(c, points, radius, offsets, counts, parts):
    """The collision of a share of a run's strands, in place in `points`: collide.first_pass
    over the ranges `parts` [(lo, hi), ...] of the run's strands (offsets, counts: all of
    them), then the walk of the strands it found (walk_into): (those strands, which of them
    moved, (points moved, unresolved, largest move), points found inside, seconds)."""
    t0 = time.perf_counter()
    strands, k0, root_value, inside = first_pass(c.collider, points, offsets, counts, radius, c.margin, parts)
    moved, totals = np.zeros(0, bool), (0, 0, 0.0)
    if strands.size:
        moved, totals = walk_into(c.collider, points, points, offsets, counts, radius, c.margin, strands, k0,
                                  root_value)
    return strands, moved, totals, inside, time.perf_counter() - t0


def _worker_collide(points, radius, offsets, counts, parts):
    """_collide_share in a worker, on the parent's shared points and radii (handles)."""
    g = processes.STATE["grower"]
    return _collide_share(g._collision, processes.open_shared(points), processes.open_shared(radius), offsets,
                          counts, parts)


def _worker_setup(spec):
    processes.STATE.clear()
    processes.STATE["grower"] = _WorkerGrower(spec)


def _worker_plan(i, inputs):
    """(counts, resolution notes or None) of block i; its inputs and plan stay here."""
    g = processes.STATE["grower"]
    g.notes = None
    plan = g._plan(g.context, inputs[0], inputs[2], inputs[3], inputs[4], slice(0, len(inputs[4])))
    processes.STATE[i] = (inputs, plan)
    return plan[1], g.notes


def _worker_grow(i, handles, lo, hi, strands=None):
    """Block i grown into rows lo..hi of the parent's shared arrays (handles); strands: None,
    or (a, b), its strands, the rows of the colour where it is kept a strand at a time."""
    g = processes.STATE["grower"]
    inputs, plan = processes.STATE.pop(i)
    rows = tuple(None if h is None else processes.open_shared(h, strands if k == 2 and strands is not None
                                                                else (lo, hi))
                 for k, h in enumerate(handles))
    grown = g._grow(g.context, *inputs, slice(0, len(inputs[4])), _quiet, plan, into=rows, collide=False)
    del plan
    _keep_rows(rows, grown)


def _deal(owner, here, send, job, done, futures):
    """Runs job(i) on the thread pool `here` where owner[i] is None and sends worker
    owner[i] the message send(i) (fn, *args) elsewhere, then takes the answers in block
    order, done(i) after each (done may be None). `futures` (a list) gets this process's
    futures, for the caller to cancel after a failure. This process's jobs start first: a
    message larger than a pipe holds (a block's inputs, its offsets) keeps its send waiting
    until the worker reads it, which it does between jobs, so sending first left this
    process idle until the worker had begun its last block (1,000,000 strands: 16.7 s
    against 11.4 s; 300,000: 3.0-3.9 s against 2.1-2.7 s)."""
    futures[:] = [None if w is not None else here.submit(job, i) for i, w in enumerate(owner)]
    for i, w in enumerate(owner):
        if w is not None:
            w.send(*send(i))
    got = []
    for i, w in enumerate(owner):
        got.append(w.receive() if w is not None else futures[i].result())
        if done is not None:
            done(i)
    return got


class Generator(_Grower):
    """Incremental generator. `generate()` gives the full result; `update_keys({i: KeyStrand})`
    replaces keys and returns the new result, recomputing only affected strands.

    Per-strand arrays are kept component-major (one contiguous row per component), the
    layout whole-array numpy code reads fastest; results are returned in the (S, 3) layout
    of GroomResult."""

    def __init__(self, scalp, keys, params, samples=None, collider=None, progress=None, block_strands=BLOCK_STRANDS):
        """samples: optional sampling.RootSamples to grow from instead of sampling
        params.count roots (measurements place roots where they need them). collider: the
        mesh the hair stays out of (collide.as_collider: a Collider, a Scalp or (vertices,
        triangles)), or None. progress: None or a callable(fraction in [0, 1], stage text),
        called from this thread as the work goes on (a progress bar for long runs).
        block_strands: most strands a block (the result does not depend on it); blocks of
        PARALLEL_BLOCK strands or more grow side by side, one per CPU."""
        self.progress = progress
        self.block_strands = block_strands
        self._report(0.0, "sampling roots")
        self.keys = _check_inputs(scalp, keys, params)
        self.scalp, self.params = scalp, params
        p = params
        if _block_workers(p.count if samples is None else len(samples.ids)) > 1:
            processes.start(cpu_threads() - 1)
        if samples is None:
            samples = sample_roots(scalp, p.count, p.seed, p.sampling_mode)
        self.samples = samples
        self._roots = np.ascontiguousarray(samples.points.T)
        self._reach = float(np.abs(self._roots).max()) if self._roots.size else 0.0
        self.root_groups = root_groups_for(scalp, samples.tri, samples.bary, samples.points, p)
        n = len(samples.ids)
        self.root_uv = None if scalp.uv is None else np.empty((n, 2))
        self.frac = np.empty(n)
        self.transforms = np.empty((9, n), np.float32)
        # The per-root work and the guides of the first generate() (they need only the key
        # roots), on the workers. The keys are resampled here afterwards, not meanwhile: a
        # thread busy with many small numpy calls slowed the workers more than it saved.
        assign_jobs, self._first_assignment = self._assign_jobs([k.root for k in self.keys],
                                                                [k.group for k in self.keys])
        per_root = [partial(self._per_root, lo, hi) for lo, hi in ranges(n, size=_ROOT_RANGE)]
        run_jobs(per_root + assign_jobs, _threads_for(n))
        self._setup_keys(collider, n)
        self._result = None
        self._cache = None
        self.last_recomputed = 0  # strands recomputed by the last update_keys

    def _axes(self, lo=0, hi=None):
        """frames.frame_axes of roots lo..hi."""
        p, s = self.params, self.samples
        return frame_axes(self.scalp.normals_blend(s.tri[lo:hi], s.bary[lo:hi], p.normal_mode), p.up, p.front)

    def _per_root(self, lo, hi):
        """Length fraction, UV and transform B of roots lo..hi."""
        _root_state(self.scalp, self.params, self.samples, lo, hi, self.frac, self.root_uv, self.transforms)

    @property
    def frames(self):
        """Root frames (S,3,3), columns (main tangent, second tangent, normal)."""
        return np.stack([a.T for a in self._axes()], axis=2)

    def _assign(self):
        """Guides (3, S) int64 and weights (3, S) float64 of every root, in ranges of roots on
        the workers."""
        jobs, assignment = self._assign_jobs([d["root"] for d in self._key_data], [d["group"] for d in self._key_data])
        run_jobs(jobs, _threads_for(len(self.frac)))
        return assignment

    def _assign_jobs(self, key_roots, key_groups):
        """(jobs, (guides, weights)): the jobs fill the arrays. Checks the groups first, once,
        so the message names every group that has no key."""
        p = self.params
        key_roots = np.array(key_roots, dtype=np.float64)
        key_groups = np.array(key_groups, np.int32)
        check_groups(self.root_groups, key_groups)
        n = len(self.frac)
        guides, weights = np.empty((3, n), np.int64), np.empty((3, n))

        def assign(lo, hi):
            g, w = guide_weights_by_guide(self.samples.points[lo:hi], key_roots, p.neighbour_mode, p.n_influence,
                                          self.root_groups[lo:hi], key_groups, check=False)
            guides[:, lo:hi], weights[:, lo:hi] = g, w
        return [partial(assign, lo, hi) for lo, hi in ranges(n, size=_ROOT_RANGE)], (guides, weights)

    def evaluate(self, sel, cylinders, exact=False):
        """Points of strands `sel` at the given numbers of equal steps in σ (S,) (measurement:
        dense samples of the curve). `exact`: from key tables of EXACT_SAMPLES samples (the
        exact curve to within 1/4096 of the lerp error of 1025 samples), not the blend's own.
        Returns (points (P,3) float32, counts (S,))."""
        if self._result is None:
            self.generate()
        sel = np.asarray(sel, np.int64)
        rows = self._exact_key_rows() if exact else np.stack([d["rows"] for d in self._key_data])
        sigma, counts = uniform_sigma(self.frac[sel], np.asarray(cylinders, np.int64))
        main = self._guides[0, sel]
        clump = clump_arguments(self.params, main, self._roots[:, sel], np.array([d["root"] for d in self._key_data]))
        pts, _ = evaluate_strands(self._roots[:, sel], self.transforms[:, sel], self._guides[:, sel],
                                  self._weights[:, sel].astype(np.float32), counts, rows, sigma=sigma,
                                  threads=_threads_for(len(sel)), clump=clump)
        shape_strands(pts, counts, sigma, None, self.transforms[:, sel], main, self.samples.ids[sel], rows, self.params,
                      _threads_for(len(sel)))
        return pts, counts

    def _exact_key_rows(self):
        """(K, EXACT_SAMPLES, 8) blend rows of the current keys (made on first use)."""
        if self._exact_rows is None or len(self._exact_rows[0]) != len(self._key_data) or any(
                a is not d["key"] for a, d in zip(self._exact_rows[0], self._key_data)):
            p = self.params
            tables = key_offsets([d["key"] for d in self._key_data], [d["frame"] for d in self._key_data],
                                 p.intelligence, EXACT_SAMPLES)
            self._exact_rows = ([d["key"] for d in self._key_data], np.stack([key_rows(t) for t, _ in tables]))
        return self._exact_rows[1]

    def _strands(self, sel, guides, weights):
        """Points and attributes of the strands `sel` (indices into the roots, in that order;
        None: all of them), grown a block of strands at a time into the arrays of the whole.
        guides (3, S), weights (3, S) as from _assign."""
        n = len(self.frac) if sel is None else len(sel)
        if not n:  # an update that touches no strand
            return (np.zeros((0, 3), np.float32), np.zeros(0, np.int64), np.zeros(0, np.float32),
                    np.zeros((0, 3), np.float32), np.zeros(0, np.float32))
        if self.params.resolution_mode != "fixed":
            # Per strand for the warning: fresh arrays for a full run; an update changes a copy
            # (an array handed out before stays as it was).
            self._resolution = (tuple(np.empty(len(self.frac)) for _ in range(3)) if sel is None or
                                self._resolution is None else tuple(old.copy() for old in self._resolution))
        context = self._blend_context()
        workers = _block_workers(n)
        blocks = _block_ranges(n, _block_size(n, self.block_strands, workers))

        def block(i):
            """(per-strand inputs of block i as _grow takes them, its idx)."""
            lo, hi = blocks[i]
            idx = slice(lo, hi) if sel is None else sel[lo:hi]
            return [x[..., idx] for x in (self._roots, self.transforms, guides, weights, self.frac,
                                          self.samples.ids)], idx
        if len(blocks) == 1:
            inputs, idx = block(0)
            grown = self._grow(context, *inputs, idx, self._block_report(0, 1))
            if self._collision is not None:
                self._collision.last = grown[5]
            self._report(0.95, "writing strands")
            return grown[:5]
        if workers > 1 and processes.available() and processes.try_lock():
            try:
                return self._grown_in_processes(context, blocks, block, workers,
                                                slice(None) if sel is None else sel)
            except processes.WorkerDied as e:
                # Deterministic either way: the same strands grow on threads instead.
                processes.disable(str(e))
                warnings.warn(f"{e}; growing on threads from now on", RuntimeWarning, stacklevel=3)
            finally:
                processes.unlock()
        return self._grown_on_threads(context, blocks, block, workers)

    def _grown_on_threads(self, context, blocks, block, workers):
        """_strands' blocks grown side by side on `workers` threads (or one after another
        on one); block(i): (block i's inputs as _grow takes them, its idx)."""
        # Each block's curve parameters first (they hold 8 bytes a point), so the arrays of
        # the whole result are made once and each block's points written into them; the
        # blocks' own arrays then come and go one at a time per thread. The blocks run side
        # by side, one per worker thread (parallel.run_each), and report from here.
        def plan(i):
            inputs, idx = block(i)
            return self._plan(context, inputs[0], inputs[2], inputs[3], inputs[4], idx)
        self._report(0.2, "placing the points")
        plans = run_each([partial(plan, i) for i in range(len(blocks))], workers,
                         lambda i: self._report(0.2 + 0.15 * (i + 1) / len(blocks), "placing the points"))
        starts = np.concatenate([[0], np.cumsum([int(c.sum()) for _, c in plans])])
        counts = np.concatenate([c for _, c in plans])
        total = int(starts[-1])
        out = (_plain_empty((total, 3)), _plain_empty(total), _plain_empty((self._color_rows(len(counts), total), 3)),
               None if alpha_is_one(self.params) else _plain_empty(total))     # None: cylinders.ones

        def grow(i):
            inputs, idx = block(i)
            plan, plans[i] = plans[i], None     # each block's curve parameters go once it has grown
            rows = _rows_of(out, int(starts[i]), int(starts[i + 1]), blocks[i] if self._colors_per_strand else None)
            # The block grows straight into its rows of the whole (no copy of some 32 bytes a
            # point, nor the fresh pages of a block's own arrays).
            grown = self._grow(context, *inputs, idx, _quiet, plan, into=rows)
            del plan
            _keep_rows(rows, grown)
            return grown[5]
        stage = self._growing_stage()
        self._report(0.35, stage)
        found = run_each([partial(grow, i) for i in range(len(blocks))], workers,
                         lambda i: self._report(0.35 + 0.6 * (i + 1) / len(blocks), stage))
        self._keep_stats(found)
        self._report(0.95, "writing strands")
        return out[0], counts, out[1], out[2], out[3]

    def _color_rows(self, n_strands, n_points):
        """Rows of the result's colour: a strand's or a point's (_colors_per_strand)."""
        return n_strands if self._colors_per_strand else n_points

    def _growing_stage(self):
        return "growing strands" + (", moving them out of the collider" if self._collision is not None else "")

    def _keep_stats(self, found):
        """The collision's stats of the blocks (CollisionStats each) as the run's."""
        if self._collision is not None:
            stats = CollisionStats()
            for part in found:
                stats.add(part)
            self._collision.last = stats

    def _grown_in_processes(self, context, blocks, block, workers, run_idx):
        """_grown_on_threads with the blocks dealt out to this process (block i for i %
        workers == 0, on a thread of its pool) and workers - 1 worker processes
        (groom.processes), which keep each block's curve parameters between its placement
        and its growing and write its points into the result's shared arrays. The collision
        then goes over the whole once every block has grown, shared out by ranges of strands
        in turn (_collide_shared: the strands that collide lie mostly in one part of the
        scalp, so in few blocks). The numbers are the same: each strand's depend on it
        alone. WorkerDied when a worker is lost."""
        # This process grows a share too (None): with a worker per CPU instead it took 1.35
        # times as long (2 cores, 100,000 strands, in a process with Blender beside).
        sides = [None] + processes.workers(workers - 1)
        helpers = sides[1:]
        owner = [sides[i % workers] for i in range(len(blocks))]
        here = one_thread()
        futures, shared, seconds = [], [], []
        c = self._collision

        def collect(send, job, done=None):
            return _deal(owner, here, send, job, done, futures)
        try:
            spec = self._worker_spec(context)
            for w in helpers:
                if c is not None:
                    w.keep(processes.token(c.collider), c.collider)
                w.send(_worker_setup, spec)
            setup = [w.pending for w in helpers]     # answers (None) to take before the plans'
            for w, n in zip(helpers, setup):
                for _ in range(n):
                    w.receive()

            def plan(i):
                inputs, idx = block(i)
                return self._plan(context, inputs[0], inputs[2], inputs[3], inputs[4], idx), None
            self._report(0.2, "placing the points")
            planned = collect(lambda i: (_worker_plan, i, block(i)[0]), plan,
                              lambda i: self._report(0.2 + 0.15 * (i + 1) / len(blocks), "placing the points"))
            plans = []
            for i, (made, notes) in enumerate(planned):
                if notes is not None:
                    self._note_resolution(block(i)[1], *notes)
                plans.append((None, made) if owner[i] is not None else made)    # a worker's curve parameters stay there
            del planned
            starts = np.concatenate([[0], np.cumsum([int(c_.sum()) for _, c_ in plans])])
            counts = np.concatenate([c_ for _, c_ in plans])
            total = int(starts[-1])
            # An opaque groom's alpha takes no memory (cylinders.ones): no file, no handle.
            per_strand = self._colors_per_strand
            shapes = ((total, 3), total, (self._color_rows(len(counts), total), 3)) + (
                () if alpha_is_one(self.params) else (total,))
            shared = [processes.shared_empty(shape) for shape in shapes]
            out = tuple(a.array for a in shared) + (None,) * (4 - len(shared))
            handles = [a.handle for a in shared] + [None] * (4 - len(shared))

            def grow(i):
                inputs, idx = block(i)
                plan, plans[i] = plans[i], None
                for k, a in enumerate(shared):
                    a.reserve(*(blocks[i] if k == 2 and per_strand else (int(starts[i]), int(starts[i + 1]))))
                rows = _rows_of(out, int(starts[i]), int(starts[i + 1]), blocks[i] if per_strand else None)
                grown = self._grow(context, *inputs, idx, _quiet, plan, into=rows, collide=False)
                del plan
                _keep_rows(rows, grown)
            stage = self._growing_stage()
            self._report(0.35, stage)
            collect(lambda i: (_worker_grow, i, handles, int(starts[i]), int(starts[i + 1]),
                               blocks[i] if per_strand else None), grow,
                    lambda i: self._report(0.35 + (0.45 if c is not None else 0.6) * (i + 1) / len(blocks), stage))
            if c is not None:
                self._report(0.8, "moving hair out of the collider")
                self._collision.last = self._collide_shared(c, sides, here, out, handles, counts, run_idx, futures)
        except BaseException:
            # No job of this run may still be running when the caller goes on, and the
            # workers' state is not known: they go, and the next run starts new ones.
            for f in futures:
                if f is not None:
                    f.cancel()
                    if not f.cancelled():
                        f.exception()
            processes.discard(helpers)
            raise
        finally:
            for a in shared:
                a.close()
        self._report(0.95, "writing strands")
        return out[0], counts, out[1], out[2], out[3]

    def _collide_shared(self, c, sides, here, out, handles, counts, run_idx, futures):
        """The collision of the run's strands (`counts` points each), shared out between
        this process and the workers, in place in the result's shared arrays: ranges of at
        most _COLLIDE_RANGE strands (at least _COLLIDE_TURNS a side) dealt to the sides in
        turn, each side's first pass over its ranges and the walk of the strands it found in
        one job (_collide_share). Ranges in turn give each side a like mix of the scalp's
        regions, whose strands collide unlike much (the first of two blocks of wavy took
        80-100 ms to look over, the second 50-56), and no side waits for the others between
        its look and its walk. Returns the run's CollisionStats, with c.moved set for the
        run's strands (run_idx); `futures` gets this process's job (for the caller to wait
        for after a failure)."""
        turns = -(-len(counts) // (_COLLIDE_TURNS * len(sides)))
        offsets = np.zeros(len(counts), np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        parts = _block_ranges(len(counts), min(_COLLIDE_RANGE, turns))
        mine = None
        for k, side in enumerate(sides):
            share = parts[k::len(sides)]
            if side is None:
                mine = here.submit(_collide_share, c, out[0], out[1], offsets, counts, share)
                futures[:] = [mine]
            else:
                side.send(_worker_collide, handles[0], handles[1], offsets, counts, share)
        stats = CollisionStats(strands=len(counts), points=int(counts.sum()))
        moved = np.zeros(len(counts), bool)
        for side in sides:
            strands, share_moved, totals, inside, took = side.receive() if side is not None else mine.result()
            moved[strands] = share_moved
            stats.add_walk(totals)
            stats.points_inside_before += inside
            stats.seconds += took
        stats.strands_moved = int(moved.sum())
        c.moved[run_idx] = moved
        return stats

    def _worker_spec(self, context):
        """What a worker process's _WorkerGrower is made of (picklable; the collider goes by
        its token, sent once per worker with Worker.keep)."""
        c = self._collision
        return {"params": self.params, "samples": self._samples, "context": context,
                "colors": [d["color"] for d in self._key_data],
                "collider": None if c is None else processes.token(c.collider),
                "margin": None if c is None else c.margin}

    def _note_resolution(self, idx, met, asked, needed):
        """Keeps per strand the tolerance its polyline is bound to, the one asked and the
        cylinders a bound says it needs (strands `idx`), for the warning."""
        for old, new in zip(self._resolution, (met, asked, needed)):
            old[idx] = new

    @property
    def tolerance_met(self):
        """(S,) the tolerance each current strand's polyline is bound to (scene units): its own
        unless the cylinder cap stopped it (inf where no bound holds); None at fixed
        resolution."""
        return None if self._resolution is None else self._resolution[0]

    def resolution_warning(self):
        """What the adaptive resolution of the current strands could not meet, or None."""
        if self._resolution is None:
            return None
        return _resolution_message(self.params, _resolution_shortfall(*self._resolution), len(self._resolution[0]))

    def _build(self, guides, weights, parts):
        pts, counts, radius, color, alpha = parts
        if alpha_is_one(self.params):
            alpha = ones(len(pts))      # however it was grown: no memory a point
        s = self.samples
        # The arrays are groom's own, already float32/int32 and checked where their inputs
        # entered (finite keys and scalp, radii >= 0, colours clamped, alpha in [0, 1]), so
        # the Strands is made directly instead of re-validating and copying 3M points.
        per_strand = self._colors_per_strand    # colour (S,3) a strand at a time, else (P,3)
        strands = Strands(pts, counts.astype(np.int32), radius, None if per_strand else color, alpha,
                          guides[0].astype(np.int32), strand_color=color if per_strand else None)
        self._cache = {"pts": pts, "counts": counts, "radius": radius, "color": color, "alpha": alpha}
        self._result = GroomResult(strands, s.points, self.root_uv, np.ascontiguousarray(guides.T, dtype=np.int32),
                                   np.ascontiguousarray(weights.T, dtype=np.float32), s.ids, s.tri, s.bary,
                                   None if self._collision is None else self._collision.report(),
                                   self.resolution_warning())
        if self._result.warning:
            warnings.warn(self._result.warning, ResolutionWarning, stacklevel=3)
        self._guides, self._weights = guides, weights
        self._report(1.0, "done")
        return self._result

    def generate(self):
        """Full regeneration from the current keys."""
        if self._first_assignment is not None:  # made in __init__ for the keys as given
            guides, weights = self._first_assignment
            self._first_assignment = None
        else:
            guides, weights = self._assign()
        return self._build(guides, weights, self._strands(None, guides, weights))

    @property
    def result(self):
        return self._result if self._result is not None else self.generate()

    def update_keys(self, changes):
        """Replace keys {index: KeyStrand} and return the new GroomResult. Strands whose old or
        new guides (with any weight) include a changed key, or whose guides or weights changed
        (a moved key root moves wisp borders), are recomputed; the others are copied."""
        if self._result is None:
            self.generate()
        if not isinstance(changes, dict):
            raise InputError("update_keys: expected a mapping {key index: KeyStrand}")
        for i, k in changes.items():
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < len(self.keys):
                raise InputError(f"update_keys: key index {i!r} out of range [0, {len(self.keys) - 1}]")
            if not isinstance(k, KeyStrand):
                raise InputError(f"update_keys[{i}]: expected a groom.KeyStrand, got {type(k).__name__}")
        old_data, old_keys, old_samples = list(self._key_data), list(self.keys), self._samples
        self._first_assignment = None
        order = sorted(changes)
        for i, d in zip(order, self._prepare_keys([changes[i] for i in order])):
            self.keys[i] = changes[i]
            self._key_data[i] = d

        def restore():
            self.keys[:], self._key_data = old_keys, old_data
            if self._samples != old_samples:
                self._samples = old_samples
                self._set_rows(old_data, old_samples)
        try:
            samples = self._table_samples(self._key_data)
        except InputError:
            restore()
            raise
        # Tables of another size change every strand: all are recomputed, as a full
        # regeneration would.
        resampled = samples != self._samples
        self._set_rows(self._key_data if resampled else [self._key_data[i] for i in order], samples)
        self._samples = samples
        if self._collision is not None:
            self._collision.check_keys(self.keys, self.params)
        changed = np.array(order, np.int64)
        old_g, old_w = self._guides, self._weights
        if all(np.array_equal(old_data[i]["root"], self._key_data[i]["root"])
               and old_data[i]["group"] == self._key_data[i]["group"] for i in order):
            # Only key shapes, radii or colours changed: guides and weights depend on the key
            # roots and groups alone, so they stay; the strands guided by a changed key redo.
            guides, weights = old_g, old_w
            dirty = np.isin(guides, changed).any(axis=0)
        else:
            try:
                guides, weights = self._assign()
            except InputError:
                restore()
                raise
            dirty = (np.isin(guides, changed).any(axis=0) | np.isin(old_g, changed).any(axis=0)
                     | (guides != old_g).any(axis=0) | (weights != old_w).any(axis=0))
        if resampled:
            dirty[:] = True
        sel = np.flatnonzero(dirty)
        self.last_recomputed = len(sel)
        return self._build(guides, weights, self._splice(sel, self._strands(sel, guides, weights)))

    def _splice(self, sel, parts):
        """Full arrays with strands `sel` replaced by `parts`, the others copied."""
        c = self._cache
        old_counts = c["counts"]
        new_counts = old_counts.copy()
        new_counts[sel] = parts[1]
        new_arrays = dict(zip(("pts", "radius", "color", "alpha"), (parts[0], parts[2], parts[3], parts[4])))
        if alpha_is_one(self.params):
            del new_arrays["alpha"]     # _build makes it (cylinders.ones)
        strand_color = None
        if self._colors_per_strand:     # a row a strand: the changed strands' rows replaced
            strand_color = c["color"].copy()
            strand_color[sel] = new_arrays.pop("color")
        old_off = np.zeros(len(old_counts), np.int64)
        np.cumsum(old_counts[:-1], out=old_off[1:])
        part_off = np.zeros(len(sel), np.int64)
        np.cumsum(parts[1][:-1], out=part_off[1:])
        n_new = int(parts[1].sum())
        out = {}
        if not len(sel):
            out = {name: c[name].copy() for name in new_arrays}
        elif (old_counts == old_counts[0]).all() and (parts[1] == old_counts[0]).all():
            # One count for all (fixed resolution): overwrite whole strands, one row each.
            for name, new in new_arrays.items():
                arr = c[name].copy()
                arr.reshape(len(old_counts), -1)[sel] = new.reshape(len(sel), -1)
                out[name] = arr
        elif np.array_equal(parts[1], old_counts[sel]):
            # Same counts: overwrite the changed points in place.
            rows = np.repeat(old_off[sel] - part_off, parts[1]) + np.arange(n_new)
            for name, new in new_arrays.items():
                arr = c[name].copy()
                arr[rows] = new
                out[name] = arr
        else:
            # Counts changed: each run of unchanged strands copied as one slice (their rows
            # only move), the new strands' rows scattered into place. A gather of every row
            # from the old arrays and the new part joined took 45 ms an array at 100,000
            # strands, the slices 15 (docs/DECISIONS.md).
            new_off = np.zeros(len(new_counts), np.int64)
            np.cumsum(new_counts[:-1], out=new_off[1:])
            runs = _unchanged_runs(sel, len(old_counts))
            old_ends, new_ends = old_off + old_counts, new_off + new_counts
            moves = [(int(old_off[a]), int(old_ends[b - 1]), int(new_off[a]), int(new_ends[b - 1])) for a, b in runs]
            rows = np.repeat(new_off[sel] - part_off, parts[1]) + np.arange(n_new)
            total = int(new_counts.sum())
            for name, new in new_arrays.items():
                old = c[name]
                arr = np.empty((total,) + old.shape[1:], old.dtype)
                for o0, o1, n0, n1 in moves:
                    arr[n0:n1] = old[o0:o1]
                arr[rows] = new
                out[name] = arr
        return out["pts"], new_counts, out["radius"], out.get("color", strand_color), out.get("alpha")


def prepare_workers(collider=None):
    """Starts the worker processes a Generator of many strands grows its blocks in, and sends
    them `collider` (a Collider), ahead of the run: the first run in a process otherwise
    waits for both (40,000 strands of `wavy`: 0.59-0.70 s against 0.42-0.49 s after this and
    0.31-0.38 s for later runs). For a caller who knows a run is coming (Blender's Add Head
    and a loaded file's scalps, on the thread that built the collider). Blocks until the
    workers have it; nothing where workers are not used (one CPU, or not Linux)."""
    threads = cpu_threads()
    if threads > 1:
        processes.prepare(threads - 1, () if collider is None else (collider,))


def generate(scalp, keys, params=None, collider=None, progress=None):
    """Grow ordinary strands on `scalp` from `keys` (list of KeyStrand) with `params`
    (GroomParams; defaults when None), kept out of `collider`, telling `progress` how far it
    is (see Generator). Returns a GroomResult."""
    return Generator(scalp, keys, params or GroomParams(), collider=collider, progress=progress).generate()


def strands_with_guides(result, keys, params=None, points_per_key=32):
    """result.strands carrying its guides (hairio.Guides: the key strands sampled at
    `points_per_key` equal arc-length steps, their radius and colour, their parting groups,
    and each strand's main key, two neighbours and weights, as interpolated) and its root
    UVs: what the .npz, .abc and .usd files carry so an engine's simulation drives every
    strand through the same keys and weights."""
    from hairio import Guides
    params = params or GroomParams()
    keys = list(keys.values()) if isinstance(keys, dict) else list(keys)
    guides = Guides.from_arrays(_key_strands(keys, params, points_per_key), result.guides, result.guide_weights,
                                [k.group for k in keys])
    return result.strands.with_guides(guides, result.root_uv)


def _key_strands(keys, params, points_per_key):
    """The key strands as a hairio.Strands of `points_per_key` equal arc-length steps each,
    with their radius and colour."""
    from .keys import arc_length_tables
    n = max(2, int(points_per_key))
    tables = arc_length_tables(keys, n)
    points = np.concatenate([k.points[0] + table for k, (table, _) in zip(keys, tables)])
    radius = np.repeat([params.radius if k.root_radius is None else k.root_radius for k in keys], n)
    color = np.repeat([params.color if k.color is None else k.color for k in keys], n, axis=0)
    return Strands.from_arrays(points, np.full(len(keys), n, np.int32), radius, color)


@dataclass(frozen=True, eq=False)
class GroomBlock:
    """Strands lo..hi of a head grown a block at a time (BlockGenerator.blocks): points (P,3)
    f32, counts (n,) int64, radius (P,) f32, color (P,3) f32, alpha (P,) f32 as in
    hairio.Strands; guides (3, n) int64 (main key first) and weights (3, n) float64 as
    Generator keeps them; root_uv (n, 2) float64 or None."""
    lo: int
    hi: int
    points: np.ndarray
    counts: np.ndarray
    radius: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    guides: np.ndarray
    weights: np.ndarray
    root_uv: np.ndarray = None

    def arrays(self):
        """This block's rows of the .npz arrays that have a row per strand or point, in the
        dtypes strands_with_guides(...).save_npz writes."""
        out = {"points": self.points, "counts": self.counts.astype(np.int32), "radius": self.radius,
               "color": self.color, "alpha": self.alpha, "wisp": self.guides[0].astype(np.int32),
               "guides": np.ascontiguousarray(self.guides.T, dtype=np.int32),
               "guide_weights": np.ascontiguousarray(self.weights.T, dtype=np.float32)}
        if self.root_uv is not None:
            out["root_uv"] = self.root_uv.astype(np.float32)
        return out


@dataclass(frozen=True)
class GroomSummary:
    """What a run a block at a time made: strands and points in all, collision (a
    collide.CollisionReport, or None without a collider) and the resolution warning (or None)."""
    num_strands: int
    num_points: int
    collision: CollisionReport = None
    warning: str = None

    @property
    def num_segments(self):
        return self.num_points - self.num_strands


# Memory of a run a block at a time, per point of a block (points_per_strand each): the
# block's arrays and temporaries (measured on wavy at 65,536 strands a block: 647 MiB peak
# RSS for 1M strands, 1057 MiB for 10M, of which some 190 MiB the interpreter and numpy).
_BLOCK_BYTES_PER_POINT = 96


class BlockGenerator(_Grower):
    """The strands of Generator(scalp, keys, params, collider=...).generate(), grown and
    handed over a block of strands at a time (`blocks()`), holding no block after handing
    it over and no per-root state of the whole head: the roots, frames, wisps and weights of
    each block are made with it, from each root's own random stream. Memory therefore stays
    that of one block whatever the count (ten million strands take what one million do);
    the blocks joined are bit-identical to the one-shot result."""

    def __init__(self, scalp, keys, params, collider=None, progress=None, block_strands=BLOCK_STRANDS):
        self.progress = progress
        self.block_strands = max(1, int(block_strands))
        self._report(0.0, "sampling roots")
        self.keys = _check_inputs(scalp, keys, params, in_memory=False)
        self.scalp, self.params = scalp, params
        p = params
        block = min(p.count, self.block_strands)
        check_memory(f"count {p.count:,} grown in blocks of {block:,} strands",
                     block * p.points_per_strand * _BLOCK_BYTES_PER_POINT + p.count,
                     f"lower points_per_strand ({p.points_per_strand}) or the block size")
        # Every root lies in a triangle of the scalp, so its corners bound how far the roots
        # reach (the float32 check; the one-shot Generator takes the roots' own).
        self._reach = float(np.abs(scalp.vertices[scalp.triangles]).max())
        self._check_root_groups()
        self._setup_keys(collider, p.count)
        self._shortfall = (0, 0.0, 0.0)
        self.summary = None

    # Its blocks carry colour a point (GroomBlock, the .npz's layout), written as they come.
    _colors_per_strand = False

    def _check_root_groups(self):
        """wisps.check_groups for every root before any work (roots sampled a block at a
        time when the scalp or a parting gives them groups; otherwise all are group 0)."""
        p, scalp = self.params, self.scalp
        key_groups = np.array([k.group for k in self.keys], np.int32)
        if scalp.groups is None and p.parting is None:
            check_groups(np.zeros(1, np.int32), key_groups)
            return
        found = set()
        for lo, hi in _block_ranges(p.count, self.block_strands):
            s = sample_roots(scalp, p.count, p.seed, p.sampling_mode, lo, hi)
            found.update(np.unique(root_groups_for(scalp, s.tri, s.bary, s.points, p)).tolist())
        check_groups(np.array(sorted(found), np.int32), key_groups)

    def _note_resolution(self, idx, met, asked, needed):
        self._shortfall = _combined_shortfall(self._shortfall, _resolution_shortfall(met, asked, needed))

    def blocks(self):
        """Yields a GroomBlock per block of strands, in order. Once all are taken, `summary`
        (a GroomSummary) says what the run made, and a ResolutionWarning is issued when the
        resolution fell short (as Generator does)."""
        p, scalp, n = self.params, self.scalp, self.params.count
        context = self._blend_context()
        key_roots = np.array([k.root for k in self.keys], dtype=np.float64)
        key_groups = np.array([k.group for k in self.keys], np.int32)
        blocks = _block_ranges(n, self.block_strands)
        stats, points = CollisionStats(), 0
        self._shortfall = (0, 0.0, 0.0)
        for i, (lo, hi) in enumerate(blocks):
            report = self._block_report(i, len(blocks))
            report(0.0, "sampling roots")
            s = sample_roots(scalp, n, p.seed, p.sampling_mode, lo, hi)
            m = hi - lo
            frac, transforms = np.empty(m), np.empty((9, m), np.float32)
            uv = None if scalp.uv is None else np.empty((m, 2))
            groups = root_groups_for(scalp, s.tri, s.bary, s.points, p)
            guides, weights = np.empty((3, m), np.int64), np.empty((3, m))

            def assign(a, b):
                g, w = guide_weights_by_guide(s.points[a:b], key_roots, p.neighbour_mode, p.n_influence, groups[a:b],
                                              key_groups, check=False)
                guides[:, a:b], weights[:, a:b] = g, w
            parts = ranges(m, size=_ROOT_RANGE)
            run_jobs([partial(_root_state, scalp, p, s, a, b, frac, uv, transforms) for a, b in parts]
                     + [partial(assign, a, b) for a, b in parts], _threads_for(m))
            roots, ids = np.ascontiguousarray(s.points.T), s.ids
            del s, groups
            grown = self._grow(context, roots, transforms, guides, weights, frac, ids, slice(lo, hi), report)
            del roots, transforms, frac, ids
            if self._collision is not None:
                stats.add(grown[5])
            points += len(grown[0])
            yield GroomBlock(lo, hi, *grown[:5], guides, weights, uv)
            # The consumer has the block now: nothing of it stays here while the next grows.
            del grown, guides, weights, uv
        collision = None
        if self._collision is not None:
            self._collision.last = stats
            collision = self._collision.report()
        warning = _resolution_message(p, self._shortfall, n)
        self.summary = GroomSummary(n, points, collision, warning)
        self._report(1.0, "done")
        if warning:
            warnings.warn(warning, ResolutionWarning, stacklevel=2)


def npz_names(scalp):
    """The arrays generate_to_npz writes (those of strands_with_guides(...).arrays(), in order)."""
    return list(NPZ_NAMES) + [n for n in GUIDE_NPZ_NAMES if n != "root_uv" or scalp.uv is not None]


def npz_bytes_bound(params, spill_bytes=None):
    """Disk a run of generate_to_npz may take at most while it writes: the archive with
    points_per_strand points a strand (32 bytes a point, 40 a strand), plus, when the blocks
    spill to temporary files (more than `spill_bytes`), its largest array (the points, 12
    bytes a point) once more."""
    spill_bytes = NpzWriter.SPILL_BYTES if spill_bytes is None else spill_bytes
    n, pps = params.count, params.points_per_strand
    archive = n * pps * 32 + n * 48 + (1 << 20)
    return archive + (n * pps * 12 if archive > spill_bytes else 0)


def check_npz_room(path, params, what=None, spill_bytes=None):
    """InputError, naming `what` (default: the path), when `path` cannot be written or its
    disk has less room than npz_bytes_bound(params): what generate_to_npz checks before any
    work (a caller may check it sooner, before its own preparations)."""
    what = what or os.fspath(path)
    check_destination(path, what)
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    need, free = npz_bytes_bound(params, spill_bytes), shutil.disk_usage(folder).free
    if need > free:
        raise InputError(f"count {params.count:,}: {what} takes up to {need / 2**30:,.2f} GiB of disk while it is "
                         f"written ({params.points_per_strand} points a strand at most, 32 bytes each) but "
                         f"{folder!r} has {free / 2**30:,.2f} GiB free; grow fewer strands or fewer points per "
                         f"strand, or write it elsewhere")


def generate_to_npz(path, scalp, keys, params=None, collider=None, progress=None, block_strands=BLOCK_STRANDS,
                    spill_bytes=None, points_per_key=32, what=None):
    """Grow the strands a block at a time (BlockGenerator) straight into the .npz at `path`:
    the arrays strands_with_guides(generate(...), keys, params).save_npz(path) writes, equal
    element for element, with memory of one block whatever the count (the blocks go to
    temporary files beside `path` once they take more than `spill_bytes`; hairio.npyfile.
    NpzWriter). Refused before any work, by an InputError naming `what` (default: the
    path), when the folder cannot take the file or has less room than npz_bytes_bound.
    progress: as Generator's. Returns a GroomSummary. All or nothing: an error leaves no file."""
    params = params or GroomParams()
    check_npz_room(path, params, what, spill_bytes)

    def growing(fraction, stage):
        if progress is not None and stage != "done":   # done once the file is
            progress(0.9 * fraction, stage)
    gen = BlockGenerator(scalp, keys, params, collider=collider, progress=growing, block_strands=block_strands)
    key_strands = _key_strands(gen.keys, params, points_per_key)
    names = npz_names(scalp)
    kwargs = {} if spill_bytes is None else {"spill_bytes": spill_bytes}
    with NpzWriter(path, names, **kwargs) as writer:
        for name, array in (("key_points", key_strands.points), ("key_counts", key_strands.counts),
                            ("key_radius", key_strands.radius), ("key_color", key_strands.color),
                            ("key_group", np.array([k.group for k in gen.keys]).astype(np.int32))):
            writer.append(name, array)
        # The blocks are written on a thread of their own while the next grows (1,000,000
        # strands of wavy: see AppendBehind's entry in docs/DECISIONS.md).
        with AppendBehind(writer) as behind:
            for block in gen.blocks():
                behind.put(block.arrays())
                del block
        label = f"writing {os.path.basename(os.fspath(path))}"
        writer.commit(None if progress is None else lambda f: progress(0.9 + 0.1 * f, label))
    if progress is not None:
        progress(1.0, "done")
    return gen.summary
