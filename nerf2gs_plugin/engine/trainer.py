"""Trainer: the optimisation loop, periodic eval, checkpoints, resume, progress and NaN guard."""

from __future__ import annotations

import dataclasses
import json
import math
import random
import time
from collections import deque
from datetime import datetime
from pathlib import Path
from typing import Any, Optional

import numpy as np
import torch

from nerf2gs_plugin.engine.callbacks import TrainingCallbackAttributes, TrainingCallbackLocation as Loc
from nerf2gs_plugin.engine.checkpoints import (
    checkpoint_path,
    dataset_fingerprint,
    list_checkpoints,
    load_checkpoint,
    resolve_checkpoint,
    save_checkpoint,
)
from nerf2gs_plugin.engine.config import save_config
from nerf2gs_plugin.engine.divergence import describe, nonfinite_counts, nonfinite_outputs
from nerf2gs_plugin.engine.run_dir import RunDirLock, unique_run_dir
from nerf2gs_plugin.engine.validate import check_trainer_config
from nerf2gs_plugin.engine.optimizers import Optimizers
from nerf2gs_plugin.engine.pipeline import Pipeline
from nerf2gs_plugin.engine.trainer_config import TrainerConfig  # also imported from here by plugins
from nerf2gs_plugin.errors import CheckpointError, ConfigError, TrainingDiverged
from nerf2gs_plugin.utils import collectives
from nerf2gs_plugin.utils.extensions import build_seconds
from nerf2gs_plugin.utils.io import atomic_write_text
from nerf2gs_plugin.utils.plugins import load_ref

AUGMENTATION = "nerf2gs_plugin.augment.reference:augmented_datamanager"
"""The factory behind ``--augment-from``, named rather than imported (as the registry names the
methods): the augmentation sits above the engine, since it loads its reference run through it."""


FINITE_CHECK_SIDE = 128
"""Before a save the first training view is rendered at most this many pixels on its longer side (must be finite)."""


