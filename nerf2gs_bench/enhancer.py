"""The built-in enhancer for ``ns2gs-bench``: trained once per dataset and scale, then reused.

With ``reference`` (the bench's StreetNeRF run) it trains on that run's real renders (training
poses and perturbed poses, see :mod:`nerf2gs_plugin.enhancer.pairs`), the setting that improves real
bird's-eye renders; without, on synthetic degradations of the training images only, which made real
bird's-eye renders slightly worse (the held-out selection then keeps it close
to the identity at best). The reference's checkpoint hash is part of the cache key.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Optional

from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig, report_path, train_enhancer
from nerf2gs_plugin.errors import ConfigError

# Training settings per bench scale: quick is a few minutes on 2 CPU cores, default the trainer's own.
SCALES: dict[str, dict] = {
    "quick": {"steps": 800, "batch_size": 8, "crop": 64},
    "default": {},
}


def bench_enhancer_config(data: Path, out: Path, scale: str) -> EnhancerTrainConfig:
    if scale not in SCALES:
        raise ConfigError(f"unknown bench scale '{scale}' (expected {', '.join(SCALES)})")
    return dataclasses.replace(EnhancerTrainConfig(data=Path(data), out=Path(out), progress=True), **SCALES[scale])


def ensure_bench_enhancer(data: Path, runs_root: Path, scale: str, reference: Optional[Path] = None, init: Optional[Path] = None) -> Path:
    """Path of the bench's ``enhancer.onnx`` for this dataset, scale (and reference run, and prior
    ``init`` it is fine-tuned from), training it when absent."""
    from nerf2gs_plugin.data import folder_fingerprint
    from nerf2gs_plugin.engine.checkpoints import file_hash, resolve_checkpoint

    fingerprint = folder_fingerprint(data)
    probe = bench_enhancer_config(data, Path("enhancer.onnx"), scale)
    ref_hash = None
    if reference is not None:
        probe = dataclasses.replace(probe, reference=(Path(reference),))
        ref_hash = file_hash(resolve_checkpoint(Path(reference))[1])
    if init is not None:
        if not Path(init).is_file():
            raise ConfigError(f"enhancer prior {init} does not exist (make it with `ns2gs-enhance pretrain`)")
        probe = dataclasses.replace(probe, init=Path(init))
    settings = {k: v for k, v in dataclasses.asdict(probe).items() if k not in ("data", "out", "progress", "reference", "init")}
    if init is not None:  # the prior by content, not by path
        settings["init"] = file_hash(Path(init))
    from nerf2gs_bench.code_version import model_code_hash  # the enhancer's training code counts too

    doc = {"data": fingerprint, "cfg": settings, "reference": ref_hash, "code": model_code_hash()}
    key = hashlib.sha1(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:12]
    out = Path(runs_root) / "enhancer" / f"{scale}-{key}" / "enhancer.onnx"
    if out.is_file() and report_path(out).is_file():
        print(f"[bench] reuse enhancer: {out}")
        return out
    print(f"[bench] train enhancer ({probe.steps} steps) -> {out}")
    report = train_enhancer(dataclasses.replace(probe, out=out))
    for line in report.summary_lines():
        print(f"[bench] {line}")
    return out


def bench_prior(prior: Path, runs_root: Path) -> Path:
    """The prior ONNX (``ns2gs-enhance pretrain``'s ``out``) copied under ``runs_root/enhancer/prior-<content hash>/``,
    so the bench runs that use it are keyed by its content, not by a path that may be overwritten."""
    import shutil

    from nerf2gs_plugin.engine.checkpoints import file_hash

    prior = Path(prior)
    if not prior.is_file():
        raise ConfigError(f"enhancer prior {prior} does not exist (make it with `ns2gs-enhance pretrain --out {prior}`)")
    out = Path(runs_root) / "enhancer" / f"prior-{file_hash(prior)[:12]}" / "prior.onnx"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        for src, dst in ((prior.with_suffix(".pt"), out.with_suffix(".pt")), (report_path(prior), report_path(out)), (prior, out)):
            if src.is_file():  # the ONNX last: its presence says the copy is whole
                shutil.copyfile(src, dst)
    return out
