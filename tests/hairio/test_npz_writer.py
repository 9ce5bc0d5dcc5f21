# SPDX-License-Identifier: GPL-3.0-or-later
"""hairio.npyfile.NpzWriter: an .npz written a block at a time is numpy.savez's archive."""
import os
import zipfile

import numpy as np
import pytest

from hairio.npyfile import NpzWriter, read_npz


def _arrays():
    rng = np.random.default_rng(7)
    return {"points": rng.normal(size=(1000, 3)).astype(np.float32),
            "counts": rng.integers(2, 9, 170).astype(np.int32),
            "empty": np.zeros((0, 2), np.float64),
            "key": np.arange(12, dtype=np.int64).reshape(4, 3)}


def _members(path):
    with zipfile.ZipFile(path) as z:
        return [(i.filename, z.read(i.filename)) for i in z.infolist()]


@pytest.mark.parametrize("spill_bytes", [0, 1 << 10, 1 << 30])
def test_blocks_make_the_archive_numpy_savez_makes(tmp_path, spill_bytes):
    arrays = _arrays()
    np.savez(tmp_path / "whole.npz", **arrays)
    progress = []
    with NpzWriter(tmp_path / "blocks.npz", list(arrays), spill_bytes=spill_bytes) as w:
        for name in ("key", "empty"):
            w.append(name, arrays[name])
        for lo in range(0, 1000, 137):   # uneven blocks, interleaved between arrays
            w.append("points", arrays["points"][lo:lo + 137])
            if lo < 170:
                w.append("counts", arrays["counts"][lo:lo + 137])
        assert w.spilled == (spill_bytes < 1 << 30)
        w.commit(progress.append)
    assert _members(tmp_path / "whole.npz") == _members(tmp_path / "blocks.npz")
    assert progress[-1] == 1.0 and progress == sorted(progress)
    assert sorted(os.listdir(tmp_path)) == ["blocks.npz", "whole.npz"]
    back = read_npz(tmp_path / "blocks.npz", list(arrays))
    for name, a in arrays.items():
        np.testing.assert_array_equal(back[name], a)


def test_a_writer_left_without_commit_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        with NpzWriter(tmp_path / "x.npz", ["a"], spill_bytes=0) as w:
            w.append("a", np.ones((100, 3)))
            assert len(os.listdir(tmp_path)) == 1     # the spilled block
            raise RuntimeError("the work failed")
    assert os.listdir(tmp_path) == []


def test_a_block_of_another_kind_is_refused(tmp_path):
    with NpzWriter(tmp_path / "x.npz", ["a", "b"]) as w:
        w.append("a", np.ones((4, 3), np.float32))
        with pytest.raises(ValueError, match="cannot join"):
            w.append("a", np.ones((4, 2), np.float32))
        with pytest.raises(ValueError, match="cannot join"):
            w.append("a", np.ones((4, 3), np.float64))
        with pytest.raises(ValueError, match=r"no data for \['b'\]"):
            w.commit()
    assert os.listdir(tmp_path) == []


def test_appends_behind_the_caller_make_the_same_archive_holding_two_batches_at_most(tmp_path):
    """AppendBehind: the batches are appended on a thread of their own, in order, and a put
    returns only once the batch before it is written (the caller's next batch and the one
    being written are all that is held)."""
    import threading
    from hairio.npyfile import AppendBehind
    arrays = _arrays()
    np.savez(tmp_path / "whole.npz", **arrays)
    written, gate = [], threading.Event()
    with NpzWriter(tmp_path / "behind.npz", list(arrays), spill_bytes=1 << 10) as w:
        real = w.append

        def append(name, rows):
            assert threading.current_thread().name == "npz-append"
            gate.wait(5)
            real(name, rows)
            written.append((name, len(rows)))
        w.append = append
        with AppendBehind(w) as behind:
            behind.put({"key": arrays["key"], "empty": arrays["empty"]})
            threading.Timer(0.2, gate.set).start()     # the first appends wait for it
            handed = 2
            for lo in range(0, 1000, 250):
                batch = {"points": arrays["points"][lo:lo + 250]}
                if lo == 0:
                    batch["counts"] = arrays["counts"]
                behind.put(batch)
                # Every batch before this one was written by the time it was handed over.
                assert len(written) >= handed
                handed += len(batch)
        assert len(written) == handed
        assert [n for n, _ in written][-1] == "points" and sum(r for n, r in written if n == "points") == 1000
        w.commit()
    assert _members(tmp_path / "whole.npz") == _members(tmp_path / "behind.npz")


def test_an_append_that_fails_behind_the_caller_fails_the_caller_and_leaves_no_file(tmp_path):
    from hairio.npyfile import AppendBehind
    with pytest.raises(ValueError, match="cannot join"):
        with NpzWriter(tmp_path / "x.npz", ["a"], spill_bytes=0) as w:
            with AppendBehind(w) as behind:
                behind.put({"a": np.ones((4, 3), np.float32)})
                behind.put({"a": np.ones((4, 2), np.float32)})     # refused on the thread
                behind.put({"a": np.ones((4, 3), np.float32)})     # raises the refusal here
            w.commit()
    assert os.listdir(tmp_path) == []
