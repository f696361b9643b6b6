"""Train the built-in enhancer (our small residual U-Net, not Difix) on this dataset's own images.

Training pairs (degraded, ground truth) come from the training images only:
* with ``reference`` runs (the StreetNeRF reference), real renders: at the training poses, and from
  cameras raised and pitched down from them with the training image warped in through the rendered
  depth (:mod:`nerf2gs_plugin.enhancer.pairs`); transient and occluded pixels are left out of the loss;
* without, synthetic degradations (:mod:`nerf2gs_plugin.enhancer.degrade`) of the real images, which
  do NOT look like real NeRF artifacts: on real bird's-eye renders such a model made PSNR worse.
The loss is L1 plus an LPIPS term (when LPIPS weights are installed). Every ``holdout_every``-th
training image is held out: the network is scored on it ``checkpoints`` times during training and the
best state is exported, the untrained network (the identity: its last layer starts at zero) included,
so the exported model never scores worse than no enhancement on those held-out training views.
The trained network is exported to ONNX with its I/O convention in the metadata and is run, like
any other model, through :mod:`nerf2gs_plugin.enhancer.onnx_runtime`.

``condition`` (default ``none``: one input, the render) conditions the network on a real view, in
the spirit of Difix: ``view`` concatenates the nearest other training image as it is; ``warped``
(needs a reference) the nearest other training view facing the same way, warped into the render's
camera through the reference's depth, and its validity mask (:func:`~nerf2gs_plugin.enhancer.warp.warped_reference`:
7 input channels in all), so where a real camera saw the surface the network can copy its detail.
A pair's condition is never warped from its own target view (the network would learn to copy its
target); the exported model says ``reference_kind: warped`` and the augmentation feeds each
bird's-eye view the nearest training view warped through the bird's-eye render's depth.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Literal, Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.enhancer.degrade import KINDS, degrade
from nerf2gs_plugin.enhancer.pairs import Pair, split_indices
from nerf2gs_plugin.enhancer.unet import MULTIPLE, ResidualUNet, export_onnx
from nerf2gs_plugin.enhancer.warp import WARPED_CHANNELS
from nerf2gs_plugin.errors import ConfigError, DataError
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.utils.image_metrics import psnr, psnr_from_mse
from nerf2gs_plugin.utils.io import atomic_write_bytes, atomic_write_text
from nerf2gs_plugin.utils.lpips import LPIPS, to_nchw

# Checkpoint selection score: PSNR - LPIPS_DB * LPIPS (0.01 LPIPS weighs like 0.2 dB).
LPIPS_DB = 20.0


@dataclass
class EnhancerTrainConfig:
    """``ns2gs-enhance train``: defaults train in under 10 minutes on 2 CPU cores (one thread, busy machine), rendering included."""

    data: Path
    """Dataset (nerfstudio transforms.json or COLMAP) whose training images make the pairs."""
    out: Path = Path("outputs/enhancer/enhancer.onnx")
    """Where the ONNX model goes (a training report is written next to it, ``*.report.json``)."""
    reference: tuple[Path, ...] = ()
    """Reference runs or checkpoints (the StreetNeRF reference): their renders make the real training
    pairs. Without one, only synthetic degradations are used (they do not help on real renders)."""
    steps: int = 600
    batch_size: int = 8
    crop: int = 64
    """Training crop size (rounded to a multiple of 4, at most the smallest image)."""
    lr: float = 2e-3
    width: int = 16
    """Channels of the first U-Net level (x2, x4 below)."""
    condition: Literal["none", "view", "warped"] = "none"
    """Reference input of the network (channel concatenation). none: the render alone; view: the nearest
    other training image as it is; warped: the nearest other training view facing the same way, warped
    into the render's camera through the reference's depth, plus its validity mask (needs --reference)."""
    perturbed: bool = True
    """With a reference: also pairs from cameras raised 2-8 m and pitched down 10-35 deg from the
    training poses (novel-view artifacts), with the training image warped in as ground truth."""
    pair_fraction: float = 1.0
    """With a reference: share of the batch's crops cut from real pairs (the rest synthetic)."""
    lpips_weight: float = 0.3
    """Weight of the LPIPS term of the loss (skipped when no LPIPS weights are installed)."""
    holdout_every: int = 8
    """Every k-th training image is held out for checkpoint selection (0: none, keep the last state)."""
    checkpoints: int = 10
    """How many times during training the held-out images score the network (best state is exported)."""
    degradations: tuple[str, ...] = KINDS
    strength: float = 1.0
    downscale: float = 1.0
    max_renders: int = 64
    """At most this many training poses rendered per reference (once, before training), held-out ones aside."""
    eval_splits: tuple[str, ...] = ()
    """Held-out splits for the before/after PSNR in the report (default: all eval splits)."""
    init: Optional[Path] = None
    """Start from a prior (``.pt`` written by ``ns2gs-enhance pretrain``) instead of the identity; the
    held-out selection then compares against the prior (step 0)."""
    seed: int = 0
    threads: int = 0
    """Torch threads; 0 = auto: all cores on an idle machine, 1 on a busy one (OpenMP threads that
    wait for each other on oversubscribed cores make a step many times slower)."""
    progress: bool = True


