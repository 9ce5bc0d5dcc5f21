# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m benchmarks --quick | --full | --gpu-only  →  benchmarks/REPORT.md + PNG plots.

Each section runs in its own child process with a wall-clock limit, so a section that
crashes (a GL driver fault, Blender) or overruns is reported as "not measured" with the
reason and the rest of the report still comes out. The report is rewritten atomically after
every section, so an interrupted run leaves a complete, shorter report, never a torn one.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from benchmarks import config as config_mod  # noqa: E402
from benchmarks.harness import machine_info, write_text_atomic, fmt_time  # noqa: E402
from benchmarks.sections import SECTIONS, run_section  # noqa: E402

BUDGET = {"quick": 500.0, "full": 2600.0, "gpu": 600.0}
SOFT = 0.75   # a section aims to finish in this fraction of its limit (it is killed at the limit + 30 s)


def _child(key, mode, outdir, budget, timeout):
    """Run one section in a fresh interpreter; returns its JSON result or a failure record."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as tmp:
        result_path = tmp.name
    cmd = [sys.executable, "-m", "benchmarks", "--section", key, "--mode", mode,
           "--outdir", outdir, "--budget", f"{budget:.1f}", "--result", result_path]
    t0 = time.perf_counter()
    with tempfile.TemporaryFile(mode="w+") as out:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, text=True)
        try:
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            # Ask first: the section keeps what it measured and writes it out.
            proc.terminate()
            try:
                proc.wait(timeout=30)
                code = "timeout"
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                code = "killed"
        out.seek(0)
        log = out.read()
    elapsed = time.perf_counter() - t0
    result = None
    try:
        with open(result_path) as f:
            result = json.load(f)
    except (OSError, ValueError):
        result = None
    finally:
        if os.path.exists(result_path):
            os.unlink(result_path)
    if result is None:
        tail = "\n".join(line for line in log.strip().splitlines()[-8:])
        reason = (f"section exceeded its {timeout:.0f} s limit" if code in ("timeout", "killed")
                  else f"section process exited with {code}")
        result = {"markdown": f"*not measured: {reason}.*\n\n```\n{tail}\n```", "status": "failed"}
    result["elapsed"] = elapsed
    return result, log


def _header(mode, machine, started, finished=None):
    lines = [
        "# Benchmarks: run time against error, side by side with Blender, and the stress suite",
        "",
        f"Mode: **{mode}** (`python -m benchmarks --{mode if mode != 'gpu' else 'gpu-only'}`). "
        "Every time is the median of at least 5 runs after one untimed warm-up; every ratio "
        "compares two medians measured in the same run on this machine. Error figures are "
        "linear RGBA against the float64 reference tracer (or a 64-sample stratified reference "
        "for anti-aliasing), and geometric distances against the exact curve (SPEC §6, §8).",
        "",
        "## Machine and versions",
        "",
        "| | |",
        "|---|---|",
    ]
    lines += [f"| {k} | {str(v).replace('|', '·')} |" for k, v in machine.items()]
    lines += ["", f"Started {started}" + (f", finished {finished}." if finished else ", still running.")
              + f" The machine may be shared: its 1-minute load average was {machine['load_average']} at the "
              f"start, {os.getloadavg()[0]:.1f} at the last write of this report (more than "
              f"{machine['cores']} means other work competed for the cores; times are then noisier, ratios "
              "less so, since both sides of a ratio ran in the same minutes).", ""]
    return "\n".join(lines)


def orchestrate(mode, outdir, only=None):
    cfg = config_mod.for_mode(mode)
    os.makedirs(outdir, exist_ok=True)
    machine = machine_info()
    started = time.strftime("%H:%M:%S UTC", time.gmtime())
    keys = [k for k, _ in SECTIONS if (only is None or k in only) and (mode != "gpu" or k == "gpu")]
    titles = dict(SECTIONS)
    results = {}
    t_start = time.perf_counter()
    budget_total = BUDGET[mode]
    # A partial run (--only, or --gpu-only on a GPU machine) must not replace the full report.
    name = "REPORT_GPU.md" if mode == "gpu" else "REPORT_PARTIAL.md" if only else "REPORT.md"
    report_path = os.path.join(outdir, name)

    def write(finished=None):
        body = [_header(mode, machine, started, finished)]
        if finished:
            body[0] += f"\nWhole run: {fmt_time(time.perf_counter() - t_start)}.\n"
        lines = []
        for i, k in enumerate(keys, 1):
            r = results.get(k)
            for line in (r or {}).get("summary") or ["not measured: the run ended before this section"]:
                lines.append(f"- §{i} {line}")
        body.append("## Summary\n\nThe key figures of each section (details, settings and plots below).\n\n"
                    + "\n".join(lines))
        for i, k in enumerate(keys, 1):
            body.append(f"## {i}. {titles[k]}")
            r = results.get(k)
            if r is None:
                body.append("*not measured: the run ended before this section.*")
            else:
                body.append(r["markdown"])
                body.append(f"<sub>section time {fmt_time(r['elapsed'])}</sub>")
        write_text_atomic(report_path, "\n\n".join(body) + "\n")

    for idx, k in enumerate(keys):
        left = budget_total - (time.perf_counter() - t_start)
        later = sum(SOFT * cfg.limits.get(x, 60) for x in keys[idx + 1:])
        limit = cfg.limits.get(k, 60)
        # Never let one section eat the time the ones after it were promised.
        limit = max(10.0, min(limit, (left - later) / SOFT))
        print(f"[bench] {k}: limit {limit:.0f} s (load average {os.getloadavg()[0]:.1f}) ...", flush=True)
        r, log = _child(k, mode, outdir, budget=SOFT * limit, timeout=limit + 30)
        results[k] = r
        for line in (r.get("summary") or []):
            print(f"[bench]   {line}", flush=True)
        if r.get("status") == "failed":
            print(f"[bench]   FAILED ({r['elapsed']:.0f} s); last output:\n{log[-1500:]}", flush=True)
        print(f"[bench] {k}: {r['elapsed']:.1f} s", flush=True)
        write()
    write(finished=time.strftime("%H:%M:%S UTC", time.gmtime()))
    total = time.perf_counter() - t_start
    print(f"[bench] wrote {report_path} in {total:.0f} s", flush=True)
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_const", dest="mode", const="quick",
                   help="every section at small sizes (under five minutes on 2 cores)")
    g.add_argument("--full", action="store_const", dest="mode", const="full",
                   help="the issue sizes (about half an hour on 2 cores)")
    g.add_argument("--gpu-only", action="store_const", dest="mode", const="gpu",
                   help="on a GPU machine: 1920x1080 frames per second for 10k and 100k strands")
    ap.add_argument("--only", nargs="+", metavar="SECTION", help=f"run only these of {[k for k, _ in SECTIONS]}")
    ap.add_argument("--outdir", default=HERE, help="where REPORT.md goes, its plots in figures/ beside it (default: benchmarks/)")
    # internal: one section in this process
    ap.add_argument("--section", help=argparse.SUPPRESS)
    ap.add_argument("--mode", dest="section_mode", help=argparse.SUPPRESS)
    ap.add_argument("--budget", type=float, default=60.0, help=argparse.SUPPRESS)
    ap.add_argument("--result", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.section:
        result = run_section(args.section, config_mod.for_mode(args.section_mode), args.outdir, args.budget)
        with open(args.result, "w") as f:
            json.dump(result, f)
        return 0
    mode = args.mode or "quick"
    if args.only:
        unknown = set(args.only) - {k for k, _ in SECTIONS}
        if unknown:
            print(f"--only: unknown section(s) {sorted(unknown)}; choose from {[k for k, _ in SECTIONS]}",
                  file=sys.stderr)
            return 2
    return orchestrate(mode, os.path.abspath(args.outdir), set(args.only) if args.only else None)


if __name__ == "__main__":
    sys.exit(main())
