"""Train the built-in enhancer (our small residual U-Net, not Difix) on this dataset's own images.

Training pairs are (degraded, ground truth) crops of the training images:
* with ``reference`` runs/checkpoints (e.g. a partially trained StreetNeRF checkpoint), the
  degraded side is that model's render at the training pose (transient pixels left out of the
  loss, since the NeRF removes cars the ground truth still shows), half of the time further
  degraded synthetically;
* always, synthetic degradations (:mod:`nerf2gs_plugin.enhance.degrade`) of the real images.
The trained network is exported to ONNX with its I/O convention in the metadata and is run, like
any other model, through :mod:`nerf2gs_plugin.enhance.onnx_runtime`.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.enhance.degrade import KINDS, degrade
from nerf2gs_plugin.enhance.unet import MULTIPLE, ResidualUNet, export_onnx
from nerf2gs_plugin.errors import ConfigError, DataError


@dataclass
class EnhancerTrainConfig:
    """``ns2gs-enhance train``: defaults train in a few minutes on 2 CPU cores."""

    data: Path
    """Dataset (nerfstudio transforms.json or COLMAP) whose training images make the pairs."""
    out: Path = Path("outputs/enhancer/enhancer.onnx")
    """Where the ONNX model goes (a training report is written next to it, ``*.report.json``)."""
    reference: tuple[Path, ...] = ()
    """Runs or checkpoints (ideally partially trained) whose renders at training poses are degraded inputs."""
    steps: int = 3000
    batch_size: int = 8
    crop: int = 64
    """Training crop size (rounded to a multiple of 4, at most the smallest image)."""
    lr: float = 2e-3
    width: int = 16
    """Channels of the first U-Net level (x2, x4 below)."""
    condition: bool = False
    """Also feed the nearest other training view (channel concatenation) as a reference input."""
    degradations: tuple[str, ...] = KINDS
    strength: float = 1.0
    downscale: float = 1.0
    max_renders: int = 64
    """At most this many reference renders (they are made once, before training)."""
    eval_splits: tuple[str, ...] = ()
    """Held-out splits for the before/after PSNR in the report (default: all eval splits)."""
    seed: int = 0
    threads: int = 0
    """Torch threads; 0 = auto: all cores on an idle machine, 1 on a busy one (OpenMP threads that
    wait for each other on oversubscribed cores made a step ~10x slower in our measurements)."""
    progress: bool = True


@dataclass
class TrainReport:
    out: str
    steps: int
    seconds: float
    losses: list[float] = field(default_factory=list)  # mean L1 per logging window
    heldout: dict = field(default_factory=dict)  # {"psnr_degraded", "psnr_enhanced", "images", "splits"}
    config: dict = field(default_factory=dict)
    threads: int = 1  # torch threads used for training


def psnr(a: Tensor, b: Tensor) -> float:
    mse = float(((a.float() - b.float()) ** 2).mean())
    return 10 * torch.log10(torch.tensor(1.0 / max(mse, 1e-12))).item()


def _chw(img: Tensor) -> Tensor:
    return img.permute(2, 0, 1).contiguous().float().cpu()


def _nearest_other(centres: Tensor) -> Tensor:
    d = torch.cdist(centres, centres)
    d.fill_diagonal_(float("inf"))
    return d.argmin(1) if len(centres) > 1 else torch.zeros(len(centres), dtype=torch.long)


def load_split_images(data: Path, split: str, downscale: float = 1.0) -> tuple[list[Tensor], Tensor]:
    """A split's images ``[3, H, W]`` and camera centres."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.datamanagers.image_set import load_image_set

    outputs = parse_dataset(data, split, downscale=downscale)
    images = load_image_set(outputs)
    return [_chw(images.image(i)) for i in range(len(images))], outputs.cameras.camera_to_worlds[:, :3, 3].float()


