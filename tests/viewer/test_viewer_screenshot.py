"""`ns2gs-viewer RUN --screenshot PNG`: the command that makes the viewer image in docs/, and its bad input."""

import socket
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from nerf2gs_plugin.viewer.browser import browser_unavailable_reason

_REASON = browser_unavailable_reason()
BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    from tiny_scene import train_tiny_run

    return train_tiny_run(tiny_scene, tmp_path_factory.mktemp("runs"))


def _viewer(*args):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return subprocess.run([str(BIN / "ns2gs-viewer"), *map(str, args), "--port", str(port)], capture_output=True, text=True, timeout=150)


@pytest.mark.skipif(_REASON is not None, reason=f"browser test skipped: {_REASON}")
def test_cli_screenshot_of_a_run(tiny_run, tmp_path):
    out = tmp_path / "docs" / "viewer.png"
    p = _viewer(tiny_run, "--max-side", "64", "--screenshot", out, "--screenshot-size", "640", "400")
    assert p.returncode == 0, p.stderr[-2000:]
    assert f"wrote {out}" in p.stdout
    img = cv2.imread(str(out))
    assert img.shape == (400, 640, 3) and img.std() > 8


def test_cli_bad_mode_is_one_line(tiny_run):
    p = _viewer(tiny_run, "--mode", "normals")
    err = p.stderr.strip()
    assert p.returncode == 2 and err.startswith("error: --mode normals") and "rgb, depth, accumulation" in err
    assert "Traceback" not in err
