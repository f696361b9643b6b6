"""A bench's log lines stay whole above its progress bar."""

from __future__ import annotations

import io


def test_bench_log_lines_keep_a_long_path_on_one_line(tmp_path):
    """A bench's log line above its progress bar: a run folder longer than the terminal stays on the line that
    names it (a narrow, non-tty console wrapped it onto the next line: "reuse <label>: " looked empty)."""
    from types import SimpleNamespace

    from rich.console import Console

    from nerf2gs_bench.runner import BenchLog, progress_log

    out = io.StringIO()
    log = progress_log(SimpleNamespace(console=Console(file=out, width=40)), BenchLog(tmp_path, "demo"))
    line = "[bench] reuse scaffold-gs default: /work/benchruns/street/scaffold-gs/93afe4172087"
    log(line)
    assert out.getvalue().splitlines() == [line]
    assert (tmp_path / "logs" / "demo.log").read_text().rstrip().endswith(line)
