# SPDX-License-Identifier: GPL-3.0-or-later
"""Whole-array work split over threads.

numpy releases the GIL inside its loops, so ranges of strands processed by separate threads
run on separate cores. Every per-strand computation in groom is element-wise, so a strand's
numbers do not depend on the range it falls in: splitting never changes a result.
"""
import os
import threading
from concurrent.futures import ThreadPoolExecutor

# Below this many strands a job is too small to be worth handing to another thread.
MIN_SPLIT = 4096
# Strands per range of whole-array work (8k float64 = 64 KB per array).
RANGE_SIZE = 8192

_POOLS = {}


def _malloc_trim():
    """glibc's malloc_trim, or None where the C library has none (macOS, Windows, musl)."""
    try:
        import ctypes
        import ctypes.util
        name = ctypes.util.find_library("c")
        trim = getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    except (OSError, AttributeError):
        return None
    if trim is not None:
        trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


_TRIM = [False]     # not looked up yet


def free_memory():
    """Hands the free pages of the C heap back to the system (glibc's malloc_trim; nothing
    where there is none). numpy's arrays of a few MB come from the heap once a larger one has
    been freed (glibc raises its threshold for a mapping of their own up to 32 MB), and the
    heap keeps what they leave: after the collider's build 122 MB of a process's 187 MB were
    such free pages. Called after the work that leaves them, once a stage; it takes some
    milliseconds."""
    if _TRIM[0] is False:
        _TRIM[0] = _malloc_trim()
    if _TRIM[0] is not None:
        _TRIM[0](0)
_PREFIX = "groom-worker"
_SERIAL = False


def cpu_threads():
    """CPUs this process may run on (its affinity set where the platform tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def _pool(threads):
    """The process's pool of `threads` worker threads, made on first use and kept: starting
    threads on every call cost more than a small job itself. Keyed by process too: a forked
    child inherits the pool but not its threads."""
    key = (os.getpid(), threads)
    pool = _POOLS.get(key)
    if pool is None:
        pool = _POOLS[key] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix=_PREFIX)
    return pool


def one_thread():
    """The pool of one worker thread: a job on it runs its own jobs itself (_on_worker), as
    the share of the work this thread is left with when worker processes have the rest."""
    return _pool(1)


def _on_worker():
    """Whether the calling thread is one of the pool's (a job that itself runs jobs would
    wait for the workers it occupies, so it runs them itself), or this is a worker process
    of groom.processes (its CPU is the share it was started for)."""
    return _SERIAL or threading.current_thread().name.startswith(_PREFIX)


def run_serially():
    """From now on this process runs every job on the calling thread (a worker process)."""
    global _SERIAL
    _SERIAL = True


def run_jobs(jobs, threads=None, here=None):
    """Call every job() (no arguments), on up to `threads` threads (default: one per CPU),
    and return their results in order. `here`: one more job that the calling thread runs
    meanwhile; its result comes last (the worker threads: _pool)."""
    threads = min(threads or cpu_threads(), len(jobs))
    if _on_worker() or threads < 1 or (threads == 1 and (here is None or cpu_threads() == 1)):
        return [job() for job in jobs] + ([here()] if here else [])
    futures = [_pool(threads).submit(job) for job in jobs]
    try:
        mine = [here()] if here else []
    finally:
        # Whatever fails, no job may still be writing when the caller goes on.
        for f in futures:
            f.exception()  # waits for it
    return [f.result() for f in futures] + mine


def run_each(jobs, threads=None, done=None):
    """run_jobs for jobs that each do a large share of the work (a block of strands), on up to
    `threads` worker threads, with done(i) called in the calling thread as job i (in order)
    has finished (progress reports stay on the thread that asked for them). Each job's own
    run_jobs then run in its thread (nested), so the threads split the work by jobs, not
    every call: numpy calls on arrays of a few thousand items do not share two cores (the
    interpreter between them takes turns), a job of its own per thread does."""
    threads = min(threads or cpu_threads(), len(jobs))
    if _on_worker() or threads <= 1:
        out = []
        for i, job in enumerate(jobs):
            out.append(job())
            if done is not None:
                done(i)
        return out
    futures = [_pool(threads).submit(job) for job in jobs]
    try:
        for i, f in enumerate(futures):
            f.exception()
            if done is not None:
                done(i)
    finally:
        # Whatever fails (a job, or done), no job may still be writing when the caller goes on.
        for f in futures:
            f.cancel()
        for f in futures:
            if not f.cancelled():
                f.exception()
    return [f.result() for f in futures]


def ranges(n, threads=None, size=RANGE_SIZE, min_size=MIN_SPLIT):
    """[(lo, hi), ...] covering 0..n: ranges of about `size` items, at least one per thread
    when each still gets `min_size`. Many modest ranges rather than one per thread: a busy
    core then holds back only a small range, and arrays of 8k float64 stay on the
    allocator's heap instead of being mapped (and page-faulted) afresh on every call."""
    parts = max(1, -(-n // max(size, 1)))
    parts = max(parts, min(threads or cpu_threads(), n // max(min_size, 1)))
    edges = [n * i // parts for i in range(parts + 1)]
    return list(zip(edges[:-1], edges[1:]))
