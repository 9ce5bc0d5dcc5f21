# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate and Render Preview in every Blender of the test matrix.

One extension zip (`make extension`'s) is installed by each Blender's own installer into a
throw-away user folder, exactly as an artist installs it, and the extension's bench hooks
time the operators there: Generate (read scalp and keys, groom, write the Curves object)
against groom alone, and Render Preview (camera, trace, pixels into the image) against the
tracer alone. Beside each time, its error: the largest difference between the Curves points
Generate wrote and groom's own, and the preview image against the tracer alone and against
the image of the first Blender in the table (the same scene must give the same picture in
every version). Draw Key Strand: from the release of a drawn key (its stroke given as points)
to the hair regrown around it by live update at the viewport count, beside the largest
difference between that hair and a full regeneration with every key. Each Blender runs in its
own process, with its own Python and numpy.
"""
import json
import pathlib
import subprocess
import tempfile

import numpy as np

from benchmarks.harness import fmt_num, fmt_time, ratio
from benchmarks.sections import left

ROOT = pathlib.Path(__file__).resolve().parents[2]
# (environment, what it holds): the matrix scripts/setup_blender.sh builds beside .venv.
MATRIX = ((".venv", "Blender 5.0, Python 3.11"), (".venv-bpy42", "Blender 4.2 LTS, Python 3.11"),
          (".venv-bpy53", "Blender 5.3, Python 3.13"))


def _zip(tmp):
    import importlib.util
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    path, _ = module.build(tmp)
    return path


def run(sec, cfg):
    sec.text(__doc__.split("\n", 2)[2].strip())
    # Three Blenders in one section: 20k strands (collision, clump and adaptive resolution on,
    # as shipped) keep each within its share; the per-version question is the same at any size.
    count, runs = min(cfg.int_strands, 20_000), min(cfg.runs, 3)
    sec.settings(strands=count, runs=runs, preset="wavy")
    rows, images, first = [], {}, None
    with tempfile.TemporaryDirectory() as tmp:
        zip_path = _zip(tmp)
        for env, label in MATRIX:
            python = ROOT / env / "bin" / "python"
            if not python.exists():
                rows.append([label, f"not measured: {env} is missing (make setup-blender)"] + [""] * 8)
                continue
            out = pathlib.Path(tmp) / f"{env.strip('.')}.json"
            budget = max(60.0, left(sec, 0.95) / max(1, len(MATRIX) - len(rows)))
            try:
                proc = subprocess.run([str(python), str(ROOT / "benchmarks" / "blender_version_probe.py"),
                                       "--zip", str(zip_path), "--count", str(count), "--runs", str(runs),
                                       "--out", str(out)], cwd=tmp, capture_output=True, text=True,
                                      timeout=budget)
            except subprocess.TimeoutExpired:
                rows.append([label, f"not measured: over its {budget:.0f} s share of the time budget"] + [""] * 8)
                continue
            if proc.returncode != 0 or not out.exists():
                tail = (proc.stdout + proc.stderr).strip().splitlines()[-3:]
                rows.append([label, "not measured: " + " / ".join(tail).replace("|", "·")] + [""] * 8)
                continue
            r = json.loads(out.read_text())
            g, p, d = r["generate"], r["preview"], r["draw"]
            image = np.load(r["image"])
            if first is None:
                first = (label, image)
            versus_first = (float(np.sqrt(np.mean((image - first[1]) ** 2)))
                            if image.shape == first[1].shape else None)
            images[label] = image
            rows.append([f"{r['blender']} (Python {r['python']}, numpy {r['numpy']})",
                         f"{fmt_time(g['operator_s'])} ({ratio(g['operator_s'], g['groom_s']):.2f}× groom)",
                         "—" if g.get("max_point_difference") is None else fmt_num(g["max_point_difference"]),
                         f"{fmt_time(p['operator_s'])} ({ratio(p['operator_s'], p['tracer_s']):.2f}× tracer)",
                         "—" if p.get("image_rmse_vs_tracer") is None else fmt_num(p["image_rmse_vs_tracer"]),
                         "—" if versus_first is None else fmt_num(versus_first),
                         f"{p['covered_pixels']:,}",
                         f"{fmt_time(d['release_to_regrown_s'])} (key {fmt_time(d['release_to_key_s'])}, "
                         f"{d['viewport_count']:,} strands)",
                         "—" if d.get("max_difference_vs_full") is None else fmt_num(d["max_difference_vs_full"]),
                         fmt_time(r["install_s"])])
            sec.summary.append(f"{r['blender']}: Generate {fmt_time(g['operator_s'])} "
                               f"({ratio(g['operator_s'], g['groom_s']):.2f}× groom), Render Preview "
                               f"{fmt_time(p['operator_s'])} at {count:,} strands")
    sec.table(["Blender", "Generate (median)", "max abs(Curves − groom) (m)", "Render Preview (median)",
               "image RMSE vs tracer alone", f"image RMSE vs {first[0] if first else 'first'}",
               "hair pixels", "drawn key: release → regrown (median)",
               "regrown vs full regeneration (m)", "install zip"], rows,
              caption=f"`wavy` at {count:,} strands on the bench scalp, the extension installed from "
                      "one zip in each Blender. Coverage (hair pixels) shows the images are not empty.")
    sec.data["versions"] = [r[0] for r in rows]
