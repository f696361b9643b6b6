"""The ONNX enhancer runtime: round trip, seamless tiling, I/O conventions, clear errors."""

import io
import json
import warnings
from pathlib import Path

import pytest
import torch
from torch import nn

from nerf2gs_plugin.enhancer import IdentityEnhancer, make_enhancer
from nerf2gs_plugin.enhancer.onnx_runtime import OnnxEnhancer
from nerf2gs_plugin.errors import ConfigError, ModelOutputError


def export(module: nn.Module, path: Path, inputs: tuple, names: list[str], dynamic: bool = True, meta: dict | None = None) -> Path:
    import onnx

    buf = io.BytesIO()
    axes = {n: {0: "b", 2: "h", 3: "w"} for n in names + ["out"]} if dynamic else None
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(module.eval(), inputs, buf, input_names=names, output_names=["out"], dynamic_axes=axes, dynamo=False)
    model = onnx.load_from_string(buf.getvalue())
    for k, v in (meta or {}).items():
        e = model.metadata_props.add()
        e.key, e.value = k, str(v)
    path.write_bytes(model.SerializeToString())
    return path


def conv_net(seed: int = 0) -> nn.Module:
    """Translation-equivariant (zero-padded 3x3 convs, receptive radius 3)."""
    torch.manual_seed(seed)
    net = nn.Sequential(nn.Conv2d(3, 8, 3, padding=1), nn.Tanh(), nn.Conv2d(8, 8, 3, padding=1), nn.Tanh(), nn.Conv2d(8, 3, 3, padding=1), nn.Sigmoid())
    return net


def test_round_trip_matches_torch(tmp_path):
    net = conv_net()
    path = export(net, tmp_path / "m.onnx", (torch.rand(1, 3, 16, 16),), ["image"])
    enh = make_enhancer(f"onnx:{path}")
    img = torch.rand(37, 45, 3)
    with torch.no_grad():
        expected = net(img.permute(2, 0, 1)[None])[0].permute(1, 2, 0)
    out = enh.enhance(img)
    assert out.shape == img.shape
    assert (out - expected).abs().max() < 1e-5


def test_tiling_has_no_seams(tmp_path):
    net = conv_net(1)
    path = export(net, tmp_path / "m.onnx", (torch.rand(1, 3, 16, 16),), ["image"])
    img = torch.rand(70, 90, 3)
    whole = OnnxEnhancer(path).enhance(img)
    tiled_rt = OnnxEnhancer(path, tile_size=24, overlap=12)
    tiled = tiled_rt.enhance(img)
    assert tiled_rt.tile == (24, 24)
    assert (whole - tiled).abs().max() < 1e-4
    # without overlap the tile borders do show: the test can see seams
    seamy = OnnxEnhancer(path, tile_size=24, overlap=0).enhance(img)
    assert (whole - seamy).abs().max() > 1e-3


class _Invert(nn.Module):
    def forward(self, x):  # in -1..1: negation == 1 - v in 0..1
        return -x


class _NHWCMean(nn.Module):
    def forward(self, image, reference):
        return (image + reference.flip(-1)) / 2


def test_sidecar_range_and_nhwc_fixed_size_with_reference(tmp_path):
    path = export(_Invert(), tmp_path / "inv.onnx", (torch.rand(1, 3, 8, 8),), ["x"])
    img = torch.rand(20, 30, 3)
    with pytest.raises(ModelOutputError, match="inv.onnx.*outside the declared range 0..1"):  # -v is no 0..1 image: refused
        make_enhancer(f"onnx:{path}").enhance(img)
    (tmp_path / "inv.onnx.json").write_text(json.dumps({"range": "-1,1"}))
    assert (make_enhancer(f"onnx:{path}").enhance(img) - (1 - img)).abs().max() < 1e-6

    path = export(_NHWCMean(), tmp_path / "nhwc.onnx", (torch.rand(1, 16, 16, 3), torch.rand(1, 16, 16, 3)), ["img", "ref"],
                  dynamic=False, meta={"layout": "NHWC", "reference_input": "ref", "input": "img", "overlap": 4})
    rt = OnnxEnhancer(path)
    assert rt.fixed_size == (16, 16) and rt.tile == (16, 16)
    ref = torch.rand(20, 30, 3)
    out = rt.enhance(img, reference=ref)
    assert (out - (img + ref.flip(-1)) / 2).abs().max() < 1e-5  # channel flip, tiled over 16x16 pieces
    small = torch.rand(10, 12, 3)  # smaller than the fixed size: padded, then cropped back
    assert (rt.enhance(small) - (small + small.flip(-1)) / 2).abs().max() < 1e-5


def test_bad_files_are_config_errors_naming_the_file(tmp_path):
    missing = tmp_path / "nope.onnx"
    with pytest.raises(ConfigError, match="nope.onnx"):
        make_enhancer(f"onnx:{missing}")
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"\x00\x01 this is not a protobuf \xff" * 50)
    with pytest.raises(ConfigError, match="garbage.onnx.*not a loadable ONNX model"):
        make_enhancer(f"onnx:{garbage}")
    four = export(nn.Conv2d(4, 3, 3, padding=1), tmp_path / "four.onnx", (torch.rand(1, 4, 8, 8),), ["image"])
    with pytest.raises(ConfigError, match="four.onnx.*expected 3 channels"):
        make_enhancer(f"onnx:{four}")
    flat = export(nn.Linear(12, 12), tmp_path / "flat.onnx", (torch.rand(2, 12),), ["v"], dynamic=False)
    with pytest.raises(ConfigError, match="flat.onnx.*4-D"):
        make_enhancer(f"onnx:{flat}")
    shrink = export(nn.Conv2d(3, 3, 3), tmp_path / "shrink.onnx", (torch.rand(1, 3, 8, 8),), ["image"])
    with pytest.raises(ConfigError, match="shrink.onnx.*does not match"):
        make_enhancer(f"onnx:{shrink}").enhance(torch.rand(8, 8, 3))
    ok = export(conv_net(), tmp_path / "ok.onnx", (torch.rand(1, 3, 8, 8),), ["image"])
    (tmp_path / "ok.onnx.json").write_text(json.dumps({"layuot": "NCHW"}))
    with pytest.raises(ConfigError, match="ok.onnx.json.*unknown convention keys"):
        make_enhancer(f"onnx:{ok}")


def test_specs_and_cache_key(tmp_path, monkeypatch):
    assert isinstance(make_enhancer("none"), IdentityEnhancer)
    with pytest.raises(ConfigError, match="unknown enhancer"):
        make_enhancer("difix")
    monkeypatch.setenv("NS2GS_ENHANCER", str(tmp_path / "missing.onnx"))
    with pytest.raises(ConfigError, match="missing.onnx.*ns2gs-enhance train"):
        make_enhancer("builtin")
    a = export(conv_net(0), tmp_path / "m.onnx", (torch.rand(1, 3, 8, 8),), ["image"])
    key_a = make_enhancer(f"onnx:{a}").cache_key()
    assert make_enhancer(f"builtin:{a}").cache_key() == key_a  # same content, same key
    monkeypatch.setenv("NS2GS_ENHANCER", str(a))
    assert make_enhancer("builtin").cache_key() == key_a
    export(conv_net(5), a, (torch.rand(1, 3, 8, 8),), ["image"])  # new weights, same path
    assert make_enhancer(f"onnx:{a}").cache_key() != key_a
