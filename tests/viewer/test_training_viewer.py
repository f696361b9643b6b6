"""`ns2gs-train ... --viewer`: the live view renders only between training steps and follows the model."""

import dataclasses
import math
import socket
from types import SimpleNamespace

import numpy as np
import pytest
from viser import transforms as vtf

from nerf2gs_plugin.engine.trainer import Trainer
from nerf2gs_plugin.registry import get_method
from nerf2gs_plugin.viewer.server import ViewerConfig, attach_training_viewer


class _Client:
    """A connected browser as the viewer sees it (camera state, per-client GUI and scene)."""

    client_id = 1

    def __init__(self):
        self.camera = SimpleNamespace(wxyz=vtf.SO3.from_rpy_radians(-math.pi / 2, 0.0, 0.0).wxyz, position=np.array([0.0, -4.0, 1.5]),
                                      fov=math.radians(50), image_width=160, image_height=120, on_update=lambda cb: None)
        self.gui = SimpleNamespace(add_markdown=lambda *a, **k: SimpleNamespace(content=""))
        self.frames = []
        self.scene = SimpleNamespace(set_background_image=lambda img, **k: self.frames.append(img.copy()))


def test_live_view_renders_between_steps_and_tracks_training(tiny_scene, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = dataclasses.replace(get_method("voxel-grid").config, data=tiny_scene, output_dir=tmp_path, max_num_iterations=10,
                              steps_per_save=1000, steps_per_eval_image=0, progress=False, timestamp="run")
    trainer = Trainer(cfg)
    trainer.setup()
    viewer = attach_training_viewer(trainer, ViewerConfig(port=port, max_side=48, rest_delay=0.0), every_n_steps=5)
    try:
        client = _Client()
        viewer._on_connect(client)
        assert client.frames == []  # nothing renders outside the trainer's step hook
        in_step = []
        model = trainer.pipeline.model
        orig_outputs, orig_render = model.get_outputs, model.render_camera

        def outputs(*a, **k):
            in_step.append(True)
            try:
                return orig_outputs(*a, **k)
            finally:
                in_step.pop()

        def render(cam):
            assert not in_step, "the viewer rendered during a training step"
            return orig_render(cam)

        model.get_outputs, model.render_camera = outputs, render
        trainer.train()
        # first frame after step 0, a re-render after each model update (steps 4 and 9)
        assert len(client.frames) == 3, len(client.frames)
        assert client.frames[-1].shape == (36, 48, 3)
        assert not np.array_equal(client.frames[0], client.frames[-1])  # the model changed under the view
        assert viewer.step == 9 and "**step** 9" in viewer.stats_markdown()
    finally:
        viewer.stop()
