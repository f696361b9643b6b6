"""External model outputs are checked before anything is written from them: a NaN enhancer or
segmenter, class ids of an odd layout or beyond the declared classes stop the command with one
line naming the model (non-zero exit), and leave the files as they were."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_plugin.data.images import write_image_atomic
from nerf2gs_plugin.errors import ModelOutputError
from nerf2gs_bench.fault_models import ENHANCERS, SEGMENTERS, conv_model


def _image(h: int = 16, w: int = 24) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    return torch.rand(h, w, 3, generator=g)


@pytest.mark.parametrize("name", sorted(ENHANCERS))
def test_bad_enhancer_output_is_refused_naming_the_model(tmp_path, name):
    from nerf2gs_plugin.enhancer import make_enhancer

    model = conv_model(tmp_path / f"{name}.onnx", **ENHANCERS[name])
    enh = make_enhancer(f"onnx:{model}")
    with pytest.raises(ModelOutputError, match=str(model)):
        enh.enhance(_image())


def test_enhance_apply_with_a_nan_model_keeps_the_inputs(tmp_path, monkeypatch, capsys):
    from nerf2gs_plugin.cli import enhance as enhance_cli

    model = conv_model(tmp_path / "nan.onnx", **ENHANCERS["nan"])
    folder = tmp_path / "imgs"
    write_image_atomic(folder / "a.png", _image())
    before = (folder / "a.png").read_bytes()
    monkeypatch.setattr(sys, "argv", ["ns2gs-enhance", "apply", "--model", str(model), "--input", str(folder / "a.png"),
                                      "--output", str(folder)])
    with pytest.raises(SystemExit) as e:
        enhance_cli.entrypoint()
    err = capsys.readouterr().err.strip()
    assert int(e.value.code) == 2 and len(err.splitlines()) == 1 and str(model) in err and "non-finite" in err
    assert (folder / "a.png").read_bytes() == before  # the input is not replaced by a black image


def test_augment_cache_is_not_filled_by_a_nan_enhancer(tmp_path):
    """The bird's-eye views go through the enhancer: a NaN one stops before the cache entry exists."""
    from nerf2gs_plugin.cameras import Cameras
    from nerf2gs_plugin.augment.config import AugmentConfig
    from nerf2gs_plugin.augment.datamanager import render_augmented_views
    from nerf2gs_plugin.datamanagers.image_set import ImageSet
    from nerf2gs_plugin.enhancer import make_enhancer

    enh = make_enhancer(f"onnx:{conv_model(tmp_path / 'nan.onnx', **ENHANCERS['nan'])}")
    n, h, w = 3, 12, 16
    c2w = torch.eye(4)[None, :3].repeat(n, 1, 1)
    c2w[:, 0, 3] = torch.arange(n, dtype=torch.float32)
    cams = Cameras(camera_to_worlds=c2w, fx=torch.full((n, 1), 10.0), fy=torch.full((n, 1), 10.0), cx=torch.full((n, 1), w / 2),
                   cy=torch.full((n, 1), h / 2), width=torch.full((n, 1), w), height=torch.full((n, 1), h))
    train = ImageSet.from_images(cams, [torch.rand(h, w, 3) for _ in range(n)])

    def render(cam):
        return {"rgb": torch.full((h, w, 3), 0.5), "depth": torch.ones(h, w, 1), "accumulation": torch.ones(h, w, 1)}

    cfg = AugmentConfig(composites=False, extra_views=True, min_coverage=0.0)
    with pytest.raises(ModelOutputError, match="nan.onnx"):
        render_augmented_views(train, _World(), render, "ref", "data", tmp_path / "cache", cfg, enhancer=enh)
    written = [p.relative_to(tmp_path) for p in (tmp_path / "cache").rglob("*") if p.is_file()]
    # the reference's own (good) renders may stay in the view store; no enhanced view, no cache entry
    assert not [p for p in written if "extra" in p.parts or p.name == "manifest.json"], written


class _World:
    """Up +z, one world unit a metre."""

    up = torch.tensor([0.0, 0.0, 1.0])

    def metres_to_world(self, metres: float) -> float:
        return metres


