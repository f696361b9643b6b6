"""A prior for the built-in enhancer: pre-training on generated streets whose truth from above is known.

Why: a capture's own pairs cannot teach what tops of buildings and the road look like from above
(the truth of a raised ``perturbed`` pair is a street photo warped up, stretched and undersampled),
so an enhancer trained on them alone barely moves bird's-eye renders. Our street generator can give
that truth. For each seed, a street of its own layout, camera height, field of view, drive length,
cars and bird's-eye heights/pitches is generated (:mod:`nerf2gs_plugin.data.synthetic_street`), a
StreetNeRF reference is trained on its training views exactly as a capture's would be, and every
held-out camera of the street (street level and from above) gives a pair: the reference's render
there and the ray-cast truth. The U-Net is trained on those pairs, the last seed's street held out
to choose the exported state. The prior is written as weights (``.pt``, for ``ns2gs-enhance train
--init``, which fine-tunes it on a capture's own pairs) and as an ONNX enhancer usable as it is.

Generated streets, references and renders are kept under ``work`` and reused (the step is
resumable). Evaluate a prior only on streets it was not pre-trained on: the generator's seeds
name the layouts (the embedded street is seed 0; the benches' second street seed 7).
"""

from __future__ import annotations

import dataclasses
import io
import json
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.enhancer.pairs import Pair
from nerf2gs_plugin.enhancer.train import _CropSampler, _lpips_loss, _Validator, fit_network, report_path, save_prior, training_threads
from nerf2gs_plugin.enhancer.unet import ResidualUNet, export_onnx
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.lpips import LPIPS
from nerf2gs_plugin.progress import make_progress
from nerf2gs_plugin.utils.io import atomic_write_bytes, atomic_write_text

# Seeds no bench evaluates on (0: the embedded street, 7: the second street).
DEFAULT_SEEDS = (101, 102, 103, 104, 105, 106)
RESERVED_SEEDS = (0, 7)


@dataclass
class EnhancerPretrainConfig:
    """``ns2gs-enhance pretrain``: generated streets -> references -> (render, truth) pairs -> a prior."""

    out: Path = Path("outputs/enhancer/prior.onnx")
    """The prior as an ONNX enhancer; its weights go next to it (``.pt``) with a report (``.report.json``)."""
    work: Path = Path("outputs/enhancer/prior_streets")
    """Generated streets and their references (reused when present)."""
    seeds: tuple[int, ...] = DEFAULT_SEEDS
    """One generated street per seed (the last one is held out to choose the exported state)."""
    width: int = 200
    """Image size of the generated streets: match the capture's (after downscale)."""
    height: int = 112
    num_bev: int = 24
    """Bird's-eye views per split (two splits) of each generated street: the pairs from above."""
    reference_steps: int = 1500
    """StreetNeRF steps per street: as long as the capture's reference trains (renders like it)."""
    steps: int = 3000
    batch_size: int = 8
    crop: int = 64
    lr: float = 2e-3
    net_width: int = 16
    """Channels of the U-Net's first level (``ns2gs-enhance train --width`` must match to fine-tune)."""
    lpips_weight: float = 0.3
    checkpoints: int = 10
    seed: int = 0
    threads: int = 0
    """Torch threads (0: auto, as ``ns2gs-enhance train``)."""
    progress: bool = True


@dataclass
class PretrainReport:
    out: str
    weights: str
    seconds: float
    streets: list[dict] = field(default_factory=list)  # per seed: generator settings, pairs
    losses: list[float] = field(default_factory=list)
    validation: list = field(default_factory=list)  # on the held-out street's pairs; step 0 = identity
    selected_step: Optional[int] = None
    config: dict = field(default_factory=dict)

    def summary_lines(self) -> list[str]:
        first = self.validation[0] if self.validation else None
        chosen = next((v for v in self.validation if v["step"] == self.selected_step), None)
        lines = [f"prior saved to {self.out} and {self.weights} ({self.seconds:.0f} s, {len(self.streets)} streets)"]
        if first and chosen:
            lp = lambda v: f", LPIPS {v['lpips']:.4f}" if v["lpips"] is not None else ""  # noqa: E731
            lines.append(f"held-out street: identity PSNR {first['psnr']:.2f} dB{lp(first)}; exported step "
                         f"{self.selected_step}: PSNR {chosen['psnr']:.2f} dB{lp(chosen)}")
        return lines


