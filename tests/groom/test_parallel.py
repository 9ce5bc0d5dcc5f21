# SPDX-License-Identifier: GPL-3.0-or-later
import threading

import pytest

from groom.parallel import ranges, run_jobs


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
