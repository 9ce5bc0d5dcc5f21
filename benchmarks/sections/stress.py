# SPDX-License-Identifier: GPL-3.0-or-later
"""7. Stress: every SPEC §9 case end to end (scalp → groom → tracer → pixels), randomised scenes
from hypothesis over scales, offsets and degenerate inputs, and hostile input to every entry point.

Each run ends in one of: *finite* (output passed every check below), *clear error* (an
InputError whose message names the input), *silently wrong* (no error, but a check failed),
*crash* (any other exception). Only the first two are acceptable.
"""
import collections
import time

from benchmarks import stress_cases as sc
from benchmarks.sections import left, over_budget


def _checks_text():
    doc = sc.__doc__
    start = doc.index('"Silently wrong"')
    end = doc.index("Any other exception")
    return doc[start:end].strip()


def run(sec, cfg):
    import groom  # noqa: F401  (the cases need it; fail early with a clear reason)
    import tracer  # noqa: F401
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.text(_checks_text())
    rows, tally = [], collections.Counter()
    t0 = time.perf_counter()
    for name, fn in sc.spec_cases():
        o = fn()
        tally[o.kind] += 1
        detail = o.detail[:160].replace("|", "/")
        extra = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in o.checks.items())
        rows.append([name, o.kind if o.ok else f"**{o.kind}**", detail or extra])
    spec_s = time.perf_counter() - t0
    sec.table(["SPEC §9 case", "outcome", "detail (error message, or checks)"], rows,
              caption=f"SPEC §9 cases ({sum(tally.values())} run in {spec_s:.1f} s).")
    sec.summary.append(f"SPEC §9: {dict(tally)}")
    sec.data["spec"] = dict(tally)

    rows = []
    for name, fn in sc.limit_probes():
        o = fn()
        extra = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in o.checks.items())
        rows.append([name, o.kind, (o.detail[:160] + "; " if o.detail else "") + extra])
        if not o.ok:
            sec.summary.append(f"beyond the SPEC range, {name}: {o.kind} ({o.detail[:80]})")
    sec.table(["beyond the SPEC range", "outcome", "detail"], rows,
              caption="Where float32 runs out: heads far smaller than their distance from the origin "
                      "(hairio.Strands and the GPU hold float32 coordinates). Reported, not promised.")

    from hypothesis import HealthCheck, given, settings
    results = []

    @settings(max_examples=cfg.stress_examples, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(sc.random_scene_strategy())
    def explore(spec):
        if over_budget(sec, 0.7):   # the rest of the budget is the hostile-input part's
            return
        results.append((sc.run_random_scene(spec), spec))

    t0 = time.perf_counter()
    explore()
    rnd_s = time.perf_counter() - t0
    rows = []
    for label, sel in (("within the SPEC range (offset ≤ 1e4 × scale)", True), ("beyond it", False)):
        part = [o for o, spec in results if sc.within_spec(spec) == sel]
        c = collections.Counter(o.kind for o in part)
        rows.append([label, str(len(part)), str(c[sc.FINITE]), str(c[sc.CLEAR_ERROR]),
                     str(c[sc.SILENTLY_WRONG]), str(c[sc.CRASH])])
    sec.table(["randomised scenes", "tried", "finite", "clear error", "silently wrong", "crash"], rows,
              caption=f"hypothesis, {len(results)} scenes in {rnd_s:.1f} s (derandomised, so the run is repeatable): "
                      "scale 1e-3…1e3, offsets 0…1e4, 1–4 keys of 2–6 control points with repeated, "
                      "zero-length, hairpin and coincident keys, zero-area/sliver triangles, every "
                      "neighbour mode, both resolution modes, 1–80 strands, 24×24 render at 4 spp "
                      "checked against the float64 reference.")
    bad = [(o, spec) for o, spec in results if not o.ok]
    if bad:
        lines = []
        for o, spec in bad[:8]:
            lines.append(f"- {o.kind}: {o.detail[:200]} (scale {spec['scale']:g}, offset {spec['offset']:g}, "
                         f"{spec['count']} strands, {len(spec['keys'])} key(s), {spec['resolution_mode']})")
        sec.text("Failures found:\n\n" + "\n".join(lines))
    c = collections.Counter(o.kind for o, _ in results)
    sec.summary.append(f"random: {len(results)} tried, {dict(c)}")
    sec.data["random"] = dict(c)
    _hostile_input(sec, cfg)


def _hostile_input(sec, cfg):
    """The fuzzer (benchmarks/fuzz_inputs.py): cases per entry point and format, outcomes,
    peak memory."""
    from benchmarks import fuzz_inputs as fz
    n = max(10, cfg.stress_examples // 2)
    jobs = [{"entry": "read", "format": f, "n": n, "hostile": True} for f in ("hair", "tfx", "tfx-small", "data", "npz")]
    jobs += [{"entry": e, "format": f, "n": max(5, n // 3), "hostile": True}
             for e in ("render", "export") for f in ("hair", "tfx", "data", "npz")]
    jobs += [{"entry": "obj", "format": "obj", "n": n, "hostile": True}, {"entry": "obj", "format": "obj-big", "n": 5},
             {"entry": "arrays", "format": "arrays", "n": 3 * n}, {"entry": "preset", "format": "json", "n": n}]
    t0 = time.perf_counter()
    records = fz.run_jobs(jobs, seconds=max(10.0, left(sec, 0.9)))
    dt = time.perf_counter() - t0
    entry_names = {"read": "read_strands", "render": "python -m tracer render", "export": "python -m groom export",
                   "obj": "groom.load_obj", "arrays": "Strands.from_arrays", "preset": "groom.load_preset + place_keys"}
    rows = []
    for (entry, fmt), c in fz.tally(records).items():
        rows.append([entry_names[entry], fmt, str(c["tried"])] + [str(c[k]) for k in fz.OUTCOMES]
                    + [f"{c['bytes'] / fz.MIB:.2f}", "–" if c["peak"] is None else f"{c['peak'] / fz.MIB:.1f}",
                       f"{c['peak_ratio']:.1f}" if c["peak_ratio"] else "–"])
    sec.table(["entry point", "input", "tried"] + list(fz.OUTCOMES)
              + ["largest input MiB", "peak MiB", "peak ÷ input"], rows,
              caption=f"Hostile input, {len(records)} cases in {dt:.1f} s (fixed seeds, derandomized hypothesis): "
                      "byte mutations of the real files in ../shared/data (the .npz made from straight.hair), "
                      "hand-made files whose headers lie, hypothesis arrays and presets. Only *clean error* "
                      "(InputError / exit 2 naming the input, nothing written) and *accepted* (valid output) "
                      "are acceptable. Each case ran under an address-space cap of what the process held "
                      "plus 8 × its input + 64 MiB (OBJ text 16 ×; arrays and presets 64 MiB), so a reader "
                      "that believed a header would fail as *memory*; *peak* is the largest Python and numpy "
                      "heap peak of one case (tracemalloc, for the readers and commands; the GL driver's memory "
                      "is not in it), *peak ÷ input* the largest ratio over inputs of 64 KiB or more.")
    bad = fz.failures(records)
    if bad:
        sec.text("Hostile-input failures:\n\n" + "\n".join(
            f"- {r['entry']} {r['format']} {r['kind']}: {r['label']} ({r['detail'][:160]})" for r in bad[:12]))
    outcome = collections.Counter(r["kind"] for r in records)
    sec.summary.append(f"hostile input: {len(records)} tried, {dict(outcome)}")
    sec.data["hostile"] = dict(outcome)
    _large_counts(sec)


def _large_counts(sec):
    """Counts past memory: the command grows and writes a block of strands at a time, so it
    refuses only a file the disk cannot take (asked here), before any work."""
    import contextlib
    import io
    import json
    import os
    import tempfile
    from benchmarks.stream_run import result_path
    from groom.__main__ import main
    rows = []
    for count in (10 ** 9, 2 ** 62):
        err = io.StringIO()
        with tempfile.TemporaryDirectory() as folder, contextlib.redirect_stderr(err):
            t0 = time.perf_counter()
            code = main(["generate", "--preset", "wavy", "--count", str(count), "--out", os.path.join(folder, "h.npz")])
            dt = time.perf_counter() - t0
            left_behind = os.listdir(folder)
        rows.append([f"{count:,}", f"exit {code}", f"{dt * 1e3:.0f} ms", str(left_behind) if left_behind else "none",
                     err.getvalue().strip().replace("|", "/")[:240]])
    try:
        with open(result_path(10_000_000)) as f:
            r = json.load(f)
        rows.insert(0, ["10,000,000", "exit 0", f"{r['time']:.0f} s", f".npz of {r['file_bytes'] / 1e9:.1f} GB",
                        f"peak RSS {r['peak_rss_mb']:.0f} MiB (§1, python -m benchmarks.stream_run, "
                        f"{r['measured']['date_utc']})"])
    except (OSError, ValueError):
        pass
    sec.table(["python -m groom generate --count", "outcome", "time", "file left", "message"], rows,
              caption="Strand counts past what memory holds: grown and written a block of strands at a time, "
                      "refused up front only when the disk cannot take the file (the bound in the message).")
    sec.summary.append("--count " + "; ".join(f"{r[0]}: {r[1]}" for r in rows))
