"""Training runs for benchmarks, reused when nothing that matters changed.

A run is keyed by (dataset fingerprint, method, resolved config, reference run, augment settings,
hash of the model code, device): regenerating a table after a change retrains only what changed,
an edit to a loss or a kernel retrains (:mod:`nerf2gs_bench.code_version` says which files
count), a GPU run never reuses a CPU one, and an interrupted bench resumes from the run's last
checkpoint. ``rerun=True`` retrains even when a finished run with the key exists.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import json
import os
import shutil
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Optional

from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
from nerf2gs_plugin.engine.run_dir import LOCK_NAME
from nerf2gs_plugin.errors import ConfigError
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


def run_key(dataset: str, spec: RunSpec, reference_key: Optional[str], device: str = "cpu") -> str:
    """Keyed by the fully resolved config, not only the overrides (a changed method default
    retrains), the model code's hash and the device label (:func:`~nerf2gs_bench.code_version.device_label`)."""
    from nerf2gs_bench.code_version import model_code_hash
    from nerf2gs_plugin.registry import get_method

    resolved = to_plain(apply_plain(get_method(spec.method).config, spec.overrides, where=f"bench run {spec.label}"))
    doc = {"data": dataset, "method": spec.method, "config": resolved, "ref": reference_key, "augment": spec.augment,
           "code": model_code_hash(), "device": device}
    return hashlib.sha1(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:12]


def wait_for_other_training(run_dir: Path, log=print) -> None:
    """Block while another process trains ``run_dir`` (holds its lock): two benches sharing a runs
    folder then reuse one training instead of the second one failing on the lock."""
    lock = Path(run_dir) / LOCK_NAME
    if not lock.is_file():
        return
    fd = os.open(lock, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            log(f"[bench] waiting for another process training {run_dir}")
            fcntl.flock(fd, fcntl.LOCK_SH)
        fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


IN_USE = "run directory is in use by another training"
"""What ``engine/run_dir.RunDirLock`` says when another process holds a run's lock."""

EVAL_LOCK_NAME = ".eval.lock"


@contextmanager
def evaluation_lock(run_dir: Path) -> Iterator[None]:
    """Hold one run's evaluation to one process at a time: two benches sharing a runs folder that reach
    the same finished run evaluate it once (the second reads the first's cached result) instead of
    both writing its renders (they raced on the same temp files and one failed)."""
    fd = os.open(Path(run_dir) / EVAL_LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


_TRAINED_HERE: set[Path] = set()
"""Runs this process trained: --rerun takes them as fresh (the bench's enhancer trains the StreetNeRF that
the plan then reuses; retraining it would leave the enhancer keyed on another checkpoint)."""


def train_or_reuse(spec: RunSpec, data: Path, runs_root: Path, dataset: str, reference: Optional[tuple[Path, str]] = None,
                   progress: bool = True, log=print, step_hook=None, device: str = "auto",
                   rerun: bool = False, _lock_tries: int = 3) -> tuple[Path, str]:
    """Returns (run_dir, key). A finished run with the same key is reused (unless ``rerun``: then
    its directory is replaced); a partial one resumes. ``step_hook(step)`` is called after every
    training step (a bench-wide progress bar). ``bench_run.json`` records where and when it trained."""
    from nerf2gs_plugin.engine.trainer import pick_device
    from nerf2gs_bench.code_version import device_label
    from nerf2gs_bench.machine import machine_line
    from nerf2gs_plugin.registry import get_method

    torch_device = pick_device(device)
    key = run_key(dataset, spec, reference[1] if reference else None, device_label(torch_device))
    base = get_method(spec.method).config
    cfg = apply_plain(base, spec.overrides, where=f"bench run {spec.label}")
    cfg = dataclasses.replace(cfg, data=Path(data), output_dir=Path(runs_root), timestamp=key, progress=progress,
                              device=str(torch_device))
    run_dir = cfg.get_run_dir()
    wait_for_other_training(run_dir, log)
    if rerun and run_dir.exists() and run_dir.resolve() not in _TRAINED_HERE:
        log(f"[bench] --rerun: retraining {spec.label} (removing {run_dir})")
        shutil.rmtree(run_dir)
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
    t_setup = time.perf_counter()
    try:
        trainer.setup()
        setup_seconds = time.perf_counter() - t_setup  # an augmented run renders its NeRF views here
        if step_hook is not None:
            trainer.step_hooks.append(step_hook)
        t0 = time.perf_counter()
        trainer.train()  # takes the run's lock first
    except ConfigError as e:
        # another bench sharing the runs folder took the run's lock between the wait above and this training (during
        # the setup's renders, say): wait for it and reuse its run (a few tries)
        if not (_lock_tries > 1 and IN_USE in str(e)):
            raise
        log(f"[bench] {spec.label}: another process started training it; waiting to reuse it")
        wait_for_other_training(run_dir, log)
        time.sleep(1.0)  # the other process may hold the lock only a moment (a setup that failed, a resume): let it go first
        return train_or_reuse(spec, data, runs_root, dataset, reference, progress, log, step_hook, device, False,
                              _lock_tries=_lock_tries - 1)
    _TRAINED_HERE.add(run_dir.resolve())
    # saved with the run: a bench reusing it reports these seconds, not the ~0 s of the reuse
    trained = {"machine": machine_line(), "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "device": device_label(torch_device),
               "seconds": round(time.perf_counter() - t0 + setup_seconds, 3), "resumed": bool(ckpts)}
    atomic_write_text(run_dir / "bench_run.json", json.dumps({"label": spec.label, **dataclasses.asdict(spec), "key": key,
                                                             "trained": trained}, indent=1, default=str))
    return run_dir, key