def pick_device(name: str = "auto") -> torch.device:
    """CUDA when present, else CPU; never hard-coded."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device '{name}' requested but CUDA is not available")
    return torch.device(name)


def augmented_steps(config: TrainerConfig) -> int:
    """The steps a run trains: with ``--augment-from``, ``--augment.step-factor`` times its configured steps."""
    if config.augment_from is None:
        return config.max_num_iterations
    return max(1, round(config.max_num_iterations * config.augment.step_factor))


def augmented_length(config: TrainerConfig) -> TrainerConfig:
    """With ``--augment-from``, the config at ``--augment.step-factor`` times its steps (every schedule
    rescaled), the factor then recorded as applied (1), so the saved config.yml is the run as trained."""
    factor = config.augment.step_factor
    if config.augment_from is None or factor == 1:
        return config
    from nerf2gs_plugin.utils.schedule import with_steps

    steps = augmented_steps(config)
    if collectives.rank() == 0:
        print(f"with NeRF views: {steps} steps ({config.max_num_iterations} x {factor:g}, schedule rescaled; "
              f"--augment.step-factor 1 keeps {config.max_num_iterations})", flush=True)
    scaled = with_steps(config, steps)
    return dataclasses.replace(scaled, augment=dataclasses.replace(scaled.augment, step_factor=1.0))


class Trainer:
    def __init__(self, config: TrainerConfig) -> None:
        check_trainer_config(config)
        config = augmented_length(config)
        # default stamp and no explicit folder: a clash gets a new folder
        self._unique_dir = config.timestamp == "{timestamp}" and config.run_dir is None
        if config.timestamp == "{timestamp}":  # rank 0's clock names the run for every rank
            config = dataclasses.replace(config, timestamp=collectives.broadcast_object(datetime.now().strftime("%Y-%m-%d_%H%M%S")))
        # recorded absolute, so eval / export / the viewer find the data from any directory
        config = dataclasses.replace(config, data=Path(config.data).expanduser().absolute())
        if config.run_dir is not None:
            config = dataclasses.replace(config, run_dir=Path(config.run_dir).expanduser().absolute())
        self.config = config
        self._lock = RunDirLock(config.get_run_dir())
        self.device = pick_device(config.device)
        self.run_dir = config.get_run_dir()
        self.step = 0
        self.last_good_checkpoint: Optional[Path] = None
        self.history = StepHistory()
        self.train_seconds = 0.0
        self.step_hooks: list = []  # called after every step (the live viewer attaches here)
        # files written into the run folder once it is chosen (name -> text): what is known before
        # training (the reference check) must not create the folder and push the run to ``<stamp>-1``
        self.run_files: dict[str, str] = {}
        # data parallel: this rank's index, and its sampling streams (rank x K + k, each seeded seed + stream)
        self.rank, self.world_size = collectives.rank(), collectives.world_size()
        self.batches = max(1, config.machine.batches_per_rank)
        self._streams: list[dict] = []  # the DataManager state of each stream, with several batches per rank

    # ------------------------------------------------------------------ setup
    def setup(self) -> None:
        torch.manual_seed(self.config.seed)
        np.random.seed(self.config.seed)
        random.seed(self.config.seed)
        first_stream = self.rank * self.batches
        self.pipeline = Pipeline(self.config.pipeline, self.config.data, self.device, seed=self.config.seed + first_stream,
                                 wrap_datamanager=self._augmentation())
        if self.batches > 1:
            self._streams = [self._fresh_stream(first_stream + k) for k in range(self.batches)]
        self.optimizers = Optimizers(self.config.optimizers, self.pipeline.model.get_param_groups())
        attrs = TrainingCallbackAttributes(optimizers=self.optimizers, pipeline=self.pipeline)
        self.callbacks = self.pipeline.model.get_training_callbacks(attrs)
        if self.config.load_checkpoint is not None:
            self._resume(self.config.load_checkpoint)
        elif self.config.warm_start is not None:
            self._warm_start(self.config.warm_start)

    def _augmentation(self):
        """With ``--augment-from``: the factory that wraps the method's DataManager in an
        AugmentedDataManager (the Pipeline applies it after building the model)."""
        if self.config.augment_from is None:
            return None
        augmented_datamanager = load_ref(AUGMENTATION)
        ref, augment, device = self.config.augment_from, self.config.augment, self.device

        def wrap(inner):  # rank 0 renders the reference views into the cache, the other ranks then read it
            with collectives.rank_zero_first():
                return augmented_datamanager(inner, ref, augment if self.rank == 0 else dataclasses.replace(augment, use_cache=True), device,
                                             self.config.max_num_iterations)

        return wrap

    # ------------------------------------------------------------------ sampling streams
    def _fresh_stream(self, stream: int) -> dict:
        """A DataManager state that samples as stream ``stream`` does from the start (seed + stream)."""
        dm = self.pipeline.datamanager
        current = dm.state_dict()
        dm.generator.manual_seed(self.config.seed + stream)
        state = dm.state_dict()
        dm.load_state_dict(current)
        return state

    def _stream_states(self) -> list[dict]:
        """This rank's streams' DataManager states, first to last."""
        return list(self._streams) if self._streams else [self.pipeline.datamanager.state_dict()]

    def _load_streams(self, ckpt: dict) -> None:
        """Each stream continues from the checkpoint's state of the same global stream; a stream the
        checkpoint did not have (it was trained on fewer ranks) starts afresh."""
        saved = ckpt.get("datamanager_streams") or [ckpt.get("datamanager", {})]
        first = self.rank * self.batches
        states = [saved[s] if s < len(saved) else self._fresh_stream(s) for s in range(first, first + self.batches)]
        if self._streams:
            self._streams = states
        self.pipeline.datamanager.load_state_dict(states[0])

    def _resume(self, path: Path) -> None:
        _, ckpt_file = resolve_checkpoint(path)
        ckpt = load_checkpoint(ckpt_file, expected_method=self.config.method_name, map_location=self.device)
        if int(ckpt["step"]) + 1 >= self.config.max_num_iterations:
            raise ConfigError(f"is {self.config.max_num_iterations} but the checkpoint {ckpt_file} is already at step "
                              f"{int(ckpt['step'])}: nothing to train (raise it to continue)", "--max-num-iterations")
        here = dataset_fingerprint(self.pipeline.datamanager.train_data.image_filenames)
        if ckpt.get("dataset") is not None and ckpt["dataset"] != here:
            raise CheckpointError(f"was trained on another dataset than {self.config.data} (its training images differ)", ckpt_file)
        self._load_state(ckpt)
        self.train_seconds = float(ckpt.get("train_seconds", 0.0))
        self.last_good_checkpoint = ckpt_file

    def _warm_start(self, path: Path) -> None:
        """Continue another run of the same model on the same data in this new run (``--warm-start``):
        its weights, optimiser moments, sampling stream and step; refused unless they match."""
        from nerf2gs_plugin.engine.warm_start import warm_start_refusal
        from nerf2gs_plugin.utils.config import to_plain

        run_dir, ckpt_file = resolve_checkpoint(path)
        ckpt = load_checkpoint(ckpt_file, map_location=self.device)
        train = self.pipeline.datamanager.train_data
        why = warm_start_refusal(ckpt, run_dir, self.config.method_name, dataset_fingerprint(train.image_filenames), train.cameras,
                                 to_plain(self.config.pipeline.model), self.pipeline.model.state_dict(), self.config.max_num_iterations)
        if why:
            raise CheckpointError(f"--warm-start refused: {why}", ckpt_file)
        self._load_state(ckpt)
        self.run_files["warm_start.json"] = json.dumps({"from": str(Path(ckpt_file).absolute()), "step": int(ckpt["step"])})

    def _load_state(self, ckpt: dict) -> None:
        """Model, training statistics, optimisers, sampling streams, RNG and step from a checkpoint."""
        self.pipeline.model.load_model_state(ckpt["model"])
        # with several ranks the statistics saved are rank 0's: the others start theirs afresh (no double count)
        self.pipeline.model.load_training_state(ckpt.get("training_state", {}) if self.rank == 0 else {})
        # parameters may have been re-created (densified): rebuild optimizers on the loaded tensors
        self.optimizers = Optimizers(self.config.optimizers, self.pipeline.model.get_param_groups())
        self.optimizers.load_state_dict(ckpt.get("optimizers", {}))
        attrs = TrainingCallbackAttributes(optimizers=self.optimizers, pipeline=self.pipeline)
        self.callbacks = self.pipeline.model.get_training_callbacks(attrs)
        self._load_streams(ckpt)
        if "torch_rng" in ckpt:
            torch.set_rng_state(ckpt["torch_rng"].cpu())
        self.step = int(ckpt["step"]) + 1

    def _write_run_files(self) -> None:
        """Rank 0 writes the run folder; every rank learns its name."""
        if self.rank == 0:
            self._write_run_files_rank0()
        self.run_dir = collectives.broadcast_object(self.run_dir)

    def _write_run_files_rank0(self) -> None:
        if self._unique_dir:
            self.run_dir = unique_run_dir(self.run_dir)
            self.config = dataclasses.replace(self.config, timestamp=self.run_dir.name)
            self._lock = RunDirLock(self.run_dir)
        self._lock.acquire(resuming_from=self.last_good_checkpoint)
        save_config(self.run_dir / "config.yml", self.config.method_name, self.config)
        from nerf2gs_plugin.data import save_dataparser_transform

        save_dataparser_transform(self.run_dir / "dataparser_transforms.json", self.pipeline.datamanager.train_data)
        from nerf2gs_plugin.engine.run_cameras import save_train_cameras

        save_train_cameras(self.run_dir, self.pipeline.datamanager.train_data.cameras)  # export without the dataset
        for name, text in self.run_files.items():
            atomic_write_text(self.run_dir / name, text)

    def check_finite_state(self, step: int) -> None:
        """Parameters, optimizer state and one rendered view must be finite before a save."""
        where = f"; last good checkpoint: {self.last_good_checkpoint}" if self.last_good_checkpoint else "; no checkpoint was written"
        bad = nonfinite_counts({"model": self.pipeline.model.state_dict(), "optimizers": self.optimizers.state_dict()})
        if bad:
            raise TrainingDiverged(f"training diverged by step {step}: non-finite values in {describe(bad)}{where}")
        camera = self.pipeline.datamanager.train_images.cameras[0]
        side = max(int(camera.width[0]), int(camera.height[0]))
        if side > FINITE_CHECK_SIDE:  # the check, not a picture: a NeRF's whole view costs seconds
            camera = camera.scaled(FINITE_CHECK_SIDE / side)
        with torch.no_grad():
            self.pipeline.model.eval()
            try:
                out = self.pipeline.model.render_camera(camera)
            finally:
                self.pipeline.model.train()
        bad_out = nonfinite_outputs(out)
        if bad_out:
            raise TrainingDiverged(f"training diverged by step {step}: finite parameters render non-finite {', '.join(bad_out)}{where}")

    def save_checkpoint(self, step: int, synced: bool = True) -> Optional[Path]:
        """Write ``step-<step>.ckpt`` (only from finite state) and flush ``train_log.json`` with it.
        With several ranks every rank calls it (``synced``): the replicas' parameter hashes must
        agree and rank 0 writes (with every rank's sampling streams); not ``synced`` (an interrupt,
        where the ranks are not in step): rank 0 writes alone and the others return None."""
        streams = self._stream_states()
        if self.world_size > 1 and synced:
            self.check_replicas(step)
            streams = [s for rank_streams in collectives.all_gather_object(streams) for s in rank_streams]
        if self.rank != 0:
            if not synced:
                return None
            self.last_good_checkpoint = checkpoint_path(self.run_dir, step)  # rank 0's, on the shared run folder
            return self.last_good_checkpoint
        self.check_finite_state(step)
        path = checkpoint_path(self.run_dir, step)
        dm = self.pipeline.datamanager
        try:
            self._write_checkpoint(path, step, dm, *([streams] if len(streams) > 1 else []))
        except OSError as e:
            kept = f"; previous checkpoint kept: {self.last_good_checkpoint}" if self.last_good_checkpoint else ""
            raise CheckpointError(f"cannot write checkpoint ({e.strerror or e}){kept}", path) from None
        if not self.config.keep_all_checkpoints:
            for old in list_checkpoints(self.run_dir):
                if old != path:
                    old.unlink(missing_ok=True)
        self.last_good_checkpoint = path
        return path

    def check_replicas(self, step: int) -> None:
        """Every rank's parameters hash the same (data-parallel replicas stay identical)."""
        digests = collectives.all_gather_object(collectives.param_digest(self.pipeline.model.state_dict()))
        if len(set(digests)) > 1:
            odd = [r for r, d in enumerate(digests) if d != digests[0]]
            raise TrainingDiverged(f"data-parallel replicas differ at step {step}: the parameters of rank(s) "
                                   f"{', '.join(map(str, odd))} are not rank 0's (hashes {', '.join(digests)})")

    def _write_train_log(self) -> None:
        views = getattr(self.pipeline.datamanager, "views", None)  # an AugmentedDataManager's reference renders
        atomic_write_text(self.run_dir / "train_log.json", json.dumps(
            {"train_seconds": self.train_seconds, "reference_render_seconds": getattr(views, "render_seconds", 0.0),
             "history_stride": self.history.stride, "history": self.history.records()}))

    def _write_checkpoint(self, path: Path, step: int, dm: Any, streams: Optional[list[dict]] = None) -> None:
        # The log first: a kill between the two writes leaves the log ahead of the newest checkpoint
        # (training that happened, resumed from the older state), never a checkpoint without its log.
        self._write_train_log()
        save_checkpoint(
            path,
            {
                "method_name": self.config.method_name,
                "step": step,
                "model": self.pipeline.model.state_dict(),
                "optimizers": self.optimizers.state_dict(),
                "training_state": self.pipeline.model.training_state(),
                "datamanager": dm.state_dict() if streams is None else streams[0],
                **({"datamanager_streams": streams} if streams is not None else {}),
                "torch_rng": torch.get_rng_state(),
                "dataset": dataset_fingerprint(dm.train_data.image_filenames),
                "train_seconds": self.train_seconds,
                "size": self.pipeline.model.size_report(),
            },
        )

    # ------------------------------------------------------------------ loop
    def _run_callbacks(self, where: Loc, step: int) -> None:
        for cb in self.callbacks:
            cb.run(where, step)

    def train_step(self, step: int) -> dict[str, float]:
        model = self.pipeline.model
        model.train()
        self._run_callbacks(Loc.BEFORE_STEP, step)
        self.optimizers.zero_grad()
        if self.batches == 1:
            out = self._backward_batch(step)
        else:
            out = self._backward_batches(step)
        if self.world_size * self.batches > 1:  # the global batch's mean gradient, on every rank
            collectives.average_gradients(list(model.parameters()), self.world_size * self.batches)
            if self.world_size > 1:
                out["loss"] = collectives.mean_over_ranks(out["loss"], self.device)
        self._run_callbacks(Loc.AFTER_BACKWARD, step)
        self.optimizers.step(step)
        self._run_callbacks(Loc.AFTER_STEP, step)
        return out

    def _backward_batch(self, step: int) -> dict[str, float]:
        """Forward and backward of one batch; its loss and scalar metrics."""
        _, losses, metrics = self.pipeline.get_train_loss_dict(step)
        loss = sum(losses.values())
        if not torch.isfinite(loss):
            bad = [k for k, v in losses.items() if not torch.isfinite(v)]
            where = f"; last good checkpoint: {self.last_good_checkpoint}" if self.last_good_checkpoint else "; no checkpoint was written yet"
            raise TrainingDiverged(f"training diverged at step {step}: non-finite loss in {', '.join(bad)}{where}")
        loss.backward()
        out = {"loss": float(loss.detach())}
        out.update({k: float(v) for k, v in metrics.items() if torch.is_tensor(v) and v.numel() == 1})
        return out

    def _backward_batches(self, step: int) -> dict[str, float]:
        """``--machine.batches-per-rank K``: K batches, batch k drawn by stream k and started from the
        step's global random state, as K ranks would (gradients summed; the caller averages).
        Returns the batches' mean loss and metrics."""
        dm = self.pipeline.datamanager
        rng = _rng_states(self.device)
        records = []
        for k in range(self.batches):
            dm.load_state_dict(self._streams[k])
            _set_rng_states(rng, self.device)
            records.append(self._backward_batch(step))
            self._streams[k] = dm.state_dict()
            if k < self.batches - 1:
                self._run_callbacks(Loc.AFTER_BATCH, step)
        keys = [key for key in records[0] if all(key in r for r in records)]
        return {key: sum(r[key] for r in records) / len(records) for key in keys}

    def train(self) -> Path:
        """Run to ``max_num_iterations``; returns the run directory."""
        from nerf2gs_plugin.progress import make_progress

        self._write_run_files()
        try:
            return self._train_loop(make_progress)
        finally:
            self._lock.release()  # held by rank 0 only

    def _train_loop(self, make_progress: Any) -> Path:
        cfg = self.config
        start = self.step
        ema: dict[str, float] = {}
        # progress False: no live bar, a plain line every 10 s (step, rate, ETA, loss), unless a step
        # hook follows the steps (a bench's own bar): then nothing, so lines do not cut through it
        with make_progress(enabled=(cfg.progress or not self.step_hooks) and self.rank == 0, live=cfg.progress) as progress:
            task = progress.add_task(f"train {cfg.method_name}", total=cfg.max_num_iterations, completed=start, stats="")
            for step in range(start, cfg.max_num_iterations):
                t0, k0 = time.perf_counter(), build_seconds()
                stats = self.train_step(step)
                # a kernel compiled (or loaded) on first use is set-up, not training
                self.train_seconds += time.perf_counter() - t0 - (build_seconds() - k0)
                self.step = step
                for k, v in stats.items():
                    ema[k] = v if k not in ema else 0.9 * ema[k] + 0.1 * v
                record = {"step": step, **stats}
                if cfg.steps_per_eval_image and (step + 1) % cfg.steps_per_eval_image == 0 and self.rank == 0:
                    record.update(self.pipeline.get_eval_image_metrics(step))
                    ema["eval_psnr_1view"] = record["eval_psnr_1view"]
                self.history.append(record)
                if (step + 1) % cfg.steps_per_save == 0 and step + 1 < cfg.max_num_iterations:
                    self.save_checkpoint(step)
                for hook in self.step_hooks:
                    hook(step)
                model = self.pipeline.model
                prims = model.num_primitives() if getattr(model, "primitive_kind", "primitives") else 0  # not a NeRF's hash entries
                progress.update(task, advance=1, stats=_format_stats(ema, prims))
        self.save_checkpoint(cfg.max_num_iterations - 1)
        return self.run_dir