@dataclass
class TrainReport:
    out: str
    steps: int
    seconds: float
    losses: list[float] = field(default_factory=list)  # mean loss per logging window
    heldout: dict = field(default_factory=dict)  # {"psnr_degraded", "psnr_enhanced", "images", "splits"}
    config: dict = field(default_factory=dict)
    threads: int = 1  # torch threads used for training
    validation: list = field(default_factory=list)  # [{"step", "psnr", "lpips"}] on held-out training views; step 0 = identity (or the --init prior)
    selected_step: Optional[int] = None  # the exported state (0: the starting state won)
    pairs: dict = field(default_factory=dict)  # {"pose": n, "perturbed": n} real pairs used for training

    def summary_lines(self) -> list[str]:
        """What a user reads after training: the held-out training views (real renders, what the
        exported state was chosen on), then the eval splits under synthetic degradations."""
        lines = [f"enhancer saved to {self.out} ({self.seconds:.0f} s, {self.steps} steps, {self.threads} threads, "
                 f"loss {self.losses[0]:.4f} -> {self.losses[-1]:.4f})" if self.losses else f"enhancer saved to {self.out}"]
        if self.validation:
            first = self.validation[0]
            chosen = next((v for v in self.validation if v["step"] == self.selected_step), self.validation[-1])
            lp = lambda v: f", LPIPS {v['lpips']:.4f}" if v["lpips"] is not None else ""  # noqa: E731
            start = "prior" if self.config.get("init") else "identity"
            lines.append(f"held-out training views: {start} PSNR {first['psnr']:.2f} dB{lp(first)}; exported step "
                         f"{self.selected_step}: PSNR {chosen['psnr']:.2f} dB{lp(chosen)}")
        if self.heldout:
            h = self.heldout
            lines.append(f"held-out {'/'.join(h['splits'])} ({h['images']} images, synthetic degradations): "
                         f"PSNR {h['psnr_degraded']:.2f} -> {h['psnr_enhanced']:.2f} dB")
        return lines


def _chw(img: Tensor) -> Tensor:
    return img.permute(2, 0, 1).contiguous().float().cpu()


def _nearest_other(centres: Tensor) -> Tensor:
    d = torch.cdist(centres, centres)
    d.fill_diagonal_(float("inf"))
    return d.argmin(1) if len(centres) > 1 else torch.zeros(len(centres), dtype=torch.long)


def _train_poses(data: Path, downscale: float) -> Tensor:
    from nerf2gs_plugin.data import parse_dataset

    return parse_dataset(data, "train", downscale=downscale).cameras.camera_to_worlds[:, :3, :4].float()


