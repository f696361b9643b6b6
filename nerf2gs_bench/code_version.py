"""Which code produced a trained model or an evaluation: hashes that key bench runs and caches.

The rule (stated once, used by :mod:`nerf2gs_bench.runs` and
:mod:`nerf2gs_bench.runner`): a trained model depends on every ``.py``/``.cpp``/``.h``/``.cu``
file of ``nerf2gs_plugin`` except those under ``eval/``, ``cli/`` and ``viewer/``, which read models but
never change one, and the dataset makers ``masking/``, ``data/process/`` and ``blocks/`` (city-block partition and merge), which write the files a run reads or merge finished
runs (those files key the run through the dataset fingerprint instead). ``masks/`` (the mask maths) keys models: the
augmentation reads the reference's sky with it. No model code imports the
excluded folders (``tests/bench/test_bench_keys.py`` checks it on the import graph); the image metrics
the enhancer trains and selects by sit under ``utils/`` and key models with the rest. That is coarser
than the files a method imports (an edit to another method retrains every bench run), but it can never
miss a dependency. An evaluation depends on the model plus the metric code: ``eval/metrics.py``,
``eval/evaluate.py``, ``utils/image_metrics.py`` and ``utils/lpips.py``.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

import nerf2gs_plugin

SOURCE_ROOT = Path(nerf2gs_plugin.__file__).resolve().parent
"""The package source that is hashed (tests point it at a modified copy)."""
SOURCE_SUFFIXES = (".py", ".cpp", ".h", ".cu")
NOT_MODEL_CODE = ("eval", "cli", "viewer", "masking", "data/process", "blocks")
"""Folders (relative to the package) whose files never key a trained model."""
METRIC_CODE = ("eval/metrics.py", "eval/evaluate.py", "utils/image_metrics.py", "utils/lpips.py")


def model_source_files(root: Path | None = None) -> list[Path]:
    """The files whose content keys a trained model (see the module docstring), sorted."""
    root = Path(root or SOURCE_ROOT)
    def excluded(rel: Path) -> bool:
        return any(rel.parts[:len(Path(f).parts)] == Path(f).parts for f in NOT_MODEL_CODE)

    return sorted(p for p in root.rglob("*") if p.suffix in SOURCE_SUFFIXES and p.is_file()
                  and not excluded(p.relative_to(root)) and "__pycache__" not in p.parts)


@lru_cache(maxsize=8)
def _hash_files(root: str, rel: tuple[str, ...], stamp: tuple[int, ...]) -> str:
    h = hashlib.sha1()
    for name in rel:
        h.update(name.encode() + b"\0")
        h.update((Path(root) / name).read_bytes())
    return h.hexdigest()[:12]


def _hash(root: Path, files: list[Path]) -> str:
    rel = tuple(str(p.relative_to(root)) for p in files)
    stamp = tuple(p.stat().st_mtime_ns for p in files)  # the cache is refreshed when a file is saved
    return _hash_files(str(root), rel, stamp)


def model_code_hash(root: Path | None = None) -> str:
    """Hash of the source that produced a model (12 hex digits)."""
    root = Path(root or SOURCE_ROOT)
    return _hash(root, model_source_files(root))


def eval_code_hash(root: Path | None = None) -> str:
    """Hash of the metric code an evaluation ran (12 hex digits)."""
    root = Path(root or SOURCE_ROOT)
    return _hash(root, [root / name for name in METRIC_CODE])


def device_label(device) -> str:
    """The device a model was trained or timed on, as it enters a key: ``cpu`` or ``cuda:<GPU name>``."""
    import torch

    device = torch.device(device)
    if device.type == "cuda" and torch.cuda.is_available():
        return f"cuda:{torch.cuda.get_device_name(device)}"
    return device.type


def source_hash(parts: tuple[str, ...], root: Path | None = None) -> str:
    """Hash of the package's source under ``parts`` (folders or files relative to the package): what
    keys a stage that is no trained model (``data/process`` for the SfM, ``masks`` for the masks)."""
    root = Path(root or SOURCE_ROOT)
    files = set()
    for part in parts:
        p = root / part
        found = [p] if p.is_file() else p.rglob("*")
        files |= {f for f in found if f.suffix in SOURCE_SUFFIXES and f.is_file() and "__pycache__" not in f.parts}
    return _hash(root, sorted(files))
