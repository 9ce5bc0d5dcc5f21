# SPDX-License-Identifier: GPL-3.0-or-later
"""Worker processes for the blocks of a large groom, where the platform lets them share
memory (Linux: memfd).

Threads share one interpreter, and much of growing a block is numpy calls on a few thousand
items at a time (the collision walk's steps, the placement's bins), between which a thread
holds the interpreter: two threads took turns more than they ran side by side
(docs/DECISIONS.md, "Blocks of strands in worker processes"). A worker process has an
interpreter of its own. Each worker is a plain Python started on this package (`python -c`,
with the parent's numpy), kept for the life of the process, fed jobs as pickled (function,
arguments) messages on its stdin (hairio.pipes) and answering each, in order, with its
result or its exception. Large arrays do not travel through the pipe: `shared_empty` makes
an array in a memory file of its own that a worker maps (`open_shared`), so a block's points
are written once, where the result keeps them. Jobs run serially in a worker
(parallel.run_serially): its CPU is the share it was started for.
"""
import atexit
import collections
import contextlib
import mmap
import os
import pickle
import queue
import subprocess
import sys
import threading
import traceback
import uuid
import weakref

import numpy as np

from hairio.pipes import package_paths, read_message, write_message

from . import parallel

# "0" keeps every block in this process (threads only).
ENV_SWITCH = "KEYSTRAND_GROOM_PROCESSES"
_APPEND_ENV = "KEYSTRAND_GROOM_APPEND_PATH"
_BOOT = ("import os, sys\n"
         f"for p in os.environ.get({_APPEND_ENV!r}, '').split(os.pathsep):\n"
         "    if p and p not in sys.path:\n"
         "        sys.path.append(p)\n"
         "from groom.processes import serve\n"
         "serve()\n")
# Objects a worker keeps between jobs (keep / kept): a collider is some 25 MB, sent once.
_KEPT_MOST = 2

# The workers of this process, by pid (a forked child inherits the list, not the processes).
_WORKERS = {}
# One caller at a time hands out the workers (jobs and answers of two callers would mix);
# another caller meanwhile grows its blocks on threads (try_lock), unless what has them is
# prepare() (set while it does), which readies them for that caller: it waits, at most
# _PREPARE_WAIT seconds.
_LOCK = threading.Lock()
_PREPARING = threading.Event()
_PREPARE_WAIT = 10.0
# Why worker processes are off in this process (by pid), once one was lost.
_DISABLED = {}

# Worker side: what jobs leave for later jobs of the same run, and kept objects.
STATE = {}
_KEPT = collections.OrderedDict()


class WorkerDied(RuntimeError):
    """A worker process exited or could not be started; the caller grows on threads instead."""


def available():
    """Whether blocks may grow in worker processes here: Linux (memory files shared by
    /proc/<pid>/fd), unless $KEYSTRAND_GROOM_PROCESSES is "0" or a worker was lost."""
    return (sys.platform.startswith("linux") and hasattr(os, "memfd_create")
            and os.environ.get(ENV_SWITCH, "1") != "0" and _DISABLED.get(os.getpid()) is None)


def disable(reason):
    """No more worker processes in this process (one could not start, or died): `reason`."""
    _DISABLED[os.getpid()] = reason


def try_lock():
    """Take the workers for one run (True), or False when another thread's run has them; a
    prepare() that has them is waited for (Generate pressed while Add Head's thread starts
    the workers grows in them, not on threads)."""
    if _LOCK.acquire(blocking=False):
        return True
    if _PREPARING.is_set():
        return _LOCK.acquire(timeout=_PREPARE_WAIT)
    return _LOCK.acquire(blocking=False)    # a prepare() that let go just now (it clears after)


def unlock():
    _LOCK.release()