def _condition_sources(c2ws: Tensor, fit: list[int], indices: Sequence[int]) -> dict[int, int]:
    """Training index -> the training view (never itself, never a held-out one) whose warp conditions its pairs."""
    from nerf2gs_plugin.enhancer.warp import condition_source

    pos = {i: k for k, i in enumerate(fit)}
    return {i: fit[condition_source(c2ws[i], c2ws[fit], pos.get(i))] for i in indices}


def load_split_images(data: Path, split: str, downscale: float = 1.0) -> tuple[list[Tensor], Tensor]:
    """A split's images ``[3, H, W]`` and camera centres."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.datamanagers.image_set import load_image_set

    outputs = parse_dataset(data, split, downscale=downscale)
    images = load_image_set(outputs)
    return [_chw(images.image(i)) for i in range(len(images))], outputs.cameras.camera_to_worlds[:, :3, 3].float()


def reference_pairs(refs: Sequence[Path], data: Path, max_renders: int, gen: torch.Generator, progress: bool = True,
                    perturbed: bool = False) -> list[Pair]:
    """Real pairs at up to ``max_renders`` random training poses per reference (see :mod:`~nerf2gs_plugin.enhancer.pairs`)."""
    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.enhancer.pairs import reference_pairs as render_pairs

    n = len(parse_dataset(data, "train").image_filenames)
    indices = sorted(torch.randperm(n, generator=gen)[:max_renders].tolist())
    return render_pairs(refs, data, indices, gen, perturbed=perturbed, progress=progress)


class _CropSampler:
    """Random same-size crops from a list of differently sized images."""

    def __init__(self, crop: int, sizes: list[tuple[int, int]], gen: torch.Generator) -> None:
        smallest = min(min(s) for s in sizes)
        self.crop = max(MULTIPLE, min(crop, smallest) // MULTIPLE * MULTIPLE)
        if smallest < MULTIPLE:
            raise DataError(f"images are too small to train on ({smallest} px)")
        self.sizes, self.gen = sizes, gen

    def corner(self, h: int, w: int) -> tuple[int, int]:
        """A random crop's top-left corner inside an ``h`` x ``w`` image."""
        return int(torch.randint(0, h - self.crop + 1, (), generator=self.gen)), int(torch.randint(0, w - self.crop + 1, (), generator=self.gen))

    def window(self, i: int) -> tuple[int, int]:
        return self.corner(*self.sizes[i])

    def pair_window(self, pair: Pair) -> tuple[int, int]:
        return self.corner(*pair.render.shape[-2:])

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
        before.append(float(psnr(deg, gt)))
        after.append(float(psnr(out, gt)))
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


class _Validator:
    """Scores a network on held-out training views: mean masked PSNR and LPIPS (pixels outside the
    mask are taken from the target, so they do not count)."""

    def __init__(self, items: list[tuple[Tensor, Tensor, Tensor, Optional[Tensor]]], lpips) -> None:
        self.items, self.lpips = items, lpips

    @torch.no_grad()
    def __call__(self, net: ResidualUNet) -> dict:
        net.eval()
        p, l = [], []
        for inp, tgt, mask, ref in self.items:
            h, w = inp.shape[-2:]
            pad = (0, (-w) % MULTIPLE, 0, (-h) % MULTIPLE)
            x = F.pad(inp[None], pad, mode="replicate")
            r = F.pad(ref[None], pad, mode="replicate") if ref is not None else None
            out = net(x, r)[0, :, :h, :w]
            mse = (((out - tgt) ** 2) * mask).sum() / (mask.sum() * 3).clamp_min(1)
            p.append(float(psnr_from_mse(mse)))
            if self.lpips is not None:
                l.append(float(self.lpips(out * mask + tgt * (1 - mask), tgt)))
        net.train()
        res = {"psnr": sum(p) / max(len(p), 1), "lpips": sum(l) / len(l) if l else None}
        res["score"] = res["psnr"] - (LPIPS_DB * res["lpips"] if res["lpips"] is not None else 0.0)
        return res