def _rng_states(device: torch.device) -> tuple:
    return (torch.get_rng_state(), torch.cuda.get_rng_state(device) if device.type == "cuda" else None)


def _set_rng_states(states: tuple, device: torch.device) -> None:
    torch.set_rng_state(states[0])
    if states[1] is not None:
        torch.cuda.set_rng_state(states[1], device)


class StepHistory:
    """Per-step records of a whole run in bounded memory: every step of the last ``recent`` steps,
    every ``stride``-th older step (the stride doubles whenever more than ``older`` of them are
    kept) and always the run's first step, so ``train_log.json`` holds at most
    ``recent + older + 1`` records (about 4000) and still shows the start of the run."""

    def __init__(self, recent: int = 2000, older: int = 2000) -> None:
        self.recent: deque[dict[str, float]] = deque(maxlen=max(1, recent))
        self.older: list[dict[str, float]] = []
        self.max_older = max(1, older)
        self.first: Optional[dict[str, float]] = None
        self.stride = 1

    def append(self, record: dict[str, float]) -> None:
        if len(self.recent) == self.recent.maxlen:
            self._age(self.recent[0])
        self.recent.append(record)

    def _age(self, record: dict[str, float]) -> None:
        if self.first is None:
            self.first = record
            return
        if int(record["step"]) % self.stride:
            return
        self.older.append(record)
        if len(self.older) > self.max_older:
            self.stride *= 2
            self.older = [r for r in self.older if int(r["step"]) % self.stride == 0]

    def records(self) -> list[dict[str, float]]:
        """Oldest first."""
        return ([self.first] if self.first is not None else []) + self.older + list(self.recent)

    def __len__(self) -> int:
        return len(self.records())


def _format_stats(ema: dict[str, float], primitives: int) -> str:
    parts = [f"loss {ema['loss']:.4f}"] if "loss" in ema else []
    if "psnr" in ema:
        parts.append(f"train psnr {ema['psnr']:.2f}")
    if "eval_psnr_1view" in ema:
        parts.append(f"eval psnr (1 view) {ema['eval_psnr_1view']:.2f}")
    if primitives:
        parts.append(f"prims {primitives}")
    return " ".join(parts)


def is_finite_number(x: float) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)
