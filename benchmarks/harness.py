# SPDX-License-Identifier: GPL-3.0-or-later
"""Timing, machine description and report pieces shared by every benchmark section.

Rules this module enforces so no section has to remember them (SPEC §8):
  * a time is the median of at least five runs after one untimed warm-up;
  * a comparison against an anchor is a ratio of two medians taken in the same process run;
  * every figure is written next to the machine, the versions and the settings it came from.
"""
import contextlib
import io
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from hairio import atomic_write

MIN_RUNS = 5


@dataclass
class Timing:
    """Wall-clock seconds of repeated runs of one job; `median` is the figure we report."""
    runs: list
    warmups: list = field(default_factory=list)   # untimed-for-the-median first calls (cold costs)

    @property
    def median(self):
        return statistics.median(self.runs)

    @property
    def spread(self):
        """(min, max) so a reader can see how noisy the machine was."""
        return min(self.runs), max(self.runs)

    def __str__(self):
        return fmt_time(self.median)


class TooSlow(Exception):
    """The warm-up showed that the timed runs would not fit the time left."""


def measure(job, runs=MIN_RUNS, warmup=1, before=None, budget=None):
    """Time `job()` `runs` times after `warmup` untimed calls; `before()` runs untimed each time.

    `before` exists for anchors whose caches must be invalidated (a depsgraph tag, a camera
    move) without charging that to the job. `budget` (seconds): raise TooSlow after the
    warm-up when `runs` more calls like it would not fit. Returns (Timing, last result).
    """
    runs = max(int(runs), MIN_RUNS)
    result = None
    warm = []
    for _ in range(warmup):
        if before:
            before()
        t0 = time.perf_counter()
        result = job()
        one = time.perf_counter() - t0
        warm.append(one)
        if budget is not None and one * runs > budget:
            raise TooSlow(f"one run takes {fmt_time(one)}, so {runs} runs would exceed the "
                          f"{fmt_time(max(budget, 0))} left in this section's budget")
    times = []
    for _ in range(runs):
        if before:
            before()
        t0 = time.perf_counter()
        result = job()
        times.append(time.perf_counter() - t0)
    return Timing(times, warm), result


def once(job):
    """Seconds of one call (for first-use costs that cannot be repeated, e.g. a first upload)."""
    t0 = time.perf_counter()
    result = job()
    return time.perf_counter() - t0, result


def fmt_time(seconds):
    if seconds is None or not np.isfinite(seconds):
        return "n/a"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1.0:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"


def fmt_num(x, digits=3):
    if x is None:
        return "n/a"
    if isinstance(x, (int, np.integer)):
        return f"{int(x):,}"
    x = float(x)
    if not np.isfinite(x):
        return str(x)
    if x == 0:
        return "0"
    if abs(x) >= 1e4 or abs(x) < 1e-3:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def ratio(a, b):
    return float("nan") if not b else a / b


def table(header, rows):
    """A Markdown table; cells are formatted already or formatted with fmt_num."""
    def cell(v):
        if isinstance(v, str):
            return v
        if isinstance(v, Timing):
            return str(v)
        return fmt_num(v)
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(out)


# ----------------------------------------------------------------------------- machine

def cpu_model():
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def gl_renderer():
    """GL renderer string of the headless context the tracer would get (probed in a child
    process so a broken driver cannot take the benchmark down)."""
    code = ("from tracer.gl_context import create_context; c, b = create_context(); "
            "print(c.info['GL_RENDERER'], '|', c.info['GL_VERSION'], '|', b)")
    try:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=root)
        if out.returncode == 0 and out.stdout.strip():
            return out.stdout.strip().splitlines()[-1]
        return "unavailable (" + (out.stderr.strip().splitlines() or ["no output"])[-1][:120] + ")"
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"unavailable ({e})"


def package_version(name):
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:  # a missing package is a fact for the report, not an error
        return "not installed"


def git_commit():
    try:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        out = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
        return out.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"


def machine_info():
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1),
        "gl_renderer": gl_renderer(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "bpy": package_version("bpy"),
        "moderngl": package_version("moderngl"),
        "matplotlib": package_version("matplotlib"),
        "hypothesis": package_version("hypothesis"),
        "commit": git_commit(),
        "load_average": f"{os.getloadavg()[0]:.1f}",
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }


