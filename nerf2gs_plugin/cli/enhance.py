"""ns2gs-enhance train | pretrain | apply | eval: the enhancer of additional views.

``pretrain`` makes a prior on generated streets whose truth from above is known (``train --init``
fine-tunes it on a capture); ``train`` fits our built-in enhancer (a small residual U-Net, not Difix) on a dataset's own images
and exports it to ONNX; ``apply`` runs any enhancer (built-in or ``onnx:PATH``) on image files;
``eval`` measures PSNR before/after enhancement on held-out views: the renders of a reference run
(``--reference``) or synthetically degraded held-out images.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_plugin.enhancer.pretrain import EnhancerPretrainConfig
from nerf2gs_plugin.enhancer.train import EnhancerTrainConfig


def _spec(model: str) -> str:
    """A bare path means ``onnx:PATH``."""
    return model if model.split(":", 1)[0] in ("none", "builtin", "onnx") else f"onnx:{model}"


@dataclass
class Train(EnhancerTrainConfig):
    """Train the built-in enhancer on DATA's training images; writes OUT (.onnx) and a report."""

    def main(self) -> None:
        from nerf2gs_plugin.enhancer.train import report_path, train_enhancer

        report = train_enhancer(self)
        for line in report.summary_lines():
            print(line)
        print(f"report: {report_path(Path(report.out))}")


@dataclass
class Pretrain(EnhancerPretrainConfig):
    """Pre-train the built-in enhancer on generated streets (truth from above known); writes OUT (.onnx), its .pt and a report."""

    def main(self) -> None:
        from nerf2gs_plugin.enhancer.pretrain import pretrain_enhancer
        from nerf2gs_plugin.enhancer.train import report_path

        report = pretrain_enhancer(self)
        for line in report.summary_lines():
            print(line)
        print(f"report: {report_path(Path(report.out))}")


@dataclass
class Apply:
    """Enhance image files: --model MODEL --input a.png b.png --output DIR."""

    model: str
    """builtin | builtin:PATH | onnx:PATH | PATH.onnx"""
    input: tuple[Path, ...]
    output: Path
    """Output folder (or a file name when there is one input)."""
    reference: Optional[Path] = None
    """Reference view given to models that take one."""
    tile_size: Optional[int] = None

    def main(self) -> None:
        from nerf2gs_plugin.data.images import load_image, write_image_atomic
        from nerf2gs_plugin.enhancer import OnnxModelEnhancer, make_enhancer
        from nerf2gs_plugin.errors import DataError

        spec = _spec(self.model)
        enh = make_enhancer(spec)
        if self.tile_size and isinstance(enh, OnnxModelEnhancer):
            enh = OnnxModelEnhancer(enh.path, tile_size=self.tile_size)
        ref = load_image(self.reference) if self.reference is not None else None
        to_file = len(self.input) == 1 and self.output.suffix.lower() in (".png", ".jpg", ".jpeg")
        for p in self.input:
            if not Path(p).is_file():
                raise DataError("input image does not exist", p)
            out = self.output if to_file else self.output / Path(p).name
            write_image_atomic(out, enh.enhance(load_image(p), reference=ref))
            print(f"{p} -> {out}")


@dataclass
class Eval:
    """PSNR and LPIPS before/after enhancement on held-out views (renders of --reference, else degraded images)."""

    model: str
    data: Path
    reference: Optional[Path] = None
    """A trained run: its renders of the held-out cameras are enhanced and compared with ground truth."""
    splits: tuple[str, ...] = ()
    """Held-out splits (default: all eval splits of the dataset)."""
    max_images: Optional[int] = None
    out: Optional[Path] = None
    """Also write the numbers as JSON here."""

    def main(self) -> None:
        result = evaluate_enhancer(_spec(self.model), self.data, self.reference, self.splits, self.max_images)
        for split, r in result["splits"].items():
            lp = f"  LPIPS {r['lpips_before']:.4f} -> {r['lpips_after']:.4f}" if r.get("lpips_before") is not None else ""
            print(f"{split:>8}: {r['images']:3d} images  PSNR {r['psnr_before']:.2f} -> {r['psnr_after']:.2f} dB{lp}")
        if self.out is not None:
            from nerf2gs_plugin.utils.io import atomic_write_text

            atomic_write_text(self.out, json.dumps(result, indent=1))


