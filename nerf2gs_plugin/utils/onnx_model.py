"""A user's ONNX model (an enhancer, a segmenter): one way to open it with onnxruntime, and one
reader of its I/O convention (string keys from the model's metadata, overridden by a
``<model>.onnx.json`` sidecar next to it)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Optional, Sequence

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


def import_onnxruntime():
    """``onnxruntime``, imported so that it leaves no files behind: on import its telemetry writes a
    device id and an event database under the user's cache folder (``XDG_CACHE_HOME``) and a ``.ses``
    file in the system temp folder; both are pointed at a private folder for the import, which is then
    removed (nothing is written there or elsewhere after the import)."""
    import os
    import shutil
    import sys
    import tempfile

    if "onnxruntime" in sys.modules:
        return sys.modules["onnxruntime"]
    private = tempfile.mkdtemp(prefix="ns2gs-ort-")
    saved = {k: os.environ.get(k) for k in ("XDG_CACHE_HOME", "TMPDIR")}
    os.environ.update(XDG_CACHE_HOME=private, TMPDIR=private)
    try:
        import onnxruntime
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        shutil.rmtree(private, ignore_errors=True)
    return onnxruntime


def open_session(path: Path, providers: Optional[Sequence[str]] = None):
    """An onnxruntime session of ``path`` (CUDA when available, else CPU; threads as torch's, no
    busy-waiting on shared CPUs). A file onnxruntime cannot load is a ConfigError naming it."""
    import torch

    ort = import_onnxruntime()

    if providers is None:
        providers = [p for p in ("CUDAExecutionProvider", "CPUExecutionProvider") if p in ort.get_available_providers()]
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = max(1, torch.get_num_threads())
    opts.log_severity_level = 3
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=list(providers))
    except Exception as e:  # onnxruntime raises its own exception types for bad files
        msg = str(e).strip().splitlines()[0][:160] if str(e).strip() else type(e).__name__
        raise ConfigError(f"not a loadable ONNX model ({msg})", path) from None
