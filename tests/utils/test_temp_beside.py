"""Atomic writes of files two commands may write at once (eval renders, cached views): each process
writes through a temp file of its own."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from nerf2gs_plugin.utils.io import temp_beside

SAVE_MANY = """
import sys
from nerf2gs_plugin.utils.plotting import pyplot, save_figure
plt = pyplot()
for _ in range(15):
    fig = plt.figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [0, 1])
    save_figure(fig, sys.argv[1])
"""


def test_temp_name_keeps_the_suffix_and_is_this_process_own(tmp_path):
    t = temp_beside(tmp_path / "street.png")
    assert t.parent == tmp_path and t.suffix == ".png" and t.name.startswith(".street.") and str(os.getpid()) in t.name
    other = subprocess.run([sys.executable, "-c", f"from nerf2gs_plugin.utils.io import temp_beside; print(temp_beside({str(tmp_path / 'street.png')!r}))"],
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(other) != t


def test_two_processes_saving_one_figure_at_once_both_succeed(tmp_path):
    out = tmp_path / "renders" / "street.png"
    procs = [subprocess.Popen([sys.executable, "-c", SAVE_MANY, str(out)], stderr=subprocess.PIPE, text=True) for _ in range(2)]
    errs = [p.communicate(timeout=120)[1] for p in procs]
    assert all(p.returncode == 0 for p in procs), errs
    assert out.stat().st_size > 0 and not [p for p in out.parent.iterdir() if p.name.startswith(".")]
