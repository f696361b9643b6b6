"""Progress off a terminal: throttled plain lines (rate, ETA, stats) and a final line; a live
bar (nothing line-by-line) on a terminal; nothing at all when disabled."""

import io

from rich.console import Console

from nerf2gs_plugin.progress import PlainProgress, make_progress


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _run(console, clock, steps=100, dt=0.5, **kw):
    with make_progress(console=console, get_time=clock, log_every=10.0, **kw) as bar:
        task = bar.add_task("train demo", total=steps, stats="")
        for i in range(steps):
            clock.t += dt
            bar.update(task, advance=1, stats=f"loss {1.0 / (i + 1):.3f}")
    return bar


def test_plain_lines_when_not_a_terminal():
    out, clock = io.StringIO(), Clock()
    bar = _run(Console(file=out, force_terminal=False, width=60), clock)
    assert isinstance(bar, PlainProgress)
    lines = out.getvalue().splitlines()
    # 100 steps x 0.5 s = 50 s: a line every 10 s (4 before the end) and the final one
    assert len(lines) == 5, lines
    assert lines[0].startswith("train demo: 20/100 (20%) 2.00 it/s ETA 0:00:40 elapsed 0:00:10 loss 0.050")
    assert lines[-1].startswith("train demo: 100/100 (100%) 2.00 it/s done elapsed 0:00:50 loss 0.010")
    assert all(len(line) > 60 for line in lines)  # never wrapped to the console width


def test_final_line_when_stopped_early_and_fast_tasks():
    out, clock = io.StringIO(), Clock()
    try:
        with make_progress(console=Console(file=out, force_terminal=False), get_time=clock) as bar:
            task = bar.add_task("render", total=10, stats="")
            bar.update(task, advance=3)
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    assert out.getvalue().splitlines() == ["render: 3/10 (30%) -- it/s ETA -:--:-- elapsed 0:00:00"]


def test_live_bar_on_a_terminal_and_silence_when_disabled():
    out, clock = io.StringIO(), Clock()
    bar = _run(Console(file=out, force_terminal=True, width=120), clock)
    assert not isinstance(bar, PlainProgress)
    assert "train demo:" not in out.getvalue() and "100/100" in out.getvalue()
    out2 = io.StringIO()
    _run(Console(file=out2, force_terminal=False), Clock(), enabled=False)
    assert out2.getvalue() == ""
