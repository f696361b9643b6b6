"""Tiny ONNX models whose outputs are wrong on purpose (NaN, inf, a 0..255 range, class ids of an
odd layout or far beyond any class): what the fault suite and the tests feed the segmenter and the
enhancer, so that a bad external model is refused instead of written."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np


def conv_model(path: Path, out_channels: int = 3, weight: Optional[float] = None, bias: float = 0.0,
               identity_scale: Optional[float] = None, ids: bool = False) -> Path:
    """``y = Conv1x1(x)`` on an NCHW image ``[1, 3, H, W]`` (dynamic H, W). Every weight is ``weight``
    (or ``identity_scale`` times the identity), every bias ``bias``; ``ids``: ``y`` cast to int64
    (a class-id output). NaN weights make a NaN model; ``identity_scale=255`` an enhancer whose
    output is in 0..255."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    if identity_scale is not None:
        W = np.zeros((out_channels, 3, 1, 1), dtype=np.float32)
        for c in range(min(out_channels, 3)):
            W[c, c] = identity_scale
    else:
        W = np.full((out_channels, 3, 1, 1), 0.0 if weight is None else weight, dtype=np.float32)
    b = np.full((out_channels,), bias, dtype=np.float32)
    nodes = [helper.make_node("Conv", ["image", "W", "b"], ["y" if not ids else "logits"])]
    if ids:
        nodes.append(helper.make_node("Cast", ["logits"], ["y"], to=TensorProto.INT64))
    out_type = TensorProto.INT64 if ids else TensorProto.FLOAT
    graph = helper.make_graph(nodes, "fault", [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "H", "W"])],
                              [helper.make_tensor_value_info("y", out_type, [1, out_channels, "H", "W"])],
                              [numpy_helper.from_array(W, "W"), numpy_helper.from_array(b, "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return Path(path)


# name -> (kwargs of conv_model, what it is for): the segmenter's and the enhancer's bad models
SEGMENTERS = {
    "nan_logits": dict(out_channels=19, weight=float("nan")),
    "inf_logits": dict(out_channels=19, bias=float("inf")),
    "ids_two_channels": dict(out_channels=2, bias=1.0, ids=True),
    "ids_huge": dict(out_channels=1, bias=1e9, ids=True),
    "ids_1e5": dict(out_channels=1, bias=1e5, ids=True),
    "ids_negative": dict(out_channels=1, bias=-5.0, ids=True),
}
ENHANCERS = {
    "nan": dict(weight=float("nan")),
    "inf": dict(bias=float("inf")),
    "range_255": dict(identity_scale=255.0),
    "negative": dict(identity_scale=-1.0, bias=-1.0),
}
