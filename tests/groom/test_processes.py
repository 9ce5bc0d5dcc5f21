# SPDX-License-Identifier: GPL-3.0-or-later
"""groom.processes: the worker processes large grooms grow their blocks in."""
import importlib
import os

import numpy as np
import pytest

from groom import parallel, processes
from hairio import InputError

pytestmark = pytest.mark.skipif(not processes.available(), reason="worker processes need Linux's memfd")


@pytest.fixture
def worker():
    w = processes.Worker()
    yield w
    w.stop()


def test_a_worker_answers_its_jobs_in_order_and_raises_their_errors_here(worker):
    worker.send(len, [1, 2, 3])
    worker.send(InputError.__call__, "not raised, returned")
    worker.send(importlib.import_module, "no_such_module_here")
    worker.send(len, [1])
    assert worker.receive() == 3
    assert str(worker.receive()) == "not raised, returned"
    with pytest.raises(ModuleNotFoundError, match="no_such_module_here"):
        worker.receive()
    assert worker.receive() == 1 and worker.alive()


def test_a_worker_maps_the_parents_shared_array_not_a_copy(worker):
    shared = processes.shared_empty((1000, 3))
    shared.array[...] = np.arange(3000, dtype=np.float32).reshape(1000, 3)
    worker.send(processes.open_shared, shared.handle)
    np.testing.assert_array_equal(worker.receive(), shared.array)
    shared.array[500] = -1.0
    worker.send(processes.open_shared, shared.handle)
    seen = worker.receive()
    shared.close()
    assert (seen[500] == -1.0).all() and seen[499, 0] == 1497.0


def test_shared_memory_a_worker_cannot_map_is_reported_as_a_lost_worker(worker):
    shared = processes.shared_empty(10)
    handle = shared.handle
    shared.close()                     # the file is gone from /proc/<pid>/fd
    worker.send(processes.open_shared, handle)
    with pytest.raises(processes.WorkerDied, match="cannot map"):
        worker.receive()
    assert worker.alive()


def test_a_worker_maps_only_the_rows_of_its_block(worker):
    shared = processes.shared_empty((5000, 3))
    shared.array[...] = np.arange(15000, dtype=np.float32).reshape(5000, 3)
    # Rows 1234..4321 start and end inside pages (12-byte rows, 4096-byte pages).
    worker.send(processes.open_shared, shared.handle, (1234, 4321))
    rows = worker.receive()
    shared.close()
    assert rows.shape == (3087, 3)
    np.testing.assert_array_equal(rows, shared.array[1234:4321])


def _file_id(fd):
    st = os.fstat(fd)
    return st.st_dev, st.st_ino


def test_inside_recycling_the_next_shared_array_takes_the_memory_of_one_that_went(worker):
    with processes.recycling():
        old = processes.shared_empty((1000, 3))
        old.array[...] = 7.0
        was = _file_id(old.fd)
        old.close()
        del old
        assert processes.spares() == 12000
        new = processes.shared_empty((1500, 3))       # bigger: the file grows
        assert processes.spares() == 0
        assert _file_id(new.fd) == was
        assert new.array.shape == (1500, 3) and (new.array[:1000] == 7.0).all()
        new.array[1000:] = 8.0
        worker.send(processes.open_shared, new.handle)
        np.testing.assert_array_equal(worker.receive(), new.array)
        new.close()
    assert new.array.sum() == 7.0 * 3000 + 8.0 * 1500


def test_memory_still_in_use_is_never_recycled():
    with processes.recycling():
        old = processes.shared_empty(1000)
        old.array[...] = np.arange(1000)
        was = _file_id(old.fd)
        view = old.array[10:20]
        old.close()
        del old
        assert processes.spares() == 0
        new = processes.shared_empty(1000)
        new.array[...] = -1.0
        assert _file_id(new.fd) != was
        new.close()
    np.testing.assert_array_equal(view, np.arange(10, 20))