def evaluate_enhancer(spec: str, data: Path, reference: Optional[Path], splits: tuple[str, ...] = (), max_images: Optional[int] = None) -> dict:
    """Per split: mean PSNR (and LPIPS, when its weights are installed) of the held-out inputs
    (reference renders or degraded images) and of their enhancement. The reference view given to the
    enhancer is the training view nearest each camera (for a ``warped``-conditioned model, the nearest
    facing the same way, warped in through the reference's depth; without ``reference`` there is no
    depth, so it gets none)."""
    import torch

    from nerf2gs_plugin.data import list_splits
    from nerf2gs_plugin.enhancer import make_enhancer
    from nerf2gs_plugin.enhancer.degrade import KINDS
    from nerf2gs_plugin.enhancer.train import heldout_psnr, load_split_images
    from nerf2gs_plugin.utils.image_metrics import psnr

    enh = make_enhancer(spec)
    names = list(splits) or [s for s in list_splits(data) if s != "train"]
    result: dict = {"model": spec, "data": str(data), "reference": str(reference) if reference else None, "splits": {}}
    if reference is None:
        train_imgs, train_c = load_split_images(data, "train")
        for s in names:
            imgs, cents = load_split_images(data, s)
            imgs, cents = imgs[:max_images], cents[:max_images]
            refs = [train_imgs[int(k)] for k in torch.cdist(cents, train_c).argmin(1)]
            r = heldout_psnr(enh.enhance, imgs, KINDS, 1.0, 0, None if getattr(enh, "reference_kind", "image") == "warped" else refs)
            result["splits"][s] = {"images": r["images"], "psnr_before": r["psnr_degraded"], "psnr_after": r["psnr_enhanced"]}
        return result
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.utils.lpips import LPIPS
    from nerf2gs_plugin.progress import make_progress

    lpips = LPIPS.load_default()
    run = load_run(reference, data=data)
    dm = run.pipeline.datamanager
    train = dm.train_images
    train_c = train.cameras.camera_to_worlds[:, :3, 3]
    source_depths: dict[int, torch.Tensor] = {}
    from nerf2gs_plugin.enhancer.warp import condition_source

    def warped(camera, rendered: dict, k: int) -> torch.Tensor:
        """Training view ``k`` warped into ``camera`` through the reference's depth, as the augmentation does."""
        from nerf2gs_plugin.enhancer.warp import clear_mask, warped_reference

        if k not in source_depths:
            source_depths[k] = run.model.render_camera(train.cameras[k])["depth"].detach().cpu()
        return warped_reference(camera.to("cpu"), rendered["depth"].detach().cpu(), train.cameras[k].to("cpu"), source_depths[k],
                                train.image(k).cpu(), clear_mask(train.mask("transient", k), *train.hw(k)), run.model.depth_along)

    with make_progress() as bar, torch.no_grad():
        for s in names:
            _, imgs = dm.eval_split(s)
            n = len(imgs) if max_images is None else min(len(imgs), max_images)
            task = bar.add_task(f"enhance {s}", total=n, stats="")
            before, after, lp_before, lp_after = [], [], [], []
            for i in range(n):
                gt = imgs.image(i).cpu()
                rendered = run.model.render_camera(imgs.cameras[i])
                render = rendered["rgb"].detach().cpu()
                k = int(torch.cdist(imgs.cameras.camera_to_worlds[i : i + 1, :3, 3], train_c).argmin())
                if getattr(enh, "reference_kind", "image") == "warped":  # the nearest training view facing the same way, warped in
                    ref = warped(imgs.cameras[i], rendered, condition_source(imgs.cameras.camera_to_worlds[i], train.cameras.camera_to_worlds))
                else:
                    ref = train.image(k).cpu()
                out = enh.enhance(render, reference=ref)
                before.append(float(psnr(render, gt)))
                after.append(float(psnr(out, gt)))
                if lpips is not None:
                    lp_before.append(float(lpips(render, gt)))
                    lp_after.append(float(lpips(out, gt)))
                bar.update(task, advance=1, stats=f"{before[-1]:.2f} -> {after[-1]:.2f}")
            result["splits"][s] = {"images": n, "psnr_before": sum(before) / max(n, 1), "psnr_after": sum(after) / max(n, 1),
                                   "lpips_before": sum(lp_before) / n if lp_before else None,
                                   "lpips_after": sum(lp_after) / n if lp_after else None}
    return result


def main() -> None:
    cmd = tyro.extras.subcommand_cli_from_dict({"train": Train, "pretrain": Pretrain, "apply": Apply, "eval": Eval}, description=__doc__)
    cmd.main()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
