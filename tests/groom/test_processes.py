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


def test_a_lost_worker_leaves_the_groom_to_threads_with_the_same_numbers(scalp, monkeypatch):
    from groom import Generator, default_collider, load_preset
    module = importlib.import_module("groom.generate")
    if parallel.cpu_threads() < 2:
        pytest.skip("one CPU: no blocks side by side")
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=1200, seed=3)
    monkeypatch.setattr(module, "PARALLEL_BLOCK", 100)
    monkeypatch.setattr(module, "PROCESS_BLOCK", 100)
    monkeypatch.setattr(processes, "_DISABLED", {})
    monkeypatch.setenv(processes.ENV_SWITCH, "0")
    expected = Generator(scalp, placement.keys, params, collider=default_collider(), block_strands=200).generate()
    monkeypatch.setenv(processes.ENV_SWITCH, "1")
    dead = processes.Worker()
    dead.send(os._exit, 1)
    dead._proc.wait()
    monkeypatch.setattr(processes, "workers", lambda n: [dead] * n)
    with pytest.warns(RuntimeWarning, match="groom worker process died"):
        got = Generator(scalp, placement.keys, params, collider=default_collider(), block_strands=200).generate()
    assert not processes.available()
    for name in ("points", "counts", "radius", "color", "alpha"):
        np.testing.assert_array_equal(getattr(got.strands, name), getattr(expected.strands, name))
    assert got.collision == expected.collision