def test_what_recycling_did_not_take_is_freed_on_leaving_and_outside_it_at_once():
    with processes.recycling():
        kept = processes.shared_empty(1000)
        kept_id = _file_id(kept.fd)
        kept.close()
        del kept
        assert processes.spares() == 4000 and kept_id in processes.open_files()
    assert processes.spares() == 0 and kept_id not in processes.open_files()
    dropped = processes.shared_empty(1000)
    dropped_id = _file_id(dropped.fd)
    dropped.close()
    assert dropped_id in processes.open_files()      # the mapping holds the file
    del dropped
    assert processes.spares() == 0 and dropped_id not in processes.open_files()


def _allocated(fd):
    return os.fstat(fd).st_blocks * 512


def test_a_shared_array_takes_its_pages_a_block_of_rows_at_a_time(worker):
    shared = processes.shared_empty((100_000, 3))       # 1.2 MB
    assert _allocated(shared.fd) == 0                   # no page before a block reserves its rows
    shared.reserve(0, 10_000)
    assert 120_000 <= _allocated(shared.fd) < 1_200_000
    worker.send(processes.open_shared, shared.handle, (50_000, 60_000))    # a worker's block
    assert worker.receive().shape == (10_000, 3)
    assert 240_000 <= _allocated(shared.fd) < 1_200_000
    shared.close()


def test_no_room_for_a_blocks_rows_is_a_memory_error_not_a_killed_process(monkeypatch):
    import errno

    def full(fd, offset, length):
        raise OSError(errno.ENOSPC, "No space left on device")
    shared = processes.shared_empty((1000, 3))
    monkeypatch.setattr(os, "posix_fallocate", full)
    with pytest.raises(MemoryError, match="no room for .* generate fewer strands"):
        shared.reserve(0, 1000)
    with pytest.raises(MemoryError, match="No space left on device"):
        processes.open_shared(shared.handle, (0, 500))
    shared.close()


def test_a_worker_keeps_what_it_was_sent_once(worker):
    big = np.arange(10)
    worker.keep("ten", big)
    worker.keep("ten", big)           # known: not sent again
    assert worker.pending == 1
    worker.send(processes.kept, "ten")
    worker.receive()
    np.testing.assert_array_equal(worker.receive(), big)
    for name in ("a", "b"):           # the worker keeps the last two; so does the list of what it knows
        worker.keep(name, name)
    worker.drain()
    assert worker.known == ["a", "b"]
    worker.send(processes.kept, "ten")
    with pytest.raises(KeyError):
        worker.receive()


def test_jobs_in_a_worker_run_on_its_one_thread(worker):
    worker.send(parallel._on_worker)
    assert worker.receive() is True
    assert parallel._on_worker() is False


def test_a_worker_that_dies_is_reported_as_lost(worker):
    worker.send(os._exit, 3)
    with pytest.raises(processes.WorkerDied, match="died"):
        worker.receive()
    assert not worker.alive()


def _small_blocks(scalp, monkeypatch, seed, collider=None):
    """A job that grows 1,200 strands of wavy in blocks of 200, side by side from 100 strands a
    block (in worker processes where they run), with `collider` (default: the bundled head's):
    a function that grows it."""
    from groom import Generator, default_collider, load_preset
    module = importlib.import_module("groom.generate")
    if parallel.cpu_threads() < 2:
        pytest.skip("one CPU: no blocks side by side")
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=1200, seed=seed)
    monkeypatch.setattr(module, "PARALLEL_BLOCK", 100)
    monkeypatch.setattr(module, "PROCESS_BLOCK", 100)
    collider = default_collider() if collider is None else collider
    return lambda: Generator(scalp, placement.keys, params, collider=collider, block_strands=200).generate()


