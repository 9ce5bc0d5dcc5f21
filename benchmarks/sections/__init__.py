# SPDX-License-Identifier: GPL-3.0-or-later
"""The report's sections, in report order. Each module has `run(sec, cfg)`."""
import importlib
import time
import traceback

from benchmarks.harness import NotMeasured, Section, TooSlow

SECTIONS = [
    ("generation", "Generation: groom against Blender's Interpolate Curves"),
    ("geometry", "Geometry: cylinders per strand, time against error"),
    ("rendering", "Rendering: time against image error"),
    ("anchors", "Anchors: the tracer against Blender Cycles"),
    ("scaling", "Scaling: strand count, image size, hair length, cost model"),
    ("accel", "Acceleration structures: beams, uniform grid and BVH"),
    ("skips", "Skips: on and off, with proof the output is unchanged"),
    ("stress", "Stress: SPEC §9 cases and randomised scenes"),
    ("gpu", "GPU"),
    ("integration", "Extension and export figures (issues 4 and 5)"),
    ("export", "Export of a groom with guides, per format (issue 17)"),
    ("versions", "Blender versions: Generate and Render Preview in each Blender of the matrix"),
    ("preview_defaults", "Preview defaults: no dust at the default settings"),
    ("contact_sheet", "Contact sheet: each preset with the head, Cycles beside the preview"),
    ("meshes", "Meshes in the preview: the cost of a head and a body"),
    ("hair_shading", "Hair shading: the preview's fibre model against Cycles' Principled Hair (Chiang)"),
    ("preview_refinement", "Preview refinement: how soon the progressive preview has no dust"),
]


class Stopped(BaseException):
    """The parent ran out of patience (SIGTERM at the section's limit)."""


def _stop(signum, frame):
    raise Stopped()


def run_section(key, cfg, outdir, budget):
    """Run one section in this process and return what the report needs (JSON-able).

    SIGTERM (the parent's time limit) stops the section where it is; what it measured so
    far is kept and the rest is marked not measured."""
    import signal
    signal.signal(signal.SIGTERM, _stop)
    title = dict(SECTIONS)[key]
    sec = Section(key, title, cfg.mode, outdir)
    sec.budget = float(budget)
    summary = []
    sec.summary = summary
    status = "ok"
    try:
        module = importlib.import_module(f"benchmarks.sections.{key}")
        module.run(sec, cfg)
    except Stopped:
        sec.text("*not measured beyond this point: the section reached its time limit and was stopped.*")
        summary.append("stopped at the time limit (partial)")
        status = "partial"
    except (NotMeasured, TooSlow) as e:
        sec.text(f"*not measured: {e}*")
        summary.append(f"not measured: {e}")
        status = "not measured"
    except Exception as e:  # one broken section must not take the report down; say why
        tb = traceback.format_exc()
        print(tb, flush=True)
        last = tb.strip().splitlines()[-3:]
        sec.text(f"*not measured: the section failed with `{type(e).__name__}: {e}`*\n\n```\n"
                 + "\n".join(last) + "\n```")
        summary.append(f"FAILED: {type(e).__name__}: {e}")
        status = "failed"
    return {"markdown": sec.markdown(), "figures": sec.figures, "summary": summary,
            "status": status, "data": sec.data}


def over_budget(sec, fraction=1.0):
    """True once the section has used `fraction` of its soft time budget."""
    return sec.elapsed() > fraction * sec.budget


def left(sec, fraction=1.0):
    """Seconds of the section's soft budget left (up to `fraction` of it)."""
    return fraction * sec.budget - sec.elapsed()


def require(module_name, what):
    """Import `module_name` or raise NotMeasured naming what is missing."""
    try:
        return importlib.import_module(module_name)
    except ImportError as e:
        raise NotMeasured(f"{what} is not available yet ({e})") from e


def now():
    return time.perf_counter()
