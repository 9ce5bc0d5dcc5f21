# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m benchmarks --quick | --full | --gpu-only  →  benchmarks/REPORT.md + PNG plots.

Each section runs in its own child process with a wall-clock limit, so a section that
crashes (a GL driver fault, Blender) or overruns is reported as "not measured" with the
reason and the rest of the report still comes out. The report is rewritten atomically after
every section, so an interrupted run leaves a complete, shorter report, never a torn one.
"""
import argparse
import collections
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

BUDGET = {"quick": 1200.0, "full": 6000.0, "gpu": 600.0}
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


RESULTS = os.path.join(HERE, "results")


def _header(runs):
    """The report's head: what ran, where, when. `runs` are the stored runs' machine records."""
    lines = [
        "# Benchmarks: run time against error, side by side with Blender, and the stress suite",
        "",
        "Made by `python -m benchmarks --quick | --full` (every section) or `--only SECTION ...` "
        "(those sections again; the others keep their last measured figures). Each section says "
        "when and in which mode it was measured. Every time is the median of at least 5 runs after "
        "one untimed warm-up; every ratio compares two medians measured in the same run on this "
        "machine. Error figures are linear RGBA against the float64 reference tracer (or a 64-sample "
        "stratified reference for anti-aliasing), and geometric distances against the exact curve "
        "(SPEC §6, §8).",
        "",
        "## Machine and versions",
        "",
    ]
    newest = runs[-1] if runs else {}
    lines += ["| | |", "|---|---|"]
    lines += [f"| {k} | {str(v).replace('|', '·')} |" for k, v in newest.items() if k != "mode"]
    lines += ["", "The machine may be shared: a section's load average above the number of cores means "
              "other work competed for them; times are then noisier, ratios less so, since both sides "
              "of a ratio ran in the same minutes.", ""]
    cpus = collections.Counter(r.get("cpu", "?") for r in runs)
    if len(cpus) > 1:
        lines += ["The sections were measured on more than one machine (" + "; ".join(
            f"{cpu}: {n} section{'s' if n > 1 else ''}" for cpu, n in cpus.most_common())
            + "); the table above is the newest's, and each section names its own. A ratio compares "
              "figures of one section's run, so of one machine; figures of two sections may not.", ""]
    return "\n".join(lines)


def _result_path(results_dir, key):
    return os.path.join(results_dir, f"{key}.json")


def load_results(results_dir):
    """The stored result of every section that has one: {key: result}."""
    out = {}
    for key, _ in SECTIONS:
        try:
            with open(_result_path(results_dir, key)) as f:
                out[key] = json.load(f)
        except (OSError, ValueError):
            continue
    return out


def render_report(results, runs):
    """REPORT.md from the stored section results, in the sections' order."""
    keys = [k for k, _ in SECTIONS]
    titles = dict(SECTIONS)
    body = [_header(runs)]
    lines = []
    for i, k in enumerate(keys, 1):
        r = results.get(k)
        for line in (r or {}).get("summary") or ["not measured yet"]:
            lines.append(f"- §{i} {line}")
    body.append("## Summary\n\nThe key figures of each section (details, settings and plots below).\n\n"
                + "\n".join(lines))
    for i, k in enumerate(keys, 1):
        body.append(f"## {i}. {titles[k]}")
        r = results.get(k)
        if r is None:
            body.append(f"*not measured yet: `python -m benchmarks --only {k}`.*")
            continue
        when = r.get("measured")
        if when:
            body.append(f"<sub>measured {when['date_utc']} in {when['mode']} mode at commit "
                        f"{when['commit']}, load average {when['load_average']} at the start on "
                        f"{when['cores']} cores ({when.get('cpu', 'cpu not recorded')}); section time "
                        f"{fmt_time(r.get('elapsed', 0.0))}</sub>")
        body.append(r["markdown"])
    return "\n\n".join(body) + "\n"


def orchestrate(mode, outdir, only=None):
    cfg = config_mod.for_mode(mode)
    os.makedirs(outdir, exist_ok=True)
    results_dir = RESULTS if os.path.abspath(outdir) == HERE else os.path.join(outdir, "results")
    os.makedirs(results_dir, exist_ok=True)
    keys = [k for k, _ in SECTIONS if (only is None or k in only) and (mode != "gpu" or k == "gpu")]
    # A GPU run writes its own report; a CPU run, partial or whole, updates the sections it ran
    # and keeps the others' last figures.
    report_path = os.path.join(outdir, "REPORT_GPU.md" if mode == "gpu" else "REPORT.md")
    results = {} if mode == "gpu" else load_results(results_dir)
    t_start = time.perf_counter()
    budget_total = BUDGET[mode]

    def write():
        stamps = [r["measured"] for r in results.values() if r.get("measured")]
        stamps.sort(key=lambda m: m["date_utc"])
        write_text_atomic(report_path, render_report(results, stamps))

    for idx, k in enumerate(keys):
        left = budget_total - (time.perf_counter() - t_start)
        later = sum(SOFT * cfg.limits.get(x, 60) for x in keys[idx + 1:])
        limit = cfg.limits.get(k, 60)
        # Never let one section eat the time the ones after it were promised.
        limit = max(10.0, min(limit, (left - later) / SOFT))
        machine = machine_info()
        print(f"[bench] {k}: limit {limit:.0f} s (load average {machine['load_average']}) ...", flush=True)
        r, log = _child(k, mode, outdir, budget=SOFT * limit, timeout=limit + 30)
        r["measured"] = {**machine, "mode": mode}
        results[k] = r
        if mode != "gpu":
            write_text_atomic(_result_path(results_dir, k), json.dumps(r, indent=1, sort_keys=True) + "\n")
        for line in (r.get("summary") or []):
            print(f"[bench]   {line}", flush=True)
        if r.get("status") == "failed":
            print(f"[bench]   FAILED ({r['elapsed']:.0f} s); last output:\n{log[-1500:]}", flush=True)
        print(f"[bench] {k}: {r['elapsed']:.1f} s", flush=True)
        write()
    write()
    total = time.perf_counter() - t_start
    print(f"[bench] wrote {report_path} in {total:.0f} s", flush=True)
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_const", dest="mode", const="quick",
                   help="every section at small sizes (about twenty minutes on 2 cores)")
    g.add_argument("--full", action="store_const", dest="mode", const="full",
                   help="the issue sizes (about an hour and a half on 2 cores)")
    g.add_argument("--rewrite", action="store_const", dest="mode", const="rewrite",
                   help="write REPORT.md again from the stored results (benchmarks/results/), measuring nothing")
    g.add_argument("--gpu-only", action="store_const", dest="mode", const="gpu",
                   help="on a GPU machine: 1920x1080 frames per second for 10k and 100k strands")
    ap.add_argument("--only", nargs="+", metavar="SECTION",
                    help=f"run only these of {[k for k, _ in SECTIONS]}; the report keeps the others' last figures")
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
    if mode == "rewrite":
        results = load_results(RESULTS)
        stamps = sorted((r["measured"] for r in results.values() if r.get("measured")),
                        key=lambda m: m["date_utc"])
        write_text_atomic(os.path.join(HERE, "REPORT.md"), render_report(results, stamps))
        return 0
    if args.only:
        unknown = set(args.only) - {k for k, _ in SECTIONS}
        if unknown:
            print(f"--only: unknown section(s) {sorted(unknown)}; choose from {[k for k, _ in SECTIONS]}",
                  file=sys.stderr)
            return 2
    return orchestrate(mode, os.path.abspath(args.outdir), set(args.only) if args.only else None)


if __name__ == "__main__":
    sys.exit(main())