def test_a_lost_worker_leaves_the_groom_to_threads_with_the_same_numbers(scalp, monkeypatch):
    grow = _small_blocks(scalp, monkeypatch, seed=3)
    monkeypatch.setattr(processes, "_DISABLED", {})
    monkeypatch.setenv(processes.ENV_SWITCH, "0")
    expected = grow()
    monkeypatch.setenv(processes.ENV_SWITCH, "1")
    dead = processes.Worker()
    dead.send(os._exit, 1)
    dead._proc.wait()
    monkeypatch.setattr(processes, "workers", lambda n: [dead] * n)
    with pytest.warns(RuntimeWarning, match="groom worker process died"):
        got = grow()
    assert not processes.available()
    for name in ("points", "counts", "radius", "color", "alpha"):
        np.testing.assert_array_equal(getattr(got.strands, name), getattr(expected.strands, name))
    assert got.collision == expected.collision


# The memory files of one run of wavy: points, radius and colour (it is opaque, so its alpha
# takes none: groom.cylinders.ones).
FILES = 3


def test_a_groom_grown_in_the_memory_of_the_one_it_replaces_is_the_same(scalp, monkeypatch, spare_takes):
    grow = _small_blocks(scalp, monkeypatch, seed=5)
    expected = grow()
    old = grow()
    assert spare_takes == [False] * (2 * FILES)    # nothing to take outside recycling()
    old.strands.points[...] = np.nan     # what the new result must not show
    spare_takes.clear()
    with processes.recycling():
        del old
        got = grow()
    assert spare_takes == [True] * FILES
    for name in ("points", "counts", "radius", "color", "alpha"):
        np.testing.assert_array_equal(getattr(got.strands, name), getattr(expected.strands, name))


def test_workers_prepared_with_the_collider_are_sent_neither_again_by_the_first_run(scalp, monkeypatch):
    """generate.prepare_workers (Blender's Add Head runs it once the head's collider is
    built): the workers are started and keep the collider, so the run that follows sends
    it none (25 MB on the bundled head) and starts no worker; its blocks grow in them."""
    from groom import default_collider
    from groom.generate import prepare_workers
    made = default_collider()
    # The same collider under a token no worker knows yet (tokens outlive a test).
    collider = object.__new__(type(made))
    collider.__dict__.update({k: v for k, v in made.__dict__.items() if k != "_worker_token"})
    grow = _small_blocks(scalp, monkeypatch, seed=7, collider=collider)
    prepare_workers(collider)
    assert all(processes.token(collider) in w.known and not w.pending
               for w in processes.workers(parallel.cpu_threads() - 1))
    sent, started, send, start = [], [], processes.Worker.send, processes.Worker.__init__

    def noted(self, fn, *args):
        sent.append(fn.__name__)
        return send(self, fn, *args)

    def starting(self):
        started.append(self)
        start(self)
    monkeypatch.setattr(processes.Worker, "send", noted)
    monkeypatch.setattr(processes.Worker, "__init__", starting)
    grow()
    assert "_worker_grow" in sent and "_keep" not in sent and not started


def test_a_run_waits_for_the_workers_being_prepared_but_not_for_another_run():
    """try_lock: while prepare() has the workers (it readies them for the run to come) a run
    waits for them; while another run has them it grows on threads at once (False)."""
    import threading
    import time
    held, release = threading.Event(), threading.Event()

    def holder(preparing):
        with processes._LOCK:
            if preparing:
                processes._PREPARING.set()
            held.set()
            release.wait(5)
            processes._PREPARING.clear()
    for preparing in (False, True):
        held.clear()
        release.clear()
        thread = threading.Thread(target=holder, args=(preparing,))
        thread.start()
        held.wait(5)
        threading.Timer(0.3, release.set).start()
        t0 = time.perf_counter()
        got = processes.try_lock()
        waited = time.perf_counter() - t0
        if got:
            processes.unlock()
        thread.join()
        assert (got, waited >= 0.25) == (preparing, preparing), (preparing, got, waited)
