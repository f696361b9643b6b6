"""The I/O convention of a user's ONNX model (an enhancer, a segmenter): string keys from the
model's metadata, overridden by a ``<model>.onnx.json`` sidecar next to it. One reader for both."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable

from nerf2gs_plugin.errors import ConfigError


def read_convention(path: Path, session, keys: Iterable[str]) -> dict[str, str]:
    """``keys`` of the model at ``path`` (an onnxruntime session of it) as strings; list values of the
    sidecar become JSON text. An unreadable sidecar or an unknown key is a ConfigError naming it."""
    keys = tuple(keys)
    meta = dict(session.get_modelmeta().custom_metadata_map or {})
    conv = {k: str(v) for k, v in meta.items() if k in keys}
    sidecar = Path(path).with_name(Path(path).name + ".json")
    if sidecar.is_file():
        try:
            extra = json.loads(sidecar.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ConfigError(f"sidecar JSON is not readable ({e})", sidecar) from None
        if not isinstance(extra, dict):
            raise ConfigError("sidecar JSON must be an object of convention keys", sidecar)
        unknown = sorted(set(extra) - set(keys))
        if unknown:
            raise ConfigError(f"unknown convention keys {unknown} (known: {', '.join(keys)})", sidecar)
        conv.update({k: (json.dumps(v) if isinstance(v, list) else str(v)) for k, v in extra.items()})
    return conv