class Worker:
    """One worker process: send(fn, *args) queues a job, receive() returns the oldest
    unanswered job's result or raises its exception (WorkerDied when the process is gone)."""

    def __init__(self):
        package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([package_root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
        env[_APPEND_ENV] = os.pathsep.join(package_paths(("numpy",)))
        try:
            self._proc = subprocess.Popen([sys.executable, "-c", _BOOT], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        except OSError as e:
            raise WorkerDied(f"groom worker process could not start ({sys.executable}: {e})") from None
        self._stderr = collections.deque(maxlen=20)
        self.pending = 0
        self.known = []             # tokens of the objects it keeps, oldest first
        # Answers are read as they come, on a thread of their own: a worker blocked writing an
        # answer nobody reads would stop reading the jobs still being sent to it.
        self._answers = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        threading.Thread(target=self._drain, daemon=True).start()

    def _pump(self):
        try:
            while True:
                self._answers.put(read_message(self._proc.stdout))
        except Exception:   # EOF: the worker is gone (its stderr says why)
            self._answers.put(None)

    def _drain(self):
        for line in self._proc.stderr:
            self._stderr.append(line.decode(errors="replace"))

    def alive(self):
        return self._proc.poll() is None

    def _died(self, during):
        self.stop()
        return WorkerDied(f"groom worker process died {during}; its last words: "
                          f"{''.join(self._stderr).strip()[-600:]!r}")

    def send(self, fn, *args):
        try:
            write_message(self._proc.stdin, (fn, args))
        except (BrokenPipeError, OSError, ValueError):
            raise self._died(f"before {fn.__name__}") from None
        self.pending += 1

    def keep(self, token, obj):
        """Have the worker keep obj under token for later jobs (sent once per worker)."""
        if token not in self.known:
            self.send(_keep, token, obj)
            # The worker keeps the _KEPT_MOST sent last, as this list does.
            self.known = (self.known + [token])[-_KEPT_MOST:]

    def receive(self):
        answer = self._answers.get()
        if answer is None:
            self._answers.put(None)     # every later receive meets the same end
            raise self._died("during a job")
        self.pending -= 1
        if answer[0] == "ok":
            return answer[1]
        raise answer[1]

    def drain(self):
        """Receive every pending answer, dropping results and errors (after a failed run)."""
        while self.pending:
            try:
                self.receive()
            except WorkerDied:
                return
            except Exception:
                pass

    def stop(self):
        proc = self._proc
        if proc.poll() is None:
            try:
                proc.stdin.close()
                proc.wait(timeout=2)
            except (OSError, subprocess.TimeoutExpired):
                proc.kill()
        self.pending = 0


def workers(n):
    """n running worker processes of this process (started where missing)."""
    pool = _WORKERS.setdefault(os.getpid(), [])
    pool[:] = [w for w in pool if w.alive()]
    while len(pool) < n:
        pool.append(Worker())
    return pool[:n]


def start(n):
    """Start n workers ahead of a run that will want them (their start overlaps the run's
    first work); off for the rest of the process when one cannot start."""
    if not available() or not try_lock():   # another thread's run has the workers: they are up
        return
    try:
        workers(n)
    except WorkerDied as e:
        disable(str(e))
    finally:
        unlock()


def discard(found):
    """Stop these workers (after a run that failed: what they hold is not known)."""
    for w in found:
        w.stop()
    pool = _WORKERS.get(os.getpid(), [])
    pool[:] = [w for w in pool if w not in found]


def prepare(n, objects=()):
    """Start n workers and have each keep `objects` (Worker.keep), waiting until they have:
    what a run's first jobs would otherwise wait for (a worker's start and imports, some
    0.15 s, then the objects, the bundled head's collider being 25 MB). Nothing where
    workers are off or another thread's run has them; off for the rest of the process
    when one cannot start."""
    if n < 1 or not available() or not _LOCK.acquire(blocking=False):
        return
    _PREPARING.set()
    try:
        for w in workers(n):
            for obj in objects:
                w.keep(token(obj), obj)
            while w.pending:
                w.receive()
    except WorkerDied as e:
        disable(str(e))
    finally:
        unlock()
        _PREPARING.clear()


@atexit.register
def _stop_all():
    for w in _WORKERS.get(os.getpid(), []):
        w.stop()


def workers_peak_mb():
    """The peak resident memory of this process's worker processes, summed, in MiB (Linux's
    VmHWM; 0 without workers). Pages of the shared arrays count where they were written."""
    total = 0.0
    for w in _WORKERS.get(os.getpid(), []):
        try:
            with open(f"/proc/{w._proc.pid}/status") as f:
                total += next((int(line.split()[1]) / 1024.0 for line in f if line.startswith("VmHWM:")), 0.0)
        except OSError:
            pass
    return total


def workers_cpu_seconds():
    """CPU seconds (user + system) this process's worker processes have used so far, summed
    (Linux's /proc/<pid>/stat; 0 without workers): a run's CPU time is this process's plus
    the change in these."""
    total = 0.0
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    for w in _WORKERS.get(os.getpid(), []):
        try:
            with open(f"/proc/{w._proc.pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            pass
    return total


def token(obj):
    """A name for obj that stays the same for its life (and for copies of its __dict__)."""
    return obj.__dict__.setdefault("_worker_token", uuid.uuid4().hex)


# --- shared memory --------------------------------------------------------------------------

class Shared:
    """An array in a memory file of its own: `array` here, `handle` for a worker's
    open_shared. close() once the workers have mapped it (the memory stays while the array
    or a view of it lives; then it goes, or, inside recycling(), waits for the next
    shared_empty)."""

    def __init__(self, shape, dtype):
        dtype = np.dtype(dtype)
        shape = tuple(int(s) for s in np.atleast_1d(shape))
        size = int(np.prod(shape))
        nbytes = max(size * dtype.itemsize, 1)
        buf, self.fd = _take_spare(nbytes)
        if buf is None:
            self.fd = os.memfd_create("keystrand-groom", os.MFD_CLOEXEC)
            try:
                # No pages yet: each block's are made when it grows (reserve, open_shared), so
                # the result's memory comes as the blocks' curve parameters go (1,000,000
                # strands of wavy: 2,647 MiB at the peak against 2,717 with every page made
                # here; docs/DECISIONS.md, "The result's memory, counted once").
                os.ftruncate(self.fd, nbytes)
                buf = mmap.mmap(self.fd, nbytes)
            except OSError as e:
                self.close()
                raise MemoryError(_no_room(nbytes, e)) from None
        flat = np.frombuffer(buf, dtype, size)
        self.array = flat.reshape(shape)
        self.handle = (os.getpid(), self.fd, shape, dtype.str)
        st = os.fstat(self.fd)
        # Watched at `flat`: every view of the memory (self.array's rows, reshapes, slices)
        # names it as its base, so it goes last.
        weakref.finalize(flat, _array_gone, buf, (st.st_dev, st.st_ino))

    def reserve(self, lo, hi):
        """Makes the pages of rows lo..hi now (_reserve), before this process writes them."""
        row = self.array.strides[0]
        _reserve(self.fd, lo * row, (hi - lo) * row)

    def close(self):
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def _no_room(nbytes, error):
    return (f"groom: no room for {nbytes / 2 ** 20:,.0f} MiB of shared memory for the strands "
            f"({error.strerror}); generate fewer strands or points per strand")


def _reserve(fd, offset, length):
    """Makes the pages of bytes offset..offset + length of memory file fd at once: one call,
    not a fault a page as they are first written (100,000 strands of wavy in a process with
    Blender beside, alternating: 0.86 against 0.97 s), and MemoryError where the machine has
    no room for them, where a write to a page it cannot make would kill the process (SIGBUS)."""
    if length > 0:
        try:
            os.posix_fallocate(fd, offset, length)
        except OSError as e:
            raise MemoryError(_no_room(length, e)) from None


# Memory files of shared arrays that went while recycling() was open: [(mmap, file id)].
_SPARES = []
_SPARE_LOCK = threading.RLock()
_RECYCLING = [0]    # open recycling() blocks of this process


@contextlib.contextmanager
def recycling():
    """Within the block, the memory of a shared array that goes (its result dropped) is kept,
    and shared_empty takes it rather than new pages; leaving the block frees what was not
    taken. For a caller that replaces one result with the next of about its size (Blender's
    Generate, which drops the hair it replaces just before it grows the new): the old
    result's pages, written and mapped already, need neither the kernel's zeroing of fresh
    pages nor the unmapping of the old ones (100,000 strands of `wavy`, some 200 MB: 0.96 s
    against 1.16 s a generate, docs/DECISIONS.md)."""
    with _SPARE_LOCK:
        _RECYCLING[0] += 1
    try:
        yield
    finally:
        with _SPARE_LOCK:
            _RECYCLING[0] -= 1
            if _RECYCLING[0] == 0:
                _SPARES.clear()     # their mappings go with these last references


def spares():
    """Bytes of memory files waiting in recycling() for a shared_empty."""
    with _SPARE_LOCK:
        return sum(len(buf) for buf, _ in _SPARES)


def _array_gone(buf, file_id):
    # Called while the array's own view of buf may still be letting go: buf is kept or
    # dropped here, never closed.
    with _SPARE_LOCK:
        if _RECYCLING[0] > 0:
            _SPARES.append((buf, file_id))


def open_files():
    """{(st_dev, st_ino): descriptor} of the files this process holds open, a mapping's
    too (Python's mmap holds a duplicate of the descriptor it was made from)."""
    found = {}
    for name in os.listdir("/proc/self/fd"):
        try:
            st = os.stat(f"/proc/self/fd/{name}")
        except OSError:
            continue
        found[(st.st_dev, st.st_ino)] = int(name)
    return found


def _descriptor_of(file_id):
    """A new descriptor of this process for the memory file `file_id` ((st_dev, st_ino)),
    which its mapping keeps open, or -1."""
    fd = open_files().get(file_id)
    return -1 if fd is None else os.dup(fd)


def _take_spare(nbytes):
    """(mmap, descriptor) of a waiting memory file made nbytes long (the one nearest that
    size), or (None, -1)."""
    with _SPARE_LOCK:
        if not _SPARES:
            return None, -1
        best = min(range(len(_SPARES)), key=lambda i: abs(len(_SPARES[i][0]) - nbytes))
        buf, file_id = _SPARES.pop(best)
    fd = -1
    try:
        fd = _descriptor_of(file_id)
        if fd < 0:
            return None, -1
        had = len(buf)
        if had != nbytes:
            buf.resize(nbytes)          # the file too; pages past the old end are new
            if nbytes > had:
                os.posix_fallocate(fd, had, nbytes - had)
    except (OSError, ValueError, SystemError, BufferError):
        if fd >= 0:
            os.close(fd)
        return None, -1
    return buf, fd


def shared_empty(shape, dtype=np.float32):
    return Shared(shape, dtype)


def open_shared(handle, rows=None):
    """The array of a Shared made by the parent process (its handle), mapped here; rows:
    None (all of it, mapped page by page as it is touched) or (lo, hi), rows lo..hi only,
    their pages made (_reserve) and mapped at once (a block that writes all its rows: one call
    instead of a fault a page)."""
    pid, fd, shape, dtype = handle
    dtype = np.dtype(dtype)
    try:
        own = os.open(f"/proc/{pid}/fd/{fd}", os.O_RDWR)
    except OSError as e:   # a sandbox that hides other processes' files: the caller grows on threads
        raise WorkerDied(f"a groom worker process cannot map its parent's shared memory ({e})") from None
    row = int(np.prod(shape[1:])) * dtype.itemsize
    lo, hi = (0, shape[0]) if rows is None else (int(rows[0]), int(rows[1]))
    start = lo * row - (lo * row) % mmap.ALLOCATIONGRANULARITY
    skip = lo * row - start
    flags = mmap.MAP_SHARED | (mmap.MAP_POPULATE if rows is not None and hasattr(mmap, "MAP_POPULATE") else 0)
    try:
        if rows is not None:
            _reserve(own, start, skip + (hi - lo) * row)
        buf = mmap.mmap(own, max(skip + (hi - lo) * row, 1), flags=flags, offset=start)
    finally:
        os.close(own)
    return np.frombuffer(buf, dtype, (hi - lo) * (row // dtype.itemsize), skip).reshape((hi - lo,) + tuple(shape[1:]))


# --- the worker's side ----------------------------------------------------------------------

def _keep(token_, obj):
    _KEPT[token_] = obj
    _KEPT.move_to_end(token_)
    while len(_KEPT) > _KEPT_MOST:
        _KEPT.popitem(last=False)


def kept(token_):
    """An object the parent sent with Worker.keep."""
    return _KEPT[token_]


def serve():
    """A worker process's loop: jobs from stdin until it closes, answers on stdout. Anything
    else the jobs print goes to stderr (stdout carries only answers)."""
    parallel.run_serially()
    # The modules of the jobs to come, loaded while the parent still samples its roots.
    import groom.generate  # noqa: F401
    inp = sys.stdin.buffer
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    while True:
        try:
            fn, args = read_message(inp)
        except EOFError:
            return
        try:
            answer = ("ok", fn(*args))
        except Exception as e:  # the caller raises it: its job failed, not the worker
            try:
                pickle.dumps(e)
                answer = ("error", e)
            except Exception:
                answer = ("error", RuntimeError(f"{type(e).__name__}: {e}\n{traceback.format_exc()}"))
        write_message(out, answer)
