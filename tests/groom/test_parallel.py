# SPDX-License-Identifier: GPL-3.0-or-later
import os
import threading

import pytest

from groom import parallel
from groom.parallel import ranges, run_each, run_jobs


@pytest.mark.parametrize("n", [0, 1, 4095, 8192, 100001])
def test_ranges_cover_every_item_once_in_order(n):
    r = ranges(n, threads=4)
    assert r[0][0] == 0 and r[-1][1] == n
    assert all(hi == lo for (_, hi), (lo, _) in zip(r, r[1:]))
    assert all(hi >= lo for lo, hi in r)


def test_run_jobs_returns_results_in_order_with_the_callers_job_last():
    out = run_jobs([lambda i=i: i * i for i in range(7)], threads=3, here=lambda: "mine")
    assert out == [0, 1, 4, 9, 16, 25, 36, "mine"]


def test_a_failing_job_raises_in_the_caller_after_the_others_finished():
    finished = []

    def slow():
        threading.Event().wait(0.05)
        finished.append(1)

    for here in (None, lambda: 1 / 0):
        finished.clear()
        with pytest.raises(ZeroDivisionError):
            run_jobs([slow, lambda: 1 / 0, slow, slow], threads=2, here=here)
        assert len(finished) == 3


def test_jobs_that_run_jobs_do_not_wait_for_themselves():
    out = run_jobs([lambda: run_jobs([lambda: 1, lambda: 2], threads=2) for _ in range(4)], threads=2)
    assert out == [[1, 2]] * 4


def test_run_each_reports_from_the_calling_thread_in_order_and_nests_each_jobs_work():
    caller = threading.current_thread()
    reported = []

    def job(i):
        # The job's own run_jobs stay on its thread.
        inner = run_jobs([lambda: threading.current_thread(), lambda: threading.current_thread()], threads=2)
        return i, threading.current_thread(), inner

    def done(i):
        reported.append((i, threading.current_thread()))
    out = run_each([lambda i=i: job(i) for i in range(5)], threads=2, done=done)
    assert [o[0] for o in out] == list(range(5))
    assert all(o[1] is not caller and o[2] == [o[1], o[1]] for o in out)
    assert reported == [(i, caller) for i in range(5)]


def test_run_each_on_one_thread_runs_in_the_caller():
    caller = threading.current_thread()
    reported = []
    out = run_each([lambda i=i: (i, threading.current_thread()) for i in range(3)], threads=1, done=reported.append)
    assert out == [(i, caller) for i in range(3)] and reported == [0, 1, 2]


def test_run_each_raises_after_every_started_job_finished():
    finished = []

    def slow():
        threading.Event().wait(0.05)
        finished.append(1)
    with pytest.raises(ZeroDivisionError):
        run_each([slow, lambda: 1 / 0, slow, slow], threads=2)
    assert len(finished) == 3

    # A failing report stops the jobs not started yet; none still runs when it raises.
    finished.clear()
    running = []

    def tracked():
        running.append(1)
        threading.Event().wait(0.05)
        finished.append(1)

    def stop(i):
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        run_each([tracked] * 8, threads=2, done=stop)
    assert len(finished) == len(running) < 8


_RSS = """
def rss():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS"))
"""


def _in_fresh_process(code):
    import json
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out = subprocess.run([sys.executable, "-c", "import json, sys\nsys.path.insert(0, '.')\n" + _RSS + code],
                         capture_output=True, text=True, cwd=root, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(parallel._malloc_trim() is None or not os.path.exists("/proc/self/status"),
                    reason="glibc's malloc_trim and Linux's /proc")
def test_free_memory_hands_the_heaps_free_pages_back_and_the_collider_build_leaves_none():
    got = _in_fresh_process("""
import numpy as np
from groom import parallel
big = np.ones(2 << 20); del big          # glibc now serves arrays below 16 MB from its heap
parts = [np.ones(1 << 19) for _ in range(40)]
last = parts[-1]                         # at the heap's top: nothing below it is trimmed on its own
del parts
held = rss()
parallel.free_memory()
print(json.dumps([held, rss()]))
""")
    assert got[0] - got[1] > 100          # of some 160 MB the arrays left
    got = _in_fresh_process("""
from groom import default_collider
before = rss()
c = default_collider()
print(json.dumps([before, rss()]))
""")
    assert got[1] - got[0] < 60           # its arrays (24 MB) and little else; 144 MB before
