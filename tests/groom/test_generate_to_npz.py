# SPDX-License-Identifier: GPL-3.0-or-later
"""A head grown a block at a time straight into its .npz (groom.generate.generate_to_npz,
hairio.npyfile.NpzWriter): the same arrays as growing it whole and saving it, in the memory
of a block, and all or nothing."""
import os
import tracemalloc
import warnings
import zipfile

import numpy as np
import pytest

import importlib
from groom import GroomParams, default_collider, generate, load_preset
from groom.generate import BlockGenerator, ResolutionWarning, generate_to_npz, strands_with_guides
from hairio import InputError, Strands

gen = importlib.import_module("groom.generate")   # the module (groom.generate is also the function)


def _members(path):
    with zipfile.ZipFile(path) as z:
        return {i.filename: z.read(i.filename) for i in z.infolist()}


def _whole(scalp, keys, params, collider, path):
    result = generate(scalp, keys, params, collider=collider)
    strands_with_guides(result, keys, params).save_npz(path)
    return result


@pytest.mark.parametrize("preset", ["wavy", "parted"])
def test_streamed_file_equals_the_one_grown_whole_byte_for_byte(scalp, tmp_path, preset):
    """Blocks of 333 strands spilled to temporary files after 64 KiB: every .npy member
    (header and data) equals numpy.savez's of the whole result, in the same order."""
    placement = load_preset(preset).place_keys(scalp)
    params = placement.params.replace(count=2000)
    collider = default_collider()
    whole = _whole(scalp, placement.keys, params, collider, tmp_path / "whole.npz")
    summary = generate_to_npz(tmp_path / "blocks.npz", scalp, placement.keys, params, collider=collider,
                              block_strands=333, spill_bytes=64 << 10)
    a, b = _members(tmp_path / "whole.npz"), _members(tmp_path / "blocks.npz")
    assert list(a) == list(b)
    for name in a:
        assert a[name] == b[name], name
    assert (summary.num_strands, summary.num_points) == (2000, whole.strands.num_points)
    assert summary.collision.strands_moved == whole.collision.strands_moved
    assert summary.collision.last == whole.collision.last
    assert sorted(os.listdir(tmp_path)) == ["blocks.npz", "whole.npz"]   # no temporary file left
    s = Strands.load_npz(tmp_path / "blocks.npz")
    assert s.guides is not None and s.num_strands == 2000


def test_blocks_held_in_memory_give_the_same_file(scalp, tmp_path):
    placement = load_preset("curly").place_keys(scalp)
    params = placement.params.replace(count=900, collision=False)
    _whole(scalp, placement.keys, params, None, tmp_path / "whole.npz")
    generate_to_npz(tmp_path / "blocks.npz", scalp, placement.keys, params, block_strands=250)
    assert _members(tmp_path / "whole.npz") == _members(tmp_path / "blocks.npz")


def test_the_resolution_warning_sums_over_the_blocks(scalp, keys_around):
    params = GroomParams(count=1500, seed=2, tolerance=1e-4, tolerance_units="scene", points_per_strand=5)
    keys = keys_around(scalp, 5)
    with warnings.catch_warnings(record=True) as whole:
        warnings.simplefilter("always")
        expected = generate(scalp, keys, params).warning
    assert expected and any(w.category is ResolutionWarning for w in whole)
    g = BlockGenerator(scalp, keys, params, block_strands=400)
    with pytest.warns(ResolutionWarning):
        points = sum(len(b.points) for b in g.blocks())
    assert g.summary.warning == expected
    assert points == g.summary.num_points


def test_a_streamed_run_holds_one_block_not_the_head(scalp, tmp_path):
    """The heap peak of growing in blocks of 2,000 strands is the same for 6,000 and 24,000
    strands, and a fraction of the larger file (a one-shot run holds all of it, and more)."""
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(collision=False)
    generate_to_npz(tmp_path / "h.npz", scalp, placement.keys, params.replace(count=200))  # caches, warm
    peaks = {}
    for count in (6000, 24_000):
        tracemalloc.start()
        try:
            generate_to_npz(tmp_path / "h.npz", scalp, placement.keys, params.replace(count=count),
                            block_strands=2000, spill_bytes=4 << 20)
            peaks[count] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    size = os.path.getsize(tmp_path / "h.npz")
    assert size > 40 << 20
    assert peaks[24_000] < 1.3 * peaks[6000], peaks   # the file grows 4x
    assert peaks[24_000] < size / 1.5, (peaks, size)


def test_a_failure_while_growing_leaves_no_file(scalp, tmp_path, monkeypatch):
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=3000, collision=False)
    calls = {"n": 0}
    grow = gen._Grower._grow

    def failing(self, *args):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(28, "No space left on device")
        return grow(self, *args)
    monkeypatch.setattr(gen._Grower, "_grow", failing)
    with pytest.raises(OSError):
        generate_to_npz(tmp_path / "h.npz", scalp, placement.keys, params, block_strands=500, spill_bytes=1 << 10)
    assert os.listdir(tmp_path) == []


def test_a_file_the_disk_cannot_take_is_refused_before_the_work(scalp, tmp_path, monkeypatch):
    import shutil
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=10_000_000)
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage._replace(free=10 << 30))
    monkeypatch.setattr(gen, "BlockGenerator", None)    # no work may start
    with pytest.raises(InputError, match=r"count 10,000,000: .*h\.npz takes up to 39\.79 GiB of disk while it is "
                                         r"written \(96 points a strand at most.* has 10\.00 GiB free"):
        generate_to_npz(tmp_path / "h.npz", scalp, placement.keys, params)
    assert os.listdir(tmp_path) == []


def test_a_missing_group_is_refused_before_any_block(scalp, tmp_path, monkeypatch):
    placement = load_preset("parted").place_keys(scalp)
    keys = [k for k in placement.keys if k.group == 0]
    params = placement.params.replace(count=3000)
    with pytest.raises(InputError, match=r"group\(s\) \[1\]"):
        generate(scalp, keys, params)
    monkeypatch.setattr(gen._Grower, "_grow", None)     # no block may start
    with pytest.raises(InputError, match=r"group\(s\) \[1\]"):
        generate_to_npz(tmp_path / "h.npz", scalp, keys, params, block_strands=500)
    assert os.listdir(tmp_path) == []


def test_roots_sampled_a_block_at_a_time_are_the_whole_samplings(scalp):
    from groom.sampling import sample_roots
    whole = sample_roots(scalp, 5000, seed=9)
    for lo, hi in ((0, 1), (0, 1234), (1234, 4321), (4999, 5000)):
        part = sample_roots(scalp, 5000, seed=9, lo=lo, hi=hi)
        for name in ("points", "tri", "bary", "ids"):
            np.testing.assert_array_equal(getattr(part, name), getattr(whole, name)[lo:hi], err_msg=name)
