"""``benchmarks/validation/real_captures_lever.py``: a bad lever is named in one line before any work."""
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "validation" / "real_captures_lever.py"


@pytest.mark.parametrize("lever, says", [("bogus=1", "KEY an --augment field"), ("real_only_from", "KEY an --augment field"),
                                         ("real_only_from=abc", "must be a Python literal")])
def test_a_bad_lever_is_named_in_one_line(tmp_path, lever, says):
    p = subprocess.run([sys.executable, str(SCRIPT), "kitti", str(tmp_path / "out"), lever, "--runs", str(tmp_path)],
                       capture_output=True, text=True)
    assert p.returncode != 0 and f"lever '{lever}'" in p.stderr and says in p.stderr
    assert "Traceback" not in p.stderr and not (tmp_path / "out.json").exists()


def test_a_capture_the_bench_never_ran_is_named(tmp_path):
    p = subprocess.run([sys.executable, str(SCRIPT), "kitti", str(tmp_path / "out"), "real_only_from=0.6", "--runs", str(tmp_path)],
                       capture_output=True, text=True)
    assert p.returncode != 0 and "real_photos.json" in p.stderr and "ns2gs-bench real-captures --captures kitti" in p.stderr
    assert "Traceback" not in p.stderr


def test_a_stem_that_names_a_value_keeps_its_dot():
    import importlib.util

    spec = importlib.util.spec_from_file_location("real_captures_lever", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    a, b = (mod._with_ext(Path("out") / f"lund_real_only_from_{v}", ".json") for v in ("0.6", "0.75"))
    assert a.name == "lund_real_only_from_0.6.json" and b.name == "lund_real_only_from_0.75.json"
