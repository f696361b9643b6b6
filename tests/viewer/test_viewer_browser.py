"""The viewer in a real headless browser (Debian's chromium through playwright) on a trained tiny run."""

import dataclasses
import socket
import time

import numpy as np
import pytest
import torch

import cv2

from nerf2gs_plugin.viewer.browser import browser_unavailable_reason, grab, headless_page

_REASON = browser_unavailable_reason()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method

    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path_factory.mktemp("runs"),
                              max_num_iterations=12, steps_per_save=1000, steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    return trainer.train()


def _wait(cond, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.skipif(_REASON is not None, reason=f"browser test skipped: {_REASON}")
def test_browser_shows_render_and_follows_camera(tiny_run, tmp_path):
    from nerf2gs_plugin.viewer.server import ViewerConfig, open_viewer

    viewer = open_viewer(tiny_run, ViewerConfig(port=_free_port(), max_side=96, rest_delay=0.1))
    centers = []
    orig = viewer.model.render_camera
    viewer.model.render_camera = lambda cam: (centers.append(cam.centers[0].detach().cpu().clone()), orig(cam))[1]
    try:
        assert viewer.modes == ["rgb", "depth", "accumulation"]
        md = viewer.stats_markdown()
        assert "voxel-grid" in md and "**step** 11" in md and "primitives" in md
        assert len(viewer._frustums["train"]) == 8 and len(viewer._frustums["eval"]) == 4
        with headless_page(viewer.url, 900, 600) as page:
            assert viewer.wait_for_frames(1, 60, full=True), "no full-resolution frame rendered"
            r = viewer.renderers[0]
            assert r.last.width == 96 and not r.last.moving
            frame_median = np.median(r.last_image.reshape(-1, 3), 0)

            def canvas_shows_frame():
                view = grab(page)[:, : 900 * 6 // 10]  # left of the GUI panel
                canvas_shows_frame.view = view
                return np.abs(np.median(view.reshape(-1, 3), 0) - frame_median).max() < 20

            # the canvas ends up showing the pushed render (viser fades scene content in; slow on software WebGL)
            shown = _wait(canvas_shows_frame, 45)
            view = canvas_shows_frame.view
            cv2.imwrite(str(tmp_path / "viewer.png"), view[..., ::-1])
            near_white = (view.min(axis=-1) > 235).mean()
            assert view.std() > 8 and near_white < 0.5, (view.std(), near_white)  # not blank, not viser's empty white scene
            assert shown, (np.median(view.reshape(-1, 3), 0), frame_median)

            # move the camera through viser's client API: the browser echoes it and a new frame renders there
            n = viewer.frames_rendered
            client = r.client
            target = np.asarray(client.camera.position) + np.array([0.3, -0.2, 0.25])
            client.camera.position = target
            assert _wait(lambda: viewer.frames_rendered > n, 30), "no frame after the camera moved"
            assert _wait(lambda: torch.allclose(centers[-1], torch.tensor(target, dtype=torch.float32), atol=1e-4), 10)

            # go to an eval camera: the view follows it and the panel shows render | GT at its intrinsics
            label, cams, i, gt = viewer._eval_targets[0]
            n = viewer.frames_rendered
            viewer.go_to(client, cams, i, gt, label)
            assert viewer.last_side_by_side["label"] == label and np.isfinite(viewer.last_side_by_side["psnr"])
            h, w = gt.shape[:2]
            assert viewer.last_side_by_side["shape"][0] == h and viewer.last_side_by_side["shape"][1] > 2 * w
            assert _wait(lambda: viewer.frames_rendered > n and torch.allclose(centers[-1], cams.centers[i].cpu(), atol=1e-4), 30)

            # render mode switch re-renders at full resolution
            n = viewer.frames_rendered
            viewer.set_mode("depth")
            assert _wait(lambda: viewer.frames_rendered > n, 30)
    finally:
        viewer.model.render_camera = orig
        viewer.stop()


def test_port_in_use_by_a_viewer_is_refused(tiny_run):
    from nerf2gs_plugin.errors import ConfigError
    from nerf2gs_plugin.viewer.server import ViewerConfig, open_viewer

    port = _free_port()
    viewer = open_viewer(tiny_run, ViewerConfig(port=port))
    try:
        with pytest.raises(ConfigError, match=f"port {port} on 127.0.0.1 is in use"):
            open_viewer(tiny_run, ViewerConfig(port=port))
    finally:
        viewer.stop()
