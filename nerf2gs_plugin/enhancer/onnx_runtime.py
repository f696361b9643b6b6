"""Run any image-to-image ONNX model as an enhancer (onnxruntime; CUDA provider when present).

The paper passes NeRF-rendered bird's-eye views through Difix3D+; its weights cannot be fetched
here, so the enhancer is whatever ONNX model the user supplies (an ONNX export of Difix, or our own
small U-Net from ``ns2gs-enhance train``). How a model wants its pixels is read from the model's
``metadata_props`` and, overriding those, from a sidecar JSON next to it (``model.onnx.json``).

I/O convention (every key optional):

=================  =========================================================================
key                meaning (default)
=================  =========================================================================
``layout``         ``NCHW`` or ``NHWC`` for every image input and the output (``NCHW``)
``range``          pixel range of inputs and output: ``0,1`` or ``-1,1`` (``0,1``)
``input``          name of the image input (the model's first input)
``reference_input`` name of an optional reference-image input, same layout and range; it gets
                   the source training view (resized to the image size), or a copy of the image
                   itself when the caller has none (none: the model takes one image)
``reference_kind`` what the reference input holds: ``image`` (above) or ``warped``: the nearest
                   training view warped into the image's camera and its validity mask, 4 channels
                   at the image's size (:func:`nerf2gs_plugin.enhancer.warp.warped_reference`),
                   all zero when the caller has none (``image``)
``output``         name of the enhanced-image output (the model's first output)
``tile_size``      ``S`` or ``HxW``: tile size. If the model's graph fixes H and W those are used
                   and must agree; with dynamic H/W it is the largest piece run in one pass (none:
                   whole image in one pass)
``multiple``       H and W fed to the model are padded (reflect) to a multiple of this (1)
``overlap``        overlap of neighbouring tiles in pixels, blended linearly (tile_size // 4)
=================  =========================================================================

Images are 3-channel RGB. The output must have the input's spatial size (after padding) and 3
channels. Tiles overlap; each tile's pixels near an inner edge get zero weight (``overlap // 4``
pixels, where a convolution sees the tile border) and a linear ramp across the rest of the
overlap, so a translation-equivariant model gives the same result tiled as in one pass.
A file that is not an ONNX model, or whose inputs do not fit the convention, is a ``ConfigError``
naming the file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Optional, Union

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.enhancer.warp import REFERENCE_KINDS, WARPED_CHANNELS
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.model_output import check_range
from nerf2gs_plugin.utils.onnx_model import open_session, read_convention

KEYS = ("layout", "range", "input", "reference_input", "reference_kind", "output", "tile_size", "multiple", "overlap")


def _parse_hw(value: str, path: Path) -> tuple[int, int]:
    try:
        parts = [int(p) for p in value.lower().replace(",", "x").split("x")]
    except ValueError:
        raise ConfigError(f"tile_size must be S or HxW, got {value!r}", path) from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) <= 0:
        raise ConfigError(f"tile_size must be S or HxW with positive sizes, got {value!r}", path)
    return parts[0], parts[1]


def _ramp(length: int, lo_inner: bool, hi_inner: bool, overlap: int) -> Tensor:
    """1-D blend weight of a tile: zero next to inner edges, linear ramp over the overlap."""
    x = torch.arange(length, dtype=torch.float64)
    margin = overlap // 4
    span = max(overlap - 2 * margin, 1)
    w = torch.ones(length, dtype=torch.float64)
    if lo_inner:
        w = torch.minimum(w, ((x - margin + 0.5) / span).clamp(0, 1))
    if hi_inner:
        w = torch.minimum(w, ((length - 1 - x - margin + 0.5) / span).clamp(0, 1))
    return w


def _starts(total: int, tile: int, stride: int) -> list[int]:
    if total <= tile:
        return [0]
    starts = list(range(0, total - tile, stride)) + [total - tile]
    return sorted(set(starts))


class OnnxEnhancer:
    """An ONNX image-to-image model, tiled and padded per its convention (see module docstring)."""

    def __init__(self, path: Union[str, Path], tile_size: Optional[int] = None, overlap: Optional[int] = None,
                 providers: Optional[list[str]] = None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ConfigError("enhancer model file does not exist", self.path)
        self.session = open_session(self.path, providers)
        conv = read_convention(self.path, self.session, KEYS)
        self.convention = conv
        self.layout = conv.get("layout", "NCHW").upper()
        if self.layout not in ("NCHW", "NHWC"):
            raise ConfigError(f"layout must be NCHW or NHWC, got {self.layout!r}", self.path)
        rng = conv.get("range", "0,1").replace(" ", "").replace("..", ",")
        if rng not in ("0,1", "-1,1"):
            raise ConfigError(f"range must be 0,1 or -1,1, got {conv.get('range')!r}", self.path)
        self.symmetric = rng == "-1,1"
        inputs = {i.name: i for i in self.session.get_inputs()}
        outputs = [o.name for o in self.session.get_outputs()]
        self.input_name = conv.get("input", self.session.get_inputs()[0].name)
        self.reference_name = conv.get("reference_input") or None
        self.output_name = conv.get("output", outputs[0])
        for name, what in ((self.input_name, "input"), (self.reference_name, "reference_input")):
            if name is not None and name not in inputs:
                raise ConfigError(f"{what} '{name}' is not an input of the model (inputs: {', '.join(inputs)})", self.path)
        if self.output_name not in outputs:
            raise ConfigError(f"output '{self.output_name}' is not an output of the model (outputs: {', '.join(outputs)})", self.path)
        others = set(inputs) - {self.input_name, self.reference_name}
        if others:
            raise ConfigError(f"model has inputs {sorted(others)} that the convention does not feed", self.path)
        shape = inputs[self.input_name].shape
        if len(shape) != 4:
            raise ConfigError(f"input '{self.input_name}' has shape {shape}; expected a 4-D {self.layout} image", self.path)
        c_dim, h_dim, w_dim = (1, 2, 3) if self.layout == "NCHW" else (3, 1, 2)
        if isinstance(shape[c_dim], int) and shape[c_dim] != 3:
            raise ConfigError(f"input '{self.input_name}' has shape {shape}; expected 3 channels in {self.layout}", self.path)
        self.reference_kind = conv.get("reference_kind", "image")
        if self.reference_kind not in REFERENCE_KINDS:
            raise ConfigError(f"reference_kind must be {' or '.join(REFERENCE_KINDS)}, got {self.reference_kind!r}", self.path)
        if self.reference_kind == "warped":
            if self.reference_name is None:
                raise ConfigError("reference_kind 'warped' needs a reference_input", self.path)
            ref_c = inputs[self.reference_name].shape[c_dim] if len(inputs[self.reference_name].shape) == 4 else None
            if isinstance(ref_c, int) and ref_c != WARPED_CHANNELS:
                raise ConfigError(f"reference_kind 'warped' needs a {WARPED_CHANNELS}-channel reference input, "
                                  f"'{self.reference_name}' has {ref_c}", self.path)
        self.dynamic_batch = not isinstance(shape[0], int)
        if not self.dynamic_batch and shape[0] != 1:
            raise ConfigError(f"input '{self.input_name}' has a fixed batch of {shape[0]}; expected 1 or dynamic", self.path)
        fixed = (shape[h_dim], shape[w_dim]) if isinstance(shape[h_dim], int) and isinstance(shape[w_dim], int) else None
        self.fixed_size = fixed
        tile = None
        if "tile_size" in conv:
            tile = _parse_hw(conv["tile_size"], self.path)
            if fixed is not None and tuple(tile) != tuple(fixed):
                raise ConfigError(f"tile_size {tile} disagrees with the model's fixed input size {fixed}", self.path)
        if fixed is not None:
            tile = fixed
        if tile_size is not None:
            if fixed is not None and (tile_size, tile_size) != tuple(fixed):
                raise ConfigError(f"the model's input size is fixed at {fixed}; a tile size of {tile_size} cannot be used", self.path)
            tile = (tile_size, tile_size)
        self.tile = tile
        try:
            self.multiple = int(conv.get("multiple", 1))
            ov = overlap if overlap is not None else int(conv.get("overlap", (min(tile) // 4) if tile else 0))
            if overlap is None and tile_size is not None:  # the caller's smaller tiles: keep the model's overlap if it fits
                ov = min(ov, tile_size // 2)
        except ValueError:
            raise ConfigError("multiple and overlap must be integers", self.path) from None
        if self.multiple < 1:
            raise ConfigError(f"multiple must be >= 1, got {self.multiple}", self.path)
        if tile is not None and fixed is None:
            tile = tuple(max(self.multiple, t - t % self.multiple) for t in tile)
            self.tile = tile
        if tile is not None and not 0 <= ov < min(tile):
            raise ConfigError(f"overlap {ov} must be >= 0 and smaller than the tile {tile}", self.path)
        self.overlap = ov
        h = hashlib.sha256(self.path.read_bytes())
        h.update(json.dumps({"conv": conv, "tile": self.tile, "overlap": self.overlap}, sort_keys=True).encode())
        self._key = f"onnx-{h.hexdigest()[:16]}"

    # ------------------------------------------------------------------ public
    def cache_key(self) -> str:
        """Changes when the model file, its convention or the tiling change."""
        return self._key

    def enhance(self, rgb: Tensor, reference: Optional[Tensor] = None) -> Tensor:
        """``rgb`` ``[H, W, 3]`` in 0..1 (and an optional reference view) -> enhanced ``[H, W, 3]``."""
        if rgb.ndim != 3 or rgb.shape[-1] != 3:
            raise ValueError(f"expected an [H, W, 3] image, got {tuple(rgb.shape)}")
        device = rgb.device
        img = rgb.detach().float().cpu().permute(2, 0, 1)[None].clamp(0, 1)
        ref = None
        if self.reference_kind == "warped":
            ref = self._warped(img, reference)
        elif self.reference_name is not None:
            ref = img if reference is None else reference.detach().float().cpu().permute(2, 0, 1)[None].clamp(0, 1)
            if ref.shape[-2:] != img.shape[-2:]:
                ref = F.interpolate(ref, size=img.shape[-2:], mode="bilinear", align_corners=False)
        out = self._tiled(img, ref)
        return out[0].permute(1, 2, 0).clamp(0, 1).to(device)

    # ------------------------------------------------------------------ internals
    def _warped(self, img: Tensor, reference: Optional[Tensor]) -> Tensor:
        """The ``warped`` reference ``[1, 4, H, W]``: the caller's, or all zero (no valid pixel) without one."""
        if reference is None:
            return img.new_zeros(1, WARPED_CHANNELS, *img.shape[-2:])
        if reference.ndim != 3 or tuple(reference.shape) != (*img.shape[-2:], WARPED_CHANNELS):
            raise ConfigError(f"this model takes a warped reference view [H, W, {WARPED_CHANNELS}] (RGB and validity, "
                              f"at the image's size {tuple(img.shape[-2:])}), got {tuple(reference.shape)}", self.path)
        return reference.detach().float().cpu().permute(2, 0, 1)[None].clamp(0, 1)

    def _pad(self, x: Tensor, th: int, tw: int) -> Tensor:
        ph, pw = th - x.shape[-2], tw - x.shape[-1]
        if ph <= 0 and pw <= 0:
            return x
        mode = "reflect" if ph < x.shape[-2] and pw < x.shape[-1] else "replicate"
        return F.pad(x, (0, max(pw, 0), 0, max(ph, 0)), mode=mode)

    def _run(self, img: Tensor, ref: Optional[Tensor]) -> Tensor:
        """One batch of same-size pieces ``[B, 3, h, w]`` through the model."""
        def prep(t: Tensor) -> np.ndarray:
            t = t * 2 - 1 if self.symmetric else t
            t = t if self.layout == "NCHW" else t.permute(0, 2, 3, 1)
            return np.ascontiguousarray(t.numpy().astype(np.float32))

        feeds = {self.input_name: prep(img)}
        if self.reference_name is not None:
            feeds[self.reference_name] = prep(ref)
        outs = []
        chunk = 4 if self.dynamic_batch else 1
        for s in range(0, img.shape[0], chunk):
            try:
                (y,) = self.session.run([self.output_name], {k: v[s : s + chunk] for k, v in feeds.items()})
            except Exception as e:
                msg = str(e).strip().splitlines()[0][:160] if str(e).strip() else type(e).__name__
                raise ConfigError(f"model failed on a {tuple(img.shape)} NCHW input ({msg})", self.path) from None
            outs.append(torch.from_numpy(np.asarray(y, dtype=np.float32)))
        y = torch.cat(outs)
        if y.ndim != 4:
            raise ConfigError(f"output '{self.output_name}' has shape {tuple(y.shape)}; expected a 4-D image", self.path)
        if self.layout == "NHWC":
            y = y.permute(0, 3, 1, 2)
        if tuple(y.shape) != tuple(img.shape):
            raise ConfigError(f"output shape {tuple(y.shape)} does not match input {tuple(img.shape)} (as NCHW)", self.path)
        check_range(y, -1.0 if self.symmetric else 0.0, 1.0, self.path, f"enhancer output '{self.output_name}'")
        return (y + 1) / 2 if self.symmetric else y

    def _tiled(self, img: Tensor, ref: Optional[Tensor]) -> Tensor:
        H, W = img.shape[-2:]
        m = self.multiple
        if self.tile is None or (H <= self.tile[0] and W <= self.tile[1] and self.fixed_size is None):
            th, tw = -(-H // m) * m, -(-W // m) * m
            out = self._run(self._pad(img, th, tw), self._pad(ref, th, tw) if ref is not None else None)
            return out[..., :H, :W]
        th, tw = self.tile
        pad_h, pad_w = max(H, th), max(W, tw)
        img_p = self._pad(img, pad_h, pad_w)
        ref_p = self._pad(ref, pad_h, pad_w) if ref is not None else None
        ys, xs = _starts(pad_h, th, max(th - self.overlap, 1)), _starts(pad_w, tw, max(tw - self.overlap, 1))
        acc = torch.zeros(1, 3, pad_h, pad_w, dtype=torch.float64)
        wsum = torch.zeros(1, 1, pad_h, pad_w, dtype=torch.float64)
        boxes = [(y, x) for y in ys for x in xs]
        pieces = torch.cat([img_p[..., y : y + th, x : x + tw] for y, x in boxes])
        ref_pieces = torch.cat([ref_p[..., y : y + th, x : x + tw] for y, x in boxes]) if ref_p is not None else None
        outs = self._run(pieces, ref_pieces)
        for k, (y, x) in enumerate(boxes):
            wy = _ramp(th, y > 0, y + th < pad_h, self.overlap)
            wx = _ramp(tw, x > 0, x + tw < pad_w, self.overlap)
            w = (wy[:, None] * wx[None, :]).clamp_min(1e-12)
            acc[..., y : y + th, x : x + tw] += outs[k : k + 1].double() * w
            wsum[..., y : y + th, x : x + tw] += w
        return (acc / wsum).float()[..., :H, :W]
