# SPDX-License-Identifier: GPL-3.0-or-later
"""The fuzzer (benchmarks/fuzz_inputs.py): mutated real files, lying headers, hypothesis
arrays and presets through every entry point. Each case is a clean error or accepted and
valid, nothing else, inside its address-space cap (fuzz_inputs.memory_bound: 8 x the input
+ 64 MiB for the strand files and commands), and its measured heap peak stays inside the
same bound. Deterministic (fixed seeds, derandomized hypothesis, bounded counts); about
30 s on 2 cores."""
import pytest

from benchmarks import fuzz_inputs as fz


def _check(records, must_accept=()):
    bad = fz.failures(records)
    assert not bad, "\n".join(f"{r['entry']} {r['format']} {r['kind']}: {r['label']} | {r['detail']}" for r in bad[:20])
    for r in records:
        assert r["peak"] is None or r["peak"] <= fz.memory_bound(r["entry"], r["bytes"]), r
    counts = fz.tally(records)
    for key in must_accept:
        # Mutations that leave a file readable must be read: a fuzzer refusing everything proves nothing.
        assert counts[key][fz.ACCEPTED] > 0 and counts[key][fz.CLEAN] > 0, (key, counts[key])
    return counts


@pytest.fixture(scope="module")
def data(shared_data):
    return shared_data


def test_fuzz_readers(data):
    jobs = [{"entry": "read", "format": f, "n": n, "hostile": True}
            for f, n in (("hair", 60), ("tfx", 60), ("tfx-small", 20), ("data", 60), ("npz", 60))]
    records = fz.run_jobs(jobs)
    counts = _check(records, [("read", "hair"), ("read", "tfx"), ("read", "npz")])
    assert sum(c["tried"] for c in counts.values()) >= 280


def test_fuzz_commands(data):
    jobs = [{"entry": e, "format": f, "n": 15, "hostile": True}
            for e in ("render", "export") for f in ("hair", "tfx", "data", "npz")]
    _check(fz.run_jobs(jobs), [("render", "hair"), ("export", "tfx")])


def test_fuzz_obj(data):
    jobs = [{"entry": "obj", "format": "obj", "n": 60, "hostile": True}, {"entry": "obj", "format": "obj-big", "n": 5}]
    _check(fz.run_jobs(jobs), [("obj", "obj")])


def test_fuzz_arrays_and_presets(data):
    jobs = [{"entry": "arrays", "format": "arrays", "n": 200}, {"entry": "preset", "format": "json", "n": 100}]
    counts = _check(fz.run_jobs(jobs), [("arrays", "arrays"), ("preset", "json")])
    assert counts[("arrays", "arrays")]["tried"] == 200


def test_fuzz_is_deterministic(data):
    jobs = [{"entry": "read", "format": "tfx-small", "n": 25}, {"entry": "arrays", "format": "arrays", "n": 30}]
    first, second = fz.run_jobs(jobs), fz.run_jobs(jobs)
    assert [(r["label"], r["kind"], r["detail"]) for r in first] == [(r["label"], r["kind"], r["detail"]) for r in second]


def test_a_blowup_fails_its_case():
    """The cap is real: a reader that believed a header would be counted as `memory`."""
    import numpy as np
    runner = fz._Runner(".")
    record = {}
    with runner.limits.case(fz.memory_bound("read", 128), record):
        fz._classify(record, lambda: np.ones(1 << 31), lambda r: [], [])
    assert record["kind"] == fz.MEMORY
