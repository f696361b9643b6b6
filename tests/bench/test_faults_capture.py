"""The capture path's fault suite (shared with ``ns2gs-bench faults``), a representative subset:
one case of each kind of fault per entry point that is quick (NaN and out-of-range models, broken
model files, checkpoints and configs, bad flags, kill -9, a junk video). Every case ends with a
result that checks out or one error line that wrote nothing from the bad input: no traceback, no
native abort, no hang. The whole suite (~80 cases, minutes) runs with ``ns2gs-bench faults``."""

from __future__ import annotations

import pytest

from nerf2gs_bench.faults_capture import ci_cases, make_capture_cases, run_capture_suite

pytestmark = pytest.mark.faults


def test_the_full_suite_covers_the_capture_path():
    cases = make_capture_cases()
    entries = {c.entry for c in cases}
    assert len(cases) >= 60 and entries == {"process images", "process video", "masks onnx", "masks auto", "enhance apply", "eval"}
    faults = {c.fault for c in cases}
    assert {"flip", "truncate", "bad model", "kill -9", "concurrent"} <= faults


@pytest.mark.timeout(400)
def test_capture_faults_subset(tmp_path):
    doc = run_capture_suite(tmp_path, cases=ci_cases())
    s = doc["summary"]
    bad = [c for c in doc["cases"] if c["outcome"] not in ("ok", "clean_error")]
    assert s["cases"] >= 8 and not bad, bad
    # the bad models, flags and cut configs are refused, not passed through
    refused = [c for c in doc["cases"] if c["case"]["fault"] in ("bad model", "bad flag", "bad config", "cut at a line")]
    assert refused and all(c["outcome"] == "clean_error" for c in refused), refused
