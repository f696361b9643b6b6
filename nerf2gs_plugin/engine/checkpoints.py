"""Checkpoints: atomic save with a checksum, latest-step lookup, and loading with clear errors."""

from __future__ import annotations

import hashlib
import io
import re
from pathlib import Path
from typing import Any, Optional

import torch

from nerf2gs_plugin.data.fingerprint import dataset_fingerprint, file_hash  # noqa: F401 (re-exported)
from nerf2gs_plugin.utils.io import atomic_write_bytes
from nerf2gs_plugin.errors import CheckpointError

CHECKPOINT_FORMAT_VERSION = 1
CHECKSUM_MAGIC = b"NS2GS-SHA256"  # then 32 bytes of digest, at the very end of the file
_STEP_RE = re.compile(r"^step-(\d{9})\.ckpt$")


def checkpoint_path(run_dir: Path, step: int) -> Path:
    return Path(run_dir) / "checkpoints" / f"step-{step:09d}.ckpt"


def list_checkpoints(run_dir: Path) -> list[Path]:
    ckpt_dir = Path(run_dir) / "checkpoints"
    if not ckpt_dir.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in ckpt_dir.iterdir() if (m := _STEP_RE.match(p.name))]
    return [p for _, p in sorted(found)]


def run_dir_of(path: Path) -> Path:
    """The run folder of a run directory or of a ``.ckpt`` file in it (``RUN/checkpoints/step-N.ckpt`` or ``RUN/x.ckpt``)."""
    path = Path(path)
    if path.suffix != ".ckpt":
        return path
    return path.parent.parent if path.parent.name == "checkpoints" else path.parent


def resolve_checkpoint(path: Path) -> tuple[Path, Path]:
    """A run directory (latest checkpoint) or a ``.ckpt`` file -> (run_dir, checkpoint file)."""
    path = Path(path)
    if path.is_file():
        if path.suffix != ".ckpt":
            raise CheckpointError("not a checkpoint (expected a run directory or a .ckpt file)", path)
        return run_dir_of(path), path
    if not path.exists():
        raise CheckpointError("no such run directory or checkpoint", path)
    ckpts = list_checkpoints(path)
    if not ckpts:
        raise CheckpointError("run directory holds no checkpoints/step-*.ckpt", path)
    return path, ckpts[-1]


def save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    """torch.save's bytes, then ``CHECKSUM_MAGIC`` and their SHA-256 (torch.load ignores bytes
    after the archive, so the file still loads with torch.load alone)."""
    buf = io.BytesIO()
    torch.save({"format_version": CHECKPOINT_FORMAT_VERSION, **payload}, buf)
    data = buf.getvalue()
    atomic_write_bytes(path, data + CHECKSUM_MAGIC + hashlib.sha256(data).digest())


def verify_checksum(path: Path) -> Optional[bool]:
    """True: the stored SHA-256 matches; False: it does not (the file changed after it was
    written); None: the file carries no checksum (written before checkpoints had one)."""
    size = path.stat().st_size
    trailer = len(CHECKSUM_MAGIC) + 32
    if size < trailer:
        return None
    with open(path, "rb") as f:
        f.seek(size - trailer)
        tail = f.read(trailer)
        if not tail.startswith(CHECKSUM_MAGIC):
            return None
        f.seek(0)
        h, left = hashlib.sha256(), size - trailer
        while left > 0:
            chunk = f.read(min(left, 1 << 22))
            if not chunk:
                return False
            h.update(chunk)
            left -= len(chunk)
    return h.digest() == tail[len(CHECKSUM_MAGIC):]


def load_checkpoint(path: Path, expected_method: Optional[str] = None, map_location: Any = "cpu") -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise CheckpointError("checkpoint file not found", path)
    if verify_checksum(path) is False:
        raise CheckpointError("corrupt checkpoint: its checksum does not match its contents (changed on disk after it was "
                              "written); resume from an earlier checkpoint", path)
    try:
        # weights_only: a checkpoint is tensors and plain values, never code
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as e:  # noqa: BLE001 - any failure to read is a corrupt file to the user
        reason = str(e).strip().splitlines()[0][:120] if str(e).strip() else type(e).__name__
        raise CheckpointError(f"corrupt or unreadable checkpoint ({reason})", path) from None
    if not isinstance(ckpt, dict) or "method_name" not in ckpt or "model" not in ckpt:
        raise CheckpointError("not an nerf2gs checkpoint (missing method_name/model)", path)
    if ckpt.get("format_version") != CHECKPOINT_FORMAT_VERSION:
        raise CheckpointError(f"checkpoint format {ckpt.get('format_version')!r}, expected {CHECKPOINT_FORMAT_VERSION}", path)
    if expected_method is not None and ckpt["method_name"] != expected_method:
        raise CheckpointError(f"checkpoint is of method '{ckpt['method_name']}', not '{expected_method}'", path)
    if not isinstance(ckpt.get("step"), int) or ckpt["step"] < 0:
        raise CheckpointError(f"checkpoint has no valid step (got {ckpt.get('step')!r})", path)
    from nerf2gs_plugin.engine.divergence import describe, nonfinite_counts

    bad = nonfinite_counts(ckpt["model"])
    if bad:
        raise CheckpointError(f"checkpoint holds non-finite parameters: {describe(bad)}", path)
    # the optimizer and training state too: a NaN there diverges on the first step after resuming
    bad = nonfinite_counts({k: ckpt[k] for k in ("optimizers", "training_state") if k in ckpt})
    if bad:
        raise CheckpointError(f"checkpoint holds non-finite optimizer or training state: {describe(bad)}", path)
    return ckpt