def hwm_mb():
    """Peak resident memory of this process so far, in MiB.

    /proc/self/status VmHWM belongs to this process's own address space; getrusage's
    ru_maxrss would not do: Linux carries it over from the parent across fork and exec."""
    with contextlib.suppress(OSError):
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class PeakMemory:
    """The peak memory this process and its child processes (groom's workers) hold while the
    `with` block runs, in MiB, sampled every `every` seconds on a thread: each process's own
    pages (its proportional set size less its share of shared memory) plus the shared-memory
    pages made since the block began (the system's Shmem, where groom's memory files live),
    so a page two processes map counts once, and a page of a memory file counts whether or
    not some process maps it just then. A sum of the processes' own peaks (VmHWM) gets both
    wrong: a worker that writes its blocks' rows and unmaps them counts one block at most.
    Linux only (`peak` stays None elsewhere)."""

    def __init__(self, every=0.01):
        self.every, self.peak, self.parts = every, None, None
        self._stop = threading.Event()

    @staticmethod
    def _shmem_mb():
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("Shmem:"):
                    return int(line.split()[1]) / 1024.0
        return 0.0

    @staticmethod
    def _own_mb(pid):
        """(Pss - Pss_Shmem) of process pid in MiB, 0 once it is gone."""
        pss = shmem = 0
        with contextlib.suppress(OSError, ValueError, IndexError):
            with open(f"/proc/{pid}/smaps_rollup") as f:
                for line in f:
                    if line.startswith("Pss:"):
                        pss = int(line.split()[1])
                    elif line.startswith("Pss_Shmem:"):
                        shmem = int(line.split()[1])
        return (pss - shmem) / 1024.0

    @staticmethod
    def _children():
        me, found = os.getpid(), []
        for name in os.listdir("/proc"):
            if name.isdigit():
                with contextlib.suppress(OSError, ValueError, IndexError):
                    with open(f"/proc/{name}/stat") as f:
                        if int(f.read().rsplit(")", 1)[1].split()[1]) == me:
                            found.append(int(name))
        return found

    def sample(self):
        own = self._own_mb(os.getpid())
        children = sum(self._own_mb(pid) for pid in self._children())
        shared = max(0.0, self._shmem_mb() - self._shmem0)
        total = own + children + shared
        if self.peak is None or total > self.peak:
            self.peak, self.parts = total, {"own": own, "children": children, "shared": shared}

    def _run(self):
        while not self._stop.wait(self.every):
            self.sample()

    def __enter__(self):
        if not os.path.exists("/proc/self/smaps_rollup"):
            return self
        self._shmem0 = self._shmem_mb()
        self.sample()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        if getattr(self, "_thread", None) is not None:
            self._stop.set()
            self._thread.join()
            self.sample()
        return False


def run_child(code, timeout=600):
    """Run Python `code` in a fresh interpreter at the repository root; it must print one JSON
    line last. Used for peak-memory figures (a fresh process has no earlier peak to hide)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=timeout, cwd=root)
    if out.returncode != 0:
        raise RuntimeError("child failed: " + (out.stderr.strip().splitlines() or ["?"])[-1][:300])
    return json.loads(out.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- sections

class NotMeasured(Exception):
    """Raised by a section (or a part of one) whose code under test is not there yet."""


# The report's plots and images go into this folder beside it (benchmarks/figures/ for the
# committed report), not among the code.
FIGURES = "figures"


def _figure_path(outdir, name):
    folder = os.path.join(outdir, FIGURES)
    os.makedirs(folder, exist_ok=True)
    return os.path.join(folder, name)


@dataclass
class Section:
    """What one report section collects while it runs."""
    key: str
    title: str
    mode: str
    outdir: str
    parts: list = field(default_factory=list)
    figures: list = field(default_factory=list)
    data: dict = field(default_factory=dict)
    started: float = field(default_factory=time.perf_counter)

    def text(self, s):
        self.parts.append(s.strip("\n"))

    def table(self, header, rows, caption=None):
        if caption:
            self.parts.append(caption)
        self.parts.append(table(header, rows))

    def not_measured(self, what, reason):
        self.parts.append(f"*{what}: not measured: {reason}*")

    def settings(self, **kw):
        self.parts.append("Settings: " + ", ".join(f"`{k}={v}`" for k, v in kw.items()))

    def elapsed(self):
        return time.perf_counter() - self.started

    def figure(self, fig, name, caption):
        """Save a matplotlib figure in the report's figures folder (atomically) and link it."""
        path = _figure_path(self.outdir, name)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        with atomic_write(path) as f:
            f.write(buf.getvalue())
        import matplotlib.pyplot as plt
        plt.close(fig)
        link = f"{FIGURES}/{name}"
        self.figures.append(link)
        self.parts.append(f"![{caption}]({link})\n\n*{caption}*")

    def image(self, rgba, name):
        """Save an (H,W,3|4) linear image as an sRGB PNG in the report's figures folder;
        returns its link from the report."""
        import matplotlib.image as mpimg
        path = _figure_path(self.outdir, name)
        buf = io.BytesIO()
        mpimg.imsave(buf, to_srgb8(rgba), format="png")
        with atomic_write(path) as f:
            f.write(buf.getvalue())
        link = f"{FIGURES}/{name}"
        self.figures.append(link)
        return link

    def markdown(self):
        return "\n\n".join(self.parts)


def to_srgb8(rgba):
    """Linear float RGBA → sRGB uint8, composited over white so transparent hair reads on paper."""
    a = np.asarray(rgba, np.float64)
    rgb = a[..., :3]
    if a.shape[-1] == 4:
        alpha = np.clip(a[..., 3:4], 0, 1)
        rgb = rgb + (1 - alpha)   # premultiplied colour over a white background
    rgb = np.clip(rgb, 0, 1)
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    return (np.clip(srgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def write_text_atomic(path, text):
    with atomic_write(path, "w") as f:
        f.write(text)
