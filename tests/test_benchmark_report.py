# SPDX-License-Identifier: GPL-3.0-or-later
"""The benchmark report keeps every section's last figures: a run of some sections rewrites
those and leaves the others as they were measured."""
import json

from benchmarks.__main__ import load_results, orchestrate, render_report
from benchmarks.sections import SECTIONS


def _stored(key, text):
    return {"markdown": text, "summary": [f"{key} figure"], "status": "ok", "elapsed": 1.5,
            "measured": {"date_utc": "2026-01-01 00:00 UTC", "mode": "full", "commit": "abc1234",
                         "load_average": "1.0", "cores": 2}}


def test_report_lists_every_section_in_order_and_says_which_were_never_measured():
    keys = [k for k, _ in SECTIONS]
    results = {keys[0]: _stored(keys[0], "FIRST-BODY"), keys[-1]: _stored(keys[-1], "LAST-BODY")}
    text = render_report(results, [results[keys[0]]["measured"]])
    assert text.index("FIRST-BODY") < text.index("LAST-BODY")
    assert f"- §1 {keys[0]} figure" in text
    assert f"- §{len(keys)} {keys[-1]} figure" in text
    assert text.count("not measured yet") == 2 * (len(keys) - 2)   # summary line + section body
    assert "measured 2026-01-01 00:00 UTC in full mode at commit abc1234" in text


def test_a_partial_run_rewrites_its_sections_and_keeps_the_others(tmp_path):
    (tmp_path / "results").mkdir()
    kept = _stored("skips", "KEPT-SKIPS-BODY")
    (tmp_path / "results" / "skips.json").write_text(json.dumps(kept))
    stale = _stored("gpu", "STALE-GPU-BODY")
    (tmp_path / "results" / "gpu.json").write_text(json.dumps(stale))
    assert orchestrate("quick", str(tmp_path), only={"gpu"}) == 0
    report = (tmp_path / "REPORT.md").read_text()
    assert "KEPT-SKIPS-BODY" in report
    assert "STALE-GPU-BODY" not in report
    fresh = load_results(str(tmp_path / "results"))
    assert fresh["gpu"]["measured"]["mode"] == "quick"
    assert fresh["skips"]["markdown"] == "KEPT-SKIPS-BODY"