def _segmenter(tmp_path: Path, name: str, classes: str | None = None):
    from nerf2gs_plugin.masks.onnx_segmenter import OnnxSegmenter

    model = conv_model(tmp_path / f"{name}.onnx", **SEGMENTERS[name])
    if classes is not None:
        (tmp_path / f"{name}.onnx.json").write_text(json.dumps({"classes": classes}))
    return OnnxSegmenter(model), model


@pytest.mark.parametrize("name", ["nan_logits", "inf_logits"])
def test_nan_segmenter_is_refused_not_all_ground(tmp_path, name):
    seg, model = _segmenter(tmp_path, name)
    with pytest.raises(ModelOutputError, match="non-finite"):
        seg.masks(_image())


@pytest.mark.parametrize("name", ["ids_two_channels", "ids_huge", "ids_1e5", "ids_negative"])
def test_bad_class_ids_are_refused_before_one_hot(tmp_path, name):
    seg, model = _segmenter(tmp_path, name, classes="cityscapes" if name != "ids_1e5" else None)
    t0 = time.perf_counter()
    with pytest.raises(ModelOutputError, match=str(model)):
        seg.masks(_image())
    assert time.perf_counter() - t0 < 5.0  # no terabyte one-hot attempted


def test_class_ids_within_the_declared_classes_still_work(tmp_path):
    from nerf2gs_plugin.masks.onnx_segmenter import OnnxSegmenter

    model = conv_model(tmp_path / "ids.onnx", out_channels=1, bias=10.0, ids=True)  # 10: cityscapes "sky"
    (tmp_path / "ids.onnx.json").write_text(json.dumps({"classes": "cityscapes"}))
    m = OnnxSegmenter(model).masks(_image())
    assert bool(m["sky"].all()) and not bool(m["ground"].any())


def test_masks_cli_with_a_nan_segmenter_writes_no_masks(tmp_path, monkeypatch, capsys):
    from nerf2gs_plugin.cli import data as data_cli

    data = tmp_path / "d"
    frames = []
    for i in range(2):
        write_image_atomic(data / "images" / f"f{i}.png", _image())
        frames.append({"file_path": f"images/f{i}.png", "transform_matrix": np.eye(4).tolist()})
    (data / "transforms.json").write_text(json.dumps({"fl_x": 20, "w": 24, "h": 16, "frames": frames}))
    model = conv_model(tmp_path / "nan.onnx", **SEGMENTERS["nan_logits"])
    monkeypatch.setattr(sys, "argv", ["ns2gs-data", "masks", str(data), "--segmenter", f"onnx:{model}"])
    with pytest.raises(SystemExit) as e:
        data_cli.entrypoint()
    err = capsys.readouterr().err.strip()
    assert int(e.value.code) == 2 and str(model) in err.splitlines()[-1] and "non-finite" in err
    assert not (data / "masks").exists() or not any((data / "masks").rglob("*.png"))




def test_masks_stop_on_a_model_failing_halfway_without_a_partial_set(tmp_path, monkeypatch):
    """The segmenter fails on the second image only: the first one's masks are not left behind."""
    from nerf2gs_plugin.masking.make_masks import MasksConfig, make_masks
    from nerf2gs_plugin.masks.onnx_segmenter import OnnxSegmenter

    data = tmp_path / "d"
    frames = []
    for i in range(3):
        write_image_atomic(data / "images" / f"f{i}.png", _image())
        frames.append({"file_path": f"images/f{i}.png", "transform_matrix": np.eye(4).tolist()})
    (data / "transforms.json").write_text(json.dumps({"fl_x": 20, "w": 24, "h": 16, "frames": frames}))
    model = conv_model(tmp_path / "road.onnx", out_channels=19, weight=0.0)
    calls = []
    real = OnnxSegmenter.masks

    def masks(self, image):
        calls.append(1)
        if len(calls) == 2:
            raise ModelOutputError("segmenter output holds NaN", model)
        return real(self, image)

    monkeypatch.setattr(OnnxSegmenter, "masks", masks)
    with pytest.raises(ModelOutputError, match="NaN"):
        make_masks(MasksConfig(data=data, segmenter=f"onnx:{model}", progress=False), log=lambda s: None)
    assert len(calls) == 2
    assert not (data / "masks").exists() or not any((data / "masks").rglob("*.png"))
    assert not list(data.glob(".masks-*"))