def street_settings(seed: int, width: int, height: int, num_bev: int) -> dict:
    """Generator settings of the pre-training street ``seed``: layout and everything else drawn from it,
    bird's-eye heights/pitches spread around the augmentation's default (10 m up, 30 deg down)."""
    if seed in RESERVED_SEEDS:
        raise ConfigError(f"seed {seed} is a bench's evaluation street ({', '.join(map(str, RESERVED_SEEDS))} are reserved): "
                          "a prior must not be pre-trained on the scenes it is measured on")
    rng = random.Random(seed * 7919 + 1)
    u = lambda lo, hi: round(rng.uniform(lo, hi), 2)  # noqa: E731
    return {"seed": seed, "width": width, "height": height, "cam_height": u(1.8, 3.5), "fov_deg": u(65.0, 90.0),
            "num_cars": rng.randint(3, 8), "drive_half_len": min(u(18.0, 32.0), 30.0), "num_bev": num_bev,  # 30: the generator's longest
            "bev_1": (u(5.0, 12.0), u(20.0, 40.0)), "bev_2": (u(8.0, 16.0), u(25.0, 45.0))}


def _street(work: Path, settings: dict, progress: bool) -> Path:
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

    out = work / f"street-{settings['seed']}"
    done = out / "settings.json"
    if done.is_file() and json.loads(done.read_text()) == json.loads(json.dumps(settings)):
        return out
    # the prior learns views from above: the street's lane-shift test views are not its pairs
    generate_street(SynthStreetConfig(out=out, overwrite=True, progress=progress, num_lane=0, num_val_lane=0, **settings))
    atomic_write_text(done, json.dumps(settings))
    return out


def _reference(data: Path, run: Path, steps: int, progress: bool, log: Callable[[str], None]) -> Path:
    """A StreetNeRF of ``steps`` steps on ``data`` in ``run`` (reused when finished, resumed when partial)."""
    from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.utils.config import apply_plain

    ckpts = list_checkpoints(run) if run.is_dir() else []
    if ckpts and int(load_checkpoint(ckpts[-1])["step"]) >= steps - 1:
        return run
    cfg = apply_plain(get_method("streetnerf").with_steps(steps), {"steps_per_eval_image": 0}, where="enhancer prior reference")
    cfg = dataclasses.replace(cfg, data=data, progress=progress, run_dir=run, load_checkpoint=ckpts[-1] if ckpts else None)
    log(f"pretrain: StreetNeRF ({steps} steps) on {data} -> {run}")
    trainer = Trainer(cfg)
    trainer.setup()
    trainer.train()
    return run


def street_pairs(data: Path, run: Path, index: int, progress: bool = True) -> list[Pair]:
    """Every held-out camera of a generated street: (the reference's render there, the ray-cast truth)."""
    from nerf2gs_plugin.runs.load import load_run

    loaded = load_run(run, data=data)
    dm = loaded.pipeline.datamanager
    pairs: list[Pair] = []
    names = dm.eval_split_names()
    with make_progress(progress) as bar, torch.no_grad():
        task = bar.add_task(f"render street {index}", total=sum(len(dm.eval_split(s)[1]) for s in names), stats="")
        for s in names:
            _, imgs = dm.eval_split(s)
            for i in range(len(imgs)):
                render = loaded.model.render_camera(imgs.cameras[i])["rgb"].detach()
                gt = imgs.image(i)
                pairs.append(Pair(render.permute(2, 0, 1).contiguous().float().cpu(), gt.permute(2, 0, 1).contiguous().float().cpu(),
                                  torch.ones(1, *gt.shape[:2]), index, s))
                bar.update(task, advance=1, stats=s)
    return pairs


