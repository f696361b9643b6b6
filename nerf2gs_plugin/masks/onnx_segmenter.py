"""``--segmenter onnx:PATH``: any ONNX semantic-segmentation model, run with onnxruntime.

How the model wants its pixels is read from its ``metadata_props`` and, overriding those, from a
sidecar JSON next to it (``model.onnx.json``), the same scheme as the enhancer
(``enhancer/onnx_runtime.py``). Every key is optional:

=================  =========================================================================
key                meaning (default)
=================  =========================================================================
``layout``         ``NCHW`` or ``NHWC`` of the image input (``NCHW``)
``range``          ``0,1``, ``0,255`` or ``-1,1``: the pixel range before normalisation (``0,1``)
``mean``, ``std``  per-channel normalisation ``(x - mean) / std`` in that range, ``"r,g,b"``
                   (none)
``input``          name of the image input (the model's first input)
``output``         name of the output (the model's first output)
``output_layout``  ``NCHW`` (logits ``[1, C, h, w]``) or ``NHWC`` (``[1, h, w, C]``); an integer
                   output ``[1, h, w]`` / ``[1, 1, h, w]`` is taken as class ids (``NCHW``)
``size``           ``HxW`` (or ``S``): the image is resized to this before the model (a model
                   with fixed H, W is always fed its own size); logits are resized back
``tile_size``      ``S`` or ``HxW``: run in overlapping tiles of this size instead (dynamic H, W)
``overlap``        tile overlap in pixels (tile // 4); overlapping logits are averaged
``multiple``       the fed H, W are padded (replicate) to a multiple of this (1)
``classes``        the dataset name ``cityscapes`` / ``ade20k``, or the class names in output
                   order as a JSON list or comma-separated; picks the default class map
=================  =========================================================================

Logits are resized (bilinear) to the image size and arg-maxed; class ids map to sky / ground /
transient through ``class_maps.py``. A bad file or convention is a ``ConfigError`` naming it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional, Union

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.masks import class_maps
from nerf2gs_plugin.errors import ConfigError, ModelOutputError
from nerf2gs_plugin.utils.model_output import check_finite, check_shape
from nerf2gs_plugin.utils.onnx_model import open_session, read_convention

KEYS = ("layout", "range", "mean", "std", "input", "output", "output_layout", "size", "tile_size", "overlap", "multiple", "classes")
# an id output with no 'classes' declared: ADE20K (150) is the largest shipped map
MAX_UNDECLARED_CLASSES = 256
_SCALE = {"0,1": (1.0, 0.0), "0,255": (255.0, 0.0), "-1,1": (2.0, -1.0)}


def _hw(value: str, key: str, path: Path) -> tuple[int, int]:
    try:
        parts = [int(p) for p in value.lower().replace(",", "x").split("x")]
    except ValueError:
        raise ConfigError(f"{key} must be S or HxW, got {value!r}", path) from None
    parts = parts * 2 if len(parts) == 1 else parts
    if len(parts) != 2 or min(parts) <= 0:
        raise ConfigError(f"{key} must be S or HxW with positive sizes, got {value!r}", path)
    return parts[0], parts[1]


def _triple(value: Optional[str], key: str, path: Path) -> Optional[Tensor]:
    if value is None:
        return None
    try:
        vals = json.loads(value) if value.strip().startswith("[") else [float(v) for v in value.split(",")]
        t = torch.tensor([float(v) for v in vals], dtype=torch.float32)
    except (ValueError, TypeError, json.JSONDecodeError):
        raise ConfigError(f"{key} must be three numbers 'r,g,b', got {value!r}", path) from None
    if t.shape != (3,) or (key == "std" and bool((t <= 0).any())):
        raise ConfigError(f"{key} must be three numbers 'r,g,b'" + (" > 0" if key == "std" else "") + f", got {value!r}", path)
    return t


class OnnxSegmenter:
    """An ONNX segmentation model + a class map -> sky / ground / transient masks."""

    def __init__(self, path: Union[str, Path], class_map: Optional[Union[str, Path]] = None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ConfigError("segmenter model file does not exist", self.path)
        self.session = open_session(self.path)
        conv = read_convention(self.path, self.session, KEYS)
        p = self.path
        self.layout = conv.get("layout", "NCHW").upper()
        self.out_layout = conv.get("output_layout", "NCHW").upper()
        for key, v in (("layout", self.layout), ("output_layout", self.out_layout)):
            if v not in ("NCHW", "NHWC"):
                raise ConfigError(f"{key} must be NCHW or NHWC, got {v!r}", p)
        rng = conv.get("range", "0,1").replace(" ", "")
        if rng not in _SCALE:
            raise ConfigError(f"range must be one of {', '.join(_SCALE)}, got {rng!r}", p)
        self.scale, self.offset = _SCALE[rng]
        self.mean, self.std = _triple(conv.get("mean"), "mean", p), _triple(conv.get("std"), "std", p)
        inputs = {i.name: i for i in self.session.get_inputs()}
        outputs = {o.name: o for o in self.session.get_outputs()}
        self.input_name = conv.get("input", self.session.get_inputs()[0].name)
        self.output_name = conv.get("output", self.session.get_outputs()[0].name)
        if self.input_name not in inputs:
            raise ConfigError(f"input '{self.input_name}' is not an input of the model (inputs: {', '.join(inputs)})", p)
        if self.output_name not in outputs:
            raise ConfigError(f"output '{self.output_name}' is not an output of the model (outputs: {', '.join(outputs)})", p)
        if len(inputs) != 1:
            raise ConfigError(f"model has {len(inputs)} inputs; a segmenter takes one image", p)
        shape = inputs[self.input_name].shape
        if len(shape) != 4:
            raise ConfigError(f"input '{self.input_name}' has shape {shape}; expected a 4-D {self.layout} image", p)
        c_dim, h_dim, w_dim = (1, 2, 3) if self.layout == "NCHW" else (3, 1, 2)
        if isinstance(shape[c_dim], int) and shape[c_dim] != 3:
            raise ConfigError(f"input '{self.input_name}' has shape {shape}; expected 3 channels in {self.layout}", p)
        self.input_dtype = np.float16 if "float16" in inputs[self.input_name].type else np.float32
        fixed = (shape[h_dim], shape[w_dim]) if isinstance(shape[h_dim], int) and isinstance(shape[w_dim], int) else None
        self.size = fixed or (_hw(conv["size"], "size", p) if "size" in conv else None)
        self.tile = None if self.size else (_hw(conv["tile_size"], "tile_size", p) if "tile_size" in conv else None)
        try:
            self.multiple = int(conv.get("multiple", 1))
            self.overlap = int(conv.get("overlap", min(self.tile) // 4 if self.tile else 0))
        except ValueError:
            raise ConfigError("multiple and overlap must be integers", p) from None
        if self.multiple < 1 or (self.tile and not 0 <= self.overlap < min(self.tile)):
            raise ConfigError(f"multiple must be >= 1 and overlap in [0, tile) (got {self.multiple}, {self.overlap})", p)
        self.model_classes, self.dataset = self._classes(conv.get("classes"))
        self._class_map_spec = class_map
        self._ids: Optional[dict[str, list[int]]] = None

    def _classes(self, value: Optional[str]) -> tuple[Optional[list[str]], Optional[str]]:
        if value is None:
            return None, None
        if value.lower() in class_maps.SHIPPED:
            return list(class_maps.SHIPPED[value.lower()][0]), value.lower()
        try:
            names = json.loads(value) if value.strip().startswith("[") else [c.strip() for c in value.split(",")]
        except json.JSONDecodeError:
            raise ConfigError(f"classes must be a dataset name or a list of names, got {value[:60]!r}", self.path) from None
        return [str(n) for n in names], None

    def class_ids(self, num_classes: int) -> dict[str, list[int]]:
        """The class map for a model with ``num_classes`` outputs (resolved once)."""
        if self._ids is None:
            spec = self._class_map_spec
            if spec is None:
                spec = self.dataset or class_maps.shipped_for(num_classes)
                if spec is None and self.model_classes is None:
                    raise ConfigError(f"the model outputs {num_classes} classes, which is neither Cityscapes (19) nor ADE20K (150): "
                                      "pass --class-map FILE.json", self.path)
                if spec is None:
                    spec = {"classes": self.model_classes, **{k: [c for c in v if c in self.model_classes]
                                                              for k, v in class_maps.SHIPPED["cityscapes"][1].items()}}
            self._ids = class_maps.resolve(spec, num_classes, self.path, self.model_classes)
        return self._ids

    # ------------------------------------------------------------------ running
    def _prep(self, img: Tensor) -> np.ndarray:
        x = img.permute(2, 0, 1)[None] * self.scale + self.offset
        if self.mean is not None:
            x = x - self.mean.view(1, 3, 1, 1)
        if self.std is not None:
            x = x / self.std.view(1, 3, 1, 1)
        if self.layout == "NHWC":
            x = x.permute(0, 2, 3, 1)
        return np.ascontiguousarray(x.numpy().astype(self.input_dtype))

    def _run(self, img: Tensor) -> Tensor:
        """``[h, w, 3]`` (already at the fed size) -> ``[C, h, w]`` logits (or one-hot of ids)."""
        h, w = img.shape[:2]
        ph, pw = (-h) % self.multiple, (-w) % self.multiple
        if ph or pw:
            img = F.pad(img.permute(2, 0, 1)[None], (0, pw, 0, ph), mode="replicate")[0].permute(1, 2, 0)
        try:
            out = self.session.run([self.output_name], {self.input_name: self._prep(img)})[0]
        except Exception as e:
            msg = str(e).strip().splitlines()[0][:160] if str(e).strip() else type(e).__name__
            raise ConfigError(f"model failed on a {img.shape[1]}x{img.shape[0]} image ({msg})", self.path) from None
        o = torch.from_numpy(np.asarray(out))
        if not o.is_floating_point():  # class ids
            o = self._one_hot(o)
        else:
            if o.dim() != 4 or o.shape[0] != 1:
                raise ConfigError(f"output '{self.output_name}' has shape {tuple(o.shape)}; expected [1, C, h, w] logits ({self.out_layout})", self.path)
            check_finite(o, self.path, f"segmenter output '{self.output_name}'")
            o = (o[0] if self.out_layout == "NCHW" else o[0].permute(2, 0, 1)).float()
        # logits at a lower resolution (SegFormer: 1/4) are resized to the fed size, then the padding is cut
        fed = (img.shape[0], img.shape[1])
        if tuple(o.shape[1:]) != fed:
            o = F.interpolate(o[None], size=fed, mode="bilinear", align_corners=False)[0]
        return o[:, :h, :w]

    def _one_hot(self, o: Tensor) -> Tensor:
        """Class ids ``[1, h, w]`` / ``[1, 1, h, w]`` -> one-hot ``[C, h, w]``; the layout and every id
        are checked first (an id of 1e9 would make one_hot allocate terabytes)."""
        what = f"segmenter output '{self.output_name}' (class ids)"
        check_shape(o, [(None, None), (1, None, None), (1, 1, None, None)], self.path, what)
        ids = o.reshape(o.shape[-2], o.shape[-1]).long()
        declared = len(self.model_classes) if self.model_classes is not None else None
        limit = declared if declared is not None else MAX_UNDECLARED_CLASSES
        lo, hi = (int(ids.min()), int(ids.max())) if ids.numel() else (0, 0)
        if lo < 0 or hi >= limit:
            bad = lo if lo < 0 else hi
            declared_txt = f"the model declares {declared} classes" if declared is not None else \
                f"without declared classes ids must be below {MAX_UNDECLARED_CLASSES} (set 'classes' in the sidecar)"
            raise ModelOutputError(f"{what} holds class id {bad}: {declared_txt}", self.path)
        return F.one_hot(ids, declared if declared is not None else max(hi + 1, 1)).permute(2, 0, 1).float()

    def logits(self, image: Tensor) -> Tensor:
        """``[H, W, 3]`` RGB in 0..1 -> ``[C, H, W]`` logits at the image size."""
        H, W = image.shape[:2]
        img = image.float().cpu().clamp(0, 1)
        if self.size is not None:
            fed = F.interpolate(img.permute(2, 0, 1)[None], size=self.size, mode="bilinear", align_corners=False, antialias=True)[0].permute(1, 2, 0)
            out = self._run(fed)
            return F.interpolate(out[None], size=(H, W), mode="bilinear", align_corners=False)[0]
        if self.tile is None or (H <= self.tile[0] and W <= self.tile[1]):
            return self._run(img)
        th, tw = min(self.tile[0], H), min(self.tile[1], W)
        acc: Optional[Tensor] = None
        cnt = torch.zeros(1, H, W)
        for y in _starts(H, th, max(1, th - self.overlap)):
            for x in _starts(W, tw, max(1, tw - self.overlap)):
                o = self._run(img[y : y + th, x : x + tw])
                if acc is None:
                    acc = torch.zeros(o.shape[0], H, W)
                if o.shape[0] != acc.shape[0]:  # id outputs: one-hot widths differ per tile
                    n = max(o.shape[0], acc.shape[0])
                    acc, o = F.pad(acc, (0, 0, 0, 0, 0, n - acc.shape[0])), F.pad(o, (0, 0, 0, 0, 0, n - o.shape[0]))
                acc[:, y : y + th, x : x + tw] += o
                cnt[:, y : y + th, x : x + tw] += 1
        assert acc is not None
        return acc / cnt

    def labels(self, image: Tensor) -> Tensor:
        """``[H, W]`` class ids."""
        return self.logits(image).argmax(0)

    def masks(self, image: Tensor) -> dict[str, Tensor]:
        """sky / ground / transient bool ``[H, W]`` for an ``[H, W, 3]`` image in 0..1."""
        lg = self.logits(image)
        ids = self.class_ids(self.num_classes(lg))
        lab = lg.argmax(0)
        from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS

        return {k: torch.isin(lab, torch.tensor(ids.get(k, []), dtype=torch.long)) for k in MASK_KINDS}

    def num_classes(self, logits: Tensor) -> int:
        first = self.session.get_outputs()[0]
        ids = "float" not in first.type  # a class-id output's channel axis is 1, not the number of classes
        out_shape = first.shape if self.output_name == first.name and not ids else None
        c_dim = 1 if self.out_layout == "NCHW" else 3
        if out_shape is not None and len(out_shape) == 4 and isinstance(out_shape[c_dim], int):
            return int(out_shape[c_dim])
        if self.model_classes is not None:
            return len(self.model_classes)
        return int(logits.shape[0])


def _starts(total: int, tile: int, stride: int) -> list[int]:
    if total <= tile:
        return [0]
    return sorted(set(list(range(0, total - tile, stride)) + [total - tile]))
