"""The fault-injection suite (shared with ``ns2gs-bench faults``).

>= 100 random byte flips and truncations (fixed seed) over every file of a tiny nerfstudio
dataset, its COLMAP twin and a trained run: each ends in finite output or one of the package's
one-line errors, never a traceback, a hang or > 2 GB. Then kill -9 at random moments of tiny
trainings: each resumes from its last checkpoint with the next step and the same loss.
"""

from __future__ import annotations

import pytest

from nerf2gs_bench.faults import run_suite

pytestmark = pytest.mark.faults


@pytest.mark.timeout(300)
def test_fault_injection_suite(tmp_path):
    doc = run_suite(tmp_path, n_files=120, n_kills=5, seed=0)
    s = doc["summary"]
    bad = [c for c in doc["cases"] if c["outcome"] not in ("ok", "clean_error")]
    assert s["file_cases"] >= 100 and s["kill_cases"] >= 5
    assert s["tracebacks"] == 0 and s["hangs"] == 0 and s["wrong_results"] == 0, bad
    assert s["clean_errors"] >= 50  # the faults are real: most inputs are refused
    assert s["peak_rss_mb_file_cases"] < 2048
    for t in ("nerfstudio", "colmap", "run"):
        assert s["by_target"][t]["cases"] >= 30, s["by_target"]
    kills = [c for c in doc["cases"] if c["case"]["target"] == "training"]
    assert any("resumed at step" in c["detail"] for c in kills), kills