def _cached_pairs(data: Path, run: Path, index: int, progress: bool) -> list[Pair]:
    """``street_pairs``, stored beside the reference (keyed by its checkpoint) so a second pre-training reuses them."""
    from nerf2gs_plugin.engine.checkpoints import file_hash, resolve_checkpoint

    key = file_hash(resolve_checkpoint(run)[1])
    path = run / f"pairs-{key}.pt"
    if path.is_file():
        doc = torch.load(path, map_location="cpu", weights_only=True)
        return [Pair(r, t, torch.ones(1, *r.shape[-2:]), index, k) for r, t, k in zip(doc["render"], doc["target"], doc["kind"])]
    pairs = street_pairs(data, run, index, progress)
    buf = io.BytesIO()
    torch.save({"render": [q.render for q in pairs], "target": [q.target for q in pairs], "kind": [q.kind for q in pairs]}, buf)
    atomic_write_bytes(path, buf.getvalue())
    return pairs


def pretrain_enhancer(config: EnhancerPretrainConfig, log: Callable[[str], None] = print) -> PretrainReport:
    """Generate, train references, render pairs, fit the U-Net; writes ``out`` (.onnx), its ``.pt`` and a report."""
    if len(config.seeds) < 2:
        raise ConfigError(f"--seeds needs at least 2 streets (one is held out to choose the exported state), got {len(config.seeds)}")
    if len(set(config.seeds)) != len(config.seeds):
        raise ConfigError(f"--seeds has repeats: {config.seeds}")
    if config.steps < 1 or config.reference_steps < 1:
        raise ConfigError(f"--steps and --reference-steps must be >= 1 (got {config.steps}, {config.reference_steps})")
    settings = [street_settings(s, config.width, config.height, config.num_bev) for s in config.seeds]
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    threads_before = torch.get_num_threads()
    torch.set_num_threads(training_threads(config.threads))
    t0 = time.time()
    try:
        work = Path(config.work)
        by_street: list[list[Pair]] = []
        for k, st in enumerate(settings):
            data = _street(work, st, config.progress)
            run = _reference(data, work / f"street-{st['seed']}-streetnerf", config.reference_steps, config.progress, log)
            by_street.append(_cached_pairs(data, run, k, config.progress))
        train_pairs = [q for pairs in by_street[:-1] for q in pairs]
        lpips = LPIPS.load_default()
        validate = _Validator([(q.render, q.target, q.mask, None) for q in by_street[-1]], lpips)
        sampler = _CropSampler(config.crop, [tuple(q.render.shape[-2:]) for q in train_pairs], gen)
        net = ResidualUNet(config.net_width)

        def next_batch() -> tuple[Tensor, Tensor, Tensor, Optional[Tensor]]:
            inp, tgt = [], []
            for _ in range(config.batch_size):
                q = train_pairs[int(torch.randint(len(train_pairs), (), generator=gen))]
                y, x = sampler.pair_window(q)
                inp.append(sampler.cut(q.render, y, x))
                tgt.append(sampler.cut(q.target, y, x))
            inp_t = torch.stack(inp)
            return inp_t, torch.stack(tgt), torch.ones(len(inp), 1, *inp_t.shape[-2:]), None

        losses, history, best_step = fit_network(net, next_batch, validate, _lpips_loss(lpips, config.lpips_weight), config.steps,
                                                 config.lr, config.checkpoints, config.progress, "pretrain enhancer")
    finally:
        torch.set_num_threads(threads_before)
    out = Path(config.out)
    weights = out.with_suffix(".pt")
    info = {"seeds": list(config.seeds), "reference_steps": config.reference_steps, "steps": config.steps, "selected_step": best_step}
    save_prior(net, weights, info)
    meta = {"tile_size": "512", "overlap": "96", "description": "nerf2gs built-in residual U-Net prior, pre-trained on generated streets (not Difix)",
            "nerf2gs.steps": str(config.steps), "nerf2gs.width": str(config.net_width), "nerf2gs.selected_step": str(best_step),
            "nerf2gs.pretrain_seeds": ",".join(map(str, config.seeds))}
    atomic_write_bytes(out, export_onnx(net, out, meta))
    streets = [st | {"pairs": len(p), "held_out": k == len(settings) - 1} for k, (st, p) in enumerate(zip(settings, by_street))]
    report = PretrainReport(str(out), str(weights), time.time() - t0, streets, losses, history, best_step,
                            {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(config).items()})
    atomic_write_text(report_path(out), json.dumps(asdict(report), indent=1))
    return report