def reference_pairs(refs: Sequence[Path], data: Path, max_renders: int, gen: torch.Generator, progress: bool = True) -> list[tuple[Tensor, Tensor, Tensor, int]]:
    """(render, ground truth, loss mask, image index) at training poses, from each reference."""
    from nerf2gs_plugin.engine.reference import load_run
    from nerf2gs_plugin.progress import make_progress

    runs = [load_run(Path(r), data=data) for r in refs]
    per_run = max(1, max_renders // max(len(runs), 1))
    pairs = []
    with make_progress(progress) as bar, torch.no_grad():
        jobs = [(run, idx) for run in runs for idx in torch.randperm(len(run.pipeline.datamanager.train_images), generator=gen)[:per_run].tolist()]
        task = bar.add_task("render reference views", total=len(jobs), stats="")
        for run, i in jobs:
            imgs = run.pipeline.datamanager.train_images
            render = run.model.render_camera(imgs.cameras[i])["rgb"].detach().cpu()
            mask = torch.ones(imgs.hw(i) + (1,))
            transient = imgs.mask("transient", i)
            if transient is not None:
                t = F.max_pool2d(transient.float().cpu().permute(2, 0, 1)[None], 5, 1, 2)[0].permute(1, 2, 0)
                mask = 1 - t
            pairs.append((_chw(render), _chw(imgs.image(i)), _chw(mask), i))
            bar.update(task, advance=1, stats=f"{run.config.method_name} step {run.step}")
    return pairs


class _CropSampler:
    """Random same-size crops from a list of differently sized images."""

    def __init__(self, crop: int, sizes: list[tuple[int, int]], gen: torch.Generator) -> None:
        smallest = min(min(s) for s in sizes)
        self.crop = max(MULTIPLE, min(crop, smallest) // MULTIPLE * MULTIPLE)
        if smallest < MULTIPLE:
            raise DataError(f"images are too small to train on ({smallest} px)")
        self.sizes, self.gen = sizes, gen

    def window(self, i: int) -> tuple[int, int]:
        h, w = self.sizes[i]
        return int(torch.randint(0, h - self.crop + 1, (), generator=self.gen)), int(torch.randint(0, w - self.crop + 1, (), generator=self.gen))

    def cut(self, img: Tensor, y: int, x: int) -> Tensor:
        """The crop at (y, x), moved inside ``img`` when it would stick out."""
        c = self.crop
        y, x = min(y, img.shape[-2] - c), min(x, img.shape[-1] - c)
        return img[..., y : y + c, x : x + c]


def heldout_psnr(enhance, images: list[Tensor], kinds: Sequence[str], strength: float, seed: int,
                 references: Optional[list[Tensor]] = None) -> dict:
    """Mean PSNR of held-out images degraded (fixed seed) vs. the same after ``enhance``."""
    gen = torch.Generator().manual_seed(seed + 7919)
    before, after = [], []
    for k, gt in enumerate(images):
        deg = degrade(gt[None], gen, kinds, strength)[0]
        ref = references[k].permute(1, 2, 0) if references is not None else None
        out = enhance(deg.permute(1, 2, 0), ref).permute(2, 0, 1)
        before.append(psnr(deg, gt))
        after.append(psnr(out, gt))
    n = max(len(images), 1)
    return {"psnr_degraded": sum(before) / n, "psnr_enhanced": sum(after) / n, "images": len(images)}


def train_enhancer(config: EnhancerTrainConfig) -> TrainReport:
    """Train, export to ONNX at ``config.out``, and measure before/after PSNR on held-out views."""
    if config.steps < 1 or config.batch_size < 1:
        raise ConfigError(f"steps and batch_size must be >= 1 (got {config.steps}, {config.batch_size})")
    unknown = set(config.degradations) - set(KINDS)
    if unknown or not config.degradations:
        raise ConfigError(f"--degradations must be some of {', '.join(KINDS)} (got {', '.join(config.degradations) or 'none'})")
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    threads_before = torch.get_num_threads()
    torch.set_num_threads(training_threads(config.threads))
    try:
        return _train(config, gen)
    finally:
        torch.set_num_threads(threads_before)


def training_threads(requested: int) -> int:
    """``requested``, or (0) the torch default when the machine is idle and 1 when it is busy."""
    import os

    if requested > 0:
        return requested
    cores = os.cpu_count() or 1
    try:
        busy = os.getloadavg()[0] > 0.75 * cores
    except OSError:
        busy = False
    return 1 if busy else torch.get_num_threads()


def _train(config: EnhancerTrainConfig, gen: torch.Generator) -> TrainReport:
    from nerf2gs_plugin.data import list_splits
    from nerf2gs_plugin.engine.config import atomic_write_bytes, atomic_write_text
    from nerf2gs_plugin.enhance import OnnxModelEnhancer
    from nerf2gs_plugin.progress import make_progress

    t0 = time.time()
    images, centres = load_split_images(config.data, "train", config.downscale)
    neighbour = _nearest_other(centres)
    pairs = reference_pairs(config.reference, config.data, config.max_renders, gen, config.progress) if config.reference else []
    sizes = [tuple(im.shape[-2:]) for im in images] + [tuple(p[0].shape[-2:]) for p in pairs]
    sampler = _CropSampler(config.crop, sizes, gen)

    net = ResidualUNet(config.width, config.condition)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=config.lr, total_steps=config.steps, pct_start=0.05)
    losses, window = [], []
    log_every = max(1, config.steps // 50)
    with make_progress(config.progress) as bar:
        task = bar.add_task("train enhancer", total=config.steps, stats="")
        for step in range(config.steps):
            inp, tgt, msk, ref = [], [], [], []
            for _ in range(config.batch_size):  # builds the batch; per-sample crops, not pixels
                use_pair = pairs and float(torch.rand((), generator=gen)) < 0.5
                if use_pair:
                    render, gt, mask, i = pairs[int(torch.randint(len(pairs), (), generator=gen))]
                    h, w = render.shape[-2:]
                    y = int(torch.randint(0, h - sampler.crop + 1, (), generator=gen))
                    x = int(torch.randint(0, w - sampler.crop + 1, (), generator=gen))
                    src = sampler.cut(render, y, x)
                    if float(torch.rand((), generator=gen)) < 0.5:
                        src = degrade(src[None], gen, config.degradations, 0.5 * config.strength)[0]
                    inp.append(src)
                    tgt.append(sampler.cut(gt, y, x))
                    msk.append(sampler.cut(mask, y, x))
                    j = int(neighbour[i]) if i < len(images) else 0
                else:
                    i = int(torch.randint(len(images), (), generator=gen))
                    y, x = sampler.window(i)
                    clean = sampler.cut(images[i], y, x)
                    inp.append(degrade(clean[None], gen, config.degradations, config.strength)[0])
                    tgt.append(clean)
                    msk.append(torch.ones(1, sampler.crop, sampler.crop))
                    j = int(neighbour[i])
                if config.condition:
                    ref.append(sampler.cut(images[j], y, x))
            inp_t, tgt_t, msk_t = torch.stack(inp), torch.stack(tgt), torch.stack(msk)
            out = net(inp_t, torch.stack(ref) if config.condition else None)
            loss = ((out - tgt_t).abs() * msk_t).sum() / (msk_t.sum() * 3).clamp_min(1)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            window.append(float(loss.detach()))
            if len(window) == log_every or step == config.steps - 1:
                losses.append(sum(window) / len(window))
                window = []
                bar.update(task, stats=f"L1 {losses[-1]:.4f}")
            bar.update(task, advance=1)
    train_seconds = time.time() - t0

    # The U-Net's receptive radius is ~24 px: an overlap of 96 gives tiles a 24 px zero-weight margin.
    meta = {"tile_size": "512", "overlap": "96", "description": "nerf2gs built-in residual U-Net (not Difix)",
            "nerf2gs.steps": str(config.steps), "nerf2gs.width": str(config.width)}
    out = Path(config.out)
    atomic_write_bytes(out, export_onnx(net, out, meta))

    heldout: dict = {}
    splits = list(config.eval_splits) or [s for s in list_splits(config.data) if s != "train"]
    if splits:
        enh = OnnxModelEnhancer(out)
        held, refs = [], []
        for s in splits:
            imgs, cents = load_split_images(config.data, s, config.downscale)
            held += imgs
            if config.condition:
                near = torch.cdist(cents, centres).argmin(1)
                refs += [images[int(k)] for k in near]
        heldout = heldout_psnr(enh.enhance, held, config.degradations, config.strength, config.seed, refs if config.condition else None)
        heldout["splits"] = splits
    report = TrainReport(str(out), config.steps, train_seconds, losses, heldout,
                         {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(config).items() if k != "reference"}
                         | {"reference": [str(r) for r in config.reference]}, threads=torch.get_num_threads())
    atomic_write_text(report_path(out), json.dumps(asdict(report), indent=1))
    return report


def report_path(model: Path) -> Path:
    """``enhancer.onnx`` -> ``enhancer.report.json`` (not ``.onnx.json``: that name is the sidecar)."""
    model = Path(model)
    return model.with_name(model.stem + ".report.json")
