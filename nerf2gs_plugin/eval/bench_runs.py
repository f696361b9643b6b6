"""Training runs for benchmarks, reused when nothing that matters changed.

A run is keyed by (dataset fingerprint, method, resolved config, reference run): regenerating a
table after a change retrains only what changed, and an interrupted bench resumes from the
run's last checkpoint.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
from nerf2gs_plugin.utils.config import apply_plain, to_plain
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.engine.trainer import Trainer


@dataclass
class RunSpec:
    """One training run of a bench: method + overrides (+ reference for --augment-from)."""

    label: str
    method: str
    overrides: dict[str, Any] = field(default_factory=dict)
    augment_from: Optional[str] = None  # label of another RunSpec in the same bench
    augment: dict[str, Any] = field(default_factory=dict)


def run_key(dataset: str, spec: RunSpec, reference_key: Optional[str]) -> str:
    """Keyed by the fully resolved config, not only the overrides: a changed method default retrains."""
    from nerf2gs_plugin.registry import get_method

    resolved = to_plain(apply_plain(get_method(spec.method).config, spec.overrides, where=f"bench run {spec.label}"))
    doc = {"data": dataset, "method": spec.method, "config": resolved, "ref": reference_key, "augment": spec.augment}
    return hashlib.sha1(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:12]


def train_or_reuse(spec: RunSpec, data: Path, runs_root: Path, dataset: str, reference: Optional[tuple[Path, str]] = None,
                   progress: bool = True, log=print, step_hook=None) -> tuple[Path, str]:
    """Returns (run_dir, key). A finished run with the same key is reused; a partial one resumes.
    ``step_hook(step)`` is called after every training step (a bench-wide progress bar)."""
    from nerf2gs_plugin.registry import get_method

    key = run_key(dataset, spec, reference[1] if reference else None)
    base = get_method(spec.method).config
    cfg = apply_plain(base, spec.overrides, where=f"bench run {spec.label}")
    cfg = dataclasses.replace(cfg, data=Path(data), output_dir=Path(runs_root), timestamp=key, progress=progress)
    run_dir = cfg.run_dir()
    if reference is not None:
        cfg = dataclasses.replace(cfg, augment_from=reference[0], augment=apply_plain(cfg.augment, spec.augment, where=f"bench run {spec.label}.augment"))
    ckpts = list_checkpoints(run_dir)
    if ckpts:
        step = int(load_checkpoint(ckpts[-1])["step"])
        if step >= cfg.max_num_iterations - 1:
            log(f"[bench] reuse {spec.label}: {run_dir}")
            return run_dir, key
        cfg = dataclasses.replace(cfg, load_checkpoint=ckpts[-1])
        log(f"[bench] resume {spec.label} from step {step}")
    else:
        log(f"[bench] train {spec.label} ({spec.method}, {cfg.max_num_iterations} steps)")
    trainer = Trainer(cfg)
    trainer.setup()
    if step_hook is not None:
        trainer.step_hooks.append(step_hook)
    trainer.train()
    atomic_write_text(run_dir / "bench_run.json", json.dumps({"label": spec.label, **dataclasses.asdict(spec), "key": key}, indent=1, default=str))
    return run_dir, key
