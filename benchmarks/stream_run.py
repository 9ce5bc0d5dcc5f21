# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m benchmarks.stream_run COUNT: one run of `python -m groom generate --preset wavy
--count COUNT`, the strands grown and written a block at a time, in a fresh process; its peak
memory (VmHWM), time and file size go to benchmarks/results/stream_COUNT.json, which the
generation section reports (ten million strands take some 20 minutes on 2 cores, far past a
section's time budget, so this run is started by hand and kept with its commit and date)."""
import json
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from benchmarks.harness import cpu_model, git_commit, run_child, write_text_atomic  # noqa: E402

PRESET = "wavy"

_CHILD = """
import json, os, resource, sys, time
sys.path.insert(0, '.')
from benchmarks.harness import hwm_mb
from groom.__main__ import main
out = {out!r}
base = hwm_mb()
t0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
assert main(["generate", "--preset", {preset!r}, "--count", "{count}", "--out", out]) == 0
t, c1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF)
size = os.path.getsize(out)
os.unlink(out)
print(json.dumps({{"base_mb": base, "peak_rss_mb": hwm_mb(), "time": t, "cpu_user": c1.ru_utime - c0.ru_utime,
                  "cpu_system": c1.ru_stime - c0.ru_stime, "file_bytes": size}}))
"""


def result_path(count):
    return os.path.join(HERE, "results", f"stream_{count}.json")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    count = int(argv[0]) if argv else 10_000_000
    folder = argv[1] if len(argv) > 1 else tempfile.gettempdir()
    out = os.path.join(folder, f"stream_{count}.npz")
    load = os.getloadavg()[0]
    r = run_child(_CHILD.format(out=out, preset=PRESET, count=count), timeout=4 * 3600)
    r.update(count=count, preset=PRESET, measured={
        "cpu": cpu_model(), "cores": os.cpu_count(), "commit": git_commit(),
        "load_average": f"{load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end",
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())})
    write_text_atomic(result_path(count), json.dumps(r, indent=1, sort_keys=True) + "\n")
    print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