def _lpips_loss(lpips, weight: float) -> Optional[Callable[[Tensor, Tensor], Tensor]]:
    """LPIPS as a differentiable loss term (frozen AlexNet), or None when not used."""
    if lpips is None or weight <= 0:
        return None

    for prm in lpips.net.parameters():
        prm.requires_grad_(False)
    return lambda out, tgt: weight * lpips.net(to_nchw(out), to_nchw(tgt)).mean()


def _train(config: EnhancerTrainConfig, gen: torch.Generator) -> TrainReport:
    from nerf2gs_plugin.data import list_splits
    from nerf2gs_plugin.enhancer import OnnxModelEnhancer
    from nerf2gs_plugin.enhancer.pairs import reference_pairs as render_pairs

    if not 0 <= config.pair_fraction <= 1:
        raise ConfigError(f"--pair-fraction must be in [0, 1] (got {config.pair_fraction})")
    if config.condition not in ("none", "view", "warped"):
        raise ConfigError(f"--condition must be none, view or warped (got {config.condition!r})")
    warped = config.condition == "warped"
    if warped and not config.reference:
        raise ConfigError("--condition warped needs --reference (the reference's depth warps the real views)")
    t0 = time.time()
    images, centres = load_split_images(config.data, "train", config.downscale)
    train_c2w = _train_poses(config.data, config.downscale) if warped else None
    fit, held = split_indices(len(images), config.holdout_every, None, gen)
    if not fit:
        raise DataError(f"no training images left to train on (holdout_every={config.holdout_every}, {len(images)} images)", config.data)
    # the reference view of an image: the nearest training image that is not held out
    fit_t = torch.tensor(fit)
    d = torch.cdist(centres, centres[fit_t])
    d[fit_t, torch.arange(len(fit))] = float("inf")
    neighbour = fit_t[d.argmin(1)] if len(fit) > 1 else torch.full((len(images),), fit[0])
    if warped and len(fit) < 2:
        raise DataError(f"--condition warped needs at least 2 training images left to train on (got {len(fit)})", config.data)

    lpips = LPIPS.load_default() if (config.lpips_weight > 0 or config.reference) else None
    pairs: list[Pair] = []
    if config.reference:
        rendered = sorted(fit[k] for k in torch.randperm(len(fit), generator=gen)[: config.max_renders].tolist())
        condition_of = _condition_sources(train_c2w, fit, rendered + held) if warped else None
        pairs = render_pairs(config.reference, config.data, rendered + held, gen, perturbed=config.perturbed, progress=config.progress,
                             condition_of=condition_of)
        if config.downscale != 1.0 and pairs and pairs[0].render.shape[-2:] != images[pairs[0].index].shape[-2:]:
            raise ConfigError("--downscale must match the reference run's image size when --reference is given")
    held_set = set(held)
    train_pairs = [q for q in pairs if q.index not in held_set]
    ref_of = lambda i: images[int(neighbour[i])] if config.condition == "view" else None  # noqa: E731
    if pairs:
        val_items = [(q.render, q.target, q.mask, q.condition if warped else ref_of(q.index)) for q in pairs if q.index in held_set]
    else:  # held-out training images, degraded synthetically with a fixed seed
        vgen = torch.Generator().manual_seed(config.seed + 7919)
        val_items = [(degrade(images[i][None], vgen, config.degradations, config.strength)[0], images[i],
                      torch.ones(1, *images[i].shape[-2:]), ref_of(i)) for i in held]
    validate = _Validator(val_items, lpips) if val_items else None

    sizes = [tuple(images[i].shape[-2:]) for i in fit] + [tuple(q.render.shape[-2:]) for q in train_pairs]
    sampler = _CropSampler(config.crop, sizes, gen)
    net = ResidualUNet(config.width, config.condition != "none", WARPED_CHANNELS if warped else 3)
    if config.init is not None:
        load_prior(net, config.init)
    lpips_term = _lpips_loss(lpips, config.lpips_weight)

    def next_batch() -> tuple[Tensor, Tensor, Tensor, Optional[Tensor]]:
        inp, tgt, msk, ref = [], [], [], []
        for _ in range(config.batch_size):  # builds the batch; per-sample crops, not pixels
            if train_pairs and float(torch.rand((), generator=gen)) < config.pair_fraction:
                q = train_pairs[int(torch.randint(len(train_pairs), (), generator=gen))]
                y, x = sampler.pair_window(q)
                inp.append(sampler.cut(q.render, y, x))
                tgt.append(sampler.cut(q.target, y, x))
                msk.append(sampler.cut(q.mask, y, x))
                i = q.index
                if warped:
                    ref.append(sampler.cut(q.condition, y, x))
            else:
                k = int(torch.randint(len(fit), (), generator=gen))
                i = fit[k]
                y, x = sampler.window(k)
                clean = sampler.cut(images[i], y, x)
                inp.append(degrade(clean[None], gen, config.degradations, config.strength)[0])
                tgt.append(clean)
                msk.append(torch.ones(1, sampler.crop, sampler.crop))
                if warped:  # no depth for a synthetic degradation: no valid warped pixel
                    ref.append(torch.zeros(WARPED_CHANNELS, sampler.crop, sampler.crop))
            if config.condition == "view":
                ref.append(sampler.cut(images[int(neighbour[i])], y, x))
        return torch.stack(inp), torch.stack(tgt), torch.stack(msk), (torch.stack(ref) if config.condition != "none" else None)

    losses, history, best_step = fit_network(net, next_batch, validate, lpips_term, config.steps, config.lr, config.checkpoints,
                                             config.progress, "train enhancer")
    train_seconds = time.time() - t0

    # The U-Net's receptive radius is ~24 px: an overlap of 96 gives tiles a 24 px zero-weight margin.
    meta = {"tile_size": "512", "overlap": "96", "description": "nerf2gs built-in residual U-Net (not Difix)",
            "nerf2gs.steps": str(config.steps), "nerf2gs.width": str(config.width),
            "nerf2gs.selected_step": str(best_step if best_step is not None else config.steps)}
    if warped:
        meta["nerf2gs.condition"] = config.condition
    out = Path(config.out)
    atomic_write_bytes(out, export_onnx(net, out, meta))

    heldout: dict = {}
    splits = list(config.eval_splits) or [s for s in list_splits(config.data) if s != "train"]
    if splits:
        enh = OnnxModelEnhancer(out)
        held_imgs, refs = [], []
        for s in splits:
            imgs, cents = load_split_images(config.data, s, config.downscale)
            held_imgs += imgs
            if config.condition == "view":
                near = torch.cdist(cents, centres[fit_t]).argmin(1)
                refs += [images[fit[int(k)]] for k in near]
        # warped: no reference depth for a degraded image, so no condition (the model gets all-zero validity)
        heldout = heldout_psnr(enh.enhance, held_imgs, config.degradations, config.strength, config.seed,
                               refs if config.condition == "view" else None)
        heldout["splits"] = splits
    counts = {kind: sum(q.kind == kind for q in train_pairs) for kind in ("pose", "perturbed")}
    report = TrainReport(str(out), config.steps, train_seconds, losses, heldout,
                         {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(config).items() if k != "reference"}
                         | {"reference": [str(r) for r in config.reference]}, threads=torch.get_num_threads(),
                         validation=history, selected_step=best_step, pairs=counts)
    atomic_write_text(report_path(out), json.dumps(asdict(report), indent=1))
    return report



