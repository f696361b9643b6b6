"""The built-in enhancer for ``ns2gs-bench``: trained once per dataset and scale, then reused.

It is trained on synthetic degradations of the training images only (no reference renders): the
bench asks for it before any StreetNeRF exists, and this keeps it independent of run order.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from nerf2gs_plugin.enhance.train import EnhancerTrainConfig, report_path, train_enhancer
from nerf2gs_plugin.errors import ConfigError

# Training settings per bench scale: quick is about a minute on 2 CPU cores, default a few.
SCALES: dict[str, dict] = {
    "quick": {"steps": 800, "batch_size": 8, "crop": 64},
    "default": {"steps": 3000, "batch_size": 8, "crop": 64},
}


def bench_enhancer_config(data: Path, out: Path, scale: str) -> EnhancerTrainConfig:
    if scale not in SCALES:
        raise ConfigError(f"unknown bench scale '{scale}' (expected {', '.join(SCALES)})")
    return dataclasses.replace(EnhancerTrainConfig(data=Path(data), out=Path(out), progress=True), **SCALES[scale])


def ensure_bench_enhancer(data: Path, runs_root: Path, scale: str) -> Path:
    """Path of the bench's ``enhancer.onnx`` for this dataset and scale, training it when absent."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.data.fingerprint import dataset_fingerprint

    fingerprint = dataset_fingerprint(parse_dataset(data, "train").image_filenames)
    probe = bench_enhancer_config(data, Path("enhancer.onnx"), scale)
    settings = {k: v for k, v in dataclasses.asdict(probe).items() if k not in ("data", "out", "progress")}
    key = hashlib.sha1(json.dumps({"data": fingerprint, "cfg": settings}, sort_keys=True, default=str).encode()).hexdigest()[:12]
    out = Path(runs_root) / "enhancer" / f"{scale}-{key}" / "enhancer.onnx"
    if out.is_file() and report_path(out).is_file():
        print(f"[bench] reuse enhancer: {out}")
        return out
    print(f"[bench] train enhancer ({probe.steps} steps) -> {out}")
    report = train_enhancer(dataclasses.replace(probe, out=out))
    if report.heldout:
        print(f"[bench] enhancer held-out PSNR {report.heldout['psnr_degraded']:.2f} -> {report.heldout['psnr_enhanced']:.2f} dB"
              f" ({report.seconds:.0f} s)")
    return out
