"""Our built-in enhancer network: a small residual U-Net (NOT Difix; no diffusion, no pretrained
weights). It predicts a correction that is added to the input render, so an untrained network is
the identity. Optionally conditioned on a reference input by channel concatenation: a nearby training
image as it is (3 channels), or one warped into the render's camera with its validity mask (4 channels,
:func:`~nerf2gs_plugin.enhancer.warp.warped_reference`). Two stride-2 levels: H and W must be
multiples of 4 (``MULTIPLE``)."""

from __future__ import annotations

from typing import Optional

import torch
from torch import Tensor, nn

MULTIPLE = 4


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.LeakyReLU(0.1), nn.Conv2d(cout, cout, 3, padding=1), nn.LeakyReLU(0.1))


class ResidualUNet(nn.Module):
    """``forward(image[, reference])``: images ``[B, 3, H, W]`` in 0..1 -> enhanced image in 0..1.
    With ``condition``, a ``[B, reference_channels, H, W]`` reference in 0..1 too: 3 channels, an image
    (the image itself when none is given); 4, a warped view and its validity (all zero when none is given)."""

    def __init__(self, width: int = 16, condition: bool = False, reference_channels: int = 3) -> None:
        super().__init__()
        if reference_channels not in (3, 4):
            raise ValueError(f"reference_channels must be 3 (an image) or 4 (a warped image and its validity), got {reference_channels}")
        self.width, self.condition, self.reference_channels = width, condition, reference_channels
        cin = 3 + reference_channels if condition else 3
        c1, c2, c3 = width, 2 * width, 4 * width
        self.enc1 = _block(cin, c1)
        self.down1 = nn.Conv2d(c1, c2, 3, stride=2, padding=1)
        self.enc2 = _block(c2, c2)
        self.down2 = nn.Conv2d(c2, c3, 3, stride=2, padding=1)
        self.mid = _block(c3, c3)
        self.up2 = nn.ConvTranspose2d(c3, c2, 2, stride=2)
        self.dec2 = _block(2 * c2, c2)
        self.up1 = nn.ConvTranspose2d(c2, c1, 2, stride=2)
        self.dec1 = _block(2 * c1, c1)
        self.head = nn.Conv2d(c1, 3, 3, padding=1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, image: Tensor, reference: Optional[Tensor] = None) -> Tensor:
        x = image * 2 - 1
        if self.condition:
            if reference is None:
                reference = image if self.reference_channels == 3 else image.new_zeros(image.shape[0], 4, *image.shape[2:])
            x = torch.cat([x, reference * 2 - 1], 1)
        e1 = self.enc1(x)
        e2 = self.enc2(self.down1(e1))
        m = self.mid(self.down2(e2))
        d2 = self.dec2(torch.cat([self.up2(m), e2], 1))
        d1 = self.dec1(torch.cat([self.up1(d2), e1], 1))
        return (image + self.head(d1)).clamp(0, 1)


class _ExportWrapper(nn.Module):
    """Fixed-arity forward for ONNX export (one or two inputs)."""

    def __init__(self, net: ResidualUNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, *inputs: Tensor) -> Tensor:
        return self.net(*inputs)


def export_onnx(net: ResidualUNet, path, metadata: dict[str, str], opset: int = 17) -> bytes:
    """Export to ONNX bytes (legacy TorchScript exporter: needs no onnxscript) with the I/O
    convention of :mod:`nerf2gs_plugin.enhancer.onnx_runtime` in ``metadata_props``."""
    import io
    import warnings

    import onnx

    net = net.eval().cpu()
    names = ["image", "reference"] if net.condition else ["image"]
    dummy = tuple(torch.rand(1, c, 32, 32) for c in (3, net.reference_channels)[: len(names)])
    axes = {n: {0: "batch", 2: "height", 3: "width"} for n in names + ["enhanced"]}
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(_ExportWrapper(net), dummy, buf, input_names=names, output_names=["enhanced"],
                          dynamic_axes=axes, opset_version=opset, dynamo=False)
    model = onnx.load_from_string(buf.getvalue())
    conv = {"layout": "NCHW", "range": "0,1", "input": "image", "output": "enhanced", "multiple": str(MULTIPLE)}
    if net.condition:
        conv["reference_input"] = "reference"
        if net.reference_channels == 4:
            conv["reference_kind"] = "warped"
    conv.update({k: str(v) for k, v in metadata.items()})
    del model.metadata_props[:]
    for k, v in conv.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    model.producer_name = "nerf2gs"
    model.doc_string = "nerf2gs built-in enhancer: a small residual U-Net trained on this dataset (not Difix)"
    return model.SerializeToString()