def fit_network(net: ResidualUNet, next_batch: Callable[[], tuple[Tensor, Tensor, Tensor, Optional[Tensor]]],
                validate: Optional["_Validator"], lpips_term, steps: int, lr: float, checkpoints: int, progress: bool,
                label: str) -> tuple[list[float], list[dict], Optional[int]]:
    """Adam + one-cycle over ``steps`` batches ``(input, target, mask, reference)`` (``[B, C, h, w]``),
    masked L1 (+ ``lpips_term``). ``validate`` scores the network before training and ``checkpoints``
    times during it; the best state is loaded back into ``net``. Returns (mean loss per logging window,
    the validation history, the selected step: 0 = the state it started from; None without ``validate``)."""
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    # 5% warm-up; one-cycle divides by (pct_start x steps - 1), zero at exactly 20 steps
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps, pct_start=0.05 if steps != 20 else 0.1)
    losses, window, history = [], [], []
    best = None
    if validate is not None:  # the starting state (the identity, or a prior): the baseline to beat
        history.append({"step": 0} | validate(net))
        best = (history[-1]["score"], 0, {k: v.clone() for k, v in net.state_dict().items()})
    every = max(1, steps // max(checkpoints, 1))
    log_every = max(1, steps // 50)
    with make_progress(progress) as bar:
        task = bar.add_task(label, total=steps, stats="")
        for step in range(steps):
            inp_t, tgt_t, msk_t, ref_t = next_batch()
            out = net(inp_t, ref_t)
            loss = ((out - tgt_t).abs() * msk_t).sum() / (msk_t.sum() * 3).clamp_min(1)
            if lpips_term is not None:
                loss = loss + lpips_term(out * msk_t + tgt_t * (1 - msk_t), tgt_t)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            window.append(float(loss.detach()))
            if len(window) == log_every or step == steps - 1:
                losses.append(sum(window) / len(window))
                window = []
                bar.update(task, stats=f"loss {losses[-1]:.4f}" + (f" val {history[-1]['psnr']:.2f} dB" if history else ""))
            if validate is not None and ((step + 1) % every == 0 or step == steps - 1):
                history.append({"step": step + 1} | validate(net))
                if history[-1]["score"] > best[0]:
                    best = (history[-1]["score"], step + 1, {k: v.clone() for k, v in net.state_dict().items()})
            bar.update(task, advance=1)
    if best is not None:
        net.load_state_dict(best[2])
    return losses, history, best[1] if best is not None else None


def save_prior(net: ResidualUNet, path: Path, info: dict) -> None:
    """The network's weights (``.pt``) for ``--init``: a prior that a capture's own pairs fine-tune."""
    import io

    buf = io.BytesIO()
    torch.save({"state": net.state_dict(), "width": net.width, "condition": net.condition,
                "reference_channels": net.reference_channels, "info": info}, buf)
    atomic_write_bytes(path, buf.getvalue())


def load_prior(net: ResidualUNet, path: Path) -> dict:
    """Load a prior saved by :func:`save_prior` into ``net`` (same width and inputs); returns its info."""
    path = Path(path)
    if not path.is_file():
        raise DataError("enhancer prior does not exist", path)
    try:
        doc = torch.load(path, map_location="cpu", weights_only=True)
        state = doc["state"]
    except Exception as e:  # noqa: BLE001 - any unreadable file is the same user error
        raise DataError(f"not an enhancer prior (expected a file written by `ns2gs-enhance pretrain`): {e}", path) from None
    if (doc.get("width"), doc.get("condition"), doc.get("reference_channels")) != (net.width, net.condition, net.reference_channels):
        raise ConfigError(f"enhancer prior {path} has width {doc.get('width')}, condition {doc.get('condition')}, "
                          f"{doc.get('reference_channels')} reference channels; this network has {net.width}, {net.condition}, "
                          f"{net.reference_channels} (set --width / --condition to match)")
    net.load_state_dict(state)
    return doc.get("info", {})


def report_path(model: Path) -> Path:
    """``enhancer.onnx`` -> ``enhancer.report.json`` (not ``.onnx.json``: that name is the sidecar)."""
    model = Path(model)
    return model.with_name(model.stem + ".report.json")
